"""KinematicController: (Omega, V) = -Tc^-1 (-k grad phi), Eqs. (18)-(19)."""

from __future__ import annotations

import math

from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.kernels import for_scalar_type, kinematic_velocity
from geovs_drake.systems._parameters import inputs_and_parameters, param_vector
from geovs_drake.systems._template import template_system

__all__ = ["KinematicController", "KinematicController_"]


@template_system("KinematicController_")
def KinematicController_(T):
    _kinematic_velocity = for_scalar_type(kinematic_velocity, T)

    class Impl(LeafSystem_[T]):
        """The kinematic visual servo: the camera velocity that descends phi.

        .. pydrake_system::

            name: KinematicController
            input_ports:
            - image_features
            - dphi
            output_ports:
            - camera_velocity

        ``dphi`` comes from a :class:`NavigationController` on the same y (which
        checks y), so the navigation function and its parameters live in one
        system. ``camera_velocity`` is the camera's body velocity ``(Omega, V)``
        in C. One numeric parameter vector: ``[rho, k]``, the radius and the
        gain k [1/s].
        """

        def _construct(self, radius: float = 0.1, gain: float = 1.0, converter=None):
            LeafSystem_[T].__init__(self, converter)
            if not (math.isfinite(gain) and gain > 0):
                raise ValueError(f"kinematic gain must be finite and > 0, got {gain}")
            self._defaults = (radius, gain)
            self._params_index = self.DeclareNumericParameter(BasicVector_[T]([radius, gain]))
            self.image_features_input = self.DeclareVectorInputPort(name="image_features", size=13)
            self.dphi_input = self.DeclareVectorInputPort(name="dphi", size=7)
            self.camera_velocity_output = self.DeclareVectorOutputPort(
                name="camera_velocity",
                size=6,
                calc=self.CalcCameraVelocity,
                prerequisites_of_calc=inputs_and_parameters(self),
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def CalcCameraVelocity(self, context, output) -> None:
            output.SetFromVector(
                _kinematic_velocity(
                    self.image_features_input.Eval(context),
                    self.dphi_input.Eval(context),
                    param_vector(context, self._params_index, T),
                )
            )

    return Impl


KinematicController = KinematicController_[None]
