"""The arm's closed loop, one start's right-hand side, compiled: the Drake loop's, kernel
for kernel.

The arm carrier's diagram (:mod:`geovs_drake.loop.carriers.arm`) wires, with a fixed
target and the exact sensor under the NF:

* dynamic: ``plant (q, v) -> ArmCamera's camera_state -> camera_image -> navigation
  -> servo_force`` (Eq. 45's wrench F_C on the camera, about Co in C) ``->
  ArmCamera``'s torque ``tau = J_C^T F_C - tau_g - B_q v - d N v`` (N the damped
  projector on J_C's null space, redundant arms only) ``-> MultibodyPlant``, which
  clamps each actuator at its effort limit and integrates ``M(q) vdot = clamp(tau) +
  tau_g(q) - C(q, v) v - D v`` (D the joints' own damping);
* kinematic: ``KinematicArm's camera_pose -> camera_image -> navigation ->
  kinematic_velocity`` (the twist nu = k Tc^-1 dphi, Eqs. 18-19) ``-> KinematicArm``:
  the damped resolved rate ``qdot = s (J^+ nu + k_n (I - J^+ J)(q_mid - q))``, J^+ =
  J^T (J J^T + lambda^2 I)^-1, lambda^2 growing in the singular zone, s <= 1 the joint
  velocity limits' scale.

:func:`arm_loop_parameters` reads the systems' own parameter vectors from a diagram
built from the same config (as :func:`~geovs_drake.batch.engine.loop_parameters` does
for the free rig), so the two cannot drift apart; :func:`arm_loop_rhs` is the compiled
right-hand side (one state; the tree's kernels of
:mod:`~geovs_drake.geometry.arm_kernels`, the loop's of
:mod:`geovs_drake.geometry.kernels`), :func:`arm_rhs` its allocating Python form.
With the pinhole camera (``sensor: !Pinhole``) the camera's ``camera_image`` feeds the
monitor only, and the law reads the sensor's held frame, or that frame moved by the
arm's own odometry (``FramePredictor`` on the camera pose the joints give):
:func:`arm_loop_rhs_held`, the same right-hand side with the image given from outside,
which :mod:`.arm_sampled` runs on the camera's clock.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from geovs_drake.batch._generated.predicted import predicted_image
from geovs_drake.geometry import arm_kernels as _k
from geovs_drake.geometry import kernels
from geovs_drake.geometry.so3 import rotation_to_quaternion
from geovs_drake.systems.arm_tree import ArmTree, arm_tree, warm_arm_kernels

if TYPE_CHECKING:
    from geovs_drake.batch.sampled import SampledCamera

__all__ = [
    "CLAMP_RTOL",
    "SCRATCH_ROWS",
    "ArmLoopParameters",
    "arm_loop_parameters",
    "arm_loop_rhs",
    "arm_loop_rhs_held",
    "arm_rhs",
    "effort_clamped",
    "warm_arm_loop",
]

_camera = kernels.camera_image.compiled
_navigation = kernels.navigation.compiled
_force = kernels.servo_force.compiled
_kinematic_velocity = kernels.kinematic_velocity.compiled
_predicted = njit(cache=True, error_model="numpy", nogil=True)(predicted_image)
# The generated kernels' output layouts, as literals (numba freezes module globals):
# camera_image (nu, y 1:14, margins 14:18), navigation (dphi 1:8, phi 8).
_NU, _Y0, _Y1, _M0, _M1, _D0, _D1, _PHI = 0, 1, 14, 14, 18, 1, 8, 8
_STATE, _POSE = 13, 7
# The dynamic arm's parameter vector: B_q (nv), then d and the projector's mu; the
# kinematic arm's: mu, m, k_n, then the velocity limits (nv).
_KIN_MU, _KIN_SINGULAR, _KIN_NULL = 0, 1, 2
_TWIST = 6
# The rows of the scratch ``vec`` (width max(nv, 13)): 0 and 1 the kinematic solve's and
# the dynamics' vectors, then the camera state, p_WC and the null-space solve, the
# twist or wrench in W, the torque, R_WC (9) and zero velocities.
_ROW_STATE, _ROW_NULL, _ROW_TWIST, _ROW_TAU, _ROW_R, _ROW_ZERO, _ROWS = 2, 3, 4, 5, 6, 7, 8
#: The rows of the scratch ``vec`` a caller of :func:`arm_loop_rhs` allocates (numba checks
#: no bounds: fewer rows would be written past their end).
SCRATCH_ROWS = _ROWS


#: A torque counts as clamped within this fraction of its effort limit: the clamped
#: torque is read back as tau + (C v - tau_g) + D v, to rounding.
CLAMP_RTOL = 1e-9


@njit(cache=True, nogil=True, error_model="numpy")
def effort_clamped(x, joint, vec):
    """Whether :func:`arm_loop_rhs`'s last evaluation (at ``x``, dynamic: its scratch
    ``vec``) clamped an actuator: its torque before the plant's terms, tau + bias + D v
    (the scratch's torque row and row 1), at the effort limit."""
    n = joint.shape[0]
    for c in range(n):
        applied = vec[_ROW_TAU, c] + vec[1, c] + joint[c, 0] * x[n + c]
        if abs(applied) >= joint[c, 2] * (1.0 - CLAMP_RTOL):
            return True
    return False


@dataclass(frozen=True)
class ArmLoopParameters:
    """Everything :func:`arm_loop_rhs` reads, from the systems of ``config``'s diagram.

    ``camera``, ``navigation``: the SphericalCamera's and the NF's parameter vectors;
    ``controller``: the ImageJacobianForce's (dynamic) or the KinematicController's;
    ``arm``: ArmCamera's ``[B_q (nv), d]`` and NULL_SPACE_MU (dynamic) or KinematicArm's
    ``[mu, m, k_n, velocity limits (nv)]``; ``q_mid`` the kinematic arm's centre of
    range; ``potential_gain`` k_p (the dynamic loop's E = 1/2 v^T M v + k_p phi);
    ``sampled`` the pinhole camera's clock and measurement (None: the exact sensor).
    """

    plant: str
    dynamic: bool
    tree: ArmTree
    camera: np.ndarray
    navigation: np.ndarray
    controller: np.ndarray
    arm: np.ndarray
    q_mid: np.ndarray
    potential_gain: float
    max_step_size: float
    #: The pinhole camera's clock and measurement (:mod:`.sampled`); None: the exact y.
    sampled: SampledCamera | None = None
    #: The loop's Drake integration scheme, as resolved: the engine steps with the pair
    #: of its order (``geovs_drake.batch._pairs.pair_for``), under its step limit.
    scheme: str = "runge_kutta3"

    @property
    def state_size(self) -> int:
        """2 nv (q, v: the plant's state) on the dynamic arm, nv (q) on the kinematic."""
        return (2 if self.dynamic else 1) * self.tree.nv

    def kernel_args(self) -> tuple:
        """:func:`arm_loop_rhs`'s arguments after ``(dynamic, x, out)``: the tree's
        arrays, the parameter vectors, then fresh scratch arrays (one set per thread)."""
        n = self.tree.nv
        scratch = (
            self.tree.workspace(), np.zeros((6, n)), np.zeros((n, n)), np.zeros((n, n)),
            np.zeros((6, 6)), np.zeros((6, 6)), np.zeros((_ROWS, max(n, _STATE))),
        )  # fmt: skip
        return (
            *self.tree.kernel_args(), self.camera, self.navigation, self.controller,
            self.arm, self.q_mid, *scratch,
        )  # fmt: skip


def arm_loop_parameters(config) -> ArmLoopParameters:
    """The parameter vectors of the arm's loop ``config`` (a ScenarioConfig or a
    ResolvedScenario) describes, read from a diagram built from it; ValueError in one
    line for what the compiled loop does not model (another law, the rendered camera, a
    pinhole whose frames arrive after their capture, a moving target, the joint-limit
    barrier)."""
    from geovs_drake.loop import assemble_loop, resolve

    resolved = resolve(config)
    config = resolved.config
    sensor = config.sensor.traits
    pinhole = sensor.camera and not sensor.renders
    if not config.controller.traits.batch_kernel or not (sensor.batch_kernel or pinhole):
        raise ValueError(
            f"the arm's compiled loop runs the NF with the exact sensor or the pinhole: "
            f"controller {config.controller!r}, sensor {type(config.sensor).__name__}"
        )
    if config.moving_target:
        raise ValueError("the arm's compiled loop takes a fixed target: target moves")
    carrier = config.carrier
    if carrier.joint_barrier_width or carrier.joint_barrier_fraction:
        raise ValueError(
            "the arm's compiled loop has no joint-limit barrier: joint_barrier_width = "
            f"{carrier.joint_barrier_width}, joint_barrier_fraction = "
            f"{carrier.joint_barrier_fraction}"
        )
    loop = assemble_loop(resolved, log=False)
    diagram = loop.diagram
    root = diagram.CreateDefaultContext()

    def params(name: str) -> np.ndarray:
        system = diagram.GetSubsystemByName(name)
        return system.GetMyContextFromRoot(root).get_numeric_parameter(0).CopyToVector()

    nav = diagram.GetSubsystemByName("navigation_controller")
    tree = arm_tree(loop.carrier.arm)
    if np.any(tree.index != np.arange(tree.nv)[:, None]):  # a chain's order is Drake's
        raise ValueError(f"the arm's joints are not in the plant's q and v order: {tree.index}")
    dynamic = config.dynamic
    lower, upper = tree.joint[:, 3], tree.joint[:, 4]
    if dynamic:
        from geovs_drake.systems.arm_camera import NULL_SPACE_MU

        arm = np.append(params("arm_camera"), NULL_SPACE_MU)
    else:
        arm = params("kinematic_arm")
    camera = params("spherical_camera")
    sampled = None
    if pinhole:  # the pinhole on the camera's own pose (the arm's X_RC = I)
        from geovs_drake.batch.sampled import camera_parameters
        from geovs_drake.systems.spherical_camera import CAMERA_OFFSET

        sampled = camera_parameters(resolved, diagram, root, camera[CAMERA_OFFSET])
    return ArmLoopParameters(
        plant="dynamic" if dynamic else "kinematic",
        dynamic=dynamic,
        tree=tree,
        camera=camera,
        navigation=np.array(nav.navigation_parameters(nav.GetMyContextFromRoot(root))),
        controller=params("image_jacobian_force" if dynamic else "kinematic_controller"),
        arm=arm,
        # KinematicArm's centre of range: 0 for an unlimited joint.
        q_mid=np.where(np.isfinite(lower + upper), 0.5 * (lower + upper), 0.0),
        potential_gain=config.control.potential_gain if dynamic else 1.0,
        max_step_size=resolved.step_limit.max_step_size,
        sampled=sampled,
        scheme=config.simulator.integration_scheme,
    )


def arm_rhs(parameters: ArmLoopParameters, x: np.ndarray) -> np.ndarray:
    """xdot of one start: ``(qdot, vdot)`` (2 nv) on the dynamic arm, qdot (nv) on the
    kinematic one, x in the plant's layout (allocating: for checks and one-offs)."""
    out = np.empty(parameters.state_size)
    arm_loop_rhs(
        parameters.dynamic, np.ascontiguousarray(x, dtype=float), out, *parameters.kernel_args()
    )
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _camera_state(dynamic, x, n, R_WC, p_WC, J, state):
    """ArmCamera's ``camera_state`` [q_WC, p_WC, w_WC_W, v_WCo_W] (13) into ``state``:
    the pose from R_WC, the twist J_C v in W (zero on the kinematic arm)."""
    rotation_to_quaternion(R_WC, state)
    for r in range(3):
        state[4 + r] = p_WC[r]
    for r in range(6):
        s = 0.0
        if dynamic:
            for c in range(n):
                s += J[r, c] * x[n + c]
        state[7 + r] = s


@njit(cache=True, nogil=True, error_model="numpy")
def _to_world(R_WC, twist_C, out):
    """A (rotational, translational) pair of 3-vectors from C into W: out = blkdiag(R_WC,
    R_WC) twist_C."""
    for b in range(2):
        for r in range(3):
            out[3 * b + r] = (
                R_WC[r, 0] * twist_C[3 * b]
                + R_WC[r, 1] * twist_C[3 * b + 1]
                + R_WC[r, 2] * twist_C[3 * b + 2]
            )


@njit(cache=True, nogil=True, error_model="numpy")
def _damped_solve(J, lam2, b, A, L, z):
    """z = (J J^T + lam2 I)^-1 b (6), J (6 x n): the damped least squares' system."""
    _k.shifted_gram(J, lam2, A)
    _k.cholesky_solve(A, b, L, z)


@njit(cache=True, nogil=True, error_model="numpy")
def _kinematic_qdot(x, out, n, nu_W, J, p_arm, q_mid, A, L, vec):
    """KinematicArm's qdot into ``out``: k_n e + J^T (J J^T + lambda^2 I)^-1 (nu - k_n J
    e), e = q_mid - q (the same as J^+ nu + k_n (I - J^+ J) e), all in W (J_C's
    expressed-in frame changes neither sigma_min nor J^+ J), scaled to the velocity
    limits by s <= 1."""
    m = p_arm[_KIN_SINGULAR]
    lam2 = p_arm[_KIN_MU] ** 2
    # sigma_min only where the singular zone may hold: J J^T - m^2 I not positive
    # definite (a Cholesky factor, 0.1 us, against Jacobi's 5 us; the damping is
    # continuous at sigma = m, so the rounding at the zone's edge changes nothing).
    if m > 0.0:
        _k.shifted_gram(J, -m * m, A)
        if not _k.cholesky_factor(A, L):
            sigma = _k.min_singular_value(J, A)
            if sigma < m:  # the singular zone: Chiaverini's damping, m^2 at the singularity
                lam2 += m * m - sigma * sigma
    k_n = p_arm[_KIN_NULL]
    b = vec[0]
    for r in range(6):
        s = 0.0
        for c in range(n):
            s += J[r, c] * (q_mid[c] - x[c])
        b[r] = nu_W[r] - k_n * s
    z = vec[1]
    _damped_solve(J, lam2, b[0:6], A, L, z[0:6])
    ratio = 0.0
    for c in range(n):
        s = k_n * (q_mid[c] - x[c])
        for r in range(6):
            s += J[r, c] * z[r]
        out[c] = s
        ratio = max(ratio, abs(s) / p_arm[3 + c])
    if ratio > 1.0:
        for c in range(n):
            out[c] /= ratio


@njit(cache=True, nogil=True, error_model="numpy")
def _arm_camera(
    dynamic, x, n, parent, index, kind, frames, axis, camera_body, X_BC, p_cam, ws, J, vec
):
    """The camera at x: its state ``[q_WC, p_WC, w, v]`` into ``vec``'s state row, R_WC
    and p_WC into theirs, J_C (in W) into ``J``; returns the exact camera's output."""
    _k.arm_forward(x[0:n], parent, index, kind, frames, axis, ws)
    R_WC = vec[_ROW_R, 0:9].reshape(3, 3)
    p_WC = vec[_ROW_NULL, 0:3]
    _k.camera_pose(camera_body, X_BC, ws, R_WC, p_WC)
    _k.camera_jacobian_W(camera_body, parent, index, p_WC, ws, J)
    state = vec[_ROW_STATE, 0:_STATE]
    _camera_state(dynamic, x, n, R_WC, p_WC, J, state)
    return _camera(state[0:_POSE], p_cam)


@njit(cache=True, nogil=True, error_model="numpy")
def _arm_law(
    dynamic, x, out, y, n, parent, index, inertia, joint, gravity, p_nav, p_ctrl, p_arm, q_mid,
    ws, J, M, L, A, L6, vec,
):  # fmt: skip
    """The law on the image ``y`` and the arm's xdot into ``out``, the camera's state,
    R_WC and J_C already in ``vec`` and ``J`` (:func:`_arm_camera`); returns (phi at y,
    1/2 v^T M v)."""
    R_WC = vec[_ROW_R, 0:9].reshape(3, 3)
    state = vec[_ROW_STATE, 0:_STATE]
    nav = _navigation(y, p_nav)
    dphi = nav[_D0:_D1]
    twist_W = vec[_ROW_TWIST, 0:_TWIST]
    if not dynamic:
        _to_world(R_WC, _kinematic_velocity(y, dphi, p_ctrl), twist_W)
        _kinematic_qdot(x, out, n, twist_W, J, p_arm, q_mid, A, L6, vec)
        return nav[_PHI], 0.0
    wrench = _force(state, y, dphi, p_ctrl)
    _to_world(R_WC, wrench[0:6], twist_W)  # F_C in W: J_C^T F_C = J_W^T F_W
    v = x[n : 2 * n]
    gravity_only = vec[0, 0:n]
    rest = vec[_ROW_ZERO, 0:n]
    rest[:] = 0.0
    _k.inverse_dynamics(rest, parent, index, inertia, gravity, ws, gravity_only)
    bias = vec[1, 0:n]  # C v - tau_g
    _k.inverse_dynamics(v, parent, index, inertia, gravity, ws, bias)
    if n > _TWIST:  # ArmCamera's -d N v: N v = v - J^T (J J^T + mu^2 I)^-1 J v
        _damped_solve(J, p_arm[n + 1] ** 2, state[7:13], A, L6, vec[_ROW_NULL, 3:9])
    tau = vec[_ROW_TAU, 0:n]
    for c in range(n):
        s = gravity_only[c] - p_arm[c] * v[c]  # -tau_g - B_q v
        for r in range(6):
            s += J[r, c] * twist_W[r]
        if n > _TWIST:
            null_v = v[c]
            for r in range(6):
                null_v -= J[r, c] * vec[_ROW_NULL, 3 + r]
            s -= p_arm[n] * null_v
        limit = joint[c, 2]  # the plant clamps each actuator at its effort limit
        s = min(max(s, -limit), limit)
        tau[c] = s - bias[c] - joint[c, 0] * v[c]  # + tau_g - C v - D v
    _k.mass_matrix(parent, index, inertia, joint, ws, M)
    _k.cholesky_solve(M, tau, L, out[n : 2 * n])
    kinetic = 0.0
    for r in range(n):
        out[r] = v[r]
        for c in range(n):
            kinetic += 0.5 * v[r] * M[r, c] * v[c]
    return nav[_PHI], kinetic


@njit(cache=True, nogil=True, error_model="numpy")
def arm_loop_rhs(
    dynamic, x, out, parent, index, kind, frames, axis, inertia, joint, camera_body, X_BC,
    gravity, p_cam, p_nav, p_ctrl, p_arm, q_mid, ws, J, M, L, A, L6, vec,
):  # fmt: skip
    """The arm loop's xdot into ``out``; returns (nu, margins (4), phi, 1/2 v^T M v) at x
    (the kinetic energy with the rotor inertia, 0 on the kinematic arm), as the free
    rig's engine does. Arguments after ``out``: :meth:`ArmLoopParameters.kernel_args`.
    """
    n = parent.shape[0]
    cam = _arm_camera(
        dynamic, x, n, parent, index, kind, frames, axis, camera_body, X_BC, p_cam, ws, J, vec
    )
    phi, kinetic = _arm_law(
        dynamic, x, out, cam[_Y0:_Y1], n, parent, index, inertia, joint, gravity, p_nav,
        p_ctrl, p_arm, q_mid, ws, J, M, L, A, L6, vec,
    )  # fmt: skip
    return cam[_NU], np.array(cam[_M0:_M1]), phi, kinetic


@njit(cache=True, nogil=True, error_model="numpy")
def arm_loop_rhs_held(
    dynamic, x, out, y_held, then, predict, p_pred, parent, index, kind, frames, axis,
    inertia, joint, camera_body, X_BC, gravity, p_cam, p_nav, p_ctrl, p_arm, q_mid, ws, J, M,
    L, A, L6, vec,
):  # fmt: skip
    """:func:`arm_loop_rhs` with the law on an image given from outside: a camera's held
    frame ``y_held``, or (``predict``) that frame moved from the camera pose ``then``
    (``[q_WC, p_WC]``, where it was taken) to the camera's pose at x, the odometry
    prediction of :class:`~geovs_drake.systems.FramePredictor` (``p_pred``: [believed
    radius, R_RC = I, p_RC = 0]: the arm's camera pose is the body's). Returns the same
    tuple, nu, the margins and phi those of the exact image at x (the Drake loop's
    monitor reads them), the kinetic energy at x.
    """
    n = parent.shape[0]
    cam = _arm_camera(
        dynamic, x, n, parent, index, kind, frames, axis, camera_body, X_BC, p_cam, ws, J, vec
    )
    y = y_held
    if predict:
        moved = _predicted(y_held, then, vec[_ROW_STATE, 0:_POSE], p_pred)
        y = np.empty(_Y1 - _Y0)
        for j in range(_Y1 - _Y0):
            y[j] = moved[j]
    _, kinetic = _arm_law(
        dynamic, x, out, y, n, parent, index, inertia, joint, gravity, p_nav, p_ctrl, p_arm,
        q_mid, ws, J, M, L, A, L6, vec,
    )  # fmt: skip
    phi = _navigation(cam[_Y0:_Y1], p_nav)[_PHI]
    return cam[_NU], np.array(cam[_M0:_M1]), phi, kinetic


def warm_arm_loop() -> None:
    """Compile the arm's kernels (:func:`~geovs_drake.systems.arm_tree.warm_arm_kernels`)
    and the closed loop's right-hand side on both plants (the shipped UR5) into numba's
    on-disk cache (:mod:`geovs_drake.batch.warm`)."""
    from geovs_drake.scenario import Arm, Dynamic, Kinematic, ScenarioConfig

    warm_arm_kernels()
    for plant in (Dynamic(), Kinematic()):
        parameters = arm_loop_parameters(ScenarioConfig(carrier=Arm(), plant=plant))
        arm_rhs(parameters, np.zeros(parameters.state_size))
