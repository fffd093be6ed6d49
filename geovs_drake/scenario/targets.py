"""How the target moves, one variant each (``ScenarioConfig.target_motion``), and what the
loop knows of that motion (the feed-forward modes, :data:`FEEDFORWARD_MODES`).

In YAML a motion is tagged with its class name, ``target_motion: !Twist {twist: [0, 0, 0.2,
0.05, 0, 0]}``; a scenario file's bare name (``target_motion: still``) reads as that
variant with its defaults. The field is ``target_motion``, not ``target``: ``target`` is
already the target's pose X_WB at t = 0 (where a moving target starts).

A moving target's body twist xi_B = (omega, v) is expressed in its own frame B, angular
part first (as ``initial_velocity``). Constant, it moves the target on a helix about its
screw axis (a circle where v is orthogonal to omega, a line where omega = 0). The goal
stays the relative pose X_BC*: the loop tracks the target.

The general motion is a trajectory of poses (:class:`Trajectory`), the target's
displacement X_B0B(t) from its start: X_WB(t) = X_WB(0) X_B0B(t), the same convention as
:class:`Twist`'s X_B0B(t) = exp(t xi^). :func:`target_trajectory` makes it Drake's
``PiecewisePose``; :func:`trajectory_of` makes a user's ``PiecewisePose`` the config.
"""

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform
from pydrake.trajectories import PiecewisePose

from geovs_drake.scenario.pose import finite_numbers
from geovs_drake.scenario.traits import TargetTraits

__all__ = [
    "ESTIMATOR_RATE_HZ",
    "FEEDFORWARD_MODES",
    "TARGET_VARIANTS",
    "Still",
    "TargetMotionConfig",
    "Trajectory",
    "Twist",
    "check_target_motion",
    "target_motion_arguments",
    "target_trajectory",
    "trajectory_of",
]

#: What the loop knows of the target's motion, by ``Twist.feedforward`` (``--feedforward``):
#: the one registry of the modes (the systems that make each: ``loop.targets``).
FEEDFORWARD_MODES: dict[str, str] = {
    "none": "no feed-forward: the still target's law as it is (it lags the target)",
    "known": "the target's true twist (and acceleration) carried to the camera",
    "estimated": (
        "the twist a constant-twist Kalman filter estimates from the images and the "
        "carrier's own pose (odometry)"
    ),
}

#: The estimator's update rate with the exact sensor [Hz] (a camera: its frame rate).
ESTIMATOR_RATE_HZ = 50.0


@dataclass
class Still:
    """The target stands still at ``target`` (X_WB): the loop of the paper, unchanged."""

    traits: ClassVar[TargetTraits] = TargetTraits(moving=False, constant_twist=False)


@dataclass
class Twist:
    """The target moves with the constant body twist ``twist`` = (omega, v) in B [rad/s,
    m/s], angular part first, from ``target`` (X_WB(0)): X_WB(t) = X_WB(0) exp(t xi^).

    ``feedforward``: what the loop adds for it (:data:`FEEDFORWARD_MODES`). The estimator
    (``estimated``) takes ``pose_noise`` [m and rad], the standard deviation it assumes of
    each measured pose of the target, and ``twist_noise`` [(m/s, rad/s) / sqrt(s)], the
    random walk it allows the twist; it updates at the camera's frame rate, or at
    :data:`ESTIMATOR_RATE_HZ` with the exact sensor.
    """

    twist: list[float] = field(default_factory=lambda: [0.0] * 6)
    feedforward: str = "estimated"
    pose_noise: float = 1e-3
    twist_noise: float = 1e-3

    traits: ClassVar[TargetTraits] = TargetTraits(moving=True, constant_twist=True)


#: A pose row's columns: the time [s], X_B0B's unit quaternion, its position [m].
POSE_COLUMNS = ("t", "qw", "qx", "qy", "qz", "x", "y", "z")
#: How close the pose at t = 0 must be to the identity (quaternion and position).
_IDENTITY_TOLERANCE = 1e-9


@dataclass
class Trajectory:
    """The target moves along a trajectory of poses from ``target`` (X_WB(0)):
    X_WB(t) = X_WB(0) X_B0B(t), X_B0B(t) the displacement from the start pose (the
    convention of :class:`Twist`, whose X_B0B(t) = exp(t xi^)).

    The knots are rows ``t, qw, qx, qy, qz, x, y, z`` [s, unit quaternion, m], either in
    the CSV file ``file`` (relative to the current directory; a header line starting
    with ``t`` and ``#`` comments allowed) or inline, ``poses`` (a list of such rows):
    exactly one of the two. The times start at 0 and increase strictly; the pose at
    t = 0 is the identity; the quaternions are normalised. Between knots the position is
    a cubic spline with zero end velocities and the orientation a slerp
    (:func:`target_trajectory`); from the last knot on the target holds its last pose.

    ``feedforward``, ``pose_noise``, ``twist_noise``: as :class:`Twist`'s.
    """

    file: str = ""
    #: None where not given (a file gives the rows): the scenario loader leaves a field
    #: whose default is None to Drake, which reads a list of rows.
    poses: list[list[float]] | None = None
    feedforward: str = "estimated"
    pose_noise: float = 1e-3
    twist_noise: float = 1e-3

    traits: ClassVar[TargetTraits] = TargetTraits(moving=True, constant_twist=False)


#: A target motion: one of the variants above.
TargetMotionConfig = Still | Twist | Trajectory
#: The target motion of each name, as a file's bare name gives it.
TARGET_VARIANTS: dict[str, type] = {"still": Still, "twist": Twist, "trajectory": Trajectory}


def check_target_motion(motion: object) -> None:
    """The motion variant's own fields, each named ``target_motion.<field>``; a
    :class:`Trajectory`'s file is read here (:func:`target_trajectory` reads it again)."""
    if isinstance(motion, Twist):
        if finite_numbers(motion.twist, 6) is None:
            raise ValueError(
                "target_motion.twist must be 6 finite numbers (omega, v) in B [rad/s, m/s], "
                f"got {motion.twist!r}"
            )
        _check_feedforward(motion)
    elif isinstance(motion, Trajectory):
        _knots(motion)
        _check_feedforward(motion)


def _rows(motion: Trajectory) -> tuple[str, list[tuple[str, list[str] | list[float]]]]:
    """Where the rows come from and each row with where it is (the file's line, or the
    index in ``poses``), for the errors; the rows not yet numbers."""
    given = [name for name in ("file", "poses") if getattr(motion, name) not in ("", None)]
    if len(given) != 1:
        raise ValueError(
            "target_motion: a Trajectory needs exactly one of file (a CSV of poses) and "
            f"poses (the rows inline), got file = {motion.file!r}, poses = "
            f"{'none' if motion.poses is None else f'{len(motion.poses)} rows'}"
        )
    if motion.poses is not None:
        if not isinstance(motion.poses, list):
            raise ValueError(
                f"target_motion.poses must be a list of rows {', '.join(POSE_COLUMNS)}, "
                f"got {motion.poses!r}"
            )
        where = "target_motion.poses"
        return where, [(f"{where}[{k}]", row) for k, row in enumerate(motion.poses)]
    where = f"target_motion.file {motion.file!r}"
    try:
        text = Path(motion.file).read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{where}: cannot read it: {getattr(e, 'strerror', None) or e}") from None
    rows: list[tuple[str, list[str] | list[float]]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        content = line.split("#", 1)[0].strip()
        # One header line, before the first row: the column names, "t, qw, ...".
        if content and not (not rows and content.lower().startswith("t")):
            rows.append((f"{where}, line {number}", [v.strip() for v in content.split(",")]))
    return where, rows


def _knots(motion: Trajectory) -> tuple[np.ndarray, list[RigidTransform]]:
    """The knots' times and poses X_B0B (quaternions normalised), checked: ValueError in
    one line naming the field (or the file and its line) and the broken condition."""
    where, rows = _rows(motion)
    values = []
    for label, row in rows:
        try:
            numbers = np.asarray(row, dtype=float)
        except (TypeError, ValueError):
            numbers = np.full(0, np.nan)
        if numbers.shape != (len(POSE_COLUMNS),) or not np.all(np.isfinite(numbers)):
            raise ValueError(
                f"{label}: expected {len(POSE_COLUMNS)} finite numbers "
                f"{', '.join(POSE_COLUMNS)}, got {row!r}"
            )
        if not np.any(numbers[1:5]):
            raise ValueError(f"{label}: the quaternion is zero, got {row!r}")
        values.append(numbers)
    if len(values) < 2:
        raise ValueError(f"{where}: a trajectory needs at least 2 poses, got {len(values)}")
    table = np.array(values)
    times = table[:, 0]
    steps = np.diff(times)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        raise ValueError(
            f"{rows[k][0]}: the times must increase strictly, got t = {times[k]:g} "
            f"after t = {times[k - 1]:g}"
        )
    if times[0] != 0:
        raise ValueError(
            f"{rows[0][0]}: the first time must be 0 (the target starts at "
            f"target, X_WB(0)), got t = {times[0]:g}"
        )
    quaternions = table[:, 1:5] / np.linalg.norm(table[:, 1:5], axis=1, keepdims=True)
    q0, p0 = quaternions[0], table[0, 5:]
    off = min(np.abs(q0 - [1, 0, 0, 0]).max(), np.abs(q0 + [1, 0, 0, 0]).max())
    if off > _IDENTITY_TOLERANCE or np.abs(p0).max() > _IDENTITY_TOLERANCE:
        raise ValueError(
            f"{rows[0][0]}: the pose at t = 0 must be the identity (the "
            "displacement from target: quaternion 1, 0, 0, 0 and position 0, 0, 0), got "
            f"{table[0, 1:].tolist()}"
        )
    poses = [
        RigidTransform(Quaternion(q), p) for q, p in zip(quaternions, table[:, 5:], strict=True)
    ]
    return times, poses


def target_trajectory(motion: Trajectory) -> PiecewisePose:
    """X_B0B(t) of ``motion`` as Drake's ``PiecewisePose``: the positions a cubic spline
    with zero end velocities, the orientations a slerp between the knots."""
    times, poses = _knots(motion)
    zero = np.zeros(3)
    return PiecewisePose.MakeCubicLinearWithEndLinearVelocity(list(times), poses, zero, zero)


def trajectory_of(pose: PiecewisePose, rate: float = 100.0) -> Trajectory:
    """A :class:`Trajectory` (``poses`` inline) of a user's ``PiecewisePose`` of X_B0B:
    its value at its knots and every ``1 / rate`` s [Hz] between them; ValueError where it
    is no displacement from the start (its start time not 0, its pose there not the
    identity). The feed-forward fields keep their defaults (``dataclasses.replace``)."""
    if not (isinstance(rate, int | float) and math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be finite and > 0 [Hz], got {rate!r}")
    knots = np.asarray(pose.get_segment_times(), dtype=float)
    grid = np.arange(knots[0], knots[-1], 1.0 / rate)
    # Why: a sample a hair from a knot would make a segment too short to fit.
    near = np.min(np.abs(grid[:, None] - knots[None, :]), axis=1) <= 1e-9 * max(1.0, knots[-1])
    rows = []
    for t in np.union1d(knots, grid[~near]):
        X = pose.GetPose(t)
        q = X.rotation().ToQuaternion()
        rows.append([float(t), q.w(), q.x(), q.y(), q.z(), *map(float, X.translation())])
    motion = Trajectory(poses=rows)
    check_target_motion(motion)
    return motion


def target_motion_arguments(motion: TargetMotionConfig) -> dict:
    """The keyword arguments of ``systems.target_motion.TargetMotion`` (besides
    ``X_WB0``) for a moving target: ``twist`` of a :class:`Twist`, ``trajectory``
    (:func:`target_trajectory`) of a :class:`Trajectory`."""
    if isinstance(motion, Twist):
        return {"twist": np.asarray(motion.twist, dtype=float)}
    if isinstance(motion, Trajectory):
        return {"trajectory": target_trajectory(motion)}
    raise ValueError(f"target_motion {type(motion).__name__}() does not move the target")


def _check_feedforward(motion: Twist | Trajectory) -> None:
    """What the loop adds for a moving target: its mode and the estimator's noises."""
    if motion.feedforward not in FEEDFORWARD_MODES:
        raise ValueError(
            f"target_motion.feedforward must be one of {', '.join(FEEDFORWARD_MODES)}, "
            f"got {motion.feedforward!r}"
        )
    for name in ("pose_noise", "twist_noise"):
        value = getattr(motion, name)
        real = isinstance(value, int | float) and not isinstance(value, bool)
        if not (real and math.isfinite(value) and value > 0):
            raise ValueError(f"target_motion.{name} must be finite and > 0, got {value!r}")
