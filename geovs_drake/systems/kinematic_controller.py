"""KinematicController: (Omega, V) = -Tc^-1 (-k grad phi), Eqs. (18)-(19)."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from geovs_drake.camera import image_jacobian_inverse
from geovs_drake.systems._common import inputs_and_parameters, set_output_or_nan

__all__ = ["KinematicController", "KinematicController_", "kinematic_velocity"]


def kinematic_velocity(y: np.ndarray, dphi: np.ndarray, radius: object, gain: object) -> np.ndarray:
    """Eqs. (18)-(19) with ``ydot_d = -k grad phi``: ``(Omega, V) = k Tc^-1 dphi``.

    The sign: Eq. (18) has ``(Omega, V) = -Tc^-1 ydot_d`` because the camera's
    body velocity is minus the right-trivialised velocity of H (Eq. 16).
    Then ``ydot = C (omega, v) = -C (Omega, V) = -k grad phi``, exactly,
    since grad phi lies in the range of C.
    """
    return gain * (image_jacobian_inverse(y, radius) @ dphi)


@TemplateSystem.define("KinematicController_")
def KinematicController_(T):
    class Impl(LeafSystem_[T]):
        """The kinematic visual servo: the camera velocity that descends phi.

        .. pydrake_system::

            name: KinematicController
            input_ports:
            - image_features
            - dphi
            output_ports:
            - camera_velocity

        ``dphi`` comes from a :class:`NavigationController` on the same y, so
        the navigation function and its parameters live in one system.
        ``camera_velocity`` is the camera's body velocity ``(Omega, V)`` in C.
        Numeric parameters: the radius rho and the gain k [1/s].
        """

        def _construct(self, radius: float = 0.1, gain: float = 1.0, converter=None):
            LeafSystem_[T].__init__(self, converter)
            if not gain > 0:
                raise ValueError(f"kinematic gain must be > 0, got {gain}")
            self._defaults = (radius, gain)
            self._radius_index = self.DeclareNumericParameter(BasicVector_[T]([radius]))
            self._gain_index = self.DeclareNumericParameter(BasicVector_[T]([gain]))
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
            set_output_or_nan(
                output,
                lambda: kinematic_velocity(
                    self.image_features_input.Eval(context),
                    self.dphi_input.Eval(context),
                    context.get_numeric_parameter(self._radius_index).GetAtIndex(0),
                    context.get_numeric_parameter(self._gain_index).GetAtIndex(0),
                ),
            )

    return Impl


KinematicController = KinematicController_[None]
