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
"""

import math
from dataclasses import dataclass, field

from geovs_drake.scenario.pose import finite_numbers

__all__ = [
    "ESTIMATOR_RATE_HZ",
    "FEEDFORWARD_MODES",
    "TARGET_VARIANTS",
    "Still",
    "TargetMotionConfig",
    "Twist",
    "check_target_motion",
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


#: A target motion: one of the variants above.
TargetMotionConfig = Still | Twist
#: The target motion of each name, as a file's bare name gives it.
TARGET_VARIANTS: dict[str, type] = {"still": Still, "twist": Twist}


def check_target_motion(motion: object) -> None:
    """The motion variant's own fields, each named ``target_motion.<field>``."""
    if not isinstance(motion, Twist):
        return
    if finite_numbers(motion.twist, 6) is None:
        raise ValueError(
            "target_motion.twist must be 6 finite numbers (omega, v) in B [rad/s, m/s], "
            f"got {motion.twist!r}"
        )
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
