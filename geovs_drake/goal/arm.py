"""The arm as a carrier's model: which arm a scenario means, and its start by IK.

:func:`arm_model` turns a scenario's ``arm`` into the hashable
:class:`~geovs_drake.systems.arm_model.ArmModel` that the systems and the
carrier load. :func:`solve_joints` finds a joint configuration that puts the
camera at a pose X_BC, with Drake's ``InverseKinematics`` (the joint limits are
its bounds) from a few seeds, keeping the solution farthest from the joint limits
and the singularities; a
pose the arm cannot reach raises :class:`Unreachable`, naming the closest
reach found.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import Solve

from geovs_drake.geometry.camera import camera_map, camera_map_inverse
from geovs_drake.geometry.domain import SafeDomain
from geovs_drake.geometry.joint_barrier import joint_barrier
from geovs_drake.geometry.navigation import (
    ModelCoordinates,
    features_from_model,
    model_coordinates,
)
from geovs_drake.goal.ik_choice import (
    IK_SCORE_TIE,
    IK_SEEDS,
    SINGULARITY_WEIGHT,
    ik_score,
    ik_seeds,
)
from geovs_drake.goal.ik_choice import better_solution as _better_solution
from geovs_drake.scenario import ScenarioConfig
from geovs_drake.systems.arm_camera import null_space_projector
from geovs_drake.systems.arm_model import (
    ARMS,
    CAMERA_FRAME,
    ArmModel,
    arm_plant,
    camera_jacobian,
)

__all__ = [
    "ARMS",
    "IK_POSITION_TOLERANCE",
    "IK_ROTATION_TOLERANCE",
    "HALF_TURN_AMBIGUITY",
    "GOAL_PATH_DAMPING",
    "GOAL_PATH_JUMP",
    "GOAL_PATH_STEPS",
    "IK_SEEDS",
    "SINGULARITY_WEIGHT",
    "Unreachable",
    "arm_model",
    "camera_jacobians",
    "chart_path",
    "chart_poses",
    "goal_on_branch",
    "initial_joints",
    "joint_barrier_values",
    "joint_count",
    "joint_limit_margins",
    "joint_velocity_for",
    "self_motion_speeds",
    "smallest_singular_values",
    "ArmGoalModel",
    "BASE_PLACEMENT_CHECKS",
    "BASE_PLACEMENT_SEEDS",
    "BasePlacement",
    "arm_goal_model",
    "place_base",
    "model_joint_damping",
    "solve_joints",
    "start_branch",
]

#: The camera pose an IK solution must reach [m] and [rad].
IK_POSITION_TOLERANCE = 1e-6
IK_ROTATION_TOLERANCE = 1e-6
#: Steps of the path along which a start's joints are carried to the goal's pose
#: (:func:`chart_path`, :func:`goal_on_branch`): the pose moves 1/512 of the way per
#: step (thousandths of a rad and of a metre on the sweep's starts), where a few Newton
#: steps converge (64 steps left 15 of the sweep's 142 paths unfollowed, 512 left 13).
GOAL_PATH_STEPS = 512
#: The damping of the continuation's least-squares steps: it keeps a step bounded where
#: the path passes near a singularity (sigma_min(J_C) of order 1e-2 and less).
GOAL_PATH_DAMPING = 1e-3
#: A joint that moves more than this [rad] over one step of the path has met a
#: singularity (:func:`goal_on_branch`); away from one a step moves the joints by
#: thousandths of a rad.
GOAL_PATH_JUMP = 0.5

#: A rotation to come within this of a half turn [rad] has no way to go that the start
#: decides (the NF's saddle is the goal with the arrow reversed, a measure-zero set of
#: starts): its branch is left as IK found it. Off the saddle the NF turns the short way.
HALF_TURN_AMBIGUITY = 1e-6


#: Joint configurations tried when :func:`place_base` looks for the best-conditioned one
#: that holds the goal camera's orientation. Measured: more did not raise the checked
#: score (the UR5's 1.82 rad at 32, 1.79 at 64 and 128; the Panda's 1.16 at 32, 64, 128).
BASE_PLACEMENT_SEEDS = 32
#: The best-scored bases that :func:`place_base` checks by the loop's own IK.
BASE_PLACEMENT_CHECKS = 4


class Unreachable(ValueError):
    """The arm cannot put the camera at the requested pose within its joint limits."""


def _xyz_rpy(pose) -> tuple[float, ...]:
    return tuple(float(v) for v in (*pose.xyz, *pose.rpy))


def arm_model(config: ScenarioConfig) -> ArmModel:
    """The scenario's arm as the systems load it: a named arm (:data:`ARMS`) with its own
    frame, base and camera where the scenario leaves them unset, or a model file, its
    base and camera at the origin unless given."""
    arm = config.carrier  # an Arm
    base = None if arm.base_pose is None else _xyz_rpy(arm.base_pose)
    camera = None if arm.camera_offset is None else _xyz_rpy(arm.camera_offset)
    packages = tuple(sorted(arm.packages.items()))
    if arm.model in ARMS:
        model = ARMS[arm.model].model(arm.end_effector_frame, base, camera)
        return dataclasses.replace(model, packages=model.packages + packages)
    return ArmModel(
        path=arm.model,
        end_effector_frame=arm.end_effector_frame,
        base_xyz_rpy=base or (0.0,) * 6,
        camera_xyz_rpy=camera or (0.0,) * 6,
        packages=packages,
    )


@dataclass(frozen=True)
class ArmGoalModel:
    """The arm at rest at the goal, what its linear model there needs: the joints ``q``
    (IK of X_BC*), the mass matrix ``M`` (rotor inertia included), the camera frame's
    Jacobian ``J`` (:func:`~geovs_drake.systems.arm_model.camera_jacobian`) and the
    damping that reads the joints alone, ``D_joint``: ``B_q I``, the model file's own
    joint damping and, for a redundant arm, ``d N`` (:class:`~geovs_drake.systems.ArmCamera`).
    The law's stiffness K and damping B act through J: ``K_q = J^T K J``,
    ``D_q = J^T B J + D_joint``."""

    q: np.ndarray
    M: np.ndarray
    J: np.ndarray
    D_joint: np.ndarray


def arm_goal_model(config: ScenarioConfig) -> ArmGoalModel:
    """:class:`ArmGoalModel` of ``config``'s arm (carrier :class:`~geovs_drake.scenario.Arm`)."""
    model = arm_model(config)
    q = solve_joints(model, config.X_WB @ config.X_BC_goal)
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    J = camera_jacobian(plant, context, plant.GetFrameByName(CAMERA_FRAME))
    nv = len(q)
    D_joint = config.carrier.joint_damping * np.eye(nv) + np.diag(model_joint_damping(plant))
    if nv > 6:  # a redundant arm's self-motion damping (ArmCamera)
        D_joint = D_joint + config.carrier.null_space_damping * null_space_projector(J)
    return ArmGoalModel(q=q, M=plant.CalcMassMatrix(context), J=J, D_joint=D_joint)


def model_joint_damping(plant) -> np.ndarray:
    """The model file's own joint damping [N m s/rad] per velocity (a URDF's
    ``<dynamics damping>``: 0.003 on each of the Panda's joints), which the plant adds."""
    damping = np.zeros(plant.num_velocities())
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        if joint.num_velocities() > 0:
            start = joint.velocity_start()
            damping[start : start + joint.num_velocities()] = joint.default_damping_vector()
    return damping


def joint_names(plant) -> tuple[str, ...]:
    """The name of the joint each of the plant's velocities belongs to."""
    names = [""] * plant.num_velocities()
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        for k in range(joint.num_velocities()):
            names[joint.velocity_start() + k] = joint.name()
    return tuple(names)


def joint_count(model: ArmModel) -> int:
    """The arm's number of joint positions nq."""
    return arm_plant(model).num_positions()


def joint_limit_margins(model: ArmModel, q: np.ndarray) -> np.ndarray:
    """Each joint's distance to its nearer limit [rad] (positive inside), for q (nq,)
    or (N, nq)."""
    plant = arm_plant(model)
    q = np.asarray(q, dtype=float)
    return np.minimum(q - plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits() - q)


def joint_barrier_values(
    model: ArmModel, q: np.ndarray, width: float | tuple[float, ...]
) -> np.ndarray:
    """phi_q, the joints' barrier of width ``width`` [rad], one for all joints or one per
    joint (:mod:`geovs_drake.geometry.joint_barrier`), at each q (N, nq); 0 with width 0."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if np.ndim(width) == 0 and width <= 0:
        return np.zeros(len(q))
    plant = arm_plant(model)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    return np.array([joint_barrier(row, lower, upper, width, min)[0] for row in q])


def joint_velocity_for(
    model: ArmModel, q: np.ndarray, twist: np.ndarray, kinetic_energy: float
) -> np.ndarray:
    """The joint velocity along ``J_C(q)^+ (Omega, V)`` whose kinetic energy
    ``1/2 v^T M(q) v`` (the arm's, rotor inertia included) is ``kinetic_energy``: a
    camera twist's direction carried to the joints, at a chosen energy (the sweep's
    moving starts keep E0 / k_p on the arm). Zero for a zero twist."""
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    direction = np.linalg.pinv(camera_jacobian(plant, context, plant.GetFrameByName(CAMERA_FRAME)))
    v = direction @ np.asarray(twist, dtype=float)
    plant.SetVelocities(context, v)
    unit = plant.CalcKineticEnergy(context)
    return v * np.sqrt(kinetic_energy / unit) if unit > 0 else np.zeros_like(v)


def camera_jacobians(model: ArmModel, q: np.ndarray) -> np.ndarray:
    """J_C (6 x nv) at each q (N, nq), stacked (N, 6, nv): the camera frame's
    spatial-velocity Jacobian expressed in C, so that ``J_C v = (Omega, V)``."""
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)
    out = []
    for row in np.atleast_2d(q):
        plant.SetPositions(context, row)
        out.append(camera_jacobian(plant, context, camera))
    return np.array(out)


def smallest_singular_values(model: ArmModel, q: np.ndarray) -> np.ndarray:
    """sigma_min of the camera frame's spatial-velocity Jacobian J_C (6 x nv) at each q
    (N, nq): where it nears 0 the arm is near a singularity, and the law's wrench
    (dynamic) or twist (kinematic) loses a direction."""
    J = camera_jacobians(model, q)
    if J.shape[2] < 6:
        return np.zeros(len(J))
    return np.linalg.svd(J, compute_uv=False)[:, -1]


def self_motion_speeds(model: ArmModel, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The norm of N(q) v [rad/s] at each (q, v), (N, nv) each: the speed of a redundant
    arm's self-motion, the part of its joint velocity that does not move the camera (N
    the damped projector on J_C's null space,
    :func:`~geovs_drake.systems.arm_camera.null_space_projector`)."""
    return np.array(
        [
            np.linalg.norm(null_space_projector(J) @ rate)
            for J, rate in zip(camera_jacobians(model, q), np.atleast_2d(v), strict=True)
        ]
    )


def solve_joints(model: ArmModel, X_WC: RigidTransform) -> np.ndarray:
    """Joint positions that put the camera frame at X_WC, within the joint limits.

    Raises :class:`Unreachable` with the closest reach found (position and
    rotation errors) when no seed gives a solution.
    """
    key = (model, tuple(X_WC.GetAsMatrix4().ravel().round(12)))
    return _solve_joints(*key).copy()


@functools.lru_cache(maxsize=64)
def _solve_joints(model: ArmModel, X_key: tuple[float, ...]) -> np.ndarray:
    X_WC = RigidTransform(np.array(X_key).reshape(4, 4))
    plant = arm_plant(model)
    camera = plant.GetFrameByName(CAMERA_FRAME)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    seeds = ik_seeds(lower, upper)
    best, best_score, closest = None, -np.inf, (np.inf, np.inf)
    for seed in seeds:
        ik = InverseKinematics(plant)
        p = X_WC.translation()
        ik.AddPositionConstraint(
            camera, np.zeros(3), plant.world_frame(), p - IK_POSITION_TOLERANCE,
            p + IK_POSITION_TOLERANCE,
        )  # fmt: skip
        ik.AddOrientationConstraint(
            camera, RigidTransform().rotation(), plant.world_frame(), X_WC.rotation(),
            IK_ROTATION_TOLERANCE,
        )  # fmt: skip
        ik.prog().SetInitialGuess(ik.q(), seed)
        result = Solve(ik.prog())
        q = result.GetSolution(ik.q())
        if result.is_success():
            q = _refine(plant, camera, q, X_WC)
            # Keep the solution farthest from both the joint limits and the
            # singularities: the smaller of the joint margin [rad] and 10 sigma_min(J_C);
            # a tie (IK_SCORE_TIE) to the one nearer q = 0.
            score = _ik_score(model, q, lower, upper)
            if _better_solution(q, score, best, best_score):
                best, best_score = q, score
        else:
            closest = min(closest, _reach_error(plant, camera, q, X_WC))
    if best is None:
        raise Unreachable(
            f"the arm cannot put the camera at {_describe(X_WC)} within its joint limits: the "
            f"closest reach found is {closest[0]:.3g} m and {closest[1]:.3g} rad away"
        )
    return best


def _ik_score(model: ArmModel, q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
    """How far q is from trouble (:func:`~geovs_drake.goal.ik_choice.ik_score`): IK's
    choice among its solutions, and :func:`place_base`'s."""
    margin = float(np.min(np.minimum(q - lower, upper - q)))
    return float(ik_score(margin, smallest_singular_values(model, q[None])[0]))


def _refine(plant, camera, q: np.ndarray, X_WC: RigidTransform, steps: int = 4) -> np.ndarray:
    """Newton steps on the camera pose error, from the IK's solution (met to its
    tolerance, 1e-6) to rounding: the goal's joints must be an equilibrium to ~1e-12,
    not 1e-6, for Drake's ``Linearize`` and for a start exactly at the goal."""
    context = plant.CreateDefaultContext()
    for _ in range(steps):
        plant.SetPositions(context, q)
        X = camera.CalcPoseInWorld(context)
        # The error as a twist of C in C (rotation first): X_WC = X exp(e^).
        X_err = X.InvertAndCompose(X_WC)
        aa = X_err.rotation().ToAngleAxis()
        e = np.concatenate([aa.axis() * aa.angle(), X_err.translation()])
        J = camera_jacobian(plant, context, camera)
        q = q + np.linalg.lstsq(J, e, rcond=None)[0]
    return q


def _reach_error(plant, camera, q: np.ndarray, X_WC: RigidTransform) -> tuple[float, float]:
    context = plant.CreateDefaultContext()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    plant.SetPositions(context, np.clip(q, lower, upper))
    X = camera.CalcPoseInWorld(context)
    dp = float(np.linalg.norm(X.translation() - X_WC.translation()))
    dr = float(X.rotation().InvertAndCompose(X_WC.rotation()).ToAngleAxis().angle())
    return dp, dr


def _describe(X: RigidTransform) -> str:
    rpy = RollPitchYaw(X.rotation()).vector()
    return f"xyz {np.round(X.translation(), 3).tolist()} rpy {np.round(rpy, 3).tolist()} in W"


def initial_joints(config: ScenarioConfig, domain: SafeDomain) -> np.ndarray:
    """The arm's start: ``carrier.initial_joints``, else X_BC(0) solved by IK (ValueError
    for a wrong number of joints, :class:`Unreachable` for a pose out of reach), on the
    branch of the NF's way to the goal in ``domain`` (the resolved D)."""
    model = arm_model(config)
    nq = arm_plant(model).num_positions()
    given = config.carrier.initial_joints
    if given:
        if len(given) != nq:
            raise ValueError(
                f"carrier.initial_joints must give the arm's {nq} joints, got {len(given)}: {given}"
            )
        return np.asarray(given, dtype=float)
    X_WC0, X_WC_goal = config.X_WB @ config.X_BC_initial, config.X_WB @ config.X_BC_goal
    path = chart_path(config, domain, config.X_BC_initial)
    return start_branch(model, solve_joints(model, X_WC0), X_WC0, X_WC_goal, path)


def chart_path(
    config: ScenarioConfig,
    domain: SafeDomain,
    X_BC: RigidTransform,
    steps: int = GOAL_PATH_STEPS,
) -> list[RigidTransform] | None:
    """The camera's poses X_WC on the straight path in the NF's model chart from the image
    of X_BC to the goal's (:mod:`geovs_drake.geometry.navigation`): lambda and the two
    discs on their segments, the arrow's angle the short way round its circle, as the
    NF's circle factor turns it; ``steps + 1`` poses, X_BC's first, the goal's last.
    None under another law (whose way round is its own) or for a start outside D (no
    chart there).

    Why this path: the joints' whole turns at the goal are those of any path in D that
    winds round the circle as the NF's does (D is the circle times a contractible
    product), so IK carried along it (:func:`goal_on_branch`) ends on the goal's joints
    that the arm reaches. The rotation's geodesic in SE(3) need not wind so: from a start
    rolled 179 deg it can turn the other way round (docs/arm.md, "The barrier's spurious
    equilibria")."""
    X_CB = _chart_X_CB(config, domain, X_BC, steps)
    if X_CB is None:
        return None
    X_WB = config.X_WB  # once: the schema's property builds it anew at each read
    return [X_WB @ RigidTransform(X).inverse() for X in X_CB]


def _chart_X_CB(
    config: ScenarioConfig, domain: SafeDomain, X_BC: RigidTransform, steps: int
) -> np.ndarray | None:
    """:func:`chart_path`'s poses as X_CB (steps + 1, 4, 4), or None."""
    radius = config.radius  # D is the resolved scenario's (``domain``)
    try:
        y0 = camera_map(X_BC.inverse(), radius)
    except ValueError:  # not visible
        return None
    if not config.controller.traits.navigation or not bool(domain.contains(y0)):
        return None
    goal = camera_map(config.X_BC_goal.inverse(), radius)
    ends = [model_coordinates(y, domain) for y in (y0, goal)]
    (m0, m1), s = ends, np.linspace(0.0, 1.0, steps + 1)
    a0, a1 = (float(np.arctan2(m.circle[1], m.circle[0])) for m in ends)
    a = a0 + s * (np.mod(a1 - a0 + np.pi, 2 * np.pi) - np.pi)  # the short way
    w = s[:, None]
    chart = ModelCoordinates(
        (1 - s) * float(m0.u) + s * float(m1.u),
        (1 - w) * np.asarray(m0.w_fov) + w * np.asarray(m1.w_fov),
        (1 - w) * np.asarray(m0.w_occ) + w * np.asarray(m1.w_occ),
        np.stack([np.cos(a), np.sin(a)], axis=-1),
    )
    return camera_map_inverse(features_from_model(chart, domain), radius)


def chart_poses(
    config: ScenarioConfig, domain: SafeDomain, X_BC: RigidTransform, steps: int = GOAL_PATH_STEPS
) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`chart_path`'s poses as arrays, (R_WC (n, 3, 3), p_WC (n, 3)), built without
    a RigidTransform per pose (:func:`goal_on_branch`'s compiled ``follow`` takes them;
    the sweep's starts, a few milliseconds less each). X_WC = X_WB X_CB^-1."""
    X_CB = _chart_X_CB(config, domain, X_BC, steps)
    if X_CB is None:
        return None
    X_WB = config.X_WB.GetAsMatrix4()
    R_BC = np.swapaxes(X_CB[:, :3, :3], 1, 2)
    p_BC = -(R_BC @ X_CB[:, :3, 3:])[:, :, 0]
    return X_WB[:3, :3] @ R_BC, X_WB[:3, 3] + p_BC @ X_WB[:3, :3].T


def goal_on_branch(
    model: ArmModel,
    q: np.ndarray,
    path: list[RigidTransform] | tuple[np.ndarray, np.ndarray],
    follow: Callable[..., np.ndarray | None] | None = None,
) -> np.ndarray | None:
    """The joints at the end of ``path`` (camera poses X_WC, the camera at q at the
    first) carried from q along it, the limits ignored: at each pose a few damped Newton
    steps, then Newton to rounding at the last. The joints keep their posture
    (shoulder, elbow, wrist) and count their whole turns along the path, unless it
    crosses a singularity; None where they do not reach the last pose.

    ``follow``: the same steps compiled, :class:`~geovs_drake.batch.arm_ik.PathFollower`
    of this model's arm (``path`` may then be :func:`chart_poses`' arrays); None: the
    plant's context, step by step (some 40 ms a path)."""
    if follow is not None:
        if not isinstance(path, tuple):  # (chart_poses' arrays go as they are)
            path = np.array([X.rotation().matrix() for X in path]), [X.translation() for X in path]
        tolerance = (IK_POSITION_TOLERANCE, IK_ROTATION_TOLERANCE)
        return follow(q, *path, GOAL_PATH_DAMPING, GOAL_PATH_JUMP, 3, 4, tolerance)
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)
    q = np.array(q, dtype=float)
    for target in path[1:]:
        before = q.copy()
        for _ in range(3):
            plant.SetPositions(context, q)
            X_err = camera.CalcPoseInWorld(context).InvertAndCompose(target)
            aa = X_err.rotation().ToAngleAxis()
            e = np.concatenate([aa.axis() * aa.angle(), X_err.translation()])
            J = camera_jacobian(plant, context, camera)
            damped = J @ J.T + GOAL_PATH_DAMPING**2 * np.eye(len(e))
            q = q + J.T @ np.linalg.solve(damped, e)
        # A joint that jumps across a small step of the camera has met a singularity:
        # past it the posture, and so the count of turns, is anyone's guess.
        if np.max(np.abs(q - before)) > GOAL_PATH_JUMP:
            return None
    q = _refine(plant, camera, q, path[-1])
    dp, dr = _pose_error(plant, camera, q, path[-1])
    return q if dp < IK_POSITION_TOLERANCE and dr < IK_ROTATION_TOLERANCE else None


def _pose_error(plant, camera, q: np.ndarray, X_WC: RigidTransform) -> tuple[float, float]:
    """(position [m], rotation [rad]) distance of the camera at q from X_WC."""
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    X = camera.CalcPoseInWorld(context)
    dr = X.rotation().InvertAndCompose(X_WC.rotation()).ToAngleAxis().angle()
    return float(np.linalg.norm(X.translation() - X_WC.translation())), float(dr)


def start_branch(
    model: ArmModel,
    q: np.ndarray,
    X_WC: RigidTransform,
    X_WC_goal: RigidTransform,
    path: list[RigidTransform] | tuple[np.ndarray, np.ndarray] | None = None,
    follow: Callable[..., np.ndarray | None] | None = None,
) -> np.ndarray:
    """The start q with each joint whose range spans 2 pi or more on the branch (whole
    turns, the same camera pose) that keeps the motion to come inside its range.

    The motion to come is the joints carried along ``path`` (camera poses from X_WC to
    X_WC*, :func:`chart_path`: the NF's own way round) to the goal
    (:func:`goal_on_branch`); without a path, or where the joints do not reach its end,
    it is estimated to first order: the camera's displacement to the goal as a twist in
    C, ``log(X_WC^-1 X_WC*)``, carried to the joints by ``J_C(q)^+``. Each such joint
    takes the branch whose start and end are farthest from its limits (the unshifted
    one on a tie): the goal's joints are chosen among their whole turns for the largest
    margin, so that with a joint barrier they lie outside it (the goal a minimum of
    phi_total) where a branch allows. A rotation of a half turn (within
    :data:`HALF_TURN_AMBIGUITY`) has no way to go that the start decides, and keeps IK's
    branch. Why: IK chose the start's branch with no regard to the motion, and from the
    suite's roll_179 the UR5's wrist 3 ran onto its limit (issue 31); the first-order
    estimate then missed the way round of starts rolled near a half turn and the travel
    of joints near a singularity, where the arm stalled at the barrier of a goal joint
    within its width of a limit (docs/arm.md, "The barrier's spurious equilibria").
    ``follow``: :func:`goal_on_branch`'s compiled path, or None."""
    plant = arm_plant(model)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    error = X_WC.InvertAndCompose(X_WC_goal)
    axis_angle = error.rotation().ToAngleAxis()
    axis, angle = axis_angle.axis(), axis_angle.angle()
    q = np.array(q, dtype=float)
    turning = np.flatnonzero(upper - lower >= 2 * np.pi)
    if angle > np.pi - HALF_TURN_AMBIGUITY or len(turning) == 0:  # (the Panda has none)
        return q
    goal = None if path is None else goal_on_branch(model, q, path, follow)
    if goal is not None:
        dq = goal - q
    else:
        J_plus = np.linalg.pinv(camera_jacobians(model, q[None])[0])
        dq = J_plus @ np.concatenate([axis * angle, error.translation()])
    for j in turning:
        best, best_margin = q[j], -np.inf
        for turns in (0, -1, 1, -2, 2):  # the unshifted branch first: it wins a tie
            start = q[j] + 2 * np.pi * turns
            margin = min(min(v - lower[j], upper[j] - v) for v in (start, start + dq[j]))
            if start >= lower[j] and start <= upper[j] and margin > best_margin + IK_SCORE_TIE:
                best, best_margin = start, margin
        q[j] = best
    return q


@dataclass(frozen=True)
class BasePlacement:
    """Where :func:`place_base` stands an arm's base: ``X_W_base`` (the field
    ``carrier.base_pose``), and the check by IK of the goal from there: the joints ``q``
    that put the camera at the goal, their nearest limit's margin ``joint_margin`` [rad],
    sigma_min(J_C) there ``singular_value``, and the goal camera's pose ``X_WC`` [m]."""

    X_W_base: RigidTransform
    q: np.ndarray
    joint_margin: float
    singular_value: float
    X_WC: RigidTransform

    @property
    def xyz_rpy(self) -> tuple[float, ...]:
        """The base pose as ``carrier.base_pose`` takes it: xyz [m], then rpy [rad]."""
        rpy = RollPitchYaw(self.X_W_base.rotation()).vector()
        return tuple(float(v) for v in (*self.X_W_base.translation(), *rpy))


def place_base(config: ScenarioConfig, seeds: int = BASE_PLACEMENT_SEEDS) -> BasePlacement:
    """A base pose for ``config``'s arm (its model, end-effector frame and camera offset;
    its ``base_pose`` ignored) that puts the goal camera pose X_WC* = X_WB X_BC* where
    the arm is best conditioned: the goal's joints as far from the joint limits and the
    singularities as the arm allows (IK's own score: the smaller of the nearest joint
    limit's margin [rad] and 10 sigma_min(J_C)).

    The base stands upright (its z along the world's, as the model's gravity expects) and
    unturned (a first joint about z turns it). With the base at the origin, the camera's
    orientation fixed at the goal's leaves a set of joint configurations; IK holds that
    orientation alone from ``seeds`` random joints (and the middle of the range), and the
    best-scored solution whose camera looks away from the base (so that the arm stands
    behind the camera, out of its view and the target's way) puts the base at
    ``p_WC* - p_base,C(q)``. Drake's InverseKinematics of the goal from that base checks
    it (:func:`solve_joints`: all seeds, the best solution). Raises :class:`Unreachable`
    where no configuration holds the goal's orientation looking away from the base.

    Why: a user's model file has its base at the world's origin, where the goal may be
    out of reach; placing it by hand meant computing X_WC* and guessing (issue 42)."""
    model = dataclasses.replace(arm_model(config), base_xyz_rpy=(0.0,) * 6)
    X_WC = config.X_WB @ config.X_BC_goal
    R_WC = X_WC.rotation()
    plant = arm_plant(model)
    camera = plant.GetFrameByName(CAMERA_FRAME)
    context = plant.CreateDefaultContext()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    starts = ik_seeds(lower, upper, seeds)
    candidates = []  # (score, the camera's position from the base)
    for seed in starts:
        ik = InverseKinematics(plant)
        ik.AddOrientationConstraint(
            camera, RotationMatrix(), plant.world_frame(), R_WC, IK_ROTATION_TOLERANCE
        )
        # Near its seed: the seeds spread the solutions over the orientation's joint set.
        ik.prog().AddQuadraticErrorCost(np.eye(len(seed)), seed, ik.q())
        ik.prog().SetInitialGuess(ik.q(), seed)
        result = Solve(ik.prog())
        if not result.is_success():
            continue
        q = result.GetSolution(ik.q())
        plant.SetPositions(context, q)
        p_base_C = camera.CalcPoseInWorld(context).translation()
        if R_WC.col(2) @ p_base_C > 0:  # else the base stands in front of the camera
            candidates.append((_ik_score(model, q, lower, upper), p_base_C))
    if not candidates:
        raise Unreachable(
            f"no configuration of the arm holds the goal camera's orientation "
            f"({_describe(X_WC)}) looking away from its base"
        )
    # The best few bases, each checked by the IK the loop runs (its solution may be
    # another of the goal's configurations, a redundant arm's self-motion elsewhere).
    candidates.sort(key=lambda c: -c[0])
    best = None
    for _, p_base_C in candidates[:BASE_PLACEMENT_CHECKS]:
        X_W_base = RigidTransform(X_WC.translation() - p_base_C)
        placed = dataclasses.replace(
            model, base_xyz_rpy=tuple(float(v) for v in X_W_base.translation()) + (0.0,) * 3
        )
        try:
            q = solve_joints(placed, X_WC)
        except Unreachable:  # (IK's seeds missed it: the next base)
            continue
        score = _ik_score(placed, q, lower, upper)
        if best is None or score > best[0]:
            best = (score, X_W_base, placed, q)
    if best is None:
        raise Unreachable(f"IK found none of the arm's best bases' goal ({_describe(X_WC)})")
    _, X_W_base, placed, q = best
    return BasePlacement(
        X_W_base=X_W_base,
        q=q,
        joint_margin=float(np.min(joint_limit_margins(placed, q))),
        singular_value=float(smallest_singular_values(placed, q[None])[0]),
        X_WC=X_WC,
    )
