"""PinholeFeatureSensor: what the feature extractor would measure, without rendering."""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry._ops import MATH
from geovs_drake.geometry.features import TargetMarks, pinhole_measurement
from geovs_drake.geometry.pinhole import PinholeIntrinsics
from geovs_drake.geometry.rigid import cross, quaternion_to_rotation, target_in_camera
from geovs_drake.systems._held_frames import declare_sampled_features, frame_index
from geovs_drake.systems._parameters import POSE_SIZE, pose_to_param
from geovs_drake.systems._template import template_system

__all__ = ["PinholeFeatureSensor", "PinholeFeatureSensor_"]

# Layout of the one numeric parameter.
_RADIUS, _X_WB, _X_RC, _K, _K_BELIEVED, _ARROW_ANGLE, _NOISE, _SEED = (
    0,
    slice(1, 13),
    slice(13, 25),
    slice(25, 29),
    slice(29, 33),
    33,
    34,
    35,
)


@template_system("PinholeFeatureSensor_", T_list=[float])
def PinholeFeatureSensor_(T):
    class Impl(LeafSystem_[T]):
        """A pinhole camera's feature measurement from the rig's pose, once per frame.

        .. pydrake_system::

            name: PinholeFeatureSensor
            input_ports:
            - body_pose
            output_ports:
            - image_features
            - feature_status
            - capture_time

        The model of :class:`FeatureExtractor` without the renderer: at each
        frame, :func:`~geovs_drake.geometry.features.pinhole_measurement` projects
        the exact limb and marks through the true intrinsics, adds Gaussian
        noise of ``pixel_noise`` px per axis to every point, and lifts them to
        rays through the *believed* intrinsics; then the same fit as the
        extractor. No quantisation and no renderer: it isolates the errors
        one asks about (noise, calibration, latency) and costs about 0.1 ms a
        frame, so robustness sweeps run through the Drake loop quickly.
        Outputs, latency and hold as :class:`FeatureExtractor`
        (:mod:`geovs_drake.systems._held_frames`). Double only (a measurement with
        random noise; nothing to differentiate).

        ``body_pose`` is the rig's ``[qw, qx, qy, qz, x, y, z]`` (as for
        :class:`SphericalCamera`); frames are read at ``offset + k period`` (a camera
        whose frames arrive after their capture reads the pose held from the capture).
        One numeric parameter vector: ``[rho, X_WB (12), X_RC (12), K (fx, fy, cx, cy),
        believed K (4), arrow_angle, pixel_noise, seed]``.
        """

        def _construct(
            self,
            radius: float,
            intrinsics: PinholeIntrinsics,
            believed: PinholeIntrinsics | None = None,
            X_WB: RigidTransform | None = None,
            X_RC: RigidTransform | None = None,
            marks: TargetMarks | None = None,
            period: float = 1.0 / 30.0,
            latency_frames: int = 0,
            max_lost_frames: int = 3,
            pixel_noise: float = 0.0,
            seed: int = 0,
            offset: float = 0.0,
            capture_delay: float = 0.0,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            believed = believed or intrinsics
            X_WB = X_WB or RigidTransform()
            X_RC = X_RC or RigidTransform()
            marks = marks or TargetMarks()
            if not (math.isfinite(radius) and radius > 0):
                raise ValueError(f"radius must be finite and > 0: radius = {radius}")
            if not (math.isfinite(pixel_noise) and pixel_noise >= 0):
                raise ValueError(f"pixel_noise must be finite and >= 0 [px], got {pixel_noise}")
            if (believed.width, believed.height) != (intrinsics.width, intrinsics.height):
                raise ValueError("the believed intrinsics must be for the same image size")
            self._defaults = (
                radius,
                intrinsics,
                believed,
                X_WB,
                X_RC,
                marks,
                period,
                latency_frames,
                max_lost_frames,
                pixel_noise,
                seed,
                offset,
                capture_delay,
            )
            self._size = (intrinsics.width, intrinsics.height)
            self._period, self._offset = period, offset
            self._marks = marks
            # The marks and intrinsics the parameters give, by their values (_camera).
            self._camera_of: tuple = (None, None)
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T](
                    [radius]
                    + pose_to_param(X_WB)
                    + pose_to_param(X_RC)
                    + list(intrinsics.K)
                    + list(believed.K)
                    + [marks.arrow_angle, float(pixel_noise), float(seed)]
                )
            )
            self.body_pose_input = self.DeclareVectorInputPort(name="body_pose", size=POSE_SIZE)
            (
                self.image_features_output,
                self.feature_status_output,
                self.capture_time_output,
            ) = declare_sampled_features(
                self, period, latency_frames, max_lost_frames, self._measure, offset, capture_delay
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _measure(self, context) -> tuple[tuple | None, int]:
            x = self.body_pose_input.Eval(context).tolist()
            p = context.get_numeric_parameter(self._params_index).get_value().tolist()
            R_WR = quaternion_to_rotation(x[0:4], MATH)
            r2, r3, d = target_in_camera(R_WR, x[4:7], p[13:22], p[22:25], p[1:10], p[10:13])
            X_CB = np.eye(4)
            X_CB[:3, :3] = np.column_stack([cross(r2, r3), r2, r3])
            X_CB[:3, 3] = d
            sigma = p[_NOISE]
            noise = None
            if sigma > 0:
                noise = np.random.default_rng(
                    [int(p[_SEED]), frame_index(context.get_time(), self._period, self._offset)]
                )
            return pinhole_measurement(X_CB, p[_RADIUS], *self._camera(p), noise, sigma)

        def _camera(self, p: list) -> tuple:
            """``(marks, intrinsics, believed intrinsics)`` of the parameters ``p``, made
            (and validated) once per value, not at every frame."""
            key = (p[_ARROW_ANGLE], *p[_K], *p[_K_BELIEVED])
            if key != self._camera_of[0]:
                marks = TargetMarks(
                    self._marks.mark_radius, p[_ARROW_ANGLE], self._marks.arrow_mark_radius
                )
                camera = PinholeIntrinsics(*self._size, *p[_K])
                believed = PinholeIntrinsics(*self._size, *p[_K_BELIEVED])
                self._camera_of = (key, (marks, camera, believed))
            return self._camera_of[1]

    return Impl


PinholeFeatureSensor = PinholeFeatureSensor_[None]
