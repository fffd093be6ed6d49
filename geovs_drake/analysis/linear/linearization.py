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
import dataclasses
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import (
    Diagram,
    DiagramBuilder,
    InputPortSelection,
    OutputPortSelection,
)
from pydrake.systems.primitives import (
    AffineSystem,
    Demultiplexer,
    FirstOrderTaylorApproximation,
    Linearize,
    LinearSystem,
    Multiplexer,
)

from geovs_drake._json import json_ready
from geovs_drake.geometry._ops import namespace
from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.navigation import image_chart
from geovs_drake.geometry.rigid import quaternion_multiply, quaternion_to_rotation
from geovs_drake.geometry.so3 import hat
from geovs_drake.goal.linear_model import (
    closed_form_A,
    closed_form_refusal,
    navigation_hessian,
    rig_spatial_inertia,
    velocity_adjoint,
)
from geovs_drake.loop import build_loop, exact_twin, resolve
from geovs_drake.loop.assembly import FEATURE_SIZE
from geovs_drake.loop.state import initial_body_states
from geovs_drake.scenario import PlantConfig, PoseConfig, ScenarioConfig, variant_name
from geovs_drake.spectrum import EigenvalueFacts, canonical_eigenvalues

__all__ = [
    "EQUILIBRIUM_TOLERANCE",
    "INPUTS",
    "OUTPUTS",
    "LinearizationAlong",
    "LinearizationResult",
    "LoopLinearization",
    "closed_form_A",
    "config_at_goal",
    "linearize",
    "linearize_along",
    "linearize_at_goal",
    "navigation_hessian",
    "noise_directions",
    "pose_error",
    "rig_spatial_inertia",
    "state_at",
    "tangent_map",
    "wrench_to_generalized_force",
]


def _quaternion_tangent(q: np.ndarray) -> np.ndarray:
    """d q / d dtheta for q(dtheta) = q (x) (1, dtheta / 2): a body-frame rotation."""
    w, x, y, z = q
    # q (x) (0, e_k) / 2, k = 1..3.
    return 0.5 * np.array([[-x, -y, -z], [w, -z, y], [z, w, -x], [-y, x, w]])


@dataclass
class LinearizationResult(EigenvalueFacts):
    """The closed loop linearised at the goal, in Drake's state and in minimal coordinates.

    Attributes:
        A_drake: Drake's ``Linearize`` A in its own state (13 dynamic, 7 kinematic).
        T: minimal coordinates -> Drake state perturbation.
        A: the minimal model ``T^+ A_drake T`` (12 dynamic, 6 kinematic).
        A_closed: the closed form (:func:`closed_form_A`) in the same coordinates.
        eigenvalues: of ``A``, in the canonical order (:mod:`geovs_drake.spectrum`).
        quaternion_eigenvalue: of ``A_drake`` along the quaternion's norm.
        invariance_residual: ``|A_drake T - T A| / |A_drake|``: T's span is invariant.
    """

    A_drake: np.ndarray  # Drake's A in its own state (13 or 7)
    T: np.ndarray  # minimal coordinates -> Drake state perturbation
    A: np.ndarray  # minimal model T^+ A_drake T (12 or 6)
    A_closed: np.ndarray  # closed form in the same coordinates
    eigenvalues: np.ndarray  # of A, in the canonical order
    quaternion_eigenvalue: complex  # of A_drake along the quaternion norm
    invariance_residual: float  # |A_drake T - T A| / |A_drake|: T's span is invariant


def config_at_goal(config: ScenarioConfig) -> ScenarioConfig:
    """A copy of ``config`` that starts at rest at the goal pose."""
    c = copy.deepcopy(config)
    c.initial_velocity = [0.0] * 6
    c.initial = PoseConfig(list(config.goal.xyz), list(config.goal.rpy))
    return c


def linearize_at_goal(
    config: ScenarioConfig | None = None, plant: PlantConfig | None = None
) -> LinearizationResult:
    """Drake's ``Linearize`` of the whole closed loop at the goal, reduced to minimal form."""
    config = config_at_goal(config or ScenarioConfig())
    plant = config.plant if plant is None else plant
    refusal = closed_form_refusal(config, "linearize_at_goal")
    if refusal is not None:
        raise ValueError(refusal)
    diagram = build_loop(dataclasses.replace(exact_twin(config), plant=plant), log=False).diagram
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
        A_closed=closed_form_A(resolve(config), plant),
        eigenvalues=canonical_eigenvalues(A),
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

#: The minimal model's input u and output z, by name: u = (disturbance, feature noise),
#: z = (pose error, y). The disturbance is the camera's wrench F_C about Co in C
#: (torque first; dynamic loop) or its body twist (Omega, V) in C (kinematic loop),
#: added to the law's. The noise moves the y that the NF and the law read within the
#: image space, in the NF's chart about y(x0) (:func:`~geovs_drake.geometry.navigation.image_chart`:
#: a rotation of Q, lambda, then s along its tangent plane; 6): the diagram adds
#: ``image_chart(y, n) - y`` to y. The pose error is :func:`pose_error` of the camera;
#: y is the true y = c(H) (Q as 9 entries, lambda, s).
INPUTS = {"disturbance": slice(0, 6), "feature_noise": slice(6, 12)}
OUTPUTS = {"pose_error": slice(0, 6), "image_features": slice(6, 6 + FEATURE_SIZE)}
_POSE_SIZE = 7


@dataclass
class LoopLinearization(EigenvalueFacts):
    """The closed loop linearised at a state x0 (:func:`linearize`).

    Attributes:
        plant: the plant's name, ``"dynamic"`` or ``"kinematic"``.
        state: x0, Drake's continuous state (13 dynamic, 7 kinematic).
        system: Drake's model there, of the loop with one input (the disturbance, then
            the noise, in the loop's own conventions) and one output (the body pose
            ``[q, p]``, then y): a ``LinearSystem`` (``Linearize``, in ``x - x0``) at an
            equilibrium, else an ``AffineSystem`` (``FirstOrderTaylorApproximation``).
        minimal: the same model in minimal coordinates, with u and z as :data:`INPUTS`
            and :data:`OUTPUTS` lay them out: a ``LinearSystem`` in deviations from
            (x0, 0, z0) at an equilibrium, else an ``AffineSystem``
            (``xdot = A x + B u + f0``, ``z = C x + D u + z0``, x the displacement from x0).
        T: minimal coordinates -> Drake state perturbation at x0 (the chart's Jacobian).
        A: the minimal model ``T^+ A_drake T`` (12 dynamic, 6 kinematic).
        f0: the drift in minimal coordinates, ``T^+ xdot(x0)`` (0 at an equilibrium).
        eigenvalues: of ``A``, in the canonical order (:mod:`geovs_drake.spectrum`).
    """

    plant: str
    state: np.ndarray
    system: object
    minimal: object
    T: np.ndarray
    A: np.ndarray
    f0: np.ndarray
    eigenvalues: np.ndarray

    @property
    def A_drake(self) -> np.ndarray:
        """Drake's A in its own state."""
        return self.system.A()

    @property
    def B(self) -> np.ndarray:
        """The minimal model's B on u = (disturbance, feature noise)."""
        return self.minimal.B()

    @property
    def C(self) -> np.ndarray:
        """The minimal model's C to z = (pose error, y)."""
        return self.minimal.C()

    @property
    def D(self) -> np.ndarray:
        """The minimal model's D (the true y and the pose do not see u: zero)."""
        return self.minimal.D()

    @property
    def at_equilibrium(self) -> bool:
        """x0 is an equilibrium (``|xdot|`` <= :data:`EQUILIBRIUM_TOLERANCE`)."""
        return bool(np.linalg.norm(self.f0) <= EQUILIBRIUM_TOLERANCE)

    def summary(self) -> dict:
        """The model as JSON values (``geovs-drake linearize --json``): ``plant``,
        ``at_equilibrium``, the minimal ``A``, ``eigenvalues`` as ``[re, im]`` pairs,
        ``max_real_part``, ``damping_ratios`` and ``time_constants`` (None where not
        finite) and ``stable``."""
        return json_ready(
            {
                "plant": self.plant,
                "at_equilibrium": self.at_equilibrium,
                "A": self.A,
                **self.eigenvalue_summary(),
            }
        )


def tangent_map(
    config: ScenarioConfig, state: np.ndarray, plant: PlantConfig | None = None
) -> np.ndarray:
    """T: the camera's right perturbation ``eps = (dtheta, dp)`` (and, dynamic, its body
    twist ``nu``) to the perturbation of Drake's state at ``state``.

    The chart: ``X_WC = X_WC0 (Cay(dtheta), dp)``, the rotation by its Gibbs vector
    (``q = q0 (x) (1, dtheta / 2)``, normalised) and the position ``p0 + R_WC0 dp``;
    the rig follows at X_RC (``eps_R = Ad_X_RC eps``, ``nu_R = Ad_X_RC nu``) and its
    Drake velocity is ``(R_WR w_R, R_WR v_R)``, whose derivative along ``dtheta_R`` is
    ``-R_WR hat(w_R)``, ``-R_WR hat(v_R)`` (zero at rest, as in :func:`linearize_at_goal`).
    """
    plant = config.plant if plant is None else plant
    x = np.asarray(state, dtype=float)
    q = x[0:4] / np.linalg.norm(x[0:4])
    R_W = RotationMatrix(Quaternion(q)).matrix()
    if not plant.traits.dynamic:
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
    plant: PlantConfig | None = None,
) -> np.ndarray:
    """Drake's continuous state for the camera pose X_BC (default: the goal) and, dynamic
    loop, the camera's body twist ``(Omega, V)`` (default: at rest)."""
    c = copy.deepcopy(config)
    c.plant = config.plant if plant is None else plant
    X = (X_BC or config.X_BC_goal).GetAsMatrix4()[None]
    twists = None if twist is None else np.asarray(twist, dtype=float)[None]
    return initial_body_states(c, X, twists)[0]


def pose_error(X_WC_goal: RigidTransform, body_pose, X_RC: RigidTransform):
    """The camera's pose error from the goal, ``(g, dp)``: the Gibbs vector g of
    ``R_WC*^T R_WC`` (``2 vec(q) / w``, the rotation vector to first order) and
    ``dp = R_WC*^T (p_WC - p_WC*)``, from the body pose ``[q_WR, p_WR]`` (7) that the
    camera system reads, with the camera at X_RC on the body. The minimal coordinates
    centred at the goal: at rest there its Jacobian along them is the identity.
    Written for float and AutoDiffXd entries (undefined at a half turn, w = 0)."""
    z = np.asarray(body_pose)
    xp = namespace(z[0])
    norm = xp.sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2] + z[3] * z[3])
    q, p = tuple(v / norm for v in z[0:4]), z[4:7]
    R_WR = np.array(quaternion_to_rotation(q, xp)).reshape(3, 3)
    q_WC = quaternion_multiply(q, tuple(X_RC.rotation().ToQuaternion().wxyz()))
    p_WC = p + R_WR @ X_RC.translation()
    w, x, y, z_ = X_WC_goal.rotation().ToQuaternion().wxyz()
    q_err = quaternion_multiply((w, -x, -y, -z_), q_WC)
    g = 2.0 * np.array(q_err[1:4]) / q_err[0]
    dp = X_WC_goal.rotation().matrix().T @ (p_WC - X_WC_goal.translation())
    return np.concatenate([g, dp])


def wrench_to_generalized_force(X_WR: RigidTransform, X_RC: RigidTransform) -> np.ndarray:
    """G: a wrench F_C on the camera about Co in C (torque first) to the free rig's
    generalized force (torque about R's origin, then force, in W):
    ``[[R_WC, hat(p_W) R_WC], [0, R_WC]]``, p_W the camera's offset from R in W. It is the
    wrench's adjoint, ``Ad_{X^-1}^T`` for X = (R_WC, p_W) (the power ``F . nu`` holds)."""
    X = RigidTransform(X_WR.rotation() @ X_RC.rotation(), X_WR.rotation() @ X_RC.translation())
    return velocity_adjoint(X.inverse()).T


def noise_directions(y: np.ndarray) -> np.ndarray:
    """d y / d n (13 x 6) of ``image_chart(y, n)`` at n = 0: the noise's chart
    directions in y's 13 entries (AutoDiffXd of the chart)."""
    n = InitializeAutoDiff(np.zeros(6)).ravel()
    return ExtractGradient(image_chart(ImageFeatures.from_vector(y), n).to_vector())


def _study_diagram(loop) -> Diagram:
    """The loop with its study ports gathered into one input u_drake = (disturbance,
    noise) and one output (body pose, y): Drake's ``Linearize`` takes one of each."""
    builder = DiagramBuilder()
    inner = builder.AddSystem(loop.diagram)
    split = builder.AddSystem(Demultiplexer([6, FEATURE_SIZE]))
    builder.ExportInput(split.get_input_port(), "u")
    builder.Connect(split.get_output_port(0), inner.GetInputPort("disturbance"))
    builder.Connect(split.get_output_port(1), inner.GetInputPort("feature_noise"))
    join = builder.AddSystem(Multiplexer([_POSE_SIZE, FEATURE_SIZE]))
    builder.Connect(inner.GetOutputPort("body_pose"), join.get_input_port(0))
    builder.Connect(inner.GetOutputPort("image_features"), join.get_input_port(1))
    builder.ExportOutput(join.get_output_port(), "z")
    return builder.Build()


def _pose_error_jacobian(X_WC_goal: RigidTransform, body_pose: np.ndarray, X_RC):
    z = InitializeAutoDiff(np.asarray(body_pose, dtype=float)).ravel()
    e = pose_error(X_WC_goal, z, X_RC)
    return ExtractValue(e).ravel(), ExtractGradient(e)


def linearize(
    config: ScenarioConfig | None = None,
    state: np.ndarray | None = None,
    plant: PlantConfig | None = None,
) -> LoopLinearization:
    """The closed loop's linear model at ``state`` (Drake's continuous state; default: at
    rest at the goal), as a Drake system and in minimal coordinates, with its inputs
    (a disturbance, the feature noise) and outputs (the pose error, y): :data:`INPUTS`,
    :data:`OUTPUTS`.

    Drake's ``Linearize`` where x0 is an equilibrium, ``FirstOrderTaylorApproximation``
    elsewhere (both by AutoDiffXd of the whole diagram, built by ``build_loop`` with its
    study ports). The minimal model is the tangent projection ``T^+ A_drake T``
    (:func:`tangent_map`): at an equilibrium it is the minimal linearisation of
    :func:`linearize_at_goal` (chart-independent there); away from one, for the
    kinematic loop it is the Jacobian of the vector field in the chart (Drake's qdot is
    orthogonal to q, so the Gibbs chart's second-order term vanishes), and for a moving
    rig it leaves out the chart's terms proportional to xdot (the frozen-time model,
    whose eigenvalues only indicate, Eq. 45's energy argument decides).

    Raises ValueError for a loop it does not model (a fixed camera, the arm) or a state
    of the wrong size.
    """
    config = copy.deepcopy(config or ScenarioConfig())
    config.plant = config.plant if plant is None else plant
    refusal = closed_form_refusal(config, "linearize")
    if refusal is not None:
        raise ValueError(refusal)
    config = exact_twin(config)  # a sampled camera has discrete state: no A
    loop = build_loop(config, log=False, study_ports=True)
    diagram = _study_diagram(loop)
    x0 = state_at(config) if state is None else np.asarray(state, dtype=float)
    n = diagram.num_continuous_states()
    if x0.shape != (n,):
        raise ValueError(
            f"state must have {n} entries for the {variant_name(config.plant)} loop: {x0.shape}"
        )
    context = diagram.CreateDefaultContext()
    context.SetContinuousState(x0)
    diagram.get_input_port().FixValue(context, np.zeros(6 + FEATURE_SIZE))
    xdot = diagram.EvalTimeDerivatives(context).CopyToVector()
    at_rest = np.linalg.norm(xdot) <= EQUILIBRIUM_TOLERANCE
    z_drake = diagram.get_output_port().Eval(context)
    ports = dict(
        input_port_index=InputPortSelection.kUseFirstInputIfItExists,
        output_port_index=OutputPortSelection.kUseFirstOutputIfItExists,
    )
    if at_rest:
        system = Linearize(diagram, context, **ports)
    else:
        system = FirstOrderTaylorApproximation(diagram, context, **ports)
    T = tangent_map(config, x0)
    P = np.linalg.pinv(T)
    A = P @ system.A() @ T
    # u: Drake's disturbance in its convention -> F_C (the free rig takes the plant's
    # generalized force) or the twist; the noise's chart to its 13 ambient entries.
    to_drake = np.zeros((6 + FEATURE_SIZE, 12))
    to_drake[0:6, 0:6] = np.eye(6)
    to_drake[6:, 6:] = noise_directions(z_drake[_POSE_SIZE:])
    if loop.disturbance == "generalized_force":
        X_WR = RigidTransform(Quaternion(x0[0:4] / np.linalg.norm(x0[0:4])), x0[4:7])
        to_drake[0:6, 0:6] = wrench_to_generalized_force(X_WR, config.X_RC)
    B = P @ system.B() @ to_drake
    # z: the pose error through the body pose's rows, then y's rows as Drake gives them.
    X_WC_goal = config.X_WB @ config.X_BC_goal
    e0, J_e = _pose_error_jacobian(X_WC_goal, z_drake[0:_POSE_SIZE], loop.carrier.X_RC)
    out = np.vstack([J_e @ system.C()[0:_POSE_SIZE], system.C()[_POSE_SIZE:]])
    C = out @ T
    D = np.vstack([J_e @ system.D()[0:_POSE_SIZE], system.D()[_POSE_SIZE:]]) @ to_drake
    f0 = P @ xdot
    if at_rest:
        minimal = LinearSystem(A, B, C, D)
    else:
        minimal = AffineSystem(A, B, f0, C, D, np.concatenate([e0, z_drake[_POSE_SIZE:]]))
    return LoopLinearization(
        plant=variant_name(config.plant),
        state=x0,
        system=system,
        minimal=minimal,
        T=T,
        A=A,
        f0=f0,
        eigenvalues=canonical_eigenvalues(A),
    )


@dataclass
class LinearizationAlong:
    """The LTV model along a run (:func:`linearize_along`).

    Attributes:
        times: the sample times [s].
        models: the :class:`LoopLinearization` at each.
        eigenvalues: (len(times), n), each row in the canonical order (:mod:`geovs_drake.spectrum`).
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
