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
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import FirstOrderTaylorApproximation, Linearize

from geovs_drake.diagrams import make_dynamic_servo_diagram, make_kinematic_servo_diagram
from geovs_drake.geometry.so3 import hat
from geovs_drake.loop.state import initial_body_states
from geovs_drake.scenario import PoseConfig, ScenarioConfig
from geovs_drake.simulation.step_limit import (
    closed_form_A,
    navigation_hessian,
    rig_spatial_inertia,
    velocity_adjoint,
)

__all__ = [
    "EQUILIBRIUM_TOLERANCE",
    "LinearizationAlong",
    "LinearizationResult",
    "LoopLinearization",
    "closed_form_A",
    "config_at_goal",
    "linearize",
    "linearize_along",
    "linearize_at_goal",
    "navigation_hessian",
    "rig_spatial_inertia",
    "state_at",
    "tangent_map",
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
    T = tangent_map(config, x0, plant)  # at rest: the velocity rows do not see eps
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


# --- The loop linearised at any state (issue 21): an AffineSystem in Drake's state and
# --- its minimal model in the coordinates above.

#: ``|xdot|`` below which a state counts as an equilibrium: there Drake's ``Linearize``
#: (which checks it) gives a LinearSystem; elsewhere FirstOrderTaylorApproximation's
#: AffineSystem keeps the drift f0.
EQUILIBRIUM_TOLERANCE = 1e-9


@dataclass
class LoopLinearization:
    """The closed loop linearised at a state x0 (:func:`linearize`).

    Attributes:
        plant: ``"dynamic"`` or ``"kinematic"``.
        state: x0, Drake's continuous state (13 dynamic, 7 kinematic).
        system: Drake's model there: a ``LinearSystem`` (``Linearize``, in ``x - x0``)
            at an equilibrium, else an ``AffineSystem`` (``FirstOrderTaylorApproximation``:
            ``xdot = A_drake x + f0``, ``f0 = xdot(x0) - A_drake x0``); no inputs or outputs.
        T: minimal coordinates -> Drake state perturbation at x0 (the chart's Jacobian).
        A: the minimal model ``T^+ A_drake T`` (12 dynamic, 6 kinematic).
        f0: the drift in minimal coordinates, ``T^+ xdot(x0)`` (0 at an equilibrium).
        eigenvalues: of ``A``, sorted by real part.
    """

    plant: str
    state: np.ndarray
    system: object
    T: np.ndarray
    A: np.ndarray
    f0: np.ndarray
    eigenvalues: np.ndarray

    @property
    def A_drake(self) -> np.ndarray:
        """Drake's A in its own state."""
        return self.system.A()

    @property
    def max_real_part(self) -> float:
        """The largest real part of the eigenvalues: < 0 for a stable (frozen) model."""
        return float(np.max(self.eigenvalues.real))

    @property
    def at_equilibrium(self) -> bool:
        """x0 is an equilibrium (``|xdot|`` <= :data:`EQUILIBRIUM_TOLERANCE`)."""
        return bool(np.linalg.norm(self.f0) <= EQUILIBRIUM_TOLERANCE)

    @property
    def damping_ratios(self) -> np.ndarray:
        """``-Re(lambda) / |lambda|`` per eigenvalue (1 for a real stable mode; NaN at 0)."""
        lam = self.eigenvalues
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(np.abs(lam) > 0, -lam.real / np.abs(lam), np.nan)

    @property
    def time_constants(self) -> np.ndarray:
        """``-1 / Re(lambda)`` [s] per eigenvalue (inf where Re(lambda) = 0, negative
        where the mode grows)."""
        with np.errstate(divide="ignore"):
            return -1.0 / self.eigenvalues.real


def tangent_map(config: ScenarioConfig, state: np.ndarray, plant: str | None = None) -> np.ndarray:
    """T: the camera's right perturbation ``eps = (dtheta, dp)`` (and, dynamic, its body
    twist ``nu``) to the perturbation of Drake's state at ``state``.

    The chart: ``X_WC = X_WC0 (Cay(dtheta), dp)``, the rotation by its Gibbs vector
    (``q = q0 (x) (1, dtheta / 2)``, normalised) and the position ``p0 + R_WC0 dp``;
    the rig follows at X_RC (``eps_R = Ad_X_RC eps``, ``nu_R = Ad_X_RC nu``) and its
    Drake velocity is ``(R_WR w_R, R_WR v_R)``, whose derivative along ``dtheta_R`` is
    ``-R_WR hat(w_R)``, ``-R_WR hat(v_R)`` (zero at rest, as in :func:`linearize_at_goal`).
    """
    plant = plant or config.plant
    x = np.asarray(state, dtype=float)
    q = x[0:4] / np.linalg.norm(x[0:4])
    R_W = RotationMatrix(Quaternion(q)).matrix()
    if plant != "dynamic":
        T = np.zeros((7, 6))
        T[0:4, 0:3] = _quaternion_tangent(q)
        T[4:7, 3:6] = R_W
        return T
    w_R, v_R = R_W.T @ x[7:10], R_W.T @ x[10:13]  # the rig's body velocity, in R
    T_R = np.zeros((13, 12))
    T_R[0:4, 0:3] = _quaternion_tangent(q)
    T_R[4:7, 3:6] = R_W
    T_R[7:10, 0:3] = -R_W @ hat(w_R)
    T_R[10:13, 0:3] = -R_W @ hat(v_R)
    T_R[7:10, 6:9] = R_W
    T_R[10:13, 9:12] = R_W
    return T_R @ np.kron(np.eye(2), velocity_adjoint(config.X_RC))


def state_at(
    config: ScenarioConfig,
    X_BC: RigidTransform | None = None,
    twist: np.ndarray | None = None,
    plant: str | None = None,
) -> np.ndarray:
    """Drake's continuous state for the camera pose X_BC (default: the goal) and, dynamic
    loop, the camera's body twist ``(Omega, V)`` (default: at rest)."""
    c = copy.deepcopy(config)
    c.plant = plant or config.plant
    X = (X_BC or config.X_BC_goal).GetAsMatrix4()[None]
    twists = None if twist is None else np.asarray(twist, dtype=float)[None]
    return initial_body_states(c, X, twists)[0]


def linearize(
    config: ScenarioConfig | None = None,
    state: np.ndarray | None = None,
    plant: str | None = None,
) -> LoopLinearization:
    """The closed loop's linear model at ``state`` (Drake's continuous state; default: at
    rest at the goal), as a Drake system and in minimal coordinates.

    Drake's ``Linearize`` where x0 is an equilibrium, ``FirstOrderTaylorApproximation``
    elsewhere (both by AutoDiffXd of the whole diagram). The minimal model is the tangent
    projection ``T^+ A_drake T`` (:func:`tangent_map`): at an equilibrium it is the
    minimal linearisation of :func:`linearize_at_goal` (chart-independent there); away
    from one, for the kinematic loop it is the Jacobian of the vector field in the chart
    (Drake's qdot is orthogonal to q, so the Gibbs chart's second-order term vanishes),
    and for a moving rig it leaves out the chart's terms proportional to xdot (the
    frozen-time model, whose eigenvalues only indicate, Eq. 45's energy argument decides).

    Inputs and outputs (a disturbance wrench or twist; the pose error and y) are not
    modelled yet: the diagrams have no such ports, so ``system`` has none.
    """
    config = copy.deepcopy(config or ScenarioConfig())
    config.plant = plant or config.plant
    if config.mount != "hand" or config.carrier != "free":
        raise ValueError(
            "linearize models the eye-in-hand free rig only: "
            f"mount = {config.mount!r}, carrier = {config.carrier!r}"
        )
    config.camera.sensor = "exact"  # a sampled camera has discrete state: no A
    if config.plant == "dynamic":
        diagram = make_dynamic_servo_diagram(config, log=False)
    else:
        diagram = make_kinematic_servo_diagram(config, log=False)
    x0 = state_at(config) if state is None else np.asarray(state, dtype=float)
    n = diagram.num_continuous_states()
    if x0.shape != (n,):
        raise ValueError(f"state must have {n} entries for the {config.plant} loop: {x0.shape}")
    context = diagram.CreateDefaultContext()
    context.SetContinuousState(x0)
    xdot = diagram.EvalTimeDerivatives(context).CopyToVector()
    ports = dict(
        input_port_index=InputPortSelection.kNoInput,
        output_port_index=OutputPortSelection.kNoOutput,
    )
    if np.linalg.norm(xdot) <= EQUILIBRIUM_TOLERANCE:
        system = Linearize(diagram, context, **ports)
    else:
        system = FirstOrderTaylorApproximation(diagram, context, **ports)
    T = tangent_map(config, x0)
    P = np.linalg.pinv(T)
    A = P @ system.A() @ T
    return LoopLinearization(
        plant=config.plant,
        state=x0,
        system=system,
        T=T,
        A=A,
        f0=P @ xdot,
        eigenvalues=np.sort_complex(np.linalg.eigvals(A)),
    )


@dataclass
class LinearizationAlong:
    """The LTV model along a run (:func:`linearize_along`).

    Attributes:
        times: the sample times [s].
        models: the :class:`LoopLinearization` at each.
        eigenvalues: (len(times), n), each row sorted by real part.
        max_real_part: (len(times),), the largest real part at each time.
    """

    times: np.ndarray
    models: list[LoopLinearization]
    eigenvalues: np.ndarray
    max_real_part: np.ndarray


def linearize_along(result, times: np.ndarray | list[float]) -> LinearizationAlong:
    """:func:`linearize` at the logged states of a
    :class:`~geovs_drake.simulation.SimulationResult` nearest each of ``times`` (the
    run's Drake states, ``result.states``)."""
    if result.states is None:
        raise ValueError("the result carries no states (run it with simulate())")
    times = np.atleast_1d(np.asarray(times, dtype=float))
    index = np.clip(np.searchsorted(result.times, times), 0, len(result.times) - 1)
    models = [linearize(result.config, result.states[k]) for k in index]
    eigenvalues = np.stack([m.eigenvalues for m in models])
    return LinearizationAlong(
        times=result.times[index],
        models=models,
        eigenvalues=eigenvalues,
        max_real_part=np.max(eigenvalues.real, axis=1),
    )
