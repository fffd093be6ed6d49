"""FramePredictor: the image between frames, from the carrier's own motion (issue 31)."""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry._ops import MATH
from geovs_drake.geometry.domain import DEFAULT_DOMAIN
from geovs_drake.geometry.kernels import CAMERA_IMAGE, camera_image
from geovs_drake.geometry.prediction import target_from_frame
from geovs_drake.geometry.rigid import quaternion_to_rotation
from geovs_drake.systems._parameters import POSE_SIZE, domain_to_param, pose_to_param
from geovs_drake.systems._template import template_system

__all__ = ["FramePredictor", "FramePredictor_"]

# Layout of the one numeric parameter: the believed radius and the camera on the body.
_RADIUS, _R_RC, _P_RC = 0, slice(1, 10), slice(10, 13)
#: The rig pose's components in ``body_pose``: the quaternion, then the position.
_QUATERNION, _POSITION = slice(0, 4), slice(4, 7)
#: The compiled camera kernel: the view from the pose now of the target a frame implies
#: is :func:`~geovs_drake.geometry.prediction.image_from_target`, the exact camera's
#: formula with that target pose (its visibility and margins unused: a domain to fill
#: its parameter vector).
_camera_image = camera_image.compiled
_DOMAIN_PARAMS = domain_to_param(DEFAULT_DOMAIN)


@template_system("FramePredictor_", T_list=[float])
def FramePredictor_(T):
    class Impl(LeafSystem_[T]):
        """The held frame's y moved to the camera's pose now: a Smith predictor.

        .. pydrake_system::

            name: FramePredictor
            input_ports:
            - image_features
            - body_pose
            - capture_pose
            output_ports:
            - predicted_image_features

        ``image_features`` is a sampled camera's held y (:class:`PinholeFeatureSensor`,
        :class:`FeatureExtractor`): the frame taken ``latency_frames`` periods ago.
        ``body_pose`` is the carrier's pose ``[qw, qx, qy, qz, x, y, z]`` of the body the
        camera rides on (at ``X_RC``), from proprioception: the arm's joints through its
        kinematics, the free rig's state.

        The predictor keeps the body's pose at each frame time on the sensor's own
        clock (the same initialization and periodic events, ``period``), in a line
        of ``latency_frames + 1`` as the sensor keeps its frames, so the oldest pose
        is the one the held frame was taken from. Its output is
        :func:`~geovs_drake.geometry.prediction.predicted_image`: that frame inverted
        (Eq. 23, the believed ``radius``), carried by the body's motion since, and
        mapped back (Eqs. 3, 6, 7).

        A camera whose frames arrive after their capture (``output_delay``) is read at
        ``offset + k period``, when the body has moved on: ``capture_pose``, where
        connected, is the body's pose ``[q, p]`` at the newest frame's capture (held from
        then, as the frame is), and the predictor stores that; unconnected, the frame
        was taken when it is read, at ``body_pose``.

        It reads ``body_pose`` now, so the law sees y
        continuously: exact for a still target and an exact camera, the hold and the
        latency removed (the sampled-data model of the loop becomes the continuous
        one's, :mod:`geovs_drake.goal.camera_fit`). NaN in, NaN out (no frame yet).
        Double only, as the sensors it follows.
        """

        def _construct(
            self,
            radius: float,
            X_RC: RigidTransform | None = None,
            period: float = 1.0 / 30.0,
            latency_frames: int = 0,
            offset: float = 0.0,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            X_RC = RigidTransform() if X_RC is None else X_RC
            if not (math.isfinite(radius) and radius > 0):
                raise ValueError(f"radius must be finite and > 0: radius = {radius}")
            if not (math.isfinite(period) and period > 0):
                raise ValueError(f"camera period must be finite and > 0 [s], got {period}")
            if isinstance(latency_frames, bool) or not (
                isinstance(latency_frames, int) and latency_frames >= 0
            ):
                raise ValueError(f"latency_frames must be an integer >= 0, got {latency_frames!r}")
            if not (math.isfinite(offset) and offset >= 0):
                raise ValueError(f"offset must be finite and >= 0 [s], got {offset}")
            self._defaults = (radius, X_RC, period, latency_frames, offset)
            # The target's pose X_WB the held frame implies (Eq. 23), as the camera
            # kernel's parameter vector, by the bytes of what it is computed from (the
            # frame's y, the pose it was taken from, the parameters): it changes once a
            # frame, and an evaluation then costs the compiled view from the pose now.
            self._target: tuple = (None, None)
            self._line = latency_frames + 1
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T]([radius] + pose_to_param(X_RC))
            )
            self.image_features_input = self.DeclareVectorInputPort("image_features", 13)
            self.body_pose_input = self.DeclareVectorInputPort("body_pose", POSE_SIZE)
            self.capture_pose_input = self.DeclareVectorInputPort("capture_pose", POSE_SIZE)
            self._poses = self.DeclareDiscreteState(np.zeros(self._line * POSE_SIZE))
            if offset == 0:  # the sensor's frame at t = 0, taken from the pose then
                self.DeclareInitializationDiscreteUpdateEvent(self._on_start)
            self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._on_frame)
            self.predicted_image_features_output = self.DeclareVectorOutputPort(
                "predicted_image_features",
                13,
                self.CalcPredictedImageFeatures,
                prerequisites_of_calc={
                    self.all_input_ports_ticket(),
                    self.all_parameters_ticket(),
                    self.xd_ticket(),
                },
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _on_start(self, context, discrete_state) -> None:
            # The first frame fills the sensor's latency line; its pose fills this one.
            pose = self.body_pose_input.Eval(context)
            discrete_state.get_mutable_vector(self._poses).SetFromVector(np.tile(pose, self._line))

        def _frame_taken_from(self, context) -> np.ndarray:
            """The body's pose ``[q, p]`` at the newest frame's capture."""
            if self.capture_pose_input.HasValue(context):
                return self.capture_pose_input.Eval(context)
            return self.body_pose_input.Eval(context)  # read at its capture: the pose now

        def _on_frame(self, context, discrete_state) -> None:
            line = context.get_discrete_state(self._poses).get_value().reshape(self._line, -1)
            new = np.vstack([line[1:], self._frame_taken_from(context)])
            discrete_state.get_mutable_vector(self._poses).SetFromVector(new.ravel())

        def frame_pose(self, context) -> np.ndarray:
            """The body's pose ``[q, p]`` when the held frame was taken."""
            return context.get_discrete_state(self._poses).get_value()[:POSE_SIZE].copy()

        def CalcPredictedImageFeatures(self, context, output) -> None:
            y = self.image_features_input.Eval(context)
            if not np.all(np.isfinite(y)):  # no frame yet, or a trial stage's NaN
                output.SetFromVector(np.full(13, math.nan))
                return
            params = context.get_numeric_parameter(self._params_index).get_value()
            line = context.get_discrete_state(self._poses).get_value()
            key = y.tobytes() + line[:POSE_SIZE].tobytes() + params.tobytes()
            if key != self._target[0]:  # a new frame: X_WB = X_WR X_RC c^-1(y) (Eq. 23)
                p = params.tolist()
                then = line[:POSE_SIZE].tolist()
                R_WR = quaternion_to_rotation(then[_QUATERNION], MATH)
                R_WB, p_WB = target_from_frame(
                    tuple(y.tolist()),
                    p[_RADIUS],
                    R_WR,
                    tuple(then[_POSITION]),
                    tuple(p[_R_RC]),
                    tuple(p[_P_RC]),
                    MATH,
                )
                # SphericalCamera's parameter layout: [rho, X_WB, X_RC, domain].
                camera = np.array([p[_RADIUS], *R_WB, *p_WB, *p[_R_RC], *p[_P_RC], *_DOMAIN_PARAMS])
                self._target = (key, camera)
            # image_from_target at the pose now, compiled: c((X_WR X_RC)^-1 X_WB).
            now = self.body_pose_input.Eval(context)
            output.SetFromVector(_camera_image(now, self._target[1])[CAMERA_IMAGE.y])

    return Impl


FramePredictor = FramePredictor_[None]
