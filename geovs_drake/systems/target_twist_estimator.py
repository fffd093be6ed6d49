"""TargetTwistEstimator: the moving target's twist from the images and the odometry."""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem_

from geovs_drake.geometry.camera import camera_map_inverse
from geovs_drake.geometry.target_motion import adjoint, se3_exp, se3_log
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems._template import template_system
from geovs_drake.systems.target_motion import TWIST_SIZE, matrix_of_pose, pose_of_matrix

__all__ = ["TargetTwistEstimator", "TargetTwistEstimator_"]

#: The filter's error state: the pose's (6, on se(3)) then the twist's (6).
ERROR_SIZE = 12
#: The twist's prior standard deviation at the first frame [rad/s, m/s]: no knowledge.
PRIOR_TWIST_STD = 1.0
# Layout of the discrete state: the pose estimate X_WB (16, row-major 4 x 4), the twist
# (6), the covariance (144), [initialised, time of the last measurement], then the line of
# the camera's poses (7 each, oldest first).
_X, _XI, _P, _FLAGS = slice(0, 16), slice(16, 22), slice(22, 166), slice(166, 168)
_LINE = 168


@template_system("TargetTwistEstimator_", T_list=[float])
def TargetTwistEstimator_(T):
    class Impl(LeafSystem_[T]):
        """A constant-twist Kalman filter on SE(3): the target's pose X_WB and body twist
        xi_B, from each frame's relative pose and the carrier's own pose.

        .. pydrake_system::

            name: TargetTwistEstimator
            input_ports:
            - image_features
            - body_pose
            output_ports:
            - twist_estimate
            - target_pose_estimate
            - covariance_diagonal

        Every ``period`` seconds (and at the start) it takes one measurement of the
        target's pose in the world, ``Z = X_WR X_RC c^-1(y)``: the image's relative pose
        X_CB by the inverse camera map (Eq. 23, the believed ``radius``) carried by the
        camera's pose in the world, ``body_pose`` (X_WR of the body the camera rides on
        at ``X_RC``, from the carrier's odometry). A camera's held frame was taken
        ``delay_frames`` periods before it is read: the filter pairs it with the body's
        pose of that time (it keeps a line of them, as
        :class:`~geovs_drake.systems.FramePredictor` does) and estimates at the frame's
        time.

        The filter: state (X_WB, xi_B), the error ``X_WB = X_hat exp(delta^)`` and ``xi
        = xi_hat + delta_xi`` with covariance P (12 x 12). Prediction over dt:
        ``X_hat <- X_hat exp(dt xi_hat^)``, ``F = [[Ad_{exp(-dt xi_hat^)}, dt I], [0,
        I]]``, ``P <- F P F^T + Q``, Q the twist's random walk ``twist_noise^2 dt``.
        Update with ``r = log(X_hat^-1 Z)`` (H = [I, 0], measurement covariance
        ``pose_noise^2 I``). The first frame sets ``X_hat = Z``, ``xi_hat = 0`` with a
        twist prior of :data:`PRIOR_TWIST_STD`. A frame without y is skipped.

        ``twist_estimate`` is xi_hat (zero until two frames have come),
        ``target_pose_estimate`` X_hat as ``[q, p]`` at the last frame's time, and
        ``covariance_diagonal`` P's diagonal (12). Double only, as the sensors.
        """

        def _construct(
            self,
            radius: float = 0.1,
            X_RC: RigidTransform | None = None,
            period: float = 0.02,
            delay_frames: int = 0,
            pose_noise: float = 1e-3,
            twist_noise: float = 1e-3,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            X_RC = RigidTransform() if X_RC is None else X_RC
            for name, value in (
                ("radius", radius),
                ("period", period),
                ("pose_noise", pose_noise),
                ("twist_noise", twist_noise),
            ):
                if not (math.isfinite(value) and value > 0):
                    raise ValueError(f"{name} must be finite and > 0, got {value}")
            if isinstance(delay_frames, bool) or not (
                isinstance(delay_frames, int) and delay_frames >= 0
            ):
                raise ValueError(f"delay_frames must be an integer >= 0, got {delay_frames!r}")
            self._defaults = (radius, X_RC, period, delay_frames, pose_noise, twist_noise)
            self._radius, self._X_RC = radius, X_RC.GetAsMatrix4()
            self._period, self._delay = period, delay_frames
            self._R = pose_noise**2 * np.eye(6)
            self._q2 = twist_noise**2
            initial = np.zeros(_LINE + (delay_frames + 1) * POSE_SIZE)
            initial[_X] = np.eye(4).ravel()
            self._state = self.DeclareDiscreteState(initial)
            self.image_features_input = self.DeclareVectorInputPort("image_features", 13)
            self.body_pose_input = self.DeclareVectorInputPort("body_pose", POSE_SIZE)
            self.DeclareInitializationDiscreteUpdateEvent(self._on_start)
            self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._on_frame)
            state = {self.xd_ticket()}
            self.twist_estimate_output = self.DeclareVectorOutputPort(
                "twist_estimate", TWIST_SIZE, self.CalcTwistEstimate, prerequisites_of_calc=state
            )
            self.target_pose_estimate_output = self.DeclareVectorOutputPort(
                "target_pose_estimate",
                POSE_SIZE,
                self.CalcTargetPoseEstimate,
                prerequisites_of_calc=state,
            )
            self.covariance_diagonal_output = self.DeclareVectorOutputPort(
                "covariance_diagonal",
                ERROR_SIZE,
                self.CalcCovarianceDiagonal,
                prerequisites_of_calc=state,
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _measure(self, y: np.ndarray, X_WR: np.ndarray) -> np.ndarray | None:
            """Z = X_WR X_RC c^-1(y), the target's pose in the world, or None (no y)."""
            if not np.all(np.isfinite(y)):
                return None
            try:
                X_CB = camera_map_inverse(y, self._radius).GetAsMatrix4()
            except ValueError:  # not an image: no measurement
                return None
            return X_WR @ self._X_RC @ X_CB

        def _on_start(self, context, discrete_state) -> None:
            # Before the first frame the camera was where it starts: the line is this pose.
            self._on_frame(context, discrete_state, start=True)

        def _on_frame(self, context, discrete_state, start: bool = False) -> None:
            s = context.get_discrete_state(self._state).get_value().copy()
            line = s[_LINE:].reshape(self._delay + 1, POSE_SIZE)
            pose = self.body_pose_input.Eval(context)
            line = np.tile(pose, (self._delay + 1, 1)) if start else np.vstack([line[1:], pose])
            s[_LINE:] = line.ravel()
            t = context.get_time() - self._delay * self._period
            Z = self._measure(self.image_features_input.Eval(context), matrix_of_pose(line[0]))
            if Z is not None:
                s[:_LINE] = self._filtered(s[:_LINE], Z, t)
            discrete_state.get_mutable_vector(self._state).SetFromVector(s)

        def _filtered(self, s: np.ndarray, Z: np.ndarray, t: float) -> np.ndarray:
            """The filter's state after the measurement Z at time t."""
            if not s[_FLAGS][0]:
                P = np.zeros((ERROR_SIZE, ERROR_SIZE))
                P[:6, :6] = self._R
                P[6:, 6:] = PRIOR_TWIST_STD**2 * np.eye(6)
                return np.concatenate([Z.ravel(), np.zeros(6), P.ravel(), [1.0, t]])
            X, xi = s[_X].reshape(4, 4), s[_XI]
            P = s[_P].reshape(ERROR_SIZE, ERROR_SIZE)
            dt = t - s[_FLAGS][1]
            # Prediction (the constant-twist model).
            step = se3_exp(dt * xi)
            X = X @ step
            F = np.eye(ERROR_SIZE)
            F[:6, :6] = adjoint(np.linalg.inv(step))
            F[:6, 6:] = dt * np.eye(6)
            P = F @ P @ F.T
            P[6:, 6:] += self._q2 * dt * np.eye(6)
            # Update (H = [I, 0]).
            r = se3_log(np.linalg.solve(X, Z))
            S = P[:6, :6] + self._R
            K = np.linalg.solve(S, P[:6, :]).T
            delta = K @ r
            X = X @ se3_exp(delta[:6])
            xi = xi + delta[6:]
            P = P - K @ P[:6, :]
            P = 0.5 * (P + P.T)
            return np.concatenate([X.ravel(), xi, P.ravel(), [1.0, t]])

        def CalcTwistEstimate(self, context, output) -> None:
            output.SetFromVector(context.get_discrete_state(self._state).get_value()[_XI])

        def CalcTargetPoseEstimate(self, context, output) -> None:
            X = context.get_discrete_state(self._state).get_value()[_X].reshape(4, 4)
            output.SetFromVector(pose_of_matrix(X))

        def CalcCovarianceDiagonal(self, context, output) -> None:
            P = context.get_discrete_state(self._state).get_value()[_P]
            output.SetFromVector(np.diag(P.reshape(ERROR_SIZE, ERROR_SIZE)))

    return Impl


TargetTwistEstimator = TargetTwistEstimator_[None]
