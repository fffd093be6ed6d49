"""Seeded random samples of poses and images, vectorised over a batch.

These generate test and Monte-Carlo inputs from the geometry's own definitions
(the visible set V of Eq. 5 and the image space I of Eq. 9), not from the
camera map, so the map can be checked against them.
"""

from __future__ import annotations

import numpy as np

from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.navigation import ModelCoordinates, features_from_model

__all__ = [
    "random_features_in_domain",
    "random_features_in_image_space",
    "random_unit_vectors",
    "random_visible_poses",
]


def random_unit_vectors(rng: np.random.Generator, n: int) -> np.ndarray:
    """n unit vectors uniform on the sphere, shape (n, 3)."""
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _random_orthogonal_unit(rng: np.random.Generator, a: np.ndarray) -> np.ndarray:
    """A random unit vector orthogonal to each row of the unit vectors ``a``."""
    v = rng.normal(size=a.shape)
    v -= np.sum(v * a, axis=-1, keepdims=True) * a
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _cap_direction(rng: np.random.Generator, axis: np.ndarray, cos_angle: np.ndarray) -> np.ndarray:
    """Unit vectors at the given cosine to ``axis``, in a random azimuth."""
    m = _random_orthogonal_unit(rng, axis)
    return cos_angle[:, None] * axis + np.sqrt(1 - cos_angle**2)[:, None] * m


def random_visible_poses(
    rng: np.random.Generator,
    n: int,
    radius: float,
    distance_range: tuple[float, float] = (1.001, 1000.0),
    nu_over_radius: tuple[float, float] | None = None,
) -> np.ndarray:
    """Random poses X_CB in the visible set V, shape (n, 4, 4).

    The distance ``|d| / radius`` is log-uniform in ``distance_range``. Visibility
    (Eq. 5) is ``nu = |d| (r3.s) - radius > 0``, i.e. ``r3.s > lambda``. By
    default ``r3.s`` is uniform on ``(lambda, 1)``; with ``nu_over_radius =
    (lo, hi)`` it is chosen so that ``nu / radius`` is log-uniform in
    ``[lo, hi]``, which puts the samples next to the visibility boundary.
    """
    lo, hi = np.log(distance_range[0]), np.log(distance_range[1])
    dist = radius * np.exp(rng.uniform(lo, hi, size=n))
    s = random_unit_vectors(rng, n)
    lam = radius / dist
    if nu_over_radius is None:
        c = rng.uniform(lam, 1.0)
        c = np.where(c <= lam, 0.5 * (lam + 1), c)
    else:
        eps = np.exp(rng.uniform(np.log(nu_over_radius[0]), np.log(nu_over_radius[1]), size=n))
        # r3.s = lambda (1 + eps) must stay below 1: close to the camera the
        # largest possible nu / radius is 1 / lambda - 1.
        eps = np.minimum(eps, 0.5 * (1 / lam - 1))
        c = lam * (1 + eps)
    r3 = _cap_direction(rng, s, c)
    r2 = _random_orthogonal_unit(rng, r3)
    r1 = np.cross(r2, r3)
    X = np.zeros((n, 4, 4))
    X[:, :3, :3] = np.stack([r1, r2, r3], axis=-1)
    X[:, :3, 3] = dist[:, None] * s
    X[:, 3, 3] = 1.0
    return X


def random_features_in_image_space(
    rng: np.random.Generator, n: int, lam_range: tuple[float, float] = (1e-3, 0.999)
) -> np.ndarray:
    """Random images y in I of Eq. (9), as (n, 13) vectors ``[q1, q2, q3, lambda, s]``.

    ``lambda`` is log-uniform in ``lam_range``; ``q1.s`` is uniform on
    ``(sqrt(1 - lambda^2), 1)``; q2 is a random unit vector orthogonal to q1.
    """
    lam = np.exp(rng.uniform(np.log(lam_range[0]), np.log(lam_range[1]), size=n))
    s = random_unit_vectors(rng, n)
    # Uniform in the cap's cosine width, which is 1 - sqrt(1 - lambda^2).
    width = lam**2 / (1 + np.sqrt(1 - lam**2))
    c = 1 - width * rng.uniform(1e-6, 1 - 1e-6, size=n)
    q1 = _cap_direction(rng, s, c)
    q2 = _random_orthogonal_unit(rng, q1)
    q3 = np.cross(q1, q2)
    return np.concatenate([q1, q2, q3, lam[:, None], s], axis=-1)


def random_features_in_domain(
    rng: np.random.Generator, n: int, nf_or_domain: object, shrink: float = 0.98
) -> ImageFeatures:
    """Random images in D, uniform in the model coordinates scaled by ``shrink``."""
    domain = getattr(nf_or_domain, "domain", nf_or_domain)
    u = shrink * rng.uniform(-1, 1, size=n)

    def disc() -> np.ndarray:
        r = shrink * np.sqrt(rng.uniform(0, 1, size=n))
        a = rng.uniform(0, 2 * np.pi, size=n)
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)

    angle = rng.uniform(0, 2 * np.pi, size=n)
    circle = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    return features_from_model(ModelCoordinates(u, disc(), disc(), circle), domain)
