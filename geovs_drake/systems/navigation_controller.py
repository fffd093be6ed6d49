"""NavigationController: phi and its differential dphi (Sec. 4.1) as a Drake system."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from geovs_drake.camera import ImageFeatures
from geovs_drake.domain import DEFAULT_DOMAIN, SafeDomain
from geovs_drake.navigation import (
    NavigationFunction,
    NavigationGains,
    navigation_differential,
    navigation_value,
)
from geovs_drake.systems._common import (
    domain_to_param,
    float_values,
    gains_to_param,
    inputs_and_parameters,
    param_to_domain,
    param_to_gains,
    set_output_or_nan,
)

__all__ = ["NavigationController", "NavigationController_"]


@TemplateSystem.define("NavigationController_")
def NavigationController_(T):
    class Impl(LeafSystem_[T]):
        """The navigation function phi on the safe domain D, and its differential.

        .. pydrake_system::

            name: NavigationController
            input_ports:
            - image_features
            output_ports:
            - dphi
            - phi

        ``dphi`` is the 7-vector with ``d/dt phi = dphi . (xi, lambda_dot,
        s_dot)`` (s-part orthogonal to s), which is also grad phi in the
        embedded metric (see :mod:`geovs_drake.navigation`).

        Numeric parameters, settable per context without rebuilding: the goal
        image y* (13), the domain ``[theta, lam_min, lam_max, kappa]`` and the
        shape gains ``[k_lam, k_fov, k_occ, circle_weight]``. Use
        :meth:`set_goal`, :meth:`set_domain`, :meth:`set_gains`, which validate.
        """

        def _construct(
            self,
            goal: ImageFeatures | np.ndarray,
            domain: SafeDomain = DEFAULT_DOMAIN,
            gains: NavigationGains | None = None,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            gains = gains or NavigationGains()
            nf = NavigationFunction(domain, goal, gains)  # validates the goal in D
            self._defaults = (nf.goal.to_vector(), domain, gains)
            self._goal_index = self.DeclareNumericParameter(BasicVector_[T](nf.goal.to_vector()))
            self._domain_index = self.DeclareNumericParameter(
                BasicVector_[T](domain_to_param(domain))
            )
            self._gains_index = self.DeclareNumericParameter(BasicVector_[T](gains_to_param(gains)))
            self.image_features_input = self.DeclareVectorInputPort(name="image_features", size=13)
            self.dphi_output = self.DeclareVectorOutputPort(
                name="dphi",
                size=7,
                calc=self.CalcDifferential,
                prerequisites_of_calc=inputs_and_parameters(self),
            )
            self.phi_output = self.DeclareVectorOutputPort(
                name="phi",
                size=1,
                calc=self.CalcValue,
                prerequisites_of_calc=inputs_and_parameters(self),
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def navigation_function(self, context) -> NavigationFunction:
            """A float NavigationFunction with this context's parameters."""
            goal = float_values(context.get_numeric_parameter(self._goal_index).CopyToVector())
            return NavigationFunction(self.domain(context), goal, self.gains(context))

        def domain(self, context) -> SafeDomain:
            return param_to_domain(context.get_numeric_parameter(self._domain_index).CopyToVector())

        def gains(self, context) -> NavigationGains:
            return param_to_gains(context.get_numeric_parameter(self._gains_index).CopyToVector())

        def goal(self, context) -> np.ndarray:
            return context.get_numeric_parameter(self._goal_index).CopyToVector()

        def set_goal(self, context, goal: ImageFeatures | np.ndarray) -> None:
            nf = NavigationFunction(self.domain(context), goal, self.gains(context))
            context.get_mutable_numeric_parameter(self._goal_index).SetFromVector(
                nf.goal.to_vector()
            )

        def set_domain(self, context, domain: SafeDomain) -> None:
            goal = float_values(self.goal(context))
            NavigationFunction(domain, goal, self.gains(context))  # goal must stay inside
            context.get_mutable_numeric_parameter(self._domain_index).SetFromVector(
                domain_to_param(domain)
            )

        def set_gains(self, context, gains: NavigationGains) -> None:
            context.get_mutable_numeric_parameter(self._gains_index).SetFromVector(
                gains_to_param(gains)
            )

        def _args(self, context) -> tuple:
            return (
                self.image_features_input.Eval(context),
                self.goal(context),
                self.domain(context),
                self.gains(context),
            )

        def CalcDifferential(self, context, output) -> None:
            args = self._args(context)
            set_output_or_nan(output, lambda: navigation_differential(*args)[1])

        def CalcValue(self, context, output) -> None:
            args = self._args(context)
            set_output_or_nan(output, lambda: np.atleast_1d(navigation_value(*args)))

    return Impl


NavigationController = NavigationController_[None]
