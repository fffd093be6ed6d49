"""The one LeafSystem body of a law toward a goal image that commands a camera twist.

PBVS and the sphere-feature law differ only in their formula
``law(y, y*, rho, lambda) -> (Omega, V)``; each keeps its own module, name and
docstring (its ``.. pydrake_system::`` block) and builds its class here, so
the ports, the parameter vector and the NaN outside I are written once.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.systems._parameters import (
    image_usable,
    inputs_and_parameters,
    twist_law_parameters,
)

# Layout of the one numeric parameter: y* (13), rho, lambda.
GOAL, RHO, GAIN = slice(0, 13), 13, 14


def goal_image_law_class(T: type, law: Callable, doc: str) -> type:
    """A ``LeafSystem_[T]`` with input ``image_features`` (13), output
    ``camera_velocity`` (6) = ``law(y, y*, rho, lambda)``, NaN where y is not in I,
    and one numeric parameter ``[y* (13), rho, lambda]``; ``doc`` is its docstring."""

    class Impl(LeafSystem_[T]):
        __doc__ = doc

        def _construct(
            self,
            goal: ImageFeatures | np.ndarray,
            radius: float = 0.1,
            gain: float = 1.0,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            params = twist_law_parameters(goal, radius, gain)
            self._defaults = (np.array(params[GOAL]), radius, gain)
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
            output.SetFromVector(law(y, p[GOAL], p[RHO], p[GAIN]))

    return Impl
