"""NavigationController: phi and its differential dphi (Sec. 4.1) as a Drake system."""

from __future__ import annotations

import functools
import math

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.camera import ImageFeatures, image_violation
from geovs_drake.geometry.domain import DEFAULT_DOMAIN, SafeDomain
from geovs_drake.geometry.kernels import for_scalar_type, navigation
from geovs_drake.geometry.navigation import (
    NavigationFunction,
    NavigationGains,
    navigation_parameters,
)
from geovs_drake.systems._parameters import (
    domain_to_param,
    floats,
    inputs_and_parameters,
    param_vector,
    read,
    values_or_none,
)
from geovs_drake.systems._template import template_system

__all__ = ["NavigationController", "NavigationController_"]

# Layout of the one numeric parameter: goal y* (13), domain (4), gains (4).
_GOAL, _DOMAIN, _GAINS = slice(0, 13), slice(13, 17), slice(17, 21)


@functools.lru_cache(maxsize=64)
def _nf_parameters(values: tuple[float, ...]) -> tuple:
    """The NF's 16 formula parameters from this system's 21 numbers (built once per value)."""
    return navigation_parameters(
        np.array(values[_GOAL]),
        SafeDomain(*values[_DOMAIN]),
        NavigationGains(*values[_GAINS]),
    )


@functools.lru_cache(maxsize=64)
def _nf_parameters_of_bytes(values: bytes) -> tuple:
    return _nf_parameters(tuple(np.frombuffer(values).tolist()))


@template_system("NavigationController_")
def NavigationController_(T):
    _navigation = for_scalar_type(navigation, T)

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
        embedded metric (see :mod:`geovs_drake.geometry.navigation`).

        The input is checked once here, at the loop's first consumer of y: an
        image outside I (or NaN, from an invisible pose) gives NaN outputs.
        Between the boundary of D and that of I the outputs continue the
        formula smoothly (the pure functions' ``extend=True``; phi may leave
        [0, 1] there), so an integrator's trial stage just outside D does not
        fail; the safe-domain monitor of ``simulate()`` stops any run whose
        accepted state leaves D.
        Downstream systems that read the same y (``ImageJacobianForce``,
        ``KinematicController``) do not check it again.

        One numeric parameter vector, settable per context without rebuilding:
        ``[y* (13), theta, lam_min, lam_max, kappa, k_lam, k_fov, k_occ,
        circle_weight]``. Use :meth:`set_goal`, :meth:`set_domain`,
        :meth:`set_gains`, which validate. The parameters are float-valued
        even in an AutoDiffXd system (their derivatives are not propagated).
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
            goal_vector = nf.goal.to_vector()
            self._defaults = (goal_vector, domain, gains)
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T](goal_vector.tolist() + domain_to_param(domain) + list(gains.params))
            )
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

        # ------------------------------------------------------- parameters
        def _values(self, context) -> tuple[float, ...]:
            return floats(read(context, self._params_index))

        def _set(self, context, goal, domain, gains) -> None:
            nf = NavigationFunction(domain, goal, gains)  # the goal must lie inside D
            context.get_mutable_numeric_parameter(self._params_index).SetFromVector(
                nf.goal.to_vector().tolist() + domain_to_param(domain) + list(gains.params)
            )

        def navigation_parameters(self, context) -> tuple:
            """The 16 floats the NF formulas take (:func:`navigation_parameters`)."""
            if T is float:  # keyed on the raw bytes: no list, no tuple of 21 floats
                return _nf_parameters_of_bytes(
                    param_vector(context, self._params_index, T).tobytes()
                )
            return _nf_parameters(self._values(context))

        def navigation_function(self, context) -> NavigationFunction:
            """A float NavigationFunction with this context's parameters."""
            return NavigationFunction(self.domain(context), self.goal(context), self.gains(context))

        def domain(self, context) -> SafeDomain:
            """The safe domain D in ``context``."""
            return SafeDomain(*self._values(context)[_DOMAIN])

        def gains(self, context) -> NavigationGains:
            """The navigation function's gains in ``context``."""
            return NavigationGains(*self._values(context)[_GAINS])

        def goal(self, context) -> np.ndarray:
            """y*, the goal image as the 13-vector ``[q1, q2, q3, lambda, s]``, in ``context``."""
            return np.array(self._values(context)[_GOAL])

        def set_goal(self, context, goal: ImageFeatures | np.ndarray) -> None:
            """Set y* in ``context``; ValueError unless it lies in the interior of D."""
            self._set(context, goal, self.domain(context), self.gains(context))

        def set_domain(self, context, domain: SafeDomain) -> None:
            """Set D in ``context``; ValueError unless the goal lies in its interior."""
            self._set(context, self.goal(context), domain, self.gains(context))

        def set_gains(self, context, gains: NavigationGains) -> None:
            """Set the navigation function's gains in ``context``."""
            self._set(context, self.goal(context), self.domain(context), gains)

        # ---------------------------------------------------------- outputs
        def _kernel(self, context) -> tuple | None:
            """(1 - phi, *dphi, phi) by the generated kernel, or None if y is not in I."""
            y = self.image_features_input.Eval(context)
            values = values_or_none(y.tolist())
            if values is not None and image_violation(values) is not None:
                return None
            return _navigation(y, self.navigation_parameters(context))

        def CalcDifferential(self, context, output) -> None:
            out = self._kernel(context)
            output.SetFromVector([math.nan] * 7 if out is None else out[1:8])

        def CalcValue(self, context, output) -> None:
            out = self._kernel(context)
            output.SetFromVector([math.nan if out is None else out[8]])

    return Impl


NavigationController = NavigationController_[None]
