"""IbvsController: point IBVS, (v, omega) = -lambda L^+ (s - s*) (Chaumette & Hutchinson 2006)."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.baselines import (
    DEFAULT_SQUARE_SIDE,
    IBVS_DEPTHS,
    TARGET_POINT_NAMES,
    ibvs_velocity,
    target_points,
)
from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.systems._parameters import (
    floats,
    image_usable,
    inputs_and_parameters,
    read,
    twist_law_parameters,
)
from geovs_drake.systems._template import template_system

__all__ = ["IbvsController", "IbvsController_"]

# Layout of the one numeric parameter: y* (13), rho, lambda, square side.
_GOAL, _RHO, _GAIN, _SIDE = slice(0, 13), 13, 14, 15


@template_system("IbvsController_")
def IbvsController_(T):
    class Impl(LeafSystem_[T]):
        """Point image-based visual servoing on four points of the target.

        .. pydrake_system::

            name: IbvsController
            input_ports:
            - image_features
            output_ports:
            - camera_velocity

        The points are b and three corners of a square in the plane tangent
        to the sphere at b, spanned by the arrow and its normal
        (:func:`~geovs_drake.geometry.baselines.target_points`). Their
        normalised image coordinates ``s = (x_1, y_1, ..., x_4, y_4)`` and
        depths come from ``c^-1(y)`` (Eq. 23): the depths are the "true depth"
        oracle a real system would estimate. The law is Chaumette &
        Hutchinson's (*Visual servo control I*, 2006) Eq. (5),
        ``(v, omega) = -lambda L^+ (s - s*)``, with the point interaction
        matrix of their Eq. (11) and the estimate ``depth``: ``"true"`` (the
        current L with the true depths), ``"desired"`` (L at s*, Z*) or
        ``"mean"`` ((L + L*) / 2). ``camera_velocity`` is the same velocity as
        ``(Omega, V)`` in C (Eq. 16's sign; see
        :mod:`geovs_drake.geometry.baselines` for the conversion).

        An image outside I (NaN from an invisible pose, an integrator's trial
        stage) gives NaN. One numeric parameter vector ``[y* (13), rho,
        lambda, side]``: the goal image, the radius [m], the gain lambda [1/s]
        and the square's side [m].
        """

        #: The names of the points, in the order of :meth:`target_points_B`.
        TARGET_POINT_NAMES = TARGET_POINT_NAMES

        def _construct(
            self,
            goal: ImageFeatures | np.ndarray,
            radius: float = 0.1,
            gain: float = 1.0,
            depth: str = "true",
            side: float | None = None,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            if depth not in IBVS_DEPTHS:
                raise ValueError(
                    f"ibvs depth must be one of {', '.join(IBVS_DEPTHS)}, got {depth!r}"
                )
            side = DEFAULT_SQUARE_SIDE * radius if side is None else side
            if not (math.isfinite(side) and side > 0):
                raise ValueError(f"square side must be finite and > 0 [m], got {side}")
            params = twist_law_parameters(goal, radius, gain) + [float(side)]
            self._defaults = (np.array(params[_GOAL]), radius, gain, depth, side)
            self.depth = depth
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

        def target_points_B(self, context) -> np.ndarray:
            """The four points in B (4, 3) [m], floats, from this context's parameters."""
            p = floats(read(context, self._params_index))
            return target_points(p[_RHO], p[_SIDE])

        def CalcCameraVelocity(self, context, output) -> None:
            y = self.image_features_input.Eval(context)
            if not image_usable(y):
                output.SetFromVector([math.nan] * 6)
                return
            p = context.get_numeric_parameter(self._params_index).CopyToVector()
            output.SetFromVector(
                ibvs_velocity(
                    y, p[_GOAL], p[_RHO], target_points(p[_RHO], p[_SIDE]), p[_GAIN], self.depth
                )
            )

    return Impl


IbvsController = IbvsController_[None]
