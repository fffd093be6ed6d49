"""PbvsController: position-based servoing on c^-1(y), straight line in Cartesian space."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from geovs_drake.geometry.baselines import pbvs_velocity
from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.systems._common import image_usable, inputs_and_parameters, twist_law_parameters

__all__ = ["PbvsController", "PbvsController_"]

# Layout of the one numeric parameter: y* (13), rho, lambda.
_GOAL, _RHO, _GAIN = slice(0, 13), 13, 14


@TemplateSystem.define("PbvsController_")
def PbvsController_(T):
    class Impl(LeafSystem_[T]):
        """Position-based visual servoing with the pose from the paper's inverse map.

        .. pydrake_system::

            name: PbvsController
            input_ports:
            - image_features
            output_ports:
            - camera_velocity

        The current and desired poses are ``c^-1(y)`` and ``c^-1(y*)`` (Eq. 23),
        so ``s = (c*t_c, theta u)``: the camera's origin in the desired camera
        frame and the angle-axis of ``c*R_c``. The law is Chaumette &
        Hutchinson's (*Visual servo control I*, 2006, Sec. IV) variant whose
        camera origin moves on a straight line: ``v = -lambda c*R_c^T c*t_c``,
        ``omega = -lambda theta u``
        (:func:`~geovs_drake.geometry.baselines.pbvs_velocity`), output as
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
            output.SetFromVector(pbvs_velocity(y, p[_GOAL], p[_RHO], p[_GAIN]))

    return Impl


PbvsController = PbvsController_[None]
