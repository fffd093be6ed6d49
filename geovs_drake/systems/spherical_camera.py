"""SphericalCamera: the camera map of Eqs. (3)-(8) as a Drake system."""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry._ops import namespace
from geovs_drake.geometry.domain import DEFAULT_DOMAIN, SafeDomain
from geovs_drake.geometry.kernels import (
    CAMERA_IMAGE,
    camera_image,
    camera_image_y_into,
    for_scalar_type,
)
from geovs_drake.geometry.rigid import cross, quaternion_to_rotation, target_in_camera
from geovs_drake.systems._parameters import (
    POSE_SIZE,
    domain_to_param,
    floats,
    inputs_and_parameters,
    param_vector,
    pose_to_param,
    read,
    scalar_value,
)
from geovs_drake.systems._template import template_system

__all__ = ["SphericalCamera", "SphericalCamera_"]

#: A MultibodyPlant free body's state: [q (4), p (3), w (3), v (3)].
BODY_STATE_SIZE = 13
# Layout of the one numeric parameter: radius, X_WB, X_RC, domain.
_RADIUS, _X_WB, _X_RC, _DOMAIN = 0, slice(1, 13), slice(13, 25), slice(25, 29)
#: A pose parameter's rotation (row-major) and translation.
_ROTATION, _TRANSLATION = slice(0, 9), slice(9, 12)
#: Where X_RC sits in the parameter vector (the batch engine reads it there).
CAMERA_OFFSET = _X_RC


@template_system("SphericalCamera_")
def SphericalCamera_(T):
    _camera_image = for_scalar_type(camera_image, T)

    class Impl(LeafSystem_[T]):
        """The spherical camera on the rig, viewing the marked target sphere.

        .. pydrake_system::

            name: SphericalCamera
            input_ports:
            - body_pose
            - body_state
            output_ports:
            - image_features
            - visibility
            - domain_margins

        The rig's pose X_WR comes from one of two inputs; connect (or fix) one:
        ``body_pose``, ``[qw, qx, qy, qz, x, y, z]`` (a kinematic body's pose), or
        ``body_state``, a MultibodyPlant free body's 13-vector state ``[q, p, w, v]``
        as the plant's state port gives it (no Demultiplexer: the camera reads its first
        7 entries), the convention of ``ImageJacobianForce``'s input of the same name.
        ``body_pose`` wins where both have a value. The camera frame C sits at X_RC on
        the rig (Appendix C.0.6).

        ``image_features`` is y = c(X_CB) as the 13-vector ``[q1, q2, q3,
        lambda, s]``; ``visibility`` is nu(X_CB) of Eq. (5);
        ``domain_margins`` is the signed margins ``[fov, lam_min, lam_max,
        occlusion]`` of :class:`~geovs_drake.geometry.domain.SafeDomain` (all
        >= 0 in D). When the pose is not visible y is undefined:
        ``image_features`` is all NaN (so an integrator rejects such a trial
        stage, see :mod:`geovs_drake.systems._parameters`) and
        every margin reads nu <= 0. The pure
        :func:`~geovs_drake.geometry.camera.camera_map` raises
        ``ValueError: pose not visible ...`` instead.

        One numeric parameter vector, settable per context (e.g. for sweeps):
        ``[rho, X_WB (12), X_RC (12), theta, lam_min, lam_max, kappa]``; use
        :meth:`set_radius`, :meth:`set_target_pose`, :meth:`set_camera_offset`
        and :meth:`set_domain`, which validate.
        """

        def _construct(
            self,
            radius: float = 0.1,
            X_WB: RigidTransform | None = None,
            X_RC: RigidTransform | None = None,
            domain: SafeDomain = DEFAULT_DOMAIN,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            X_WB = RigidTransform() if X_WB is None else X_WB
            X_RC = RigidTransform() if X_RC is None else X_RC
            if not (math.isfinite(radius) and radius > 0):
                raise ValueError(f"radius must be finite and > 0: radius = {radius}")
            self._defaults = (radius, X_WB, X_RC, domain)
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T](
                    [radius] + pose_to_param(X_WB) + pose_to_param(X_RC) + domain_to_param(domain)
                )
            )
            self.body_pose_input = self.DeclareVectorInputPort(name="body_pose", size=POSE_SIZE)
            self.body_state_input = self.DeclareVectorInputPort(
                name="body_state", size=BODY_STATE_SIZE
            )
            self.image_features_output = self.DeclareVectorOutputPort(
                name="image_features",
                size=13,
                calc=self.CalcImageFeatures,
                prerequisites_of_calc=inputs_and_parameters(self),
            )
            self.visibility_output = self.DeclareVectorOutputPort(
                name="visibility",
                size=1,
                calc=self.CalcVisibility,
                prerequisites_of_calc=inputs_and_parameters(self),
            )
            self.domain_margins_output = self.DeclareVectorOutputPort(
                name="domain_margins",
                size=4,
                calc=self.CalcDomainMargins,
                prerequisites_of_calc=inputs_and_parameters(self),
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        # ------------------------------------------------------- parameters
        def _set(self, context, where: int | slice, values) -> None:
            v = context.get_mutable_numeric_parameter(self._params_index)
            full = v.CopyToVector()
            full[where] = values
            v.SetFromVector(full)

        def radius(self, context) -> object:
            """rho [m], the target sphere's radius, in ``context``."""
            return context.get_numeric_parameter(self._params_index).GetAtIndex(_RADIUS)

        def set_radius(self, context, radius: float) -> None:
            """Set rho [m] in ``context``; ValueError unless finite and > 0."""
            if not (math.isfinite(radius) and radius > 0):
                raise ValueError(f"radius must be finite and > 0: radius = {radius}")
            self._set(context, _RADIUS, radius)

        def set_target_pose(self, context, X_WB: RigidTransform) -> None:
            """Set X_WB, the target sphere's pose in the world, in ``context``."""
            self._set(context, _X_WB, pose_to_param(X_WB))

        def set_camera_offset(self, context, X_RC: RigidTransform) -> None:
            """Set X_RC, the camera frame's pose on the rig, in ``context``."""
            self._set(context, _X_RC, pose_to_param(X_RC))

        def set_domain(self, context, domain: SafeDomain) -> None:
            """Set the safe domain D whose margins ``domain_margins`` reports, in ``context``."""
            self._set(context, _DOMAIN, domain_to_param(domain))

        def domain(self, context) -> SafeDomain:
            """The safe domain D in ``context``."""
            return SafeDomain(*floats(read(context, self._params_index)[_DOMAIN]))

        def body_pose(self, context):
            """X_WR as ``[q, p]`` (7), from ``body_pose`` or else ``body_state``'s first 7
            entries; ValueError naming both ports when neither has a value."""
            if self.body_pose_input.HasValue(context):
                return self.body_pose_input.Eval(context)
            if self.body_state_input.HasValue(context):
                return self.body_state_input.Eval(context)[:POSE_SIZE]
            raise ValueError(
                "SphericalCamera: connect (or fix) body_pose or body_state; neither has a value"
            )

        def pose_terms(self, context) -> tuple:
            """``(rho, r2, r3, d)``: the radius and the parts of X_CB the camera map uses."""
            x = self.body_pose(context).tolist()
            p = read(context, self._params_index)
            R_WR = quaternion_to_rotation(x[0:4], namespace(x[0]))
            R_RC, p_RC = p[_X_RC][_ROTATION], p[_X_RC][_TRANSLATION]
            R_WB, p_WB = p[_X_WB][_ROTATION], p[_X_WB][_TRANSLATION]
            r2, r3, d = target_in_camera(R_WR, x[4:7], R_RC, p_RC, R_WB, p_WB)
            return p[_RADIUS], r2, r3, d

        def X_CB(self, context) -> np.ndarray:
            """The paper's H for the rig pose on the input port, as a 4x4 array."""
            _, r2, r3, d = self.pose_terms(context)
            r1 = cross(r2, r3)
            X = np.array([[r1[i], r2[i], r3[i], d[i]] for i in range(3)] + [[0, 0, 0, 1]])
            return X if X.dtype == object else X.astype(float)

        # ---------------------------------------------------------- outputs
        def _image(self, context) -> tuple:
            """(nu, *y) by the generated kernel (compiled for floats)."""
            x = self.body_pose(context)
            p = param_vector(context, self._params_index, T)
            return _camera_image(x, p)

        def CalcImageFeatures(self, context, output) -> None:
            if T is float:  # y written into the port's array (geometry.kernels)
                y = output.get_mutable_value()
                p = param_vector(context, self._params_index, T)
                if not camera_image_y_into(self.body_pose(context), p, y) > 0:
                    y[:] = math.nan  # not visible (or NaN): y is undefined
                return
            out = self._image(context)
            nu = scalar_value(out[CAMERA_IMAGE.nu])
            if nu is not None and not nu > 0:  # not visible (or NaN): y is undefined
                output.SetFromVector([math.nan] * 13)
                return
            output.SetFromVector(out[CAMERA_IMAGE.y])

        def CalcVisibility(self, context, output) -> None:
            output.SetFromVector([self._image(context)[CAMERA_IMAGE.nu]])

        def CalcDomainMargins(self, context, output) -> None:
            out = self._image(context)
            nu = scalar_value(out[CAMERA_IMAGE.nu])
            # Every margin reads nu where the pose is not visible (y undefined).
            margins = out[CAMERA_IMAGE.margins]
            not_visible = nu is not None and not nu > 0
            output.SetFromVector([out[CAMERA_IMAGE.nu]] * 4 if not_visible else margins)

    return Impl


SphericalCamera = SphericalCamera_[None]
