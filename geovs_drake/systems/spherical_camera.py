"""SphericalCamera: the camera map of Eqs. (3)-(8) as a Drake system."""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from geovs_drake._scalar import values_or_none
from geovs_drake.camera import camera_map, visibility
from geovs_drake.domain import DEFAULT_DOMAIN, SafeDomain
from geovs_drake.systems._common import (
    POSE_SIZE,
    X_CB_matrix,
    camera_pose,
    domain_to_param,
    inputs_and_parameters,
    param_to_domain,
    param_to_pose,
    pose_to_param,
    set_output_or_nan,
)

__all__ = ["SphericalCamera", "SphericalCamera_"]


@TemplateSystem.define("SphericalCamera_")
def SphericalCamera_(T):
    class Impl(LeafSystem_[T]):
        """The spherical camera on the rig, viewing the marked target sphere.

        .. pydrake_system::

            name: SphericalCamera
            input_ports:
            - body_pose
            output_ports:
            - image_features
            - visibility
            - domain_margins

        ``body_pose`` is the rig's pose X_WR as ``[qw, qx, qy, qz, x, y, z]``
        (the first 7 entries of a MultibodyPlant free-body state). The camera
        frame C sits at X_RC on the rig (Appendix C.0.6).

        ``image_features`` is y = c(X_CB) as the 13-vector ``[q1, q2, q3,
        lambda, s]``; ``visibility`` is nu(X_CB) of Eq. (5);
        ``domain_margins`` is the signed margins ``[fov, lam_min, lam_max,
        occlusion]`` of :class:`~geovs_drake.domain.SafeDomain` (all >= 0 in D).
        When the pose is not visible y is undefined: ``image_features`` is all
        NaN (so an integrator rejects such a trial stage, see
        :func:`~geovs_drake.systems._common.set_output_or_nan`) and every
        margin reads nu <= 0. The pure :func:`~geovs_drake.camera.camera_map`
        raises ``ValueError: pose not visible ...`` instead.

        Numeric parameters (settable per context, e.g. for sweeps): the radius
        rho, the target pose X_WB, the camera offset X_RC and the domain.
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
            self._defaults = (radius, X_WB, X_RC, domain)
            self._radius_index = self.DeclareNumericParameter(BasicVector_[T]([radius]))
            self._X_WB_index = self.DeclareNumericParameter(BasicVector_[T](pose_to_param(X_WB)))
            self._X_RC_index = self.DeclareNumericParameter(BasicVector_[T](pose_to_param(X_RC)))
            self._domain_index = self.DeclareNumericParameter(
                BasicVector_[T](domain_to_param(domain))
            )
            self.body_pose_input = self.DeclareVectorInputPort(name="body_pose", size=POSE_SIZE)
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
        def radius(self, context) -> object:
            return context.get_numeric_parameter(self._radius_index).GetAtIndex(0)

        def set_radius(self, context, radius: float) -> None:
            if not radius > 0:
                raise ValueError(f"radius must be > 0: radius = {radius}")
            context.get_mutable_numeric_parameter(self._radius_index).SetAtIndex(0, radius)

        def set_target_pose(self, context, X_WB: RigidTransform) -> None:
            context.get_mutable_numeric_parameter(self._X_WB_index).SetFromVector(
                pose_to_param(X_WB)
            )

        def set_camera_offset(self, context, X_RC: RigidTransform) -> None:
            context.get_mutable_numeric_parameter(self._X_RC_index).SetFromVector(
                pose_to_param(X_RC)
            )

        def set_domain(self, context, domain: SafeDomain) -> None:
            context.get_mutable_numeric_parameter(self._domain_index).SetFromVector(
                domain_to_param(domain)
            )

        def domain(self, context) -> SafeDomain:
            return param_to_domain(context.get_numeric_parameter(self._domain_index).CopyToVector())

        def X_CB(self, context) -> np.ndarray:
            """The paper's H for the rig pose on the input port."""
            x = self.body_pose_input.Eval(context)
            X_RC = context.get_numeric_parameter(self._X_RC_index).CopyToVector()
            R_WC, p_WC = camera_pose(x, X_RC)
            R_WB, p_WB = param_to_pose(
                context.get_numeric_parameter(self._X_WB_index).CopyToVector()
            )
            return X_CB_matrix(R_WC, p_WC, R_WB, p_WB)

        # ---------------------------------------------------------- outputs
        def CalcImageFeatures(self, context, output) -> None:
            set_output_or_nan(
                output, lambda: camera_map(self.X_CB(context), self.radius(context)).to_vector()
            )

        def CalcVisibility(self, context, output) -> None:
            output.SetAtIndex(0, visibility(self.X_CB(context), self.radius(context)).item())

        def CalcDomainMargins(self, context, output) -> None:
            nu = self.visibility_output.Eval(context)
            nu_value = values_or_none(nu)
            if nu_value is not None and nu_value[0] <= 0:
                output.SetFromVector(np.full(4, nu[0]))
                return
            y = self.image_features_output.Eval(context)
            margins = self.domain(context).margins(y)
            output.SetFromVector(np.array([m.item() for m in margins]))

    return Impl


SphericalCamera = SphericalCamera_[None]
