"""One task of a sweep, as it runs on a worker: draw its starts, run them, write its part.

A task is a :class:`Part`: starts [first, last) of a sweep. It draws them
(:func:`~geovs_drake.analysis.sweep.starts.sample_starts`, or slices of arrays
the caller gave), runs them through the batch engine or Drake's Simulator,
and turns them into columns (:data:`ROW_FIELDS`). With a results folder it
writes ``part-XXXXX.parquet`` there, to a hidden temporary name first and then
renamed (``os.replace`` is atomic on one filesystem), so a file under its
final name is always whole, and readers of the folder (pyarrow, pandas, Dask)
skip the hidden ones. The part's :class:`~.summary.SweepSummary` travels in
the file's metadata, so a resumed sweep reads its finished parts' summaries
without reading their rows. The task returns the summary (and, without a
folder, the table itself), a few kB whatever the chunk.
"""

from __future__ import annotations

import copy
import functools
import json
import math
import os
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

from geovs_drake._optional import require
from geovs_drake.analysis.sweep.starts import sample_starts
from geovs_drake.analysis.sweep.summary import SweepSummary, run_ends
from geovs_drake.batch import LoopParameters, loop_parameters, run_batch
from geovs_drake.geometry.domain import SafeDomain
from geovs_drake.loop.resolved import free_twin
from geovs_drake.loop.state import poses_in_target
from geovs_drake.scenario import PoseConfig, ScenarioConfig, load_scenario

if TYPE_CHECKING:  # the Drake loop stays out of the batch engine's workers
    from geovs_drake.systems.arm_model import ArmModel

__all__ = [
    "HOVER_FIELDS",
    "ROW_FIELDS",
    "SUMMARY_KEY",
    "Part",
    "part_name",
    "read_part_summary",
    "row_fields",
    "PartStarts",
    "compute_part",
    "finish_part",
    "prepare_part",
    "run_part",
]

#: Per-start columns, in order. Poses are X_BC (metres, Drake RollPitchYaw in radians);
#: the twist is the camera's body twist (Omega, V) in C [rad/s, m/s].
ROW_FIELDS = (
    "start",
    "x",
    "y",
    "z",
    "roll",
    "pitch",
    "yaw",
    "wx",
    "wy",
    "wz",
    "vx",
    "vy",
    "vz",
    "status",
    "t_converged",
    "final_position_error_m",
    "final_rotation_error_rad",
    "min_fov_margin",
    "min_lambda_margin",
    "min_occlusion_margin",
    "initial_energy_ratio",
    "max_energy_ratio",
    "monotone",
    "final_x",
    "final_y",
    "final_z",
    "final_roll",
    "final_pitch",
    "final_yaw",
    # The arm at the end (NaN on the free rig and the batch engine): its fastest joint
    # [rad/s], phi_q (0 without a barrier) and the nearest joint's margin to its limit
    # [rad]; and how the run ended (summary.run_ends: a stall where the barrier and the
    # NF balance is told from a run still on its way).
    "final_joint_speed",
    "final_joint_barrier",
    "final_joint_margin",
    # Whether an actuator's torque was clamped at its effort limit (the dynamic arm; False
    # elsewhere): the batch engine at any accepted step, the Drake engine at its logged
    # states (the arm carrier's run entry). The one term of the arm's loop that
    # Appendix C's energy argument does not cover.
    "torque_clamped",
    "end",
)
#: The columns a hovering carrier's rows add (``traits.hover``: the quadrotor), after
#: ROW_FIELDS, from its run's ``carrier_entries``: the share of logged samples where the
#: rotor allocation gave anything up, and the largest tilt of the body from level [deg].
HOVER_FIELDS = ("rotor_saturation_fraction", "max_tilt_deg")
#: The Parquet key-value metadata entry that holds a part's summary (JSON).
SUMMARY_KEY = b"geovs_drake.summary"
_POSE = ("x", "y", "z", "roll", "pitch", "yaw")
_TWIST = ("wx", "wy", "wz", "vx", "vy", "vz")
#: The arm's columns at the end of a run (ROW_FIELDS), NaN where there is no arm.
_ARM_END = ("final_joint_speed", "final_joint_barrier", "final_joint_margin")


@dataclass(frozen=True)
class Part:
    """One task: starts [first, last) of a sweep, and how to run and keep them.

    ``config_yaml``: the scenario as YAML (Drake's SimulatorConfig does not pickle).
    ``parameters``: its :func:`~geovs_drake.batch.loop_parameters`, read once by the
    client from the built diagram, so that a worker runs the batch engine's kernels
    without importing the Drake systems (None: the worker builds the diagram itself).
    ``seed``/``velocity``: where the starts come from, unless ``X_BC``/``twists``
    give them. ``results``: the folder of the part files, or None to return the
    table instead. ``single_thread``: one numba thread (K worker processes on K
    cores, not K x cores threads).
    """

    config_yaml: str
    index: int
    first: int
    last: int
    duration: float
    engine: str
    parameters: LoopParameters | None = None
    seed: int = 0
    velocity: str = "none"
    X_BC: np.ndarray | None = None
    twists: np.ndarray | None = None
    results: str | None = None
    single_thread: bool = False


def row_fields(config: ScenarioConfig) -> tuple[str, ...]:
    """The columns of ``config``'s rows: :data:`ROW_FIELDS`, and :data:`HOVER_FIELDS` on a
    hovering carrier."""
    return (*ROW_FIELDS, *HOVER_FIELDS) if config.carrier.traits.hover else ROW_FIELDS


def part_name(index: int, parts: int) -> str:
    """``part-00042.parquet``: five digits at least, more when a sweep has more parts,
    so that the names sort as the parts do."""
    return f"part-{index:0{max(5, len(str(parts - 1)))}d}.parquet"


@functools.lru_cache(maxsize=4)
def _worker_config(config_yaml: str) -> ScenarioConfig:
    """The config, parsed once per worker process."""
    return load_scenario(data=config_yaml)


@functools.lru_cache(maxsize=4)
def _worker_parameters(config_yaml: str) -> LoopParameters:
    """The loop parameters of a part that came without them, once per worker process."""
    return loop_parameters(_worker_config(config_yaml))


@dataclass(frozen=True)
class PartStarts:
    """A part's starts before it runs (:func:`prepare_part`): the camera poses ``X_BC``
    (n, 4, 4), the body twists ``twists`` (n, 6) and, on an arm, each start's joints
    ``joints`` (``(q, v)``, or None where the arm cannot reach it; None off the arm)."""

    X_BC: np.ndarray
    twists: np.ndarray
    joints: list | None = None


def prepare_part(part: Part) -> PartStarts:
    """A part's starts: drawn (or given), and on an arm carried to its joints (IK, the
    branch, the twist to the joints: :class:`_ArmStarts`). It calls no parallel kernel,
    so a sweep in one process prepares the next part on a thread of its own while this
    one integrates (the arm's IK is about half of its sweep's CPU time)."""
    config = _worker_config(part.config_yaml)
    p = part.parameters or _worker_parameters(part.config_yaml)
    n = part.last - part.first
    if part.X_BC is None:
        X_BC, twists = sample_starts(config, n, part.seed, part.velocity, part.first, p)
    else:
        X_BC, twists = part.X_BC, part.twists
    joints = None
    if config.carrier.traits.joints:
        joints = _ArmStarts.of(config, p).part_joints(config, X_BC, twists)
    return PartStarts(X_BC, twists, joints)


def run_part(
    part: Part, name: str | None = None, starts: PartStarts | None = None
) -> tuple[dict, object | None]:
    """Run one part: (its summary as JSON, its pyarrow Table or None when written to
    ``part.results / name``). ``starts``: its :func:`prepare_part`, if made already."""
    return finish_part(part, name, compute_part(part, starts))


def compute_part(part: Part, starts: PartStarts | None = None) -> dict[str, np.ndarray]:
    """A part's result columns before its ends and summary (:func:`finish_part`): the
    engine's run of its starts (``starts``: its :func:`prepare_part`, if made already)."""
    if part.single_thread:
        import numba

        # Not NUMBA_NUM_THREADS in the workers' environment: numba rereads it when it
        # compiles, and refuses a value that differs from the one its pool started with.
        numba.set_num_threads(1)
    config = _worker_config(part.config_yaml)
    p = part.parameters or _worker_parameters(part.config_yaml)
    starts = starts or prepare_part(part)
    X_BC, twists = starts.X_BC, starts.twists
    run = _batch_columns if part.engine == "batch" else _drake_columns
    columns = {"start": np.arange(part.first, part.last, dtype=np.int64)}
    columns.update(_pose_columns(X_BC))
    columns.update(zip(_TWIST, np.asarray(twists, float).T, strict=True))
    columns.update(run(config, p, starts, part.duration))
    return columns


def finish_part(
    part: Part, name: str | None, columns: dict[str, np.ndarray]
) -> tuple[dict, object | None]:
    """A computed part (:func:`compute_part`) finished: its runs' ends, its summary, its
    table, written to ``part.results / name`` (then None in the table's place). It calls
    no compiled kernel: a sweep in one process finishes a part on a thread while the
    next one integrates."""
    config = _worker_config(part.config_yaml)
    columns["end"] = run_ends(columns)
    summary = SweepSummary.of_rows(config, part.duration, columns).to_json()
    table = _table(columns, summary)
    if part.results is None:
        return summary, table
    _write_atomically(table, Path(part.results) / name)
    return summary, None


def _pose_columns(X_BC: np.ndarray, prefix: str = "") -> dict[str, np.ndarray]:
    """x, y, z and the RollPitchYaw (Drake's convention: R = Rz(yaw) Ry(pitch) Rx(roll))
    of each X_BC, for the batch at once; NaN for a non-finite pose."""
    X = np.asarray(X_BC, dtype=float)
    R = X[:, :3, :3]
    columns = {
        "x": X[:, 0, 3],
        "y": X[:, 1, 3],
        "z": X[:, 2, 3],
        "roll": np.arctan2(R[:, 2, 1], R[:, 2, 2]),
        "pitch": np.arctan2(-R[:, 2, 0], np.hypot(R[:, 0, 0], R[:, 1, 0])),
        "yaw": np.arctan2(R[:, 1, 0], R[:, 0, 0]),
    }
    finite = np.all(np.isfinite(X.reshape(len(X), -1)), axis=1)
    return {prefix + k: np.where(finite, v, math.nan) for k, v in columns.items()}


def _batch_columns(
    config: ScenarioConfig, p: LoopParameters, starts: PartStarts, duration: float
) -> dict[str, np.ndarray]:
    """The result columns of the batch engine's run."""
    if config.carrier.traits.joints:
        return _arm_batch_columns(config, starts, duration)
    X_BC, twists = starts.X_BC, starts.twists
    dynamic = p.dynamic
    r = run_batch(config, X_BC, twists if dynamic else None, duration=duration, parameters=p)
    finite = np.all(np.isfinite(r.final_states), axis=1)
    final = np.full((len(X_BC), 4, 4), math.nan)
    if np.any(finite):
        final[finite] = poses_in_target(config, r.final_states[finite])
    return {
        "status": r.status.astype(object),  # the pinhole's feature_lost among them
        "t_converged": r.t_converged,
        "final_position_error_m": r.final_position_error_m,
        "final_rotation_error_rad": r.final_rotation_error_rad,
        "min_fov_margin": r.min_margins[:, 0],
        "min_lambda_margin": np.minimum(r.min_margins[:, 1], r.min_margins[:, 2]),
        "min_occlusion_margin": r.min_margins[:, 3],
        "initial_energy_ratio": r.initial_lyapunov / p.potential_gain,
        "max_energy_ratio": r.max_lyapunov_ratio,
        "monotone": r.monotone,
        **_pose_columns(final, "final_"),
        **{k: np.full(len(X_BC), math.nan) for k in _ARM_END},  # no arm in the batch engine
        "torque_clamped": np.zeros(len(X_BC), bool),
    }


def _arm_batch_columns(
    config: ScenarioConfig, starts: PartStarts, duration: float
) -> dict[str, np.ndarray]:
    """The arm's columns from the batch engine (:mod:`geovs_drake.batch.arm_engine`):
    the same starts as the Drake engine's (:class:`_ArmStarts`: IK, the branch, the
    twist to the joints), the unreachable ones a row with their status."""
    from geovs_drake.batch.arm_engine import run_arm_batch
    from geovs_drake.batch.arm_rhs import arm_loop_parameters, arm_rhs
    from geovs_drake.loop.resolver import resolve
    from geovs_drake.simulation.result import convergence_tolerance

    config = copy.deepcopy(config)
    config.duration = duration
    resolved = resolve(config)
    arm_p = arm_loop_parameters(resolved)
    nv = arm_p.tree.nv
    n = len(starts.X_BC)
    q0, v0 = np.zeros((n, nv)), np.zeros((n, nv))
    reached = np.zeros(n, bool)
    for i, joints in enumerate(starts.joints):
        if joints is not None:
            reached[i], q0[i] = True, joints[0]
            v0[i] = 0.0 if joints[1] is None else joints[1]
    rows = {k: np.full(n, math.nan) for k in ROW_FIELDS[ROW_FIELDS.index("status") + 1 : -1]}
    rows["status"] = np.full(n, "unreachable", dtype=object)
    rows["monotone"] = np.ones(n, bool)
    rows["torque_clamped"] = np.zeros(n, bool)
    if np.any(reached):
        goal = (resolved.config.X_WB @ resolved.config.X_BC_goal).GetAsMatrix4()
        r = run_arm_batch(
            arm_p, goal, q0[reached], v0[reached], duration, config.simulator.accuracy,
            convergence_tolerance(resolved),
        )  # fmt: skip
        k_p = arm_p.potential_gain
        X_BW = np.linalg.inv(resolved.config.X_WB.GetAsMatrix4())
        final = np.full((len(r.final_states), 4, 4), math.nan)
        speed = np.full(len(final), math.nan)
        for j, x in enumerate(r.final_states):
            if np.all(np.isfinite(x)):
                R, t = arm_p.tree.camera_pose(x[:nv])
                final[j] = X_BW @ np.block([[R, t.reshape(3, 1)], [np.zeros((1, 3)), 1.0]])
                speed[j] = np.max(np.abs(x[nv:] if arm_p.dynamic else arm_rhs(arm_p, x)))
        columns = {
            "status": r.status.astype(object),
            "t_converged": r.t_converged,
            "final_position_error_m": r.final_position_error_m,
            "final_rotation_error_rad": r.final_rotation_error_rad,
            "min_fov_margin": r.min_margins[:, 0],
            "min_lambda_margin": np.minimum(r.min_margins[:, 1], r.min_margins[:, 2]),
            "min_occlusion_margin": r.min_margins[:, 3],
            "initial_energy_ratio": r.initial_lyapunov / k_p,
            "max_energy_ratio": r.max_lyapunov_ratio,
            "monotone": r.monotone,
            **_pose_columns(final, "final_"),
            "final_joint_speed": speed,
            "final_joint_barrier": np.zeros(len(final)),  # the batch arm has no barrier
            "final_joint_margin": _final_joint_margin(arm_p.tree, r.final_states[:, :nv]),
            "torque_clamped": r.torque_clamped,
        }
        for k, v in columns.items():
            rows[k][reached] = v
    return rows


def _final_joint_margin(tree, q: np.ndarray) -> np.ndarray:
    """The least distance of each row's joints from their limits [rad]."""
    lower, upper = tree.joint[:, 3], tree.joint[:, 4]
    return np.min(np.minimum(q - lower, upper - q), axis=1)


def _drake_columns(
    config: ScenarioConfig, p: LoopParameters, starts: PartStarts, duration: float
) -> dict[str, np.ndarray]:
    """The same columns, a start at a time through simulate() (slow: for cross-checks,
    and the only engine of the arm). Margins and energies are those of simulate()'s logs
    (``config.log_rate``), not of every step as in the batch engine.

    On the arm (``carrier: !Arm``) each start's joints come from IK (a start the arm
    cannot reach gets the status ``unreachable``), and a start's twist becomes a joint
    velocity along ``J_C^+ (Omega, V)`` whose kinetic energy is the free rig's for that
    twist times the ratio of the loops' k_p, so that E0 / k_p keeps the sampler's
    distribution (``velocity bounded``: E0 < k_p on the arm too)."""
    dynamic = config.dynamic
    X_BC, twists = starts.X_BC, starts.twists
    # The arm's starts (the compiled IK, all at once), the same as the batch engine's.
    arm = starts.joints is not None
    joints = starts.joints if arm else [None] * len(X_BC)
    rows = []
    for X, twist, q_v in zip(X_BC, twists, joints, strict=True):
        c = copy.deepcopy(config)
        c.duration = duration
        c.initial = PoseConfig.from_rigid_transform(RigidTransform(X))
        c.initial_velocity = [float(v) for v in twist] if dynamic else [0.0] * 6
        rows.append(_arm_row(c, q_v) if arm else _drake_row(c))
    names = [k for k in row_fields(config) if k not in ("start", *_POSE, *_TWIST, "end")]
    return {
        k: np.array([r[k] for r in rows], dtype=object if k == "status" else None) for k in names
    }


def _arm_row(config: ScenarioConfig, joints: tuple | None) -> dict:
    """:func:`_drake_row` on the arm from the start's ``joints`` (:meth:`_ArmStarts.part_joints`):
    the arm starts there (``carrier.initial_joints``, so that the Drake loop runs from the
    batch engine's joints), the twist carried to joint velocities."""
    if joints is None:
        return _stopped_row("unreachable")
    q, v = joints
    config.initial_velocity = [0.0] * 6
    config.carrier.initial_joints = [float(x) for x in q]
    if v is not None:
        config.carrier.initial_joint_velocity = [float(x) for x in v]
    return _drake_row(config)


def _stopped_row(status: str) -> dict:
    """A start that stopped before its first step, with its status."""
    row = dict.fromkeys((*ROW_FIELDS[ROW_FIELDS.index("status") :], *HOVER_FIELDS), math.nan)
    row.update(status=status, monotone=True, torque_clamped=False)
    return row


@dataclass(frozen=True)
class _ArmStarts:
    """What carrying a part's starts to the arm needs, read once per part: the arm's
    model, the free rig's twin of the scenario (whose kinetic energy the sampler drew)
    and the ratio of the loops' k_p (resolve() scales the arm's), the compiled IK
    (``solver``, :class:`~geovs_drake.batch.arm_ik.StartSolver`; None: Drake's
    ``InverseKinematics``, :func:`~geovs_drake.goal.arm.solve_joints`) and the compiled
    branch path (``follow``; None: the plant's, step by step)."""

    model: ArmModel
    free: ScenarioConfig
    parameters: LoopParameters
    gain_ratio: float
    domain: SafeDomain
    follow: object = None  # the compiled path (goal_on_branch's follow), once per part
    solver: object = None  # the compiled IK of the part's starts, once per part

    @classmethod
    def of(cls, config: ScenarioConfig, p: LoopParameters) -> _ArmStarts:
        from geovs_drake.batch.arm_ik import PathFollower, StartSolver
        from geovs_drake.goal.arm import arm_model
        from geovs_drake.loop.resolver import resolve
        from geovs_drake.systems.arm_tree import arm_tree

        resolved = resolve(config)  # once per part, in its worker
        k_p_arm = resolved.config.control.potential_gain
        ratio = k_p_arm / p.potential_gain
        model = arm_model(config)
        follow = PathFollower(arm_tree(model))
        solver = StartSolver(model)
        return cls(model, free_twin(config), p, ratio, resolved.domain, follow, solver)

    def part_joints(self, config: ScenarioConfig, X_BC: np.ndarray, twists) -> list:
        """:meth:`joints` of each of the part's starts X_BC (n, 4, 4), the IK of all of
        them in one compiled call (with ``solver``)."""
        if self.solver is None:
            return [self.joints(config, X, t) for X, t in zip(X_BC, twists, strict=True)]
        X_WC = config.X_WB.GetAsMatrix4() @ np.asarray(X_BC)
        q, reached = self.solver(X_WC[:, :3, :3], X_WC[:, :3, 3])
        return [
            self.joints(config, X, t, q[i]) if reached[i] else None
            for i, (X, t) in enumerate(zip(X_BC, twists, strict=True))
        ]

    def joints(
        self, config: ScenarioConfig, X: np.ndarray, twist, q: np.ndarray | None = None
    ) -> tuple | None:
        """The start X_BC's joints ``(q, v)`` (v None at rest or on the kinematic arm):
        IK (``q`` where given, else ``solver``'s or Drake's) on the branch the NF's way to
        the goal carries along, the twist carried to the joints at the same E0 / k_p; None
        where the arm cannot reach it."""
        from geovs_drake.analysis.sweep.starts import kinetic_energy
        from geovs_drake.goal.arm import (
            Unreachable,
            chart_path,
            chart_poses,
            joint_velocity_for,
            solve_joints,
            start_branch,
        )

        X_WC = config.X_WB @ RigidTransform(X)
        if q is None and self.solver is not None:
            q, reached = self.solver(X_WC.rotation().matrix()[None], X_WC.translation()[None])
            if not reached[0]:
                return None
            q = q[0]
        elif q is None:
            try:
                q = solve_joints(self.model, X_WC)
            except Unreachable:
                return None
        # The start's whole turns from the joints carried along the NF's way to the goal
        # (the compiled path takes the poses as arrays, the plant's as RigidTransforms).
        chart = chart_path if self.follow is None else chart_poses
        path = chart(config, self.domain, RigidTransform(X))
        goal = config.X_WB @ config.X_BC_goal
        q = start_branch(self.model, q, X_WC, goal, path, self.follow)
        v = None
        if config.dynamic and np.any(np.asarray(twist) != 0):
            twist = np.asarray(twist, dtype=float)
            free = kinetic_energy(self.free, self.parameters, X[None], twist[None])[0]
            v = joint_velocity_for(self.model, q, twist, free * self.gain_ratio)
        return np.asarray(q, dtype=float), v


def _drake_row(config: ScenarioConfig) -> dict:
    # Here, not at the top: the batch engine's workers need none of the Drake loop.
    from geovs_drake.simulation import StartOutsideDomain, simulate

    try:
        r = simulate(config)
    except StartOutsideDomain as e:  # stopped at t = 0, as the batch engine would
        return _stopped_row("lost_visibility" if "not visible" in str(e) else "left_domain")
    k_p = r.energy_bound or 1.0  # the loop's own (the arm's is scaled; 1 for phi)
    dp, dr = r.final_errors
    L = r.lyapunov
    final = r.final_X_BC
    pose = [math.nan] * 6
    if final is not None:
        pose = [*final.translation(), *RollPitchYaw(final.rotation()).vector()]
    return {
        "status": r.status,
        "t_converged": r.convergence_time,
        "final_position_error_m": dp,
        "final_rotation_error_rad": dr,
        "min_fov_margin": float(np.min(r.margins[:, 0])),
        "min_lambda_margin": float(np.min(r.margins[:, 1:3])),
        "min_occlusion_margin": float(np.min(r.margins[:, 3])),
        "initial_energy_ratio": float(L[0] / k_p),
        "max_energy_ratio": float(np.max(L) / k_p),
        "monotone": bool(r.lyapunov_monotone),
        **dict(zip(("final_" + k for k in _POSE), map(float, pose), strict=True)),
        **_arm_end(r),
        # A hovering carrier's own entries (its rotors' saturation, its peak tilt); the
        # columns keep only the fields of the config's rows (row_fields).
        **{k: float(r.carrier_entries.get(k, math.nan)) for k in HOVER_FIELDS},
        "torque_clamped": r.carrier_entries.get("torque_clamped_fraction", 0.0) > 0,
    }


def _arm_end(r) -> dict[str, float]:
    """The :data:`_ARM_END` columns of a run (simulate's result): the arm's joints at its
    last logged state, NaN without an arm. The joint speed is the state's own on the
    torque-driven arm, the last logged step's difference on the kinematic one (its state
    holds no velocity); phi_q is that of the carrier's barrier (0 without one, 1 at or
    beyond a limit)."""
    if r.arm is None or r.states is None or len(r.states) == 0:
        return dict.fromkeys(_ARM_END, math.nan)
    from geovs_drake.geometry.joint_barrier import joint_barrier, joint_widths
    from geovs_drake.goal.arm import arm_model
    from geovs_drake.systems.arm_model import arm_plant

    plant = arm_plant(arm_model(r.config))
    nq, nv = plant.num_positions(), plant.num_velocities()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    q = r.states[-1, :nq]
    if r.states.shape[1] >= nq + nv:
        v = r.states[-1, nq : nq + nv]
    elif len(r.states) > 1:
        v = (q - r.states[-2, :nq]) / (r.times[-1] - r.times[-2])
    else:
        v = np.full(nq, math.nan)
    margin = float(np.min(np.minimum(q - lower, upper - q)))
    arm = r.config.carrier
    widths = joint_widths(lower, upper, arm.joint_barrier_width, arm.joint_barrier_fraction)
    if widths is None:
        phi_q = 0.0
    else:  # the step's formula holds inside the range only
        phi_q = 1.0 if margin <= 0 else float(joint_barrier(q, lower, upper, widths, min)[0])
    return {
        "final_joint_speed": float(np.max(np.abs(v))),
        "final_joint_barrier": phi_q,
        "final_joint_margin": margin,
    }


def _table(columns: dict[str, np.ndarray], summary: dict):
    """The columns as a pyarrow Table in :data:`ROW_FIELDS` order, with the summary in
    its schema's metadata.

    Each array is built from its buffers (:func:`_arrow_array`), not by ``pa.array``:
    pyarrow's conversion of a NumPy array or a list imports pandas where pandas is
    installed (its check for a categorical), 0.3-0.9 s of the sweep's start-up for
    columns that hold no pandas object; the arrays are the same (a test compares them).
    """
    pa = require("pyarrow", "sweep", "a sweep's part files")
    names = [*ROW_FIELDS, *(k for k in HOVER_FIELDS if k in columns)]
    arrays = [_arrow_array(pa, name, columns[name]) for name in names]
    table = pa.Table.from_arrays(arrays, names=names)
    return table.replace_schema_metadata({SUMMARY_KEY: json.dumps(summary).encode()})


def _arrow_array(pa, name: str, values):
    """One column as a pyarrow Array of its Parquet type (strings for ``status`` and
    ``end``, booleans for ``monotone`` and ``torque_clamped``, int64 for ``start``,
    float64 for the rest, NaN kept as NaN, no nulls), from its buffers."""
    if name in ("status", "end"):
        data = [str(s).encode() for s in values]
        offsets = np.zeros(len(data) + 1, np.int32)
        np.cumsum([len(b) for b in data], out=offsets[1:])
        buffers = [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(data))]
        return pa.Array.from_buffers(pa.string(), len(data), buffers)
    if name in ("monotone", "torque_clamped"):
        bits = np.packbits(np.asarray(values, bool), bitorder="little")
        return pa.Array.from_buffers(pa.bool_(), len(values), [None, pa.py_buffer(bits)])
    kind, dtype = (pa.int64(), np.int64) if name == "start" else (pa.float64(), np.float64)
    array = np.ascontiguousarray(values, dtype)
    return pa.Array.from_buffers(kind, len(array), [None, pa.py_buffer(array)])


def _write_atomically(table, path: Path) -> None:
    """Write ``path`` under a hidden temporary name in its folder, then rename it."""
    pq = require("pyarrow.parquet", "sweep", "a sweep's part files")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        pq.write_table(table, tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def read_part_summary(path: Path, rows: int) -> dict:
    """A written part's summary from its metadata, without reading its rows.

    Raises ValueError, naming the file, when it is unreadable, has no summary, or holds
    another number of rows than ``rows``.
    """
    pq = require("pyarrow.parquet", "sweep", "a sweep's part files")
    try:
        meta = pq.read_metadata(path)
        data = json.loads(meta.metadata[SUMMARY_KEY])
    except Exception as e:  # pyarrow's errors for damaged files vary by version
        raise ValueError(f"{path}: unreadable part ({type(e).__name__}: {e})") from e
    if meta.num_rows != rows or data.get("finished") != rows:
        raise ValueError(f"{path}: {meta.num_rows} rows where the part has {rows}")
    return data
