"""Numerical evidence for Definition 1: batched gradient descent and a critical-point search.

Everything here is vectorised over a batch of images and calls the same
:mod:`geovs_drake.geometry.navigation` functions as the Drake systems.

Local chart at y = (Q, lambda, s), for delta in R^6::

    y(delta) = (exp(hat(delta[0:3])) Q,  lambda + delta[3],  normalize(s + B delta[4:6]))

with ``B = [R_s e1, R_s e2]`` an orthonormal basis of T_s S^2 (R_s the minimal
rotation taking e3 to s). The chart gradient of phi is
``F = (dphi_xi, dphi_lambda, B^T dphi_s)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.navigation import (  # chart_basis: the earlier name here
    NavigationFunction,
    chart_basis,
)
from geovs_drake.geometry.so3 import so3_exp
from geovs_drake.sampling import random_features_in_domain  # noqa: F401 - the earlier name

__all__ = [
    "CriticalPoint",
    "DescentResult",
    "chart_basis",
    "chart_gradient",
    "chart_hessian",
    "critical_point_search",
    "gradient_descent",
    "retract",
]


def retract(y: ImageFeatures, delta: np.ndarray) -> ImageFeatures:
    """y(delta) in the chart above (float batches)."""
    Q = so3_exp(delta[..., 0:3]) @ y.Q
    lam = y.lam + delta[..., 3]
    s = y.s + np.einsum("...ij,...j->...i", chart_basis(y.s), delta[..., 4:6])
    s = s / np.linalg.norm(s, axis=-1, keepdims=True)
    return ImageFeatures(Q, lam, s)


def chart_gradient(nf: NavigationFunction, y: ImageFeatures) -> tuple[np.ndarray, np.ndarray]:
    """(phi, F) with F = (dphi_xi, dphi_lambda, B^T dphi_s), shape (..., 6).

    The formula's smooth extension is used just outside D: the Hessian's
    difference probes around points in D's boundary layer straddle it.
    """
    phi, dphi = nf.value_and_differential(y, extend=True)
    Bs = np.einsum("...ij,...i->...j", chart_basis(y.s), dphi[..., 4:7])
    return phi, np.concatenate([dphi[..., 0:4], Bs], axis=-1)


def chart_hessian(nf: NavigationFunction, y: ImageFeatures, h: float = 1e-6) -> np.ndarray:
    """Central differences of the chart gradient, symmetrised, shape (..., 6, 6).

    At a critical point this is the (chart-independent) Hessian of phi.
    """
    batch = np.shape(y.lam)
    cols = []
    for j in range(6):
        e = np.zeros(batch + (6,))
        e[..., j] = h
        Fp = chart_gradient(nf, retract(y, e))[1]
        Fm = chart_gradient(nf, retract(y, -e))[1]
        cols.append((Fp - Fm) / (2 * h))
    H = np.stack(cols, axis=-1)
    return 0.5 * (H + np.swapaxes(H, -1, -2))


@dataclass
class DescentResult:
    """The end of :func:`gradient_descent` from a batch of starts.

    Attributes:
        y: the final images.
        phi: phi at the final images.
        grad_norm: ``|dphi|`` there.
        iterations: the iterations run.
        phi_monotone: phi never rose along any path.
        rejected_outside: candidate steps rejected because they left D.
    """

    y: ImageFeatures
    phi: np.ndarray
    grad_norm: np.ndarray
    iterations: int
    phi_monotone: bool
    rejected_outside: int


def _take(y: ImageFeatures, mask: np.ndarray) -> ImageFeatures:
    return ImageFeatures(y.Q[mask], y.lam[mask], y.s[mask])


def _put(y: ImageFeatures, mask: np.ndarray, new: ImageFeatures) -> None:
    y.Q[mask], y.lam[mask], y.s[mask] = new.Q, new.lam, new.s


def gradient_descent(
    nf: NavigationFunction,
    y0: ImageFeatures,
    max_iterations: int = 3000,
    grad_tol: float = 1e-7,
    step0: float = 0.02,
) -> DescentResult:
    """Steepest descent ``y <- R_y(-h grad phi)`` in the embedded metric, batched.

    Armijo backtracking per sample, with retraction ``Q <- exp(-h hat(dphi_xi)) Q``,
    ``lambda <- lambda - h dphi_lambda``, ``s <- normalize(s - h dphi_s)``. A
    candidate outside D is rejected like one that does not decrease phi, so
    the iterates stay in D by construction; ``rejected_outside`` counts such
    rejections (a diagnostic, not a failure). Iteration stops once every
    ``|grad phi| <= grad_tol``; 1e-7 is where phi ~ 1e-15 reaches rounding and
    Armijo can no longer tell a decrease.
    """
    y = ImageFeatures(y0.Q.copy(), np.array(y0.lam, dtype=float), y0.s.copy())
    phi, dphi = nf.value_and_differential(y)
    h = np.full(phi.shape, step0)
    monotone = True
    rejected_outside = 0
    iterations = 0
    while iterations < max_iterations:
        g2 = np.sum(dphi**2, axis=-1)
        active = np.sqrt(g2) > grad_tol
        if not np.any(active):
            break
        iterations += 1
        idx = np.flatnonzero(active)
        ya = _take(y, idx)
        step = -h[idx, None] * dphi[idx]
        cand = ImageFeatures(
            so3_exp(step[:, 0:3]) @ ya.Q,
            ya.lam + step[:, 3],
            (ya.s + step[:, 4:7]) / np.linalg.norm(ya.s + step[:, 4:7], axis=-1, keepdims=True),
        )
        inside = _in_domain(nf, cand)
        rejected_outside += int(np.sum(~inside))
        phi_c = np.full(len(idx), np.inf)
        dphi_c = np.zeros((len(idx), 7))
        if np.any(inside):
            pc, dc = nf.value_and_differential(_take(cand, inside))
            phi_c[inside], dphi_c[inside] = pc, dc
        accept = phi_c <= phi[idx] - 0.25 * h[idx] * g2[idx]
        acc = idx[accept]
        if np.any(phi_c[accept] > phi[acc]):
            monotone = False
        _put(y, acc, _take(cand, accept))
        phi[acc], dphi[acc] = phi_c[accept], dphi_c[accept]
        h[acc] = np.minimum(h[acc] * 1.5, 1.0)
        h[idx[~accept]] *= 0.5
    return DescentResult(
        y=y,
        phi=phi,
        grad_norm=np.linalg.norm(dphi, axis=-1),
        iterations=iterations,
        phi_monotone=monotone,
        rejected_outside=rejected_outside,
    )


def _in_domain(nf: NavigationFunction, y: ImageFeatures) -> np.ndarray:
    lam_ok = (y.lam > 0) & (y.lam < 1)
    ok = np.zeros(len(y.lam), dtype=bool)
    if np.any(lam_ok):
        ok[lam_ok] = nf.domain.contains(_take(y, lam_ok))
    return ok


#: Below this clearance 1 - phi a point is on the boundary of D as far as doubles
#: can tell: |F| underflows to 0 there, and a zero residual certifies nothing.
_RESOLVABLE_CLEARANCE = 1e-100


def _relative_residual(nf: NavigationFunction, y: ImageFeatures, F: np.ndarray) -> np.ndarray:
    clearance = np.asarray(nf.clearance(y, extend=True), dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.linalg.norm(F, axis=-1) / clearance
    return np.where(clearance > _RESOLVABLE_CLEARANCE, r, np.inf)


@dataclass
class CriticalPoint:
    """A critical point of phi found by :func:`critical_point_search`.

    Attributes:
        y: the image.
        phi: phi there.
        hessian_eigenvalues: the eigenvalues of the chart Hessian there.
    """

    y: ImageFeatures
    phi: float
    hessian_eigenvalues: np.ndarray

    @property
    def signature(self) -> tuple[int, int, int]:
        """(positive, negative, zero) eigenvalue counts of the chart Hessian."""
        ev = self.hessian_eigenvalues
        tol = 1e-6 * np.max(np.abs(ev))
        return (int(np.sum(ev > tol)), int(np.sum(ev < -tol)), int(np.sum(np.abs(ev) <= tol)))


@dataclass
class CriticalPointSearch:
    points: list[CriticalPoint]
    starts: int
    converged: int
    stalled: int
    left_domain: int


def critical_point_search(
    nf: NavigationFunction,
    starts: ImageFeatures,
    iterations: int = 60,
    tol: float = 1e-10,
    trust_radius: float = 0.05,
) -> CriticalPointSearch:
    """Find zeros of dphi from many starts with damped Newton steps in the chart.

    Convergence is judged on ``|F| / (1 - phi)``, the gradient of
    ``-log(1 - phi)``, which has the same critical points inside D. The plain
    ``|F|`` underflows in the boundary layer where 1 - phi < 1e-16 (near
    corners of D), and would report flat-looking points there that are not
    critical.

    Each step solves ``(H^2 + mu I) delta = -H F`` (Levenberg-Marquardt on
    ``F = 0``, which accepts saddles as readily as minima), clipped to
    ``trust_radius``. Converged points are merged when closer than 1e-6 and
    classified by their Hessian's signature.
    """
    y = ImageFeatures(starts.Q.copy(), np.array(starts.lam, dtype=float), starts.s.copy())
    n = len(y.lam)
    alive = np.ones(n, dtype=bool)
    done = np.zeros(n, dtype=bool)
    for _ in range(iterations):
        idx = np.flatnonzero(alive & ~done)
        if len(idx) == 0:
            break
        ya = _take(y, idx)
        _, F = chart_gradient(nf, ya)
        conv = _relative_residual(nf, ya, F) < tol
        done[idx[conv]] = True
        idx, ya, F = idx[~conv], _take(ya, ~conv), F[~conv]
        if len(idx) == 0:
            break
        H = chart_hessian(nf, ya)
        mu = 1e-8 * np.max(np.abs(H), axis=(-2, -1))[:, None, None]
        rhs = np.einsum("nij,nj->ni", H, F)[..., None]
        delta = -np.linalg.solve(H @ H + mu * np.eye(6), rhs)[..., 0]
        norm = np.linalg.norm(delta, axis=-1, keepdims=True)
        delta *= np.minimum(1.0, trust_radius / np.maximum(norm, 1e-300))
        cand = retract(ya, delta)
        inside = _in_domain(nf, cand)
        _put(y, idx[inside], _take(cand, inside))
        alive[idx[~inside]] = False
    y_alive = _take(y, alive)
    _, F = chart_gradient(nf, y_alive)
    ok = np.flatnonzero(alive)[_relative_residual(nf, y_alive, F) < tol]
    points: list[CriticalPoint] = []
    vecs: list[np.ndarray] = []
    for i in ok:
        yi = _take(y, np.array([i]))
        v = yi.to_vector()[0]
        if any(np.max(np.abs(v - w)) < 1e-6 for w in vecs):
            continue
        vecs.append(v)
        H = chart_hessian(nf, yi)[0]
        points.append(
            CriticalPoint(
                y=yi[0], phi=float(nf.value(yi)[0]), hessian_eigenvalues=np.linalg.eigvalsh(H)
            )
        )
    return CriticalPointSearch(
        points=sorted(points, key=lambda p: p.phi),
        starts=n,
        converged=len(ok),
        stalled=int(np.sum(alive)) - len(ok),
        left_domain=int(np.sum(~alive)),
    )
