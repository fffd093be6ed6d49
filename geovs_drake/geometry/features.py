"""Image features y = (Q, lambda, s) from what a camera measures: rays to the sphere's
silhouette, to the marked point b and to a second mark along the arrow.

A real camera does not output c(H); it sees the target. The target carries two
marks (:class:`TargetMarks`): a disc centred on the marked point b, and a
second disc at the angle delta from b, at the sphere's centre, in the direction
of the arrow a = e2, i.e. at ``m_B = rho (0, sin delta, -cos delta)``. From the
unit rays (in C) to those points and to the silhouette's edge:

* **s and lambda**: the silhouette of a sphere is a circular cone of rays about
  s with half-angle gamma, ``sin gamma = lambda`` (Eq. 3): on the image
  sphere, the small circle ``s.r = cos gamma``, i.e. the plane ``n.r = 1`` with
  ``n = s / cos gamma``. :func:`silhouette_cone` fits n to the edge rays by
  linear least squares (3 unknowns; an ellipse fit in the image has 5 and does
  not know the cone is circular).
* **q1** is the ray to b itself (Eq. 6: ``q1 = b / |b|``).
* **q2**: where the rays to b and to m meet the sphere, its normals are
  ``(d - b) / rho = r3`` and ``(d - m) / rho = cos(delta) r3 - sin(delta) r2``
  (:func:`~geovs_drake.geometry.camera.inward_normal`, Eqs. 21 and 23), so
  ``r2 = (cos(delta) r3 - n_m) / sin(delta)``; then y is
  :func:`~geovs_drake.geometry.camera.image_of_pose` of (r2, r3, d = s / lambda)
  for a unit sphere, which returns q1 unchanged (b = d - r3 lies on the ray q1)
  and q2 as r2 projected on T_q1 S^2 (Eq. 7). None of this needs rho: the
  image fixes the scene's shape, not its scale.

The same functions serve the rendered-image extractor
(:class:`~geovs_drake.systems.FeatureExtractor`, which finds the rays in
pixels) and the synthetic pinhole sensor (:func:`pinhole_measurement`, which
projects the exact points), so the two differ only in how the pixels are
found. Float only: these are measurements, not formulas to differentiate.
A measurement that cannot give a trustworthy y returns a failure code
(:data:`FEATURE_FAILURES`), never a y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from geovs_drake.geometry._ops import MATH, NUMPY
from geovs_drake.geometry.camera import image_of_pose, image_violation, inward_normal, ray_terms
from geovs_drake.geometry.pinhole import PinholeIntrinsics, pixel_ray, ray_pixel
from geovs_drake.geometry.rigid import cross

__all__ = [
    "FEATURE_FAILURES",
    "FEATURE_OK",
    "TargetMarks",
    "features_from_rays",
    "limb_points",
    "pinhole_measurement",
    "silhouette_cone",
]

#: Why a measurement gave no y, by code (0: it did). A status, never a garbage y.
FEATURE_FAILURES = (
    "ok",
    "sphere not found",
    "sphere cut by the image border",
    "marked point not found (hidden behind the limb or too small)",
    "arrow mark not found (hidden behind the limb or too small)",
    "marked point outside the silhouette",
    "arrow mark outside the silhouette",
    "arrow mark inconsistent with the sphere",
    "measured y not in I",
)
FEATURE_OK = 0
_SPHERE_NOT_FOUND, _CUT, _NO_MARK, _NO_ARROW, _MARK_OUT, _ARROW_OUT, _INCONSISTENT, _NOT_IN_I = (
    range(1, 9)
)

#: The least number of silhouette rays for a fit (3 unknowns; a few more for a check).
MIN_SILHOUETTE_RAYS = 8


@dataclass(frozen=True)
class TargetMarks:
    """The marks on the target sphere, scale-free (fractions of rho, angles).

    Args:
        mark_radius: the disc centred on b, its radius / rho.
        arrow_angle: delta [rad], the angle at the sphere's centre from b to the
            arrow mark, towards a_B = e2. Larger separates the marks more in the
            image (a better q2) but hides the arrow mark sooner behind the limb.
        arrow_mark_radius: the arrow mark's radius / rho.

    The defaults keep both discs wholly on the visible cap everywhere in the
    default domain D: there the marked point is at least 0.294 rad (at the
    sphere's centre) from the limb (at lambda = lam_max = 0.4; kappa = 0.1), and
    the arrow mark reaches ``arrow_angle + arrow_mark_radius = 0.27`` rad from it.
    """

    mark_radius: float = 0.1
    arrow_angle: float = 0.2
    arrow_mark_radius: float = 0.07

    def __post_init__(self) -> None:
        for name in ("mark_radius", "arrow_angle", "arrow_mark_radius"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"marks: {name} must be finite and > 0, got {name} = {value}")
        gap = self.arrow_angle - self.mark_radius - self.arrow_mark_radius
        if not (self.arrow_angle < math.pi / 2 and gap > 0):
            raise ValueError(
                "marks: need the two discs apart and arrow_angle < pi/2: arrow_angle = "
                f"{self.arrow_angle} rad, radii {self.mark_radius} + {self.arrow_mark_radius} rho"
            )

    def points_B(self, rho: float) -> tuple[np.ndarray, np.ndarray]:
        """``(b_B, m_B)``: the centres of the two marks in the target frame B."""
        d = self.arrow_angle
        return np.array([0.0, 0.0, -rho]), rho * np.array([0.0, math.sin(d), -math.cos(d)])


def limb_points(d: np.ndarray, rho: float, n: int) -> np.ndarray:
    """n points (n, 3) evenly around the limb: where the rays from Co touch the sphere.

    The rays tangent to the sphere of centre d touch it on the circle of centre
    ``(1 - lambda^2) d`` and radius ``rho sqrt(1 - lambda^2)`` in the plane
    normal to d (``lambda = rho / |d|``).
    """
    d = np.asarray(d, dtype=float)
    dist = float(np.linalg.norm(d))
    if not rho < dist:
        raise ValueError(f"the camera is inside the sphere: |d| = {dist:.6g} <= rho = {rho}")
    s = d / dist
    lam = rho / dist
    a = (1.0, 0.0, 0.0) if abs(s[0]) < 0.9 else (0.0, 1.0, 0.0)
    # rigid.cross on floats: np.cross's products and differences, without its
    # array machinery (about 25 us a call, twice a frame).
    e1 = np.array(cross(tuple(s.tolist()), a))
    e1 /= np.linalg.norm(e1)
    e2 = np.array(cross(tuple(s.tolist()), tuple(e1.tolist())))
    t = 2 * np.pi * np.arange(n) / n
    radius = rho * math.sqrt(1 - lam * lam)
    return (1 - lam * lam) * d + radius * (np.outer(np.cos(t), e1) + np.outer(np.sin(t), e2))


def silhouette_cone(rays: np.ndarray) -> tuple[np.ndarray, float] | None:
    """``(s, lambda)`` of the circular cone through unit rays (N, 3), or None.

    The least-squares plane ``n.r = 1`` (normal equations, 3x3), then
    ``s = n / |n|`` and ``cos gamma = 1 / |n|``, ``lambda = sin gamma =
    sqrt(|n|^2 - 1) / |n|``. Residual ``n.r - 1 = (cos angle(r, s) - cos gamma)
    / cos gamma``: every point's angular error weighted alike, so the algebraic
    fit is the geometric one to first order. None if fewer than
    :data:`MIN_SILHOUETTE_RAYS` rays or the fit is not a cone in front of C.
    """
    rays = np.asarray(rays, dtype=float)
    if rays.ndim != 2 or rays.shape[1] != 3 or len(rays) < MIN_SILHOUETTE_RAYS:
        return None
    A = rays.T @ rays
    try:
        n = np.linalg.solve(A, rays.sum(axis=0))
    except np.linalg.LinAlgError:
        return None
    n2 = float(n @ n)
    if not (math.isfinite(n2) and n2 > 1 and n[2] > 0):
        return None
    norm = math.sqrt(n2)
    return n / norm, math.sqrt(n2 - 1) / norm


def features_from_rays(
    s: np.ndarray, lam: float, q1: np.ndarray, w: np.ndarray, arrow_angle: float
) -> tuple[tuple | None, int]:
    """``(y, 0)`` from the silhouette's cone (s, lambda) and the unit rays q1 to b and w to the
    arrow mark, or ``(None, code)`` (:data:`FEATURE_FAILURES`).

    See the module docstring for the geometry. Checks: both rays meet the sphere,
    the normals there are ``arrow_angle`` apart to within half of it (a mark
    half hidden by the limb or a wrong blob breaks that), and y lies in I (Eq. 9).
    """
    s, q1, w = (tuple(float(c) for c in v) for v in (s, q1, w))
    lam = float(lam)
    for ray, code in ((q1, _MARK_OUT), (w, _ARROW_OUT)):
        cos_phi, sin2 = ray_terms(ray, s)
        if not (cos_phi > 0 and sin2 < lam * lam):
            return None, code
    r3 = inward_normal(q1, lam, s, MATH)
    n_m = inward_normal(w, lam, s, MATH)
    cos_between = sum(a * b for a, b in zip(r3, n_m, strict=True))
    between = math.acos(max(-1.0, min(1.0, cos_between)))
    if abs(between - arrow_angle) > 0.5 * arrow_angle:
        return None, _INCONSISTENT
    c, sn = math.cos(arrow_angle), math.sin(arrow_angle)
    r2 = tuple((c * a - b) / sn for a, b in zip(r3, n_m, strict=True))
    # r2 _|_ r3 exactly for exact rays; remove the part noise adds.
    k = sum(a * b for a, b in zip(r2, r3, strict=True))
    r2 = tuple(a - k * b for a, b in zip(r2, r3, strict=True))
    d = tuple(c_ / lam for c_ in s)
    y = image_of_pose(r2, r3, d, 1.0, MATH)
    if image_violation(y) is not None:
        return None, _NOT_IN_I
    return y, FEATURE_OK


def _visible(p: np.ndarray, d: np.ndarray) -> bool:
    """A point p on the sphere (centre d) faces the camera at Co: (p - d).(0 - p) > 0."""
    return float((p - d) @ (-p)) > 0


def pinhole_measurement(
    X_CB: np.ndarray,
    rho: float,
    marks: TargetMarks,
    camera: PinholeIntrinsics,
    believed: PinholeIntrinsics,
    noise: np.random.Generator | None = None,
    pixel_noise: float = 0.0,
) -> tuple[tuple | None, int]:
    """What the feature extractor would measure at pose X_CB (4x4), without rendering.

    The exact image points: the limb (one point per pixel of its perimeter in
    the image, at least 16), b and the arrow mark, projected by ``camera``;
    a sphere not wholly inside the image, or a mark facing away, is a failure,
    as in the rendered image. Each point gets independent Gaussian noise of
    ``pixel_noise`` px per axis (``noise`` draws it), and the pixels are lifted
    to rays by the ``believed`` intrinsics (a focal-length error enters here),
    then :func:`silhouette_cone` and :func:`features_from_rays`. Returns
    ``(y, 0)`` or ``(None, code)``.
    """
    X = np.asarray(X_CB, dtype=float)
    R, d = X[:3, :3], X[:3, 3]
    dist = float(np.linalg.norm(d))
    if not (rho < dist and d[2] > 0):
        return None, _SPHERE_NOT_FOUND
    b_B, m_B = marks.points_B(rho)
    b, m = d + R @ b_B, d + R @ m_B
    gamma = math.asin(rho / dist)
    perimeter = 2 * math.pi * 0.5 * (camera.fx + camera.fy) * math.tan(gamma)
    limb = limb_points(d, rho, max(16, math.ceil(perimeter)))
    if np.any(limb[:, 2] <= 0):
        return None, _CUT
    # The formulas on the columns (ray_to_pixel's, without its checks: z > 0 above).
    uv = np.stack(ray_pixel(limb[:, 0], limb[:, 1], limb[:, 2], camera.K), axis=-1)
    if not np.all(camera.contains(uv, border_px=0.5)):  # a pixel of background around it
        return None, _CUT
    if not _visible(b, d):
        return None, _NO_MARK
    if not _visible(m, d):
        return None, _NO_ARROW
    marks_uv = (
        [ray_pixel(*b.tolist(), camera.K), ray_pixel(*m.tolist(), camera.K)]
        if b[2] > 0 and m[2] > 0
        else camera.ray_to_pixel(np.stack([b, m]))  # says which is behind the camera
    )
    points = np.vstack([uv, marks_uv])
    if pixel_noise > 0:
        if noise is None:
            raise ValueError("pixel_noise > 0 needs a noise generator")
        points = points + noise.normal(0.0, pixel_noise, size=points.shape)
    rays = np.stack(pixel_ray(points[:, 0], points[:, 1], believed.K, NUMPY), axis=-1)
    cone = silhouette_cone(rays[:-2])
    if cone is None:
        return None, _SPHERE_NOT_FOUND
    return features_from_rays(cone[0], cone[1], rays[-2], rays[-1], marks.arrow_angle)
