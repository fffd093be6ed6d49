"""SphericalFeatureController: decoupled sphere features (p = s / lambda, theta u)."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from geovs_drake.geometry.baselines import spherical_velocity
from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.systems._common import image_usable, inputs_and_parameters, twist_law_parameters

__all__ = ["SphericalFeatureController", "SphericalFeatureController_"]

# Layout of the one numeric parameter: y* (13), rho, lambda.
_GOAL, _RHO, _GAIN = slice(0, 13), 13, 14


@TemplateSystem.define("SphericalFeatureController_")
def SphericalFeatureController_(T):
    class Impl(LeafSystem_[T]):
        """Visual servoing on decoupled features of the marked sphere.

        .. pydrake_system::

            name: SphericalFeatureController
            input_ports:
            - image_features
            output_ports:
            - camera_velocity

        After Tatsambon Fomena & Chaumette, *Improvements on visual servoing
        from spherical targets using a spherical projection model* (IEEE
        T-RO 25(4), 2009): ``s = (p, theta u)`` with ``p = s / lambda``, the
        sphere's centre over its radius read from the image (their feature
        for a sphere, with interaction ``[-(1 / rho) I, [p]x]``), and theta u
        of the target's rotation ``c*R_c`` from ``c^-1(y)``, ``c^-1(y*)``
        (Eq. 23). The rotational part is our derivation for the arrow, not a
        transcription of the paper's (whose text we could not retrieve); see
        :mod:`geovs_drake.geometry.baselines`. The interaction matrix is block
        triangular, and ``(v, omega) = -lambda L^-1 (p - p*, theta u)`` is, in
        closed form, ``omega = -lambda theta u``, ``v = rho (lambda (p - p*) +
        p x omega)`` (:func:`~geovs_drake.geometry.baselines.spherical_velocity`):
        the centre moves on a straight line in the camera frame. Output as
        ``(Omega, V)`` in C (Eq. 16's sign).

        An image outside I gives NaN. One numeric parameter vector ``[y* (13),
        rho, lambda]``: the goal image, the radius [m], the gain [1/s].
        """

        def _construct(
            self,
            goal: ImageFeatures | np.ndarray,
            radius: float = 0.1,
            gain: float = 1.0,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            params = twist_law_parameters(goal, radius, gain)
            self._defaults = (np.array(params[_GOAL]), radius, gain)
            self._params_index = self.DeclareNumericParameter(BasicVector_[T](params))
            self.image_features_input = self.DeclareVectorInputPort(name="image_features", size=13)
            self.camera_velocity_output = self.DeclareVectorOutputPort(
                name="camera_velocity",
                size=6,
                calc=self.CalcCameraVelocity,
                prerequisites_of_calc=inputs_and_parameters(self),
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def CalcCameraVelocity(self, context, output) -> None:
            y = self.image_features_input.Eval(context)
            if not image_usable(y):
                output.SetFromVector([math.nan] * 6)
                return
            p = context.get_numeric_parameter(self._params_index).CopyToVector()
            output.SetFromVector(spherical_velocity(y, p[_GOAL], p[_RHO], p[_GAIN]))

    return Impl


SphericalFeatureController = SphericalFeatureController_[None]
