"""A navigation function on the safe domain D (paper Sec. 4.1-4.2, Definition 1).

The paper leaves the construction open and conjectures D ~ [0,1]^5 x S^1.
This module builds it.

Construction
------------
1. **A diffeomorphism Psi from D to a model product space**
   ``M = [-1, 1] x B^2 x B^2 x S^1`` (interval x disc x disc x circle), built
   fibre by fibre, so its Jacobian is block-triangular with invertible blocks:

   * ``u = (2 lambda - lam_min - lam_max) / (lam_max - lam_min)``: lambda's interval.
   * ``w_s = (s_x, s_y) / sin(rho(lambda))`` with ``rho = theta - arcsin(lambda)``:
     for fixed lambda the FOV constraint is the spherical cap ``angle(s, e3) <=
     rho``, and ``|w_s| <= 1`` is exactly that cap (both angles < pi/2).
   * ``w_q = (p_x, p_y) / sin(psi(lambda))`` with ``p = R_s^T q1``: q1 seen
     from the minimal rotation R_s taking e3 to s; ``psi`` is the occlusion
     cap's angular radius, so ``|w_q| <= 1`` is exactly the occlusion constraint.
   * ``(cos a, sin a) = (R_q1 e1 . q2, R_q1 e2 . q2)``: the angle of the arrow
     q2 about q1, measured from a frame that is smooth in q1 over D.

   Every face of D maps to a face of M. The minimal rotations are smooth
   because s and q1 stay in the open upper hemisphere on D.

2. **A navigation function on each factor.** On a ball (interval or disc) with
   goal ``w*`` in its interior, ``phi_i = g / (g + k beta)`` with
   ``g = |w - w*|^2`` and ``beta = 1 - |w|^2`` (Koditschek-Rimon with no
   obstacle). Its only critical point is ``w*``: ``beta grad g = g grad beta``
   forces w, w*, 0 to be collinear, ``w = t e``, ``w* = t* e``, and then
   ``t t* = 1``, impossible for ``|t*| < 1``. It equals 1 exactly on the sphere
   ``|w| = 1`` and its Hessian at ``w*`` is ``2 / (k beta*) I``. On the circle,
   ``phi_c = c_w (1 - cos(a - a*)) / 2`` with weight ``0 < c_w < 1``:
   a minimum at ``a*`` and a maximum (value ``c_w < 1``) at ``a* + pi``.

3. **The product**: ``phi = 1 - (1 - phi_lam)(1 - phi_s)(1 - phi_q)(1 - phi_c)``.
   On the boundary of D one ball factor is 1, so phi = 1 uniformly; inside, every
   factor is < 1, so phi < 1. ``dphi = sum_i dphi_i prod_{j != i} (1 - phi_j)``
   with every product positive inside, so dphi = 0 iff every dphi_i = 0: the
   critical points are products of the factors' critical points, and at them the
   Hessian is block-diagonal, ``diag((prod_{j != i}(1 - phi_j)) H_i)``. Hence
   exactly two critical points, both non-degenerate (Morse):

   * the minimum y* (phi = 0), and
   * one saddle of index 1: y* with Q replaced by ``Q* Rx(pi)``, i.e. the
     arrow turned by pi about q1 (phi = c_w). Any smooth function on the
     circle factor has at least two critical points, so one saddle is the least
     possible; its stable manifold (5-dimensional, measure zero) is the only
     set of starts that does not reach y*.

   This meets Definition 1: a Morse function on D, unique minimum 0 at y*,
   ``phi^-1(1) = boundary of D``.

Metric and differential
-----------------------
:func:`navigation_differential` returns the 7-vector ``dphi = (dphi_xi,
dphi_lambda, dphi_s)`` such that ``d/dt phi(y(t)) = dphi . (xi, lambda_dot,
s_dot)`` for every motion in I (xi of Eq. 13), with its s-part orthogonal to s.
It is therefore also the gradient for the *embedded Euclidean metric* on
``T_y I = R^3 x R x T_s S^2`` (the bi-invariant metric on SO(3) through xi,
plus the round metrics on lambda and S^2), the metric the kinematic
controller ``ydot = -grad phi`` (Eq. 19) descends.

One source, generated derivatives
---------------------------------
The formula is written once, in scalar style: :func:`model_coordinates_of`
(Psi) and :func:`clearance_of` (``1 - phi``, the product itself, which keeps
its digits near the boundary of D). Evaluated directly they give phi for every
number type. The differential is code generated from that same source
(:mod:`geovs_drake.geometry._codegen`: sympy differentiates it along the 7
directions of ``T_y I`` and eliminates common subexpressions) into the
``navigation`` kernel of :mod:`geovs_drake.geometry.kernels`, committed, and
regenerated and compared by a test. It uses only ``+ - * /`` and ``sqrt``, so it
too runs on floats (compiled by numba), float batches, AutoDiffXd and Expression.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from geovs_drake.geometry._ops import (
    MATH,
    Ops,
    OutOfDomainError,
    components,
    first_bad,
    namespace,
    pack,
    to_float,
)
from geovs_drake.geometry.camera import ImageFeatures, as_features, validated_components
from geovs_drake.geometry.domain import SafeDomain, domain_margins, fov_cap, occlusion_cap
from geovs_drake.geometry.kernels import navigation as navigation_kernel
from geovs_drake.geometry.so3 import so3_exp

__all__ = [
    "ModelCoordinates",
    "check_in_domain",
    "NavigationFunction",
    "NavigationGains",
    "clearance_of",
    "phi_of",
    "features_from_model",
    "model_coordinates",
    "model_coordinates_of",
    "navigation_clearance",
    "navigation_differential",
    "navigation_parameters",
    "navigation_value",
    "saddle_of",
    "chart_basis",
    "image_chart",
]


@dataclass(frozen=True)
class NavigationGains:
    """Shape parameters of phi.

    Args:
        k_lam, k_fov, k_occ: the ``k`` of ``g / (g + k beta)`` for the lambda
            interval, the FOV disc and the occlusion disc. Larger k makes the
            factor's bowl wider and flatter (Hessian at the goal ``2 / (k beta*)``
            times the chart's scale); smaller k steepens the walls.
        circle_weight: c_w in (0, 1), the value of phi at the saddle (the
            arrow reversed). Larger c_w means a stiffer roll about q1.

    The defaults balance the chart Hessian at the default goal: its eigenvalues
    are 0.45 (roll about q1), 2.5 (x2, FOV disc), 16.7 (lambda) and 17.7 (x2,
    occlusion disc), a condition number of 39 instead of 470 with unit gains,
    which is what sets the convergence rate of every descent and servo loop.
    """

    k_lam: float = 4.0
    k_fov: float = 2.0
    k_occ: float = 8.0
    circle_weight: float = 0.9

    def __post_init__(self) -> None:
        for name in ("k_lam", "k_fov", "k_occ"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"navigation gain {name} must be finite and > 0, got {v}")
        c = self.circle_weight
        if not (math.isfinite(c) and 0 < c < 1):
            raise ValueError(f"navigation gain circle_weight must be in (0, 1), got {c}")

    @property
    def params(self) -> tuple[float, float, float, float]:
        """``(k_lam, k_fov, k_occ, circle_weight)``, the kernels' layout."""
        return (self.k_lam, self.k_fov, self.k_occ, self.circle_weight)


class ModelCoordinates(NamedTuple):
    """Psi(y): the point of [-1, 1] x B^2 x B^2 x S^1 (circle as (cos a, sin a))."""

    u: object
    w_fov: object
    w_occ: object
    circle: object


# --------------------------------------------------------------------------
# The source formula (scalar style, any number type; also run on sympy
# symbols by the code generator)
# --------------------------------------------------------------------------
def _rotate_from_e3(a: tuple, v: tuple, sign: int) -> tuple:
    """``R v`` (sign +1) or ``R^T v`` (sign -1), R the minimal rotation taking e3 to
    the unit vector a (a.e3 > -1): ``R = I + K + K^2 / (1 + a.e3)``, ``K = hat(e3 x a)``."""
    kx, ky = -a[1], a[0]  # k = e3 x a; k_z = 0
    vx, vy, vz = v
    kvx, kvy, kvz = ky * vz, -kx * vz, kx * vy - ky * vx
    kkvx, kkvy, kkvz = ky * kvz, -kx * kvz, kx * kvy - ky * kvx
    den = 1 + a[2]
    return (
        vx + sign * kvx + kkvx / den,
        vy + sign * kvy + kkvy / den,
        vz + sign * kvz + kkvz / den,
    )


def model_coordinates_of(y: tuple, domain_params: tuple, xp: Ops) -> tuple:
    """Psi(y) as 7 components ``(u, w_fov, w_occ, cos a, sin a)`` (module docstring).

    ``y`` is the 13 components of an image, ``domain_params`` is
    :attr:`SafeDomain.params`.
    """
    q1, q2, lam, s = y[0:3], y[3:6], y[9], y[10:13]
    lo, hi = domain_params[2], domain_params[3]
    u = (2 * lam - (lo + hi)) / (hi - lo)
    _, sin_fov = fov_cap(lam, domain_params, xp)
    # q1 seen from the minimal rotation taking e3 to s.
    p = _rotate_from_e3(s, q1, -1)
    _, sin2_occ = occlusion_cap(lam, domain_params, xp)
    r_occ = xp.sqrt(sin2_occ)
    # The arrow's angle about q1, from the frame (R_q1 e1, R_q1 e2).
    a1 = _rotate_from_e3(q1, (1, 0, 0), 1)
    a2 = _rotate_from_e3(q1, (0, 1, 0), 1)
    return (
        u,
        s[0] / sin_fov,
        s[1] / sin_fov,
        p[0] / r_occ,
        p[1] / r_occ,
        a1[0] * q2[0] + a1[1] * q2[1] + a1[2] * q2[2],
        a2[0] * q2[0] + a2[1] * q2[1] + a2[2] * q2[2],
    )


def _ball(g: object, r2: object, k: object) -> tuple[object, object]:
    """``(phi_i, 1 - phi_i)`` of the ball's factor ``g / (g + k beta)``, beta = 1 - |w|^2,
    each formed without cancellation: ``1 - phi_i = k beta / (g + k beta)``."""
    kb = k * (1 - r2)
    return g / (g + kb), kb / (g + kb)


def _factors(y: tuple, params: tuple, xp: Ops) -> tuple:
    """``((phi_i, 1 - phi_i) for the lambda, FOV, occlusion and circle factors)``.

    The circle's ``1 - cos(a - a*)`` is ``|c - c*|^2 / 2`` for unit circle points:
    formed that way it keeps its digits near the goal, where ``1 - cos`` loses them.
    """
    k_lam, k_fov, k_occ, c_w = params[5:9]
    u0, wf0x, wf0y, wo0x, wo0y, c0x, c0y = params[9:16]
    u, wfx, wfy, wox, woy, cx, cy = model_coordinates_of(y, params[0:5], xp)
    lam = _ball((u - u0) * (u - u0), u * u, k_lam)
    fov = _ball(
        (wfx - wf0x) * (wfx - wf0x) + (wfy - wf0y) * (wfy - wf0y), wfx * wfx + wfy * wfy, k_fov
    )
    occ = _ball(
        (wox - wo0x) * (wox - wo0x) + (woy - wo0y) * (woy - wo0y), wox * wox + woy * woy, k_occ
    )
    phi_circle = c_w * ((cx - c0x) * (cx - c0x) + (cy - c0y) * (cy - c0y)) / 4
    return lam, fov, occ, (phi_circle, 1 - phi_circle)


def clearance_of(y: tuple, params: tuple, xp: Ops) -> object:
    """``1 - phi(y)`` (module docstring), with ``params`` from :func:`navigation_parameters`:
    the product of the factors' ``1 - phi_i``, accurate near the boundary of D."""
    (_, c1), (_, c2), (_, c3), (_, c4) = _factors(y, params, xp)
    return c1 * c2 * c3 * c4


def phi_of(y: tuple, params: tuple, xp: Ops) -> object:
    """``phi(y)`` itself, accurate near the goal, where ``1 - clearance`` rounds to 0.

    ``1 - c1 c2 c3 c4 = phi_1 + c1 phi_2 + c1 c2 phi_3 + c1 c2 c3 phi_4``
    (telescoping), a sum of non-negative terms.
    """
    (p1, c1), (p2, c2), (p3, c3), (p4, _) = _factors(y, params, xp)
    return p1 + c1 * (p2 + c2 * (p3 + c3 * p4))


# --------------------------------------------------------------------------
# Parameters and the array API
# --------------------------------------------------------------------------
def navigation_parameters(
    goal: ImageFeatures | np.ndarray, domain: SafeDomain, gains: NavigationGains | None = None
) -> tuple:
    """The 16 floats the formulas take: ``domain.params``, ``gains.params`` and Psi(y*)."""
    gains = gains or NavigationGains()
    v = np.asarray(as_features(goal).to_vector(), dtype=float)
    return _parameters(tuple(v.tolist()), domain.params, gains.params)


@functools.lru_cache(maxsize=256)
def _parameters(goal: tuple, domain_params: tuple, gains_params: tuple) -> tuple:
    # The servo loop asks for the same goal at every derivative evaluation.
    return domain_params + gains_params + model_coordinates_of(goal, domain_params, MATH)


_MARGIN_NAMES = ("fov", "lam_min", "lam_max", "occlusion")


def check_in_domain(comps: tuple, domain: SafeDomain) -> None:
    """Raise OutOfDomainError naming the first face of D that the image y crosses.

    phi is defined on D (Definition 1): on its boundary phi = 1, and outside
    it the formula's extension is no navigation function (values below 0 or
    above 1 happen). ``comps`` are y's 13 components, already checked to lie
    in I; symbolic entries with free variables pass unchecked.
    """
    values = to_float(pack(comps))
    if values is None:
        return
    y = components(values, 13, "y")
    xp = namespace(y[9])
    for name, margin in zip(_MARGIN_NAMES, domain_margins(y, domain.params, xp), strict=True):
        bad = np.asarray(margin) < 0
        if np.any(bad):
            value, where = first_bad(margin, bad)
            raise OutOfDomainError(f"y outside D: {name} margin = {value:.6g} < 0{where}")


def _evaluate(y, goal, domain, gains, differential: bool, extend: bool = False, value=False):
    comps = validated_components(y)
    if not extend:
        check_in_domain(comps, domain)
    params = navigation_parameters(goal, domain, gains)
    xp = namespace(comps[9])
    if differential:
        return navigation_kernel(comps, params)
    return phi_of(comps, params, xp) if value else clearance_of(comps, params, xp)


def navigation_value(
    y: ImageFeatures | np.ndarray,
    goal: ImageFeatures | np.ndarray,
    domain: SafeDomain,
    gains: NavigationGains | None = None,
    extend: bool = False,
) -> np.ndarray:
    """phi(y) in [0, 1] (see the module docstring for the construction).

    Raises OutOfDomainError outside D (``y outside D: fov margin = -0.03 < 0``)
    and ValueError outside I; phi = 1 exactly on the boundary of D. With
    ``extend=True`` it returns the formula's smooth extension to I instead (no
    navigation function there: values outside [0, 1] happen), for numerical
    probes that straddle the boundary; the same holds for the differential
    and the clearance.
    """
    return np.asarray(_evaluate(y, goal, domain, gains, False, extend, value=True))


def navigation_differential(
    y: ImageFeatures | np.ndarray,
    goal: ImageFeatures | np.ndarray,
    domain: SafeDomain,
    gains: NavigationGains | None = None,
    extend: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """(phi(y), dphi(y)); dphi has shape (..., 7), its s-part orthogonal to s.

    ``d/dt phi(y(t)) = dphi . (xi, lambda_dot, s_dot)``; dphi is also the
    gradient of phi for the embedded Euclidean metric.
    """
    out = _evaluate(y, goal, domain, gains, True, extend)
    return np.asarray(out[8]), pack(out[1:8])


def navigation_clearance(
    y: ImageFeatures | np.ndarray,
    goal: ImageFeatures | np.ndarray,
    domain: SafeDomain,
    gains: NavigationGains | None = None,
    extend: bool = False,
) -> np.ndarray:
    """1 - phi(y), without the cancellation of forming it from phi near the boundary."""
    return np.asarray(_evaluate(y, goal, domain, gains, False, extend))


def model_coordinates(y: ImageFeatures | np.ndarray, domain: SafeDomain) -> ModelCoordinates:
    """Psi(y), as arrays of y's scalar type."""
    comps = as_features(y).components()
    u, wfx, wfy, wox, woy, cx, cy = model_coordinates_of(comps, domain.params, namespace(comps[9]))
    return ModelCoordinates(np.asarray(u), pack((wfx, wfy)), pack((wox, woy)), pack((cx, cy)))


def features_from_model(m: ModelCoordinates, domain: SafeDomain) -> ImageFeatures:
    """Psi^-1: the image with the given model coordinates (float arrays)."""
    u = np.asarray(m.u, dtype=float)
    wfx, wfy = components(np.asarray(m.w_fov, dtype=float), 2, "w_fov")
    wox, woy = components(np.asarray(m.w_occ, dtype=float), 2, "w_occ")
    cx, cy = components(np.asarray(m.circle, dtype=float), 2, "circle")
    params = domain.params
    lam = 0.5 * (domain.lam_min + domain.lam_max) + 0.5 * u * (domain.lam_max - domain.lam_min)
    _, sin_fov = fov_cap(lam, params, np)
    sx, sy = sin_fov * wfx, sin_fov * wfy
    s = (sx, sy, np.sqrt(1 - sx * sx - sy * sy))
    _, sin2_occ = occlusion_cap(lam, params, np)
    r = np.sqrt(sin2_occ)
    px, py = r * wox, r * woy
    q1 = _rotate_from_e3(s, (px, py, np.sqrt(1 - px * px - py * py)), 1)
    a1 = _rotate_from_e3(q1, (1, 0, 0), 1)
    a2 = _rotate_from_e3(q1, (0, 1, 0), 1)
    q2 = tuple(cx * a1[i] + cy * a2[i] for i in range(3))
    q3 = (
        q1[1] * q2[2] - q1[2] * q2[1],
        q1[2] * q2[0] - q1[0] * q2[2],
        q1[0] * q2[1] - q1[1] * q2[0],
    )
    return ImageFeatures.from_components((*q1, *q2, *q3, lam, *s))


def saddle_of(goal: ImageFeatures | np.ndarray, domain: SafeDomain) -> ImageFeatures:
    """The saddle of phi: the goal image with the arrow turned by pi about q1."""
    m = model_coordinates(goal, domain)
    return features_from_model(m._replace(circle=-np.asarray(m.circle, dtype=float)), domain)


class NavigationFunction:
    """phi on a :class:`SafeDomain` with a goal image that can be changed in place.

    Example::

        nf = NavigationFunction(DEFAULT_DOMAIN, goal=y_star)
        nf.value(y), nf.differential(y)
        nf.goal = other_goal   # no rebuild
    """

    def __init__(
        self,
        domain: SafeDomain,
        goal: ImageFeatures | np.ndarray,
        gains: NavigationGains | None = None,
    ) -> None:
        self.domain = domain
        self.gains = gains or NavigationGains()
        self.goal = goal

    @property
    def goal(self) -> ImageFeatures:
        """y*, the goal image; setting it checks that it is in the interior of D."""
        return self._goal

    @goal.setter
    def goal(self, goal: ImageFeatures | np.ndarray) -> None:
        comps = validated_components(goal)
        margins = domain_margins(comps, self.domain.params, namespace(comps[9]))
        for name, value in zip(("fov", "lam_min", "lam_max", "occlusion"), margins, strict=True):
            v = to_float(value)
            if v is not None and np.any(v <= 0):
                raise ValueError(
                    f"goal not in the interior of D: {name} margin = {float(np.min(v)):.6g} <= 0"
                )
        self._goal = as_features(goal)

    @property
    def params(self) -> tuple:
        """The 16 floats of :func:`navigation_parameters`."""
        return navigation_parameters(self._goal, self.domain, self.gains)

    def value(self, y: ImageFeatures | np.ndarray, extend: bool = False) -> np.ndarray:
        """phi(y); raises outside D unless ``extend`` (see :func:`navigation_value`)."""
        return navigation_value(y, self._goal, self.domain, self.gains, extend)

    def differential(self, y: ImageFeatures | np.ndarray, extend: bool = False) -> np.ndarray:
        """dphi(y), the 7-vector along ``(xi, lambda_dot, s_dot)`` with its s-part orthogonal to s
        (also grad phi in the embedded metric); raises outside D unless ``extend``.
        """
        return navigation_differential(y, self._goal, self.domain, self.gains, extend)[1]

    def value_and_differential(
        self, y: ImageFeatures | np.ndarray, extend: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(phi(y), dphi(y))`` in one evaluation (see :meth:`value`, :meth:`differential`)."""
        return navigation_differential(y, self._goal, self.domain, self.gains, extend)

    def clearance(self, y: ImageFeatures | np.ndarray, extend: bool = False) -> np.ndarray:
        """1 - phi(y), accurate where phi is within rounding of 1."""
        return navigation_clearance(y, self._goal, self.domain, self.gains, extend)

    def saddle(self) -> ImageFeatures:
        """The index-1 saddle of phi: the goal image with the arrow reversed (:func:`saddle_of`)."""
        return saddle_of(self._goal, self.domain)

    def angle_to_saddle(self, y: ImageFeatures | np.ndarray) -> np.ndarray:
        """How far [rad] the arrow's roll about q1 is from the saddle's, in [0, pi].

        The saddle is the goal with the arrow reversed (the circle factor's
        maximum); a roll within a few degrees of it starts near the saddle's
        stable manifold, where the loop slows down or, exactly on it, stops at
        the saddle.
        """
        c = model_coordinates(y, self.domain).circle
        g = model_coordinates(self._goal, self.domain).circle
        cx, cy = np.asarray(c[..., 0], dtype=float), np.asarray(c[..., 1], dtype=float)
        sx, sy = -float(g[0]), -float(g[1])  # the saddle's circle point
        return np.abs(np.arctan2(cx * sy - cy * sx, cx * sx + cy * sy))


def chart_basis(s: np.ndarray) -> np.ndarray:
    """B(s) = [R_s e1, R_s e2], shape (..., 3, 2), for s in the upper hemisphere."""
    k = np.stack([-s[..., 1], s[..., 0], np.zeros_like(s[..., 0])], axis=-1)
    denom = (1 + s[..., 2])[..., None]
    cols = []
    for e in (np.array([1.0, 0, 0]), np.array([0, 1.0, 0])):
        e = np.broadcast_to(e, s.shape)
        ke = np.cross(k, e)
        cols.append(e + ke + np.cross(k, ke) / denom)
    return np.stack(cols, axis=-1)


def image_chart(y: ImageFeatures, d: np.ndarray) -> ImageFeatures:
    """The NF's chart about y: ``d = (dtheta, dlambda, ds)`` (6) to
    ``(exp(hat(dtheta)) Q, lambda + dlambda, (s + B(s) ds) / |s + B(s) ds|)``, the image
    moved within the image space (float and AutoDiffXd entries of d; y float)."""
    B = chart_basis(y.s)
    s = y.s + B @ d[4:6]
    return ImageFeatures(
        so3_exp(d[0:3]) @ y.Q, np.asarray(y.lam + d[3]), s / np.sqrt(np.sum(s * s))
    )
