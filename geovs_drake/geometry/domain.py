"""The safe domain D of Sec. 4.2, with the corrections of docs/paper-notes.md.

D is the set of images y = (Q, lambda, s) with

* field of view: the whole silhouette inside the cone of half-angle theta
  about the optical axis e3. With ``cos(alpha) = s.e3`` and the silhouette's
  angular radius ``gamma = arcsin(lambda)``, this is ``alpha + gamma <= theta``
  (errata, Sec. 4.2: ``f(y) = cos(alpha + gamma) >= cos(theta)``);
* distance: ``lam_min <= lambda <= lam_max``;
* occlusion: the marked point strictly inside the silhouette with a margin
  relative to the visible cap's cosine width (errata, design note)::

      q1.s >= sqrt(1 - lambda^2) + kappa (1 - sqrt(1 - lambda^2)),  0 < kappa < 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from geovs_drake.geometry._ops import NUMPY, Ops, components, namespace, to_float
from geovs_drake.geometry.camera import (
    ImageFeatures,
    as_features,
    limb_margin,
    silhouette_margin,
    validated_components,
)
from geovs_drake.geometry.pinhole import PinholeIntrinsics

__all__ = ["DEFAULT_DOMAIN", "DomainMargins", "SafeDomain", "domain_margins"]


class DomainMargins(NamedTuple):
    """Signed margin of each constraint of D: >= 0 inside, 0 on the face.

    * ``fov = s.e3 - cos(theta - arcsin(lambda))``: the same sign as the
      errata's ``f(y) - cos(theta)`` (cosines of angles in [0, pi/2)), and
      smooth at s = e3, where ``f`` is not.
    * ``lam_min = lambda - lam_min``, ``lam_max = lam_max - lambda``.
    * ``occlusion = q1.s - sqrt(1 - lambda^2) - kappa (1 - sqrt(1 - lambda^2))``.
    """

    fov: np.ndarray
    lam_min: np.ndarray
    lam_max: np.ndarray
    occlusion: np.ndarray

    def minimum(self) -> np.ndarray:
        """The smallest margin (float inputs)."""
        return np.min(np.stack([np.asarray(m, dtype=float) for m in self]), axis=0)


@dataclass(frozen=True)
class SafeDomain:
    """The compact safe domain D inside the image space I.

    Args:
        fov_half_angle: theta, the FOV cone's half-angle [rad], in
            ``(arcsin(lam_max), pi/2)`` so the nearest allowed sphere fits.
        lam_min, lam_max: bounds on ``lambda = rho / |d|``, ``0 < lam_min < lam_max < 1``.
        occlusion_margin: kappa in (0, 1), the fraction of the visible cap's
            cosine width kept between the marked point and the limb.
    """

    fov_half_angle: float = math.radians(35.0)
    lam_min: float = 0.05
    lam_max: float = 0.4
    occlusion_margin: float = 0.1

    def __post_init__(self) -> None:
        th, lo, hi, k = self.fov_half_angle, self.lam_min, self.lam_max, self.occlusion_margin
        for name, value in (
            ("fov_half_angle", th),
            ("lam_min", lo),
            ("lam_max", hi),
            ("occlusion_margin", k),
        ):
            if not math.isfinite(value):
                raise ValueError(f"infeasible domain: {name} = {value} is not finite")
        if not 0 < lo < hi < 1:
            raise ValueError(
                f"infeasible domain: need 0 < lam_min < lam_max < 1, got "
                f"lam_min = {lo}, lam_max = {hi}"
            )
        if not math.asin(hi) < th < math.pi / 2:
            raise ValueError(
                f"infeasible domain: need arcsin(lam_max) < fov_half_angle < pi/2, got "
                f"arcsin({hi}) = {math.asin(hi):.6g} rad ({math.degrees(math.asin(hi)):.4g} deg) "
                f"and fov_half_angle = {th:.6g} rad ({math.degrees(th):.4g} deg)"
            )
        if not 0 < k < 1:
            raise ValueError(f"infeasible domain: need 0 < occlusion_margin < 1, got {k}")

    @classmethod
    def from_intrinsics(
        cls,
        intrinsics: PinholeIntrinsics,
        lam_min: float = 0.05,
        lam_max: float = 0.4,
        occlusion_margin: float = 0.1,
        border_px: float = 0.0,
    ) -> SafeDomain:
        """The domain whose field of view is the camera's inscribed cone.

        theta is :meth:`PinholeIntrinsics.inscribed_half_angle` (``border_px`` in
        from the image's edges). The FOV constraint keeps the silhouette's cone
        (half-angle arcsin(lambda) about s) inside the cone of half-angle theta
        about e3, and that cone lies inside the image rectangle: so at every
        pose of D the whole sphere is in the image.
        """
        theta = intrinsics.inscribed_half_angle(border_px)
        if 0 < lam_max < 1 and not math.asin(lam_max) < theta:  # else SafeDomain says why
            raise ValueError(
                f"infeasible domain: the camera's inscribed cone, {math.degrees(theta):.4g} deg, "
                f"is no wider than the nearest sphere's, arcsin(lam_max = {lam_max}) = "
                f"{math.degrees(math.asin(lam_max)):.4g} deg"
            )
        return cls(theta, lam_min, lam_max, occlusion_margin)

    @property
    def params(self) -> tuple[float, float, float, float, float]:
        """``(cos theta, sin theta, lam_min, lam_max, kappa)``: what the formulas take."""
        th = self.fov_half_angle
        return (math.cos(th), math.sin(th), self.lam_min, self.lam_max, self.occlusion_margin)

    def fov_cap(self, lam: object) -> tuple[object, object]:
        """(cos, sin) of the largest angle ``theta - arcsin(lambda)`` between s and e3."""
        return fov_cap(lam, self.params, namespace(lam))

    def occlusion_cap(self, lam: object) -> tuple[object, object]:
        """(cos, sin^2) of the largest angle between q1 and s (:func:`occlusion_cap`)."""
        return occlusion_cap(lam, self.params, namespace(lam))

    def margins(self, y: ImageFeatures | np.ndarray) -> DomainMargins:
        """Each constraint's signed margin (see :class:`DomainMargins`), y checked to be in I."""
        y = validated_components(y)
        return DomainMargins(
            *(np.asarray(m) for m in domain_margins(y, self.params, namespace(y[9])))
        )

    def contains(self, y: ImageFeatures | np.ndarray) -> np.ndarray:
        """True where y lies in D: in I and every margin >= 0 (float or evaluable inputs)."""
        v = to_float(as_features(y).to_vector())
        if v is None:
            raise ValueError("contains() needs numeric (evaluable) features")
        y = components(v, 13, "y")
        # Beyond the limb (q1.s <= 0) the stable margin formula does not apply.
        inside = np.isfinite(v).all(axis=-1) & (silhouette_margin(y) > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            for m in domain_margins(y, self.params, NUMPY):
                inside &= np.asarray(m) >= 0
        return inside


# Smooth, scalar-generic pieces shared with the navigation function. Each takes
# lambda (any number type) and uses only + - * / sqrt.
def fov_cap(lam: object, params: tuple, xp: Ops) -> tuple[object, object]:
    """(cos, sin) of the largest angle ``theta - arcsin(lambda)`` between s and e3."""
    ct, st = params[0], params[1]
    c_lam = xp.sqrt(1 - lam * lam)
    return ct * c_lam + st * lam, st * c_lam - ct * lam


def occlusion_cap(lam: object, params: tuple, xp: Ops) -> tuple[object, object]:
    """(cos, sin^2) of the largest angle between q1 and s.

    ``1 - cos = (1 - kappa)(1 - sqrt(1 - lambda^2))`` with
    ``1 - sqrt(1 - lambda^2) = lambda^2 / (1 + sqrt(1 - lambda^2))`` formed
    without cancellation.
    """
    lam2 = lam * lam
    one_minus_cos = (1 - params[4]) * lam2 / (1 + xp.sqrt(1 - lam2))
    cos = 1 - one_minus_cos
    return cos, one_minus_cos * (1 + cos)


def domain_margins(y: tuple, params: tuple, xp: Ops) -> tuple:
    """The margins ``(fov, lam_min, lam_max, occlusion)`` of :class:`DomainMargins`.

    ``y`` is the 13 components of an image in I; ``params`` is
    :attr:`SafeDomain.params`.
    """
    lam = y[9]
    cos_fov, _ = fov_cap(lam, params, xp)
    lam2 = lam * lam
    # kappa (1 - sqrt(1 - lambda^2)), with 1 - sqrt(1 - lambda^2) formed as
    # lambda^2 / (1 + sqrt(1 - lambda^2)); limb_margin is cancellation-free too.
    occlusion = limb_margin(y, xp) - params[4] * lam2 / (1 + xp.sqrt(1 - lam2))
    return (y[12] - cos_fov, lam - params[2], params[3] - lam, occlusion)


#: The default scenario's domain: theta = 35 deg, lambda in [0.05, 0.4], kappa = 0.1.
DEFAULT_DOMAIN = SafeDomain()
