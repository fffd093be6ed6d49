"""A moving target against an arm's reach and speed: whether the arm can follow the goal
over the run, before it starts (issue 42).

The goal camera pose moves with the target, X_WC*(t) = X_WB(t) X_BC*, while the arm's
base stands still. :func:`target_reach` carries the goal's joints along that path, from
IK's solution at t = 0 (:func:`~geovs_drake.goal.arm.solve_joints`), by damped Newton
steps at each sample (the continuation of :func:`~geovs_drake.goal.arm.goal_on_branch`:
the minimum-norm joint motion, which keeps a redundant arm's posture), and reports the
first sample where the joints

* no longer reach the goal (its pose more than :data:`REACH_POSITION_M` or
  :data:`REACH_ROTATION_RAD` away after the steps: out of reach, or across a
  singularity),
* leave a joint's range, or
* need more than a joint's velocity limit between two samples.

A run that goes on past that time cannot follow the target: the kinematic Panda behind
the issue's twist sat with its wrist at its limit and crawled (191 s of wall time for
30 s). The check is an estimate: the run's own joints lag and, on the kinematic arm,
the null space pulls a redundant arm towards mid-range, where these follow the goal
exactly with the least motion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform

from geovs_drake.goal.arm import (
    GOAL_PATH_DAMPING,
    Unreachable,
    arm_model,
    joint_names,
    solve_joints,
)
from geovs_drake.scenario import ScenarioConfig, target_motion_arguments
from geovs_drake.systems.arm_model import CAMERA_FRAME, arm_plant, camera_jacobian
from geovs_drake.systems.target_motion import TargetMotion

__all__ = [
    "REACH_POSITION_M",
    "REACH_ROTATION_RAD",
    "REACH_STEP_S",
    "TargetReach",
    "target_reach",
    "target_reach_warning",
]

#: The time between the goal's samples [s]: the target moves a few mm between two (the
#: issue's 0.05 m/s), where three damped Newton steps converge.
REACH_STEP_S = 0.05
#: How far the carried joints may leave the goal before it counts as out of reach [m],
#: [rad]: well above the Newton steps' residue on a path they follow (1e-6 and less),
#: well below a lost goal.
REACH_POSITION_M = 1e-3
REACH_ROTATION_RAD = 1e-3
#: Damped Newton steps per sample.
_NEWTON_STEPS = 3


@dataclass(frozen=True)
class TargetReach:
    """Where the arm stops following the moving goal: the time ``time`` [s] of the first
    sample that fails, of a run of ``duration`` [s], and why (``reason``, one clause)."""

    time: float
    duration: float
    reason: str

    def warning(self) -> str:
        """The line a run prints before it starts."""
        return (
            f"the target's motion takes the goal out of the arm's reach or speed at "
            f"t = {self.time:.3g} s of the {self.duration:g} s run: {self.reason} (the goal's "
            f"joints carried along the target's motion from IK's at t = 0); the run will "
            f"lag, stop at a joint limit or leave D there: a shorter --duration, a slower "
            f"target, or a base nearer its path"
        )


def target_reach(config: ScenarioConfig, step: float = REACH_STEP_S) -> TargetReach | None:
    """The first time the arm cannot follow ``config``'s moving goal (module docstring),
    or None where it can over the whole run, where the target stands still or where the
    carrier is not an arm."""
    if not (config.moving_target and config.carrier.traits.joints):
        return None
    motion = TargetMotion(X_WB0=config.X_WB, **target_motion_arguments(config.target_motion))
    X_BC = config.X_BC_goal.GetAsMatrix4()
    model = arm_model(config)
    plant = arm_plant(model)
    camera = plant.GetFrameByName(CAMERA_FRAME)
    context = plant.CreateDefaultContext()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    speed_limits = plant.GetVelocityUpperLimits()
    names = joint_names(plant)
    duration = float(config.duration)
    try:
        q = solve_joints(model, RigidTransform(motion.X_WB(0.0) @ X_BC))
    except Unreachable as e:
        return TargetReach(0.0, duration, str(e))
    count = max(1, math.ceil(duration / step))
    for t in np.linspace(0.0, duration, count + 1)[1:]:
        goal = RigidTransform(motion.X_WB(float(t)) @ X_BC)
        before = q.copy()
        for _ in range(_NEWTON_STEPS):
            plant.SetPositions(context, q)
            e = _pose_error(camera.CalcPoseInWorld(context), goal)
            J = camera_jacobian(plant, context, camera)
            damped = J @ J.T + GOAL_PATH_DAMPING**2 * np.eye(6)
            q = q + J.T @ np.linalg.solve(damped, e)
        plant.SetPositions(context, q)
        e = _pose_error(camera.CalcPoseInWorld(context), goal)
        if np.linalg.norm(e[3:]) > REACH_POSITION_M or np.linalg.norm(e[:3]) > REACH_ROTATION_RAD:
            return TargetReach(
                float(t),
                duration,
                f"the joints no longer reach the goal ({np.linalg.norm(e[3:]):.3g} m and "
                f"{np.linalg.norm(e[:3]):.3g} rad off: out of reach, or at a singularity)",
            )
        outside = np.flatnonzero((q < lower) | (q > upper))
        if len(outside):
            i = int(outside[0])
            return TargetReach(
                float(t),
                duration,
                f"{names[i]} leaves its range ({q[i]:.4g} rad outside "
                f"[{lower[i]:.4g}, {upper[i]:.4g}])",
            )
        speeds = np.abs(q - before) / (duration / count)
        i = int(np.argmax(speeds / speed_limits))
        if speeds[i] > speed_limits[i]:
            return TargetReach(
                float(t),
                duration,
                f"{names[i]} needs {speeds[i]:.3g} rad/s, above its limit {speed_limits[i]:.3g}",
            )
    return None


def target_reach_warning(config: ScenarioConfig) -> str | None:
    """:func:`target_reach`'s warning line, or None where the arm can follow the goal."""
    reach = target_reach(config)
    return None if reach is None else reach.warning()


def _pose_error(X: RigidTransform, X_goal: RigidTransform) -> np.ndarray:
    """The error from X to X_goal as a twist of the camera in its own frame, rotation
    first: X_goal = X exp(e^) to first order."""
    X_err = X.InvertAndCompose(X_goal)
    aa = X_err.rotation().ToAngleAxis()
    return np.concatenate([aa.axis() * aa.angle(), X_err.translation()])
