"""The arm loop at the goal: Drake's ``Linearize`` against the closed form through J_C.

At the goal the camera is at rest at y*, the NF's differential vanishes, and the
gravity compensation cancels gravity exactly, so only three terms of the arm's
torque ``tau = J_C^T F_C - tau_g - B_q v`` (:class:`~geovs_drake.systems.ArmCamera`)
survive to first order. With the camera's displacement ``eps = J_C dq``
(right-trivialised, in C, rotation first, as in :mod:`.linearization`) and the free
body's stiffness ``K = k_p C_chart^T H C_chart``, the arm's model is::

    M(q*) ddq = -J_C^T K J_C dq - (J_C^T B J_C + B_q I + D_model + d N) dq_dot,

with D_model the model file's own joint damping (the Panda's 0.003 N m s/rad) and,
for a redundant arm (nv > 6), d N the self-motion's damping (N the damped projector
on J_C's null space, :class:`~geovs_drake.systems.ArmCamera`). That is,
``A = [[0, I], [-M^-1 K_q, -M^-1 D_q]]`` on (dq, dq_dot): the free body's
closed form with the rig's M replaced by the arm's M(q*) and K, B mapped through
J_C. Where J_C loses rank K_q does too: the goal is then not isolated in joint
space (the argument that E decreases needs no rank; the one that the arm stops at
the goal needs J_C^T F_C = 0 to imply F_C = 0, i.e. full rank).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import Linearize

from geovs_drake._json import json_ready
from geovs_drake.goal.arm import arm_goal_model, arm_model, solve_joints
from geovs_drake.goal.step_limit import arm_goal_A
from geovs_drake.loop import build_loop, exact_twin, resolve
from geovs_drake.scenario import Dynamic, Rendered, ScenarioConfig, camera_like
from geovs_drake.spectrum import SPECTRUM_RTOL, EigenvalueFacts, continuum_modes

__all__ = [
    "SELF_MOTION",
    "ArmLinearization",
    "ReachableGoals",
    "arm_pixels",
    "linearize_arm_at_goal",
    "reachable_goals",
]


#: What a redundant arm's eigenvalue 0 at the goal is (:func:`self_motion_directions`).
SELF_MOTION = (
    "the redundant arm's self-motion (J_C's null space, at rest): a continuum of "
    "equilibria, the goal's joint configurations"
)


@dataclass
class ArmLinearization(EigenvalueFacts):
    """The arm loop's linearisation at the goal: Drake's A on (q, v), the closed form,
    the goal's joints, sigma_min of J_C there, and the eigenvalues of A_drake in the
    canonical order (:mod:`geovs_drake.spectrum`). On a redundant arm ``continuum``
    holds the self-motion's modes (:data:`SELF_MOTION`, :func:`self_motion_directions`):
    an eigenvalue 0 to rounding that the verdict, the damping ratios and the time
    constants leave out."""

    q_goal: np.ndarray
    A_drake: np.ndarray
    A_closed: np.ndarray
    jacobian_singular_value: float
    eigenvalues: np.ndarray
    #: The plant's name, and the model is at rest at the goal (an equilibrium), as
    #: ``linearize`` reports it.
    plant: str = "dynamic"
    at_equilibrium: bool = True
    continuum: tuple[int, ...] = ()
    continuum_name: str | None = None

    def summary(self) -> dict:
        """As :meth:`LoopLinearization.summary
        <geovs_drake.analysis.linear.linearization.LoopLinearization.summary>`, A on the
        arm's (q, v), with the goal's joints and sigma_min of J_C there."""
        return json_ready(
            {
                "plant": self.plant,
                "carrier": "arm",
                "at_equilibrium": True,
                "A": self.A_drake,
                **self.eigenvalue_summary(),
                "q_goal": self.q_goal,
                "jacobian_singular_value": self.jacobian_singular_value,
            }
        )


def linearize_arm_at_goal(config: ScenarioConfig) -> ArmLinearization:
    """Drake's ``Linearize`` of the dynamic arm loop at rest at the goal (the joints by
    IK of the goal pose), and the closed form (module docstring)."""
    config = exact_twin(config)  # a sampled camera has discrete state: no A
    if not (config.carrier.traits.joints and config.dynamic):
        raise ValueError(
            f"linearize_arm_at_goal needs carrier Arm and plant Dynamic, got "
            f"{type(config.carrier).__name__} and {type(config.plant).__name__}"
        )
    goal = arm_goal_model(config)
    q_goal = goal.q
    config.initial = copy.deepcopy(config.goal)
    config.carrier.initial_joints = q_goal.tolist()
    config.carrier.initial_joint_velocity = []
    resolved = resolve(config)
    loop = build_loop(resolved, log=False)
    context = loop.diagram.CreateDefaultContext()
    A_drake = Linearize(
        loop.diagram,
        context,
        input_port_index=InputPortSelection.kNoInput,
        output_port_index=OutputPortSelection.kNoOutput,
    ).A()

    # The closed form the step limit reads (the arm's gains, Arm.gain_scale applied).
    A_closed = arm_goal_A(resolved).A
    directions = self_motion_directions(goal.J)
    eigenvalues, continuum = continuum_modes(A_drake, directions)
    return ArmLinearization(
        q_goal=q_goal,
        A_drake=A_drake,
        A_closed=A_closed,
        jacobian_singular_value=float(np.linalg.svd(goal.J, compute_uv=False)[-1]),
        eigenvalues=eigenvalues,
        continuum=continuum,
        continuum_name=SELF_MOTION if continuum else None,
    )


def self_motion_directions(J: np.ndarray, rtol: float = SPECTRUM_RTOL) -> np.ndarray:
    """The self-motion at rest in the arm's state (q, v): ``(n, 0)`` for n in the null
    space of the camera's Jacobian J (6 x nv) at the goal, as orthonormal columns
    (2 nv x (nv - 6)). Where J has full rank 6 the joint configurations that put the
    camera at the goal form a manifold of dimension nv - 6 (the implicit function
    theorem) whose tangent is that null space: a continuum of equilibria at rest. None
    on a 6-joint arm, nor where J loses rank (sigma_min <= ``rtol`` sigma_max): its null
    space is then a first-order fact only, not a known continuum."""
    nv = J.shape[1]
    _, sigma, Vt = np.linalg.svd(J)
    if nv <= len(sigma) or sigma[-1] <= rtol * sigma[0]:
        return np.zeros((2 * nv, 0))
    null = Vt[len(sigma) :].T
    return np.vstack([null, np.zeros_like(null)])


@dataclass
class ReachableGoals:
    """Which goals the joint barrier leaves reachable (:func:`reachable_goals`).

    ``sampled``: goal poses tried (random, in D); ``solvable``: those Drake's
    InverseKinematics reaches within the joint limits; ``reachable[w]``: those whose
    joint solution is at least w [rad] from every limit, so phi_q = 0 there and the
    goal stays the minimum of phi_total for a barrier of width w. A lower bound: the IK
    keeps the best of its seeds, not every branch.
    """

    sampled: int
    solvable: int
    reachable: dict[float, int]


def reachable_goals(
    config: ScenarioConfig, widths: tuple[float, ...], n: int = 100, seed: int = 0
) -> ReachableGoals:
    """Sample n goal poses X_BC in D, 0.2-0.8 m from the target, and count those the
    arm reaches with every joint ``w`` or more from its limits, for each width w."""
    from geovs_drake.analysis.linear.region import poses_in_domain
    from geovs_drake.goal.arm import Unreachable, joint_limit_margins
    from geovs_drake.sampling import random_visible_poses

    model = arm_model(config)
    rng = np.random.default_rng(seed)
    goals: list[np.ndarray] = []
    while len(goals) < n:
        X_CB = random_visible_poses(rng, 4 * n, config.radius, (2.0, 8.0))
        X_BC = np.linalg.inv(X_CB)
        goals.extend(X_BC[poses_in_domain(config, X_BC)][: n - len(goals)])
    margins = []
    for X_BC in goals:
        try:
            q = solve_joints(model, config.X_WB @ RigidTransform(X_BC))
        except Unreachable:
            continue
        margins.append(float(np.min(joint_limit_margins(model, q))))
    margins_arr = np.asarray(margins)
    return ReachableGoals(
        sampled=n,
        solvable=len(margins),
        reachable={float(w): int(np.sum(margins_arr >= w)) for w in widths},
    )


def arm_pixels(config: ScenarioConfig, joint_positions: np.ndarray) -> np.ndarray:
    """How many pixels of the arm's own camera frame show the arm, at each joint
    configuration (N, nq): the rendered camera of ``config`` (its intrinsics, its clipping
    range, RenderEngineVtk), its label image, the pixels whose label is one of the arm's
    bodies. Zero where the arm stays out of its camera's view; wherever it is not zero
    the feature extractor sees the arm too (and a part of the arm in front of the
    sphere would hide it)."""
    config = copy.deepcopy(config)
    config.sensor = camera_like(config.sensor, Rendered)
    config.plant = Dynamic()  # the rendered camera's loop; the drawing is the same arm
    loop = build_loop(config, log=False)
    rgbd = loop.diagram.GetSubsystemByName("rgbd_sensor")
    plant = loop.carrier.plant
    labels = [int(index) for index in plant.GetBodyIndices(loop.carrier.body.model_instance())]
    root = loop.diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(root)
    sensor_context = rgbd.GetMyContextFromRoot(root)
    out = np.empty(len(joint_positions), dtype=int)
    for k, q in enumerate(np.atleast_2d(joint_positions)):
        plant.SetPositions(plant_context, q)
        image = rgbd.label_image_output_port().Eval(sensor_context).data[:, :, 0]
        out[k] = int(np.count_nonzero(np.isin(image, labels)))
    return out
