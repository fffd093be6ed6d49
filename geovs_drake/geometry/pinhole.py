"""A pinhole camera lifted to the image sphere: intrinsics, pixel <-> ray, inscribed cone.

The paper's camera is spherical: it sees unit rays. A real camera sees pixels
of a finite rectangle. This module is the bridge:

* ``pixel_to_ray`` / ``ray_to_pixel``: the pinhole model, between a pixel
  ``(u, v)`` and the unit ray in the camera frame C;
* ``inscribed_half_angle``: the half-angle of the largest cone about the
  optical axis that lies inside the image rectangle. A safe domain D whose
  field-of-view half-angle is at most that keeps the whole sphere inside the
  image at every pose of D (:meth:`geovs_drake.geometry.domain.SafeDomain.from_intrinsics`).

Conventions, Drake's (``pydrake.systems.sensors.CameraInfo``): pixel column i,
row j has its centre at ``(u, v) = (i, j)``, so the image covers
``u in [-0.5, W - 0.5]``, ``v in [-0.5, H - 0.5]``; the camera frame C has x
right, y down and z along the optical axis (the paper's e3, Drake's
RgbdSensor frame). A ray r = (x, y, z) with z > 0 lands on
``u = cx + fx x / z``, ``v = cy + fy y / z``.

The formulas (``pixel_ray``, ``ray_pixel``) are scalar style, for floats,
float batches, AutoDiffXd and Expression; the methods validate once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from geovs_drake.geometry._ops import Ops, components, namespace, pack, to_float

__all__ = ["PinholeIntrinsics", "pixel_ray", "ray_pixel"]


def pixel_ray(u: object, v: object, K: tuple, xp: Ops) -> tuple:
    """The unit ray ``normalize(((u - cx) / fx, (v - cy) / fy, 1))`` of pixel (u, v).

    ``K = (fx, fy, cx, cy)``.
    """
    fx, fy, cx, cy = K
    x, y = (u - cx) / fx, (v - cy) / fy
    n = xp.sqrt(x * x + y * y + 1)
    return x / n, y / n, 1 / n


def ray_pixel(rx: object, ry: object, rz: object, K: tuple) -> tuple:
    """The pixel ``(cx + fx rx / rz, cy + fy ry / rz)`` where the ray (rz > 0) lands."""
    fx, fy, cx, cy = K
    return cx + fx * rx / rz, cy + fy * ry / rz


def _is_count(n: object) -> bool:
    return isinstance(n, int | np.integer) and not isinstance(n, bool) and n >= 1


@dataclass(frozen=True)
class PinholeIntrinsics:
    """A pinhole camera's intrinsics: image size [px], focal lengths [px], principal point [px].

    Args:
        width, height: the image size, integers >= 1.
        fx, fy: focal lengths, finite and > 0.
        cx, cy: the principal point, strictly inside the image
            (``-0.5 < cx < width - 0.5``, ``-0.5 < cy < height - 0.5``): else
            no cone about the optical axis fits in the image.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if not _is_count(value):
                raise ValueError(f"intrinsics: {name} must be an integer >= 1, got {value!r}")
        for name in ("fx", "fy", "cx", "cy"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float | np.floating):
                raise ValueError(f"intrinsics: {name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"intrinsics: {name} must be finite, got {name} = {value}")
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if not value > 0:
                raise ValueError(f"intrinsics: {name} must be > 0, got {name} = {value}")
        if not -0.5 < self.cx < self.width - 0.5:
            raise ValueError(
                f"intrinsics: the principal point must lie inside the image: need -0.5 < cx < "
                f"{self.width - 0.5}, got cx = {self.cx}"
            )
        if not -0.5 < self.cy < self.height - 0.5:
            raise ValueError(
                f"intrinsics: the principal point must lie inside the image: need -0.5 < cy < "
                f"{self.height - 0.5}, got cy = {self.cy}"
            )

    @classmethod
    def for_fov(
        cls, width: int, height: int, fov_half_angle: float, border_px: float = 0.0
    ) -> PinholeIntrinsics:
        """Square pixels, the principal point at the image centre, and the focal length whose
        inscribed cone (``border_px`` in from the image's edges) has half-angle theta.

        ``fx = fy = (min(width, height) / 2 - border_px) / tan(theta)``.
        """
        if not _is_count(width) or not _is_count(height):
            raise ValueError(f"image size must be integers >= 1, got {width!r} x {height!r}")
        if not (math.isfinite(fov_half_angle) and 0 < fov_half_angle < math.pi / 2):
            raise ValueError(
                f"fov_half_angle must be in (0, pi/2) [rad], got fov_half_angle = {fov_half_angle}"
            )
        reach = min(width, height) / 2 - border_px
        if not (math.isfinite(border_px) and border_px >= 0 and reach > 0):
            raise ValueError(
                f"border_px must be >= 0 and below half the image's smaller side "
                f"({min(width, height) / 2}), got border_px = {border_px}"
            )
        f = reach / math.tan(fov_half_angle)
        return cls(int(width), int(height), f, f, width / 2 - 0.5, height / 2 - 0.5)

    @property
    def K(self) -> tuple[float, float, float, float]:
        """``(fx, fy, cx, cy)``: what the formulas take."""
        return (float(self.fx), float(self.fy), float(self.cx), float(self.cy))

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 intrinsic matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled(self, focal_scale: float) -> PinholeIntrinsics:
        """The same camera with both focal lengths multiplied by ``focal_scale`` (> 0)."""
        if not (math.isfinite(focal_scale) and focal_scale > 0):
            raise ValueError(f"focal_scale must be finite and > 0, got {focal_scale}")
        return PinholeIntrinsics(
            self.width,
            self.height,
            self.fx * focal_scale,
            self.fy * focal_scale,
            self.cx,
            self.cy,
        )

    def inscribed_half_angle(self, border_px: float = 0.0) -> float:
        """theta of the largest cone about the optical axis inside the image [rad].

        The cone of half-angle theta meets the plane z = 1 in the circle of radius
        tan(theta) about the principal point; in normalised coordinates
        ``((u - cx) / fx, (v - cy) / fy)`` the image (less ``border_px`` on each
        side) is a rectangle around it, and the largest such circle reaches its
        nearest edge.
        """
        reach = min(
            (self.cx + 0.5 - border_px) / self.fx,
            (self.width - 0.5 - self.cx - border_px) / self.fx,
            (self.cy + 0.5 - border_px) / self.fy,
            (self.height - 0.5 - self.cy - border_px) / self.fy,
        )
        if not (math.isfinite(border_px) and border_px >= 0 and reach > 0):
            raise ValueError(
                f"border_px = {border_px} leaves no image around the principal point "
                f"({self.cx}, {self.cy})"
            )
        return math.atan(reach)

    def pixel_to_ray(self, uv: object) -> np.ndarray:
        """Unit rays in C of pixels ``uv`` (..., 2), shape (..., 3). Any scalar type."""
        u, v = components(uv, 2, "uv")
        return pack(pixel_ray(u, v, self.K, namespace(u)))

    def ray_to_pixel(self, rays: object) -> np.ndarray:
        """Pixels ``(u, v)`` (..., 2) where rays (..., 3) land. Any scalar type.

        The rays need not be unit; they must point in front of the camera (z > 0).
        A pixel may lie outside the image (see :meth:`contains`).
        """
        rx, ry, rz = components(rays, 3, "rays")
        z = to_float(rz)
        if z is not None and not np.all(z > 0):
            value = float(np.asarray(z).ravel()[np.argmin(np.asarray(z).ravel() > 0)])
            raise ValueError(f"ray not in front of the camera: z = {value:.6g} <= 0")
        return pack(ray_pixel(rx, ry, rz, self.K))

    def contains(self, uv: np.ndarray, border_px: float = 0.0) -> np.ndarray:
        """True where pixels ``uv`` (..., 2) lie in the image, ``border_px`` in from its edges."""
        uv = np.asarray(uv, dtype=float)
        u, v = uv[..., 0], uv[..., 1]
        lo = -0.5 + border_px
        return (
            (u >= lo)
            & (u <= self.width - 0.5 - border_px)
            & (v >= lo)
            & (v <= self.height - 0.5 - border_px)
        )
