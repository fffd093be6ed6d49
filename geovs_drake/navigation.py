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

It is computed by propagating tangents through the very formula that gives
phi (:mod:`geovs_drake._jet`), for any scalar type.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from geovs_drake import _jet
from geovs_drake._jet import Jet
from geovs_drake._scalar import as_array, sqrt, values_or_none
from geovs_drake.camera import ImageFeatures, as_features, validate_features
from geovs_drake.domain import SafeDomain

__all__ = [
    "ModelCoordinates",
    "NavigationFunction",
    "NavigationGains",
    "features_from_model",
    "model_coordinates",
    "navigation_clearance",
    "navigation_differential",
    "navigation_value",
    "saddle_of",
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


class ModelCoordinates(NamedTuple):
    """Psi(y): the point of [-1, 1] x B^2 x B^2 x S^1 (circle as (cos a, sin a))."""

    u: object
    w_fov: object
    w_occ: object
    circle: object


def _axis_cross(a: Jet) -> Jet:
    """k = e3 x a, the axis of the minimal rotation from e3 to a."""
    return _jet.stack([-a[..., 1], a[..., 0], a[..., 0] * 0.0])


def _minimal_rotation_apply(a: Jet, v: Jet, transpose: bool = False) -> Jet:
    """R v with R the minimal rotation taking e3 to the unit vector a (a.e3 > -1).

    ``R = I + K + K^2 / (1 + a.e3)`` with ``K = hat(e3 x a)``; R^T flips K's sign.
    """
    k = _axis_cross(a)
    kv = _jet.cross(k, v)
    kkv = _jet.cross(k, kv)
    first = v - kv if transpose else v + kv
    return first + kkv / (1 + a[..., 2])[..., None]


def _constant_vector(e: np.ndarray, like: Jet) -> Jet:
    return Jet.constant(np.broadcast_to(e, like.shape), like.n)


def _model_jets(Q: Jet, lam: Jet, s: Jet, domain: SafeDomain) -> ModelCoordinates:
    lo, hi = domain.lam_min, domain.lam_max
    u = (2 * lam - (lo + hi)) / (hi - lo)
    _, sin_fov = domain.fov_cap(lam)
    w_fov = _jet.stack([s[..., 0], s[..., 1]]) / sin_fov[..., None]
    q1, q2 = Q[..., :, 0], Q[..., :, 1]
    p = _minimal_rotation_apply(s, q1, transpose=True)
    _, sin2_occ = domain.occlusion_cap(lam)
    w_occ = _jet.stack([p[..., 0], p[..., 1]]) / sqrt(sin2_occ)[..., None]
    a1 = _minimal_rotation_apply(q1, _constant_vector(np.array([1.0, 0, 0]), q1))
    a2 = _minimal_rotation_apply(q1, _constant_vector(np.array([0, 1.0, 0]), q1))
    circle = _jet.stack([_jet.dot(a1, q2), _jet.dot(a2, q2)])
    return ModelCoordinates(u, w_fov, w_occ, circle)


def _seed(y: ImageFeatures, with_tangents: bool) -> tuple[Jet, Jet, Jet]:
    """Jets for (Q, lambda, s), seeded with the 7 directions of T_y I in R^7.

    Directions 0-2: Qdot = hat(e_k) Q (xi = e_k, Eq. 13); 3: lambda_dot = 1;
    4-6: s_dot = (I - s s^T) e_k. The derivative of a function along direction
    4+k is then the k-th entry of its gradient projected on T_s S^2.
    """
    Q, lam, s = as_array(y.Q), as_array(y.lam), as_array(y.s)
    if not with_tangents:
        return Jet.constant(Q, 0), Jet.constant(lam, 0), Jet.constant(s, 0)
    batch = lam.shape
    nb = len(batch)
    E = np.zeros((3, 3, 3))  # E[k] = hat(e_k)
    E[0, 2, 1], E[0, 1, 2] = 1, -1
    E[1, 0, 2], E[1, 2, 0] = 1, -1
    E[2, 1, 0], E[2, 0, 1] = 1, -1
    dQ = np.zeros((7,) + Q.shape, dtype=Q.dtype)
    dQ[:3] = E.reshape((3,) + (1,) * nb + (3, 3)) @ Q[None]
    dlam = np.zeros((7,) + batch, dtype=lam.dtype)
    dlam[3] = 1.0
    ds = np.zeros((7,) + s.shape, dtype=s.dtype)
    s_k = np.moveaxis(s, -1, 0)[..., None]  # (3, ..., 1)
    ds[4:] = np.eye(3).reshape((3,) + (1,) * nb + (3,)) - s[None] * s_k
    return Jet(Q, dQ), Jet(lam, dlam), Jet(s, ds)


def _ball_factor(w: Jet, w_goal: object, k: float, vector: bool) -> Jet:
    """g / (g + k beta), the navigation function of the unit ball about w_goal."""
    diff = w - w_goal
    if vector:
        g, r2 = _jet.dot(diff, diff), _jet.dot(w, w)
    else:
        g, r2 = diff * diff, w * w
    return g / (g + k * (1 - r2))


def _clearance_jet(
    y: ImageFeatures, goal: ModelCoordinates, domain: SafeDomain, gains: NavigationGains, n: bool
) -> Jet:
    """1 - phi, formed as the product itself so it keeps its digits near the boundary."""
    Q, lam, s = _seed(y, n)
    m = _model_jets(Q, lam, s, domain)
    phi_lam = _ball_factor(m.u, goal.u.v, gains.k_lam, vector=False)
    phi_fov = _ball_factor(m.w_fov, goal.w_fov.v, gains.k_fov, vector=True)
    phi_occ = _ball_factor(m.w_occ, goal.w_occ.v, gains.k_occ, vector=True)
    cos_rel = _jet.dot(m.circle, Jet.constant(goal.circle.v, m.circle.n))
    phi_circle = (0.5 * gains.circle_weight) * (1 - cos_rel)
    return (1 - phi_lam) * (1 - phi_fov) * (1 - phi_occ) * (1 - phi_circle)


def _model_of(y: ImageFeatures, domain: SafeDomain) -> ModelCoordinates:
    """Psi(y) as jets without tangents."""
    return _model_jets(*_seed(y, False), domain)


def model_coordinates(y: ImageFeatures | np.ndarray, domain: SafeDomain) -> ModelCoordinates:
    """Psi(y), as arrays of y's scalar type."""
    return ModelCoordinates(*(x.v for x in _model_of(as_features(y), domain)))


def _goal_coordinates(goal: ImageFeatures, domain: SafeDomain) -> ModelCoordinates:
    v = goal.to_vector()
    if v.dtype != object and v.shape == (13,):
        # The servo loop asks for the same goal at every derivative evaluation.
        return _cached_goal_coordinates(v.tobytes(), domain)
    return _model_of(goal, domain)


@functools.lru_cache(maxsize=64)
def _cached_goal_coordinates(goal_bytes: bytes, domain: SafeDomain) -> ModelCoordinates:
    goal = ImageFeatures.from_vector(np.frombuffer(goal_bytes, dtype=float).copy())
    return _model_of(goal, domain)


def _evaluate(
    y: ImageFeatures | np.ndarray,
    goal: ImageFeatures | np.ndarray,
    domain: SafeDomain,
    gains: NavigationGains | None,
    tangents: bool,
) -> Jet:
    """The clearance 1 - phi at y (validated), with its 7 tangents if asked for."""
    goal_m = _goal_coordinates(as_features(goal), domain)
    return _clearance_jet(
        validate_features(y), goal_m, domain, gains or NavigationGains(), tangents
    )


def navigation_value(
    y: ImageFeatures | np.ndarray,
    goal: ImageFeatures | np.ndarray,
    domain: SafeDomain,
    gains: NavigationGains | None = None,
) -> np.ndarray:
    """phi(y) in [0, 1] (see the module docstring for the construction)."""
    return 1 - _evaluate(y, goal, domain, gains, False).v


def navigation_differential(
    y: ImageFeatures | np.ndarray,
    goal: ImageFeatures | np.ndarray,
    domain: SafeDomain,
    gains: NavigationGains | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(phi(y), dphi(y)); dphi has shape (..., 7), its s-part orthogonal to s.

    ``d/dt phi(y(t)) = dphi . (xi, lambda_dot, s_dot)``; dphi is also the
    gradient of phi for the embedded Euclidean metric.
    """
    clearance = _evaluate(y, goal, domain, gains, True)
    return 1 - clearance.v, -np.moveaxis(clearance.d, 0, -1)


def navigation_clearance(
    y: ImageFeatures | np.ndarray,
    goal: ImageFeatures | np.ndarray,
    domain: SafeDomain,
    gains: NavigationGains | None = None,
) -> np.ndarray:
    """1 - phi(y), without the cancellation of forming it from phi near the boundary."""
    return _evaluate(y, goal, domain, gains, False).v


def features_from_model(m: ModelCoordinates, domain: SafeDomain) -> ImageFeatures:
    """Psi^-1: the image with the given model coordinates (float arrays)."""
    u = np.asarray(m.u, dtype=float)
    w_fov, w_occ, circle = (np.asarray(x, dtype=float) for x in m[1:])
    lam = 0.5 * (domain.lam_min + domain.lam_max) + 0.5 * u * (domain.lam_max - domain.lam_min)
    _, sin_fov = domain.fov_cap(lam)
    s_xy = sin_fov[..., None] * w_fov
    s = np.concatenate([s_xy, np.sqrt(1 - np.sum(s_xy**2, -1))[..., None]], axis=-1)
    _, sin2_occ = domain.occlusion_cap(lam)
    p_xy = np.sqrt(sin2_occ)[..., None] * w_occ
    p = np.concatenate([p_xy, np.sqrt(1 - np.sum(p_xy**2, -1))[..., None]], axis=-1)
    sj, pj = Jet.constant(s, 0), Jet.constant(p, 0)
    q1 = _minimal_rotation_apply(sj, pj).v
    q1j = Jet.constant(q1, 0)
    a1 = _minimal_rotation_apply(q1j, _constant_vector(np.array([1.0, 0, 0]), q1j)).v
    a2 = _minimal_rotation_apply(q1j, _constant_vector(np.array([0, 1.0, 0]), q1j)).v
    q2 = circle[..., 0:1] * a1 + circle[..., 1:2] * a2
    q3 = np.cross(q1, q2)
    return ImageFeatures(np.stack([q1, q2, q3], axis=-1), lam, s)


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
        return self._goal

    @goal.setter
    def goal(self, goal: ImageFeatures | np.ndarray) -> None:
        goal = validate_features(goal)
        margins = self.domain.margins(goal)
        for name, value in zip(margins._fields, margins, strict=True):
            v = values_or_none(value)
            if v is not None and np.any(v <= 0):
                raise ValueError(
                    f"goal not in the interior of D: {name} margin = {float(np.min(v)):.6g} <= 0"
                )
        self._goal = goal

    def value(self, y: ImageFeatures | np.ndarray) -> np.ndarray:
        return navigation_value(y, self._goal, self.domain, self.gains)

    def differential(self, y: ImageFeatures | np.ndarray) -> np.ndarray:
        return navigation_differential(y, self._goal, self.domain, self.gains)[1]

    def value_and_differential(
        self, y: ImageFeatures | np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        return navigation_differential(y, self._goal, self.domain, self.gains)

    def clearance(self, y: ImageFeatures | np.ndarray) -> np.ndarray:
        """1 - phi(y), accurate where phi is within rounding of 1."""
        return navigation_clearance(y, self._goal, self.domain, self.gains)

    def saddle(self) -> ImageFeatures:
        return saddle_of(self._goal, self.domain)
