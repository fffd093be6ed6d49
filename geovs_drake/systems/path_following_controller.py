"""PathFollowingController: Eq. (18), following a planned image path y_d(t)."""

from __future__ import annotations

import math

from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry._ops import namespace
from geovs_drake.geometry.camera import image_violation
from geovs_drake.geometry.image_path import image_error
from geovs_drake.geometry.servo import path_following_velocity
from geovs_drake.systems._parameters import inputs_and_parameters, read, values_or_none
from geovs_drake.systems._template import template_system

__all__ = ["PathFollowingController", "PathFollowingController_", "check_path_gains"]

# Layout of the one numeric parameter: the model radius rho, the feedback gain k.
_RADIUS, _GAIN = 0, 1


def check_path_gains(radius: float, gain: float) -> tuple[float, float]:
    """``(radius, gain)`` as floats; ValueError unless radius > 0 and gain >= 0, finite."""
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"path follower: model radius must be finite and > 0, got {radius}")
    if not (math.isfinite(gain) and gain >= 0):
        raise ValueError(f"path follower: feedback gain must be finite and >= 0, got {gain}")
    return float(radius), float(gain)


@template_system("PathFollowingController_")
def PathFollowingController_(T):
    class Impl(LeafSystem_[T]):
        """The camera velocity that moves the image along a planned path (Sec. 4, Eq. 18).

        .. pydrake_system::

            name: PathFollowingController
            input_ports:
            - image_features
            - desired_image
            output_ports:
            - camera_velocity
            - image_error

        ``desired_image`` is ``[y_d (13), dy_d/dt (13)]``, what a
        ``TrajectorySource(trajectory, output_derivative_order=1)`` of the
        planned 13-vector path puts out (see :mod:`geovs_drake.planning`).
        ``camera_velocity`` is ``(Omega, V) = -Tc^-1(y) ydot_cmd`` with
        ``ydot_cmd = ydot_d`` carried to y plus ``k log_y(y_d)``
        (:func:`~geovs_drake.geometry.servo.path_following_velocity`):

        * ``k = 0``: Eq. (18) as written, open loop. With an exact model the
          image follows y_d(t) to the integrator's accuracy, and nothing pulls
          it back from any error;
        * ``k > 0``: feed-forward plus feedback on the log-map error on
          SO(3) x R x S^2; with an exact model each geodesic error decays as
          ``exp(-k t)``.

        ``image_error`` is ``log_y(y_d)`` (7 numbers, Eq. 12's identification),
        whose three parts have the lengths of the three geodesic errors.

        One numeric parameter vector ``[rho, k]``: the radius the controller
        assumes (it may differ from the true one, for model-error studies) and
        the feedback gain k [1/s]. An image outside I (an integrator's trial
        stage past the limb, or NaN from an invisible pose) gives NaN outputs,
        never an exception (see :mod:`geovs_drake.systems._parameters`).
        """

        def _construct(self, radius: float = 0.1, gain: float = 0.0, converter=None):
            LeafSystem_[T].__init__(self, converter)
            radius, gain = check_path_gains(radius, gain)
            self._defaults = (radius, gain)
            self._params_index = self.DeclareNumericParameter(BasicVector_[T]([radius, gain]))
            self.image_features_input = self.DeclareVectorInputPort(name="image_features", size=13)
            self.desired_image_input = self.DeclareVectorInputPort(name="desired_image", size=26)
            self.camera_velocity_output = self.DeclareVectorOutputPort(
                name="camera_velocity",
                size=6,
                calc=self.CalcCameraVelocity,
                prerequisites_of_calc=inputs_and_parameters(self),
            )
            self.image_error_output = self.DeclareVectorOutputPort(
                name="image_error",
                size=7,
                calc=self.CalcImageError,
                prerequisites_of_calc=inputs_and_parameters(self),
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def set_gain(self, context, gain: float) -> None:
            """Set the feedback gain k [1/s] (0: Eq. 18 open loop); validated."""
            p = context.get_mutable_numeric_parameter(self._params_index)
            p.SetAtIndex(_GAIN, check_path_gains(1.0, gain)[1])

        def set_radius(self, context, radius: float) -> None:
            """Set the law's model of the radius rho [m]; validated."""
            p = context.get_mutable_numeric_parameter(self._params_index)
            p.SetAtIndex(_RADIUS, check_path_gains(radius, 0.0)[0])

        def _inputs(self, context) -> tuple[list, list, list] | None:
            """``(y, y_d, dy_d/dt)``, or None if y is not in I."""
            y = self.image_features_input.Eval(context).tolist()
            values = values_or_none(y)
            if values is not None and image_violation(values) is not None:
                return None
            desired = self.desired_image_input.Eval(context).tolist()
            return y, desired[0:13], desired[13:26]

        def CalcCameraVelocity(self, context, output) -> None:
            inputs = self._inputs(context)
            if inputs is None:
                output.SetFromVector([math.nan] * 6)
                return
            y, y_d, ydot_d = inputs
            p = read(context, self._params_index)
            output.SetFromVector(
                path_following_velocity(y, y_d, ydot_d, p[_RADIUS], p[_GAIN], namespace(y[0]))
            )

        def CalcImageError(self, context, output) -> None:
            inputs = self._inputs(context)
            if inputs is None:
                output.SetFromVector([math.nan] * 7)
                return
            y, y_d, _ = inputs
            output.SetFromVector(image_error(y, y_d, namespace(y[0])))

    return Impl


PathFollowingController = PathFollowingController_[None]
