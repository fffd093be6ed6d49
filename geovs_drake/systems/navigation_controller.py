"""NavigationController: phi and its differential dphi (Sec. 4.1) as a Drake system."""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.camera import UNIT_TOL, ImageFeatures, image_violation
from geovs_drake.geometry.domain import DEFAULT_DOMAIN, SafeDomain
from geovs_drake.geometry.kernels import for_scalar_type, navigation, navigation_dphi_into
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


#: How far inside I (Eq. 9) a float y must lie for :func:`_surely_in_image` to pass it
#: without :func:`image_violation`: the orthonormality, unit-s and silhouette margins it
#: checks must clear these, far above the rounding (1e-16) of the two ways of computing
#: them, so a y it passes is one that image_violation passes too.
_ORTHONORMAL_SLACK = 0.5 * UNIT_TOL
_SILHOUETTE_SLACK = 1e-9


@njit(cache=True, error_model="numpy", nogil=True)
def _surely_in_image(y: np.ndarray) -> bool:
    """True where the float y lies in I with room to spare (finite, 0 < lambda < 1, Q a
    rotation and s a unit vector to half of UNIT_TOL, the marked point inside the
    silhouette by :data:`_SILHOUETTE_SLACK`); False leaves the verdict to
    :func:`image_violation` (the NF's check in about 0.3 us instead of 3 us)."""
    for k in range(13):
        if not math.isfinite(y[k]):
            return False
    lam = y[9]
    if not (0.0 < lam < 1.0):
        return False
    for i in range(3):
        for j in range(i, 3):
            dot = y[3 * i] * y[3 * j] + y[3 * i + 1] * y[3 * j + 1] + y[3 * i + 2] * y[3 * j + 2]
            if abs(dot - (1.0 if i == j else 0.0)) > _ORTHONORMAL_SLACK:
                return False
    det = (
        y[6] * (y[1] * y[5] - y[2] * y[4])
        + y[7] * (y[2] * y[3] - y[0] * y[5])
        + y[8] * (y[0] * y[4] - y[1] * y[3])
    )
    s_norm = math.sqrt(y[10] * y[10] + y[11] * y[11] + y[12] * y[12])
    if not det > 0.5 or abs(s_norm - 1.0) > _ORTHONORMAL_SLACK:
        return False
    # Eq. (9), q1.s > sqrt(1 - lambda^2), with room (the plain form: its rounding is
    # far below the slack; limb_margin's form is image_violation's).
    c = y[0] * y[10] + y[1] * y[11] + y[2] * y[12]
    return c - math.sqrt(1.0 - lam * lam) > _SILHOUETTE_SLACK


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
            # Float only: the parameters' bytes and the NF's 16 numbers made of them.
            self._nf_of: tuple = (None, None)
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
                key = param_vector(context, self._params_index, T).tobytes()
                if key != self._nf_of[0]:
                    self._nf_of = (key, _nf_parameters_of_bytes(key))
                return self._nf_of[1]
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
            if T is float:
                # The compiled check passes a y well inside I; any other y (near I's
                # boundary, NaN) gets image_violation's verdict, as every y once did.
                if not _surely_in_image(y) and image_violation(tuple(y.tolist())) is not None:
                    return None
                return _navigation(y, self.navigation_parameters(context))
            values = values_or_none(y.tolist())
            if values is not None and image_violation(values) is not None:
                return None
            return _navigation(y, self.navigation_parameters(context))

        def CalcDifferential(self, context, output) -> None:
            if T is float:  # dphi written into the port's array, where y is surely in I
                y = self.image_features_input.Eval(context)
                if _surely_in_image(y):
                    p = self.navigation_parameters(context)
                    navigation_dphi_into(y, p, output.get_mutable_value())
                    return
            out = self._kernel(context)
            output.SetFromVector([math.nan] * 7 if out is None else out[1:8])

        def CalcValue(self, context, output) -> None:
            out = self._kernel(context)
            output.SetFromVector([math.nan if out is None else out[8]])

    return Impl


NavigationController = NavigationController_[None]
