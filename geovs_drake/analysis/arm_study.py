"""The arm loop at the goal: Drake's ``Linearize`` against the closed form through J_C.

At the goal the camera is at rest at y*, the NF's differential vanishes, and the
gravity compensation cancels gravity exactly, so only three terms of the arm's
torque ``tau = J_C^T F_C - tau_g - B_q v`` (:class:`~geovs_drake.systems.ArmCamera`)
survive to first order. With the camera's displacement ``eps = J_C dq``
(right-trivialised, in C, rotation first, as in :mod:`.linearization`) and the free
body's stiffness ``K = k_p C_chart^T H C_chart``, the arm's model is::

    M(q*) ddq = -J_C^T K J_C dq - (J_C^T B J_C + B_q I) dq_dot,

i.e. ``A = [[0, I], [-M^-1 K_q, -M^-1 D_q]]`` on (dq, dq_dot): the free body's
closed form with the rig's M replaced by the arm's M(q*) and K, B mapped through
J_C. Where J_C loses rank K_q does too: the goal is then not isolated in joint
space (the argument that E decreases needs no rank; the one that the arm stops at
the goal needs J_C^T F_C = 0 to imply F_C = 0, i.e. full rank).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import Linearize

from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.loop import build_loop
from geovs_drake.loop.arm import arm_model, solve_joints
from geovs_drake.scenario import ScenarioConfig, resolve
from geovs_drake.simulation.step_limit import chart_jacobian, navigation_hessian
from geovs_drake.systems._arm_model import CAMERA_FRAME, arm_plant, camera_jacobian

__all__ = ["ArmLinearization", "linearize_arm_at_goal"]


@dataclass
class ArmLinearization:
    """The arm loop's linearisation at the goal: Drake's A on (q, v), the closed form,
    the goal's joints, sigma_min of J_C there, and the eigenvalues."""

    q_goal: np.ndarray
    A_drake: np.ndarray
    A_closed: np.ndarray
    jacobian_singular_value: float
    eigenvalues: np.ndarray

    @property
    def max_real_part(self) -> float:
        """The largest real part of the eigenvalues: < 0 for a stable goal."""
        return float(np.max(self.eigenvalues.real))


def linearize_arm_at_goal(config: ScenarioConfig) -> ArmLinearization:
    """Drake's ``Linearize`` of the dynamic arm loop at rest at the goal (the joints by
    IK of the goal pose), and the closed form (module docstring)."""
    config = copy.deepcopy(config)
    if config.carrier != "arm" or config.plant != "dynamic":
        raise ValueError(
            f"linearize_arm_at_goal needs carrier 'arm' and plant 'dynamic', got "
            f"{config.carrier!r} and {config.plant!r}"
        )
    model = arm_model(config)
    q_goal = solve_joints(model, config.X_WB @ config.X_BC_goal)
    config.initial = copy.deepcopy(config.goal)
    config.arm.initial_joints = q_goal.tolist()
    config.arm.initial_joint_velocity = []
    resolved = resolve(config)
    loop = build_loop(resolved, log=False)
    context = loop.diagram.CreateDefaultContext()
    A_drake = Linearize(
        loop.diagram,
        context,
        input_port_index=InputPortSelection.kNoInput,
        output_port_index=OutputPortSelection.kNoOutput,
    ).A()

    c = resolved.config  # the arm's gains (ArmConfig.gain_scale applied)
    y = resolved.y_goal
    H = navigation_hessian(NavigationFunction(resolved.domain, y, resolved.gains), y)
    Cc = chart_jacobian(y, resolved.believed_radius)
    K = c.control.potential_gain * Cc.T @ H @ Cc
    plant = arm_plant(model)
    pc = plant.CreateDefaultContext()
    plant.SetPositions(pc, q_goal)
    camera = plant.GetFrameByName(CAMERA_FRAME)
    J = camera_jacobian(plant, pc, camera)
    M = plant.CalcMassMatrix(pc)
    nv = len(q_goal)
    K_q = J.T @ K @ J
    D_q = J.T @ np.diag(resolved.damping) @ J + c.arm.joint_damping * np.eye(nv)
    A_closed = np.zeros((2 * nv, 2 * nv))
    A_closed[:nv, nv:] = np.eye(nv)
    A_closed[nv:, :nv] = -np.linalg.solve(M, K_q)
    A_closed[nv:, nv:] = -np.linalg.solve(M, D_q)
    return ArmLinearization(
        q_goal=q_goal,
        A_drake=A_drake,
        A_closed=A_closed,
        jacobian_singular_value=float(np.linalg.svd(J, compute_uv=False)[-1]),
        eigenvalues=np.sort_complex(np.linalg.eigvals(A_drake)),
    )
