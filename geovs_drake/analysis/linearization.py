"""Linearisation of the closed loops at the goal, by Drake's ``Linearize`` and in closed form.

Minimal coordinates. The camera's pose is perturbed on the right, in its own
frame: ``X_WC = X_WC* exp(hat(eps))``, ``eps = (dtheta, dp)`` (rotation first),
and ``nu = (Omega, V)`` is its body velocity. Then ``X_CB = exp(-hat(eps)) H*``,
so the right-trivialised displacement of H is ``(omega, v) = -eps`` (Eq. 16) and
the image moves by ``-C_chart eps`` in the NF's chart (:mod:`nf_study`).

Closed forms, with ``H`` the chart Hessian of phi at y* and
``C_chart = diag(I_4, B^T) C(y*)`` (6x6, invertible):

* dynamic (Eq. 45 on Eq. 46): ``K = k_p C_chart^T H C_chart`` and
  ``A = [[0, I], [-M^-1 K, -M^-1 B]]``, M the rig's spatial inertia about the
  camera origin in C (Appendix C.0.6: ``Ad^T M_R Ad``);
* kinematic (Eqs. 17-19): ``A = -k C_chart^-1 H C_chart``, whose eigenvalues
  are ``-k eig(H)``.

Drake's state carries a quaternion; the map ``T`` from minimal coordinates to
its state perturbation has the quaternion's norm direction as complement, an
eigenvector of Drake's A with eigenvalue 0. ``T^+ A T`` is the minimal model.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import Linearize

from geovs_drake.diagrams import make_dynamic_servo_diagram, make_kinematic_servo_diagram
from geovs_drake.scenario import PoseConfig, ScenarioConfig
from geovs_drake.simulation.step_limit import (
    closed_form_A,
    navigation_hessian,
    rig_spatial_inertia,
    velocity_adjoint,
)

__all__ = [
    "LinearizationResult",
    "closed_form_A",
    "config_at_goal",
    "linearize_at_goal",
    "navigation_hessian",
    "rig_spatial_inertia",
]


def _quaternion_tangent(q: np.ndarray) -> np.ndarray:
    """d q / d dtheta for q(dtheta) = q (x) (1, dtheta / 2): a body-frame rotation."""
    w, x, y, z = q
    # q (x) (0, e_k) / 2, k = 1..3.
    return 0.5 * np.array([[-x, -y, -z], [w, -z, y], [z, w, -x], [-y, x, w]])


@dataclass
class LinearizationResult:
    """The closed loop linearised at the goal, in Drake's state and in minimal coordinates.

    Attributes:
        A_drake: Drake's ``Linearize`` A in its own state (13 dynamic, 7 kinematic).
        T: minimal coordinates -> Drake state perturbation.
        A: the minimal model ``T^+ A_drake T`` (12 dynamic, 6 kinematic).
        A_closed: the closed form (:func:`closed_form_A`) in the same coordinates.
        eigenvalues: of ``A``, sorted by real part.
        quaternion_eigenvalue: of ``A_drake`` along the quaternion's norm.
        invariance_residual: ``|A_drake T - T A| / |A_drake|``: T's span is invariant.
    """

    A_drake: np.ndarray  # Drake's A in its own state (13 or 7)
    T: np.ndarray  # minimal coordinates -> Drake state perturbation
    A: np.ndarray  # minimal model T^+ A_drake T (12 or 6)
    A_closed: np.ndarray  # closed form in the same coordinates
    eigenvalues: np.ndarray  # of A, sorted by real part
    quaternion_eigenvalue: complex  # of A_drake along the quaternion norm
    invariance_residual: float  # |A_drake T - T A| / |A_drake|: T's span is invariant

    @property
    def max_real_part(self) -> float:
        """The largest real part of the eigenvalues: < 0 for a stable goal."""
        return float(np.max(self.eigenvalues.real))


def config_at_goal(config: ScenarioConfig) -> ScenarioConfig:
    """A copy of ``config`` that starts at rest at the goal pose."""
    c = copy.deepcopy(config)
    c.initial = PoseConfig(list(config.goal.xyz), list(config.goal.rpy))
    return c


def linearize_at_goal(
    config: ScenarioConfig | None = None, plant: str | None = None
) -> LinearizationResult:
    """Drake's ``Linearize`` of the whole closed loop at the goal, reduced to minimal form."""
    config = config_at_goal(config or ScenarioConfig())
    plant = plant or config.plant
    if config.mount != "hand":
        raise ValueError(
            f"linearize_at_goal's closed form is the eye-in-hand loop's: mount = {config.mount!r}"
        )
    if plant == "dynamic":
        diagram = make_dynamic_servo_diagram(config, log=False)
    else:
        diagram = make_kinematic_servo_diagram(config, log=False)
    context = diagram.CreateDefaultContext()
    lin = Linearize(
        diagram,
        context,
        input_port_index=InputPortSelection.kNoInput,
        output_port_index=OutputPortSelection.kNoOutput,
    )
    A_drake = lin.A()
    x0 = context.get_continuous_state_vector().CopyToVector()
    q = x0[0:4]
    if plant == "dynamic":
        X_RC = config.X_RC
        X_WR = config.X_WB @ config.X_BC_goal @ X_RC.inverse()
        R_WR = X_WR.rotation().matrix()
        T_R = np.zeros((13, 12))
        T_R[0:4, 0:3] = _quaternion_tangent(q)
        T_R[4:7, 3:6] = R_WR
        T_R[7:10, 6:9] = R_WR
        T_R[10:13, 9:12] = R_WR
        Ad = velocity_adjoint(X_RC)
        T = T_R @ np.kron(np.eye(2), Ad)
    else:
        R_W = (config.X_WB @ config.X_BC_goal).rotation().matrix()
        T = np.zeros((7, 6))
        T[0:4, 0:3] = _quaternion_tangent(q)
        T[4:7, 3:6] = R_W
    A = np.linalg.pinv(T) @ A_drake @ T
    e_q = np.zeros(len(x0))
    e_q[0:4] = q / np.linalg.norm(q)
    return LinearizationResult(
        A_drake=A_drake,
        T=T,
        A=A,
        A_closed=closed_form_A(config, plant),
        eigenvalues=np.sort_complex(np.linalg.eigvals(A)),
        quaternion_eigenvalue=complex(e_q @ A_drake @ e_q),
        invariance_residual=float(
            np.linalg.norm(A_drake @ T - T @ A) / max(1e-300, np.linalg.norm(A_drake))
        ),
    )
