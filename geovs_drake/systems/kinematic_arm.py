"""KinematicArm: an arm whose joint velocities are commanded, qdot = J_C^+ (Omega, V)."""

from __future__ import annotations

import numpy as np
from numba import njit
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import inv
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.arm_kernels import cholesky_factor, shifted_gram
from geovs_drake.systems._parameters import POSE_SIZE, param_vector
from geovs_drake.systems._template import template_system
from geovs_drake.systems.arm_model import (
    CAMERA_FRAME,
    ArmModel,
    arm_plant,
    camera_jacobian,
    default_arm_model,
)

__all__ = ["KinematicArm", "KinematicArm_"]

# Layout of the one numeric parameter: the damped least squares' mu [-], the singular
# zone's damping m [-], the null-space gain [1/s], then the joints' velocity limits (nv)
# [rad/s].
_MU, _SINGULAR, _NULL_GAIN, _LIMITS = 0, 1, 2, slice(3, None)


#: The room by which sigma_min(J_C)^2 must clear m^2 (relative to m^2, and to |J_C|_F^2)
#: for :func:`_clear_of_singular_zone` to skip the SVD: far above a Cholesky factor's
#: rounding (about 1e-15 |J_C|^2), so a J_C it clears has sigma_min > m by the SVD too.
_ZONE_SLACK = 1e-6
_ZONE_SLACK_ABS = 1e-12


@njit(cache=True, error_model="numpy", nogil=True)
def _clear_of_singular_zone(J: np.ndarray, m2: float) -> bool:
    """True where sigma_min(J)^2 exceeds m2 for sure: J J^T - (m2 + room) I has a Cholesky
    factor (a 6 x 6 one in about 0.3 us, where the SVD takes 8 us); False leaves the
    verdict to the SVD. The batch engine's arm asks the same (``geometry.arm_kernels``'
    ``shifted_gram`` and ``cholesky_factor``) with no room: its damping is continuous at
    the zone's edge."""
    rows = J.shape[0]
    A = np.empty((rows, rows))
    shifted_gram(J, 0.0, A)  # J J^T once: its trace sets the room, then the shift
    trace = 0.0
    for i in range(rows):
        trace += A[i, i]
    shift = m2 * (1.0 + _ZONE_SLACK) + _ZONE_SLACK_ABS * trace
    for i in range(rows):
        A[i, i] -= shift
    return cholesky_factor(A, np.empty((rows, rows)))


@njit(cache=True, error_model="numpy", nogil=True)
def _largest_ratio(value: np.ndarray, bound: np.ndarray) -> float:
    """``max |value| / bound`` (NaN if any ratio is): np.max's of the same ratios, exact
    in any order, in 0.3 us where numpy's three calls take 3 us."""
    largest = -np.inf
    for i in range(value.shape[0]):
        ratio = abs(value[i]) / bound[i]
        if ratio != ratio:
            return ratio
        if ratio > largest:
            largest = ratio
    return largest


# float and AutoDiffXd (Linearize) only: the pseudo-inverse and the velocity scaling do
# not take Expression (a symbolic inverse, a comparison).
@template_system("KinematicArm_", T_list=[float, AutoDiffXd])
def KinematicArm_(T):
    class Impl(LeafSystem_[T]):
        """A first-order arm: the camera's commanded body twist, made joint velocities.

        .. pydrake_system::

            name: KinematicArm
            input_ports:
            - camera_velocity
            output_ports:
            - arm_position
            - camera_pose
            - velocity_scale

        Continuous state q. Dynamics, with J_C the camera frame's
        spatial-velocity Jacobian expressed in C (so J_C qdot = (Omega, V), the
        body twist of Eq. 17)::

            qdot = s (J_C^+ nu + k_n (I - J_C^+ J_C)(q_mid - q)),
            J_C^+ = J_C^T (J_C J_C^T + lambda^2 I)^-1,
            lambda^2 = mu^2 + m^2 (1 - (sigma_min / m)^2)  where sigma_min < m, else mu^2,

        ``nu`` the law's twist at ``camera_velocity``. mu (damped least
        squares, 1e-4) keeps qdot bounded at a singularity; away from one it changes
        the executed twist by a factor 1 - O(mu^2 / sigma_min^2), a positive
        definite map, so the law's twist stays a descent direction of phi. In the
        singular zone sigma_min(J_C) < m (``singularity_damping``, the
        damping of Nakamura and Hanafusa's singularity-robust inverse, as
        Chiaverini varies it) the damping grows to m^2 at the singularity: the arm
        no longer follows the twist in the singular direction (phi may rise there),
        and in exchange does not spin its wrist over through the singularity, which
        the plain pseudo-inverse does (and which can leave a wrist at its limit once
        the camera is home). sigma_min is read as a value (a constant for
        AutoDiffXd). The
        null-space term pulls a redundant arm's self-motion towards the middle of
        its joint range (zero for a 6-joint arm off its singularities). ``s`` <= 1
        scales the whole of qdot, never one joint, so that the fastest joint
        is at its velocity limit and the camera's twist keeps its direction;
        ``velocity_scale`` reports it (1: not limited); for AutoDiffXd the scale
        is a constant (its derivative where the clip acts is not wanted). Scalar
        types: float and AutoDiffXd (not Expression). ``camera_pose`` is
        ``[q_WC, p_WC]`` (7), the layout the camera system reads; it depends on the
        state only.
        """

        def _construct(
            self,
            model: ArmModel | None = None,
            q0=None,
            mu: float = 1e-4,
            null_space_gain: float = 1.0,
            singularity_damping: float = 0.0,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            model = default_arm_model() if model is None else model
            self._plant = arm_plant(model, T)
            self._context = self._plant.CreateDefaultContext()
            self._camera = self._plant.GetFrameByName(CAMERA_FRAME)
            # The last joints' kinematics (float only): (q, camera_pose, J_C), shared by
            # camera_pose and the derivatives, which the simulator evaluates at the same
            # q within a step (:meth:`_kinematics`).
            self._last: tuple | None = None
            float_plant = arm_plant(model)
            lower = float_plant.GetPositionLowerLimits()
            upper = float_plant.GetPositionUpperLimits()
            self._q_mid = np.where(np.isfinite(lower + upper), 0.5 * (lower + upper), 0.0)
            nq = float_plant.num_positions()
            self._eye_twist, self._eye_joints = np.eye(6), np.eye(nq)
            q0 = np.zeros(nq) if q0 is None else np.asarray(q0, dtype=float)
            self._defaults = (model, q0, mu, null_space_gain, singularity_damping)
            limits = float_plant.GetVelocityUpperLimits()
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T](
                    np.concatenate([[mu, singularity_damping, null_space_gain], limits])
                )
            )
            self.DeclareContinuousState(BasicVector_[T](q0))
            self.camera_velocity_input = self.DeclareVectorInputPort(name="camera_velocity", size=6)
            self.arm_position_output = self.DeclareVectorOutputPort(
                name="arm_position", size=nq, calc=self.CalcArmPosition,
                prerequisites_of_calc={self.xc_ticket()},
            )  # fmt: skip
            self.camera_pose_output = self.DeclareVectorOutputPort(
                name="camera_pose", size=POSE_SIZE, calc=self.CalcCameraPose,
                prerequisites_of_calc={self.xc_ticket()},
            )  # fmt: skip
            self.velocity_scale_output = self.DeclareVectorOutputPort(
                name="velocity_scale", size=1, calc=self.CalcVelocityScale,
                prerequisites_of_calc={self.all_sources_ticket()},
            )  # fmt: skip

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def set_joints(self, context, q) -> None:
            """Set the state to the joint configuration ``q`` in ``context``."""
            context.SetContinuousState(np.asarray(q, dtype=float))

        def _kinematics(self, context) -> tuple:
            """``(q, camera_pose, J_C)`` at the state's q: for float computed once per q
            and kept (the derivatives and ``camera_pose`` read the same q within a step,
            and the plant's own kinematics cache in its private context survives while
            its positions are not set again); for AutoDiffXd computed on every call."""
            q = context.get_continuous_state_vector().CopyToVector()
            key = q.tobytes() if T is float else None  # the exact values, compared in 0.1 us
            last = self._last
            if last is not None and key == last[0]:
                return last[1]
            self._plant.SetPositions(self._context, q)
            X_WC = self._camera.CalcPoseInWorld(self._context)
            pose = np.concatenate([X_WC.rotation().ToQuaternion().wxyz(), X_WC.translation()])
            J = camera_jacobian(self._plant, self._context, self._camera)
            kinematics = (q, pose, J)
            if T is float:
                self._last = (key, kinematics)
            return kinematics

        def CalcArmPosition(self, context, output) -> None:
            output.SetFromVector(context.get_continuous_state_vector().CopyToVector())

        def CalcCameraPose(self, context, output) -> None:
            output.SetFromVector(self._kinematics(context)[1])

        def _unscaled(self, context) -> tuple[np.ndarray, np.ndarray]:
            """(qdot before the velocity scaling, the velocity limits)."""
            q, _, J = self._kinematics(context)
            p = param_vector(context, self._params_index, T)
            nu = self.camera_velocity_input.Eval(context)
            J_pinv = J.T @ inv(J @ J.T + self._damping(J, p) * self._eye_twist)
            null = self._eye_joints - J_pinv @ J
            return J_pinv @ nu + p[_NULL_GAIN] * (null @ (self._q_mid - q)), p[_LIMITS]

        def _damping(self, J: np.ndarray, p: np.ndarray):
            """lambda^2: mu^2, plus the singular zone's share where sigma_min < m."""
            m = p[_SINGULAR] if T is float else p[_SINGULAR].value()
            lam2 = p[_MU] ** 2
            if m <= 0:
                return lam2
            if T is float and _clear_of_singular_zone(J, m * m):
                return lam2 + 0.0  # the SVD's branch for sigma >= m, without the SVD
            values = J if T is float else np.array([[x.value() for x in row] for row in J])
            sigma = np.linalg.svd(values, compute_uv=False)[min(values.shape) - 1]
            return lam2 + (m**2 - sigma**2 if sigma < m else 0.0)

        def _scale(self, qdot: np.ndarray, limits: np.ndarray) -> float:
            """s: 1, or what brings the fastest joint to its limit (a constant factor
            for AutoDiffXd: the derivative of the clip where it acts is not wanted)."""
            if T is float:
                ratio = _largest_ratio(qdot, limits)
            else:
                value = np.array([x.value() for x in qdot], dtype=float)
                bound = np.array([x.value() for x in limits], dtype=float)
                ratio = np.max(np.abs(value) / bound)
            return 1.0 if ratio <= 1.0 else 1.0 / ratio

        def CalcVelocityScale(self, context, output) -> None:
            qdot, limits = self._unscaled(context)
            output.SetFromVector([self._scale(qdot, limits)])

        def DoCalcTimeDerivatives(self, context, derivatives) -> None:
            qdot, limits = self._unscaled(context)
            derivatives.get_mutable_vector().SetFromVector(self._scale(qdot, limits) * qdot)

    return Impl


KinematicArm = KinematicArm_[None]
