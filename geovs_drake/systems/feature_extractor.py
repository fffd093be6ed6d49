"""FeatureExtractor: the image features y = (Q, lambda, s) from a rendered colour image.

The image processing is OpenCV's (``opencv-python-headless``, the ``vision``
extra): colour arithmetic with saturation, the bounding box of a mask,
connected components with their areas and centroids, and image moments, each a
single C++ call (all of :func:`find_target_pixels`, numpy's sub-pixel edge
included, takes about 0.8 ms a 320x240 frame, ``benchmarks/bench_rendered.py``).
Why OpenCV rather than
scikit-image: one wheel whose only dependency is numpy (scikit-image pulls in
scipy, networkx, imageio, tifffile and more), and these calls are several
times faster. What no image library offers is the geometry after it, which
lives in :mod:`geovs_drake.geometry.features`: the silhouette's edge lifted to
rays and fitted as a small circle on the image sphere (a 3-unknown linear
least-squares problem: an ellipse fit in the image has 5 unknowns and does not
know that a sphere's image is a circular cone), and the two marks lifted to
rays and intersected with that sphere.

The scene's colours (:data:`SCENE_COLOURS`, which
:func:`~geovs_drake.visualization.add_marked_target_geometry` draws): a blue
background, a grey sphere, a red disc on the marked point b and a green disc
on the arrow mark. Classification is by the dominant channel, so it does not
depend on the shading:

* foreground coverage ``f = 1 - (B - max(R, G)) / 255``, clipped to [0, 1]:
  exactly the covered fraction of an anti-aliased pixel that mixes grey (or a
  mark's colour) with the blue background;
* the silhouette's edge: where f crosses 1/2 between two neighbouring pixels
  (along rows and along columns), placed by linear interpolation: sub-pixel
  points, the vertices of marching squares at level 1/2;
* a mark: the largest 8-connected blob whose dominant channel (red, green) is
  more than twice the others; its centroid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.sensors import ImageRgba8U

from geovs_drake._optional import require
from geovs_drake.geometry.features import (
    FEATURE_OK,
    MIN_SILHOUETTE_RAYS,
    TargetMarks,
    features_from_rays,
    silhouette_cone,
)
from geovs_drake.geometry.pinhole import PinholeIntrinsics
from geovs_drake.systems._held_frames import declare_sampled_features, frame_index
from geovs_drake.systems._template import template_system

#: OpenCV (the ``vision`` extra), imported on first use by :func:`_require_cv2`, so that
#: the rest of the package works without it.
cv2 = None

__all__ = [
    "MIN_MARK_AREA_PX",
    "SCENE_COLOURS",
    "FeatureExtractor",
    "FeatureExtractor_",
    "TargetPixels",
    "extract_features",
    "find_target_pixels",
]

#: RGB in [0, 1] of the rendered scene: the extractor's classification assumes them.
SCENE_COLOURS = {
    "background": (0.0, 0.0, 1.0),
    "sphere": (0.8, 0.8, 0.8),
    "marked_point": (1.0, 0.0, 0.0),
    "arrow_mark": (0.0, 0.85, 0.0),
}
#: A mark's blob needs at least this many pixels (a disc of radius 1 px has 3).
MIN_MARK_AREA_PX = 3
#: Channels darker than this are not classified as a mark (8-bit).
_MIN_MARK_LEVEL = 24


def _require_cv2() -> None:
    """Import OpenCV, or raise MissingExtra naming ``pip install "geovs-drake[vision]"``."""
    global cv2
    if cv2 is None:
        cv2 = require("cv2", "vision", "the rendered camera", package="opencv-python-headless")


@dataclass(frozen=True)
class TargetPixels:
    """What :func:`find_target_pixels` found: sub-pixel ``(u, v)`` positions."""

    edge: np.ndarray  # (N, 2): the silhouette's edge points
    mark: np.ndarray  # (2,): the marked point's centroid
    arrow: np.ndarray  # (2,): the arrow mark's centroid
    mark_area: int
    arrow_area: int


def _edge_points(f: np.ndarray) -> np.ndarray:
    """Where the coverage f crosses 1/2 between neighbours, as (u, v) (N, 2)."""
    inside = f > 0.5
    points = []
    for axis in (1, 0):  # along rows (u varies), then along columns (v varies)
        a = f[:, :-1] if axis == 1 else f[:-1, :]
        b = f[:, 1:] if axis == 1 else f[1:, :]
        ia = inside[:, :-1] if axis == 1 else inside[:-1, :]
        ib = inside[:, 1:] if axis == 1 else inside[1:, :]
        rows, cols = np.nonzero(ia != ib)
        fa, fb = a[rows, cols], b[rows, cols]
        t = (0.5 - fa) / (fb - fa)
        if axis == 1:
            points.append(np.column_stack([cols + t, rows]))
        else:
            points.append(np.column_stack([cols, rows + t]))
    return np.vstack(points)


def _largest_blob(mask: np.ndarray, weight: np.ndarray) -> tuple[np.ndarray, int] | None:
    """The centroid (u, v) and area of the largest 8-connected blob of ``mask``.

    The centroid is weighted by ``weight`` (how much the mark's channel dominates,
    proportional to the covered fraction of an anti-aliased pixel) over the blob's
    box grown by a pixel: sub-pixel, where the binary blob's centroid moves in
    whole-pixel steps.
    """
    count, _, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if count < 2:
        return None
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    x, y, w, h = (int(v) for v in stats[k, :4])
    x0, y0 = max(0, x - 1), max(0, y - 1)
    m = cv2.moments(weight[y0 : y + h + 1, x0 : x + w + 1])
    if not m["m00"] > 0:
        return centroids[k], int(stats[k, cv2.CC_STAT_AREA])
    return np.array([x0 + m["m10"] / m["m00"], y0 + m["m01"] / m["m00"]]), int(
        stats[k, cv2.CC_STAT_AREA]
    )


def find_target_pixels(rgba: np.ndarray) -> TargetPixels | int:
    """The silhouette's edge and the marks' centroids in an (H, W, 3 or 4) uint8 image.

    Returns :class:`TargetPixels`, or a failure code of
    :data:`~geovs_drake.geometry.features.FEATURE_FAILURES`: no sphere, the
    sphere touching the image's border (its edge would be cut), a mark missing
    or smaller than :data:`MIN_MARK_AREA_PX`.
    """
    _require_cv2()
    img = np.ascontiguousarray(rgba[..., :3])
    height, width = img.shape[:2]
    r, g, b = cv2.split(img)
    # Saturating uint8 arithmetic: B - max(R, G), 0 wherever a mark or the sphere is.
    background = cv2.subtract(b, cv2.max(r, g))
    x, y, w, h = cv2.boundingRect(cv2.compare(background, 128, cv2.CMP_LT))
    if w == 0 or h == 0:
        return 1  # sphere not found
    if x == 0 or y == 0 or x + w == width or y + h == height:
        return 2  # sphere cut by the image border
    # Work on the silhouette's box and one pixel of background around it.
    x0, y0, x1, y1 = x - 1, y - 1, x + w + 1, y + h + 1
    f = 1.0 - background[y0:y1, x0:x1].astype(np.float32) / 255.0
    edge = _edge_points(f).astype(float) + [x0, y0]
    if len(edge) < MIN_SILHOUETTE_RAYS:
        return 1
    rc, gc, bc = (c[y0:y1, x0:x1].astype(np.int16) for c in (r, g, b))
    found = []
    for main, others in ((rc, (gc, bc)), (gc, (rc, bc))):
        rest = np.maximum(*others)
        mask = (main > 2 * rest) & (main >= _MIN_MARK_LEVEL)
        weight = np.maximum(main - rest, 0).astype(np.float32)
        found.append(_largest_blob(mask.astype(np.uint8), weight))
    (mark, arrow), codes = found, (3, 4)
    for blob, code in zip(found, codes, strict=True):
        if blob is None or blob[1] < MIN_MARK_AREA_PX:
            return code
    return TargetPixels(
        edge=edge,
        mark=mark[0] + [x0, y0],
        arrow=arrow[0] + [x0, y0],
        mark_area=mark[1],
        arrow_area=arrow[1],
    )


def extract_features(
    rgba: np.ndarray,
    intrinsics: PinholeIntrinsics,
    arrow_angle: float,
    noise: np.random.Generator | None = None,
    pixel_noise: float = 0.0,
) -> tuple[tuple | None, int]:
    """``(y, 0)`` from a colour image, or ``(None, code)``; ``arrow_angle`` is the marks' delta
    (:class:`~geovs_drake.geometry.features.TargetMarks`).

    The pixels of :func:`find_target_pixels`, each point (edge and centroids)
    with independent Gaussian noise of ``pixel_noise`` px per axis if asked,
    lifted to rays by ``intrinsics`` (what the extractor believes), then
    :func:`~geovs_drake.geometry.features.silhouette_cone` and
    :func:`~geovs_drake.geometry.features.features_from_rays`.
    """
    found = find_target_pixels(rgba)
    if not isinstance(found, TargetPixels):
        return None, found
    points = np.vstack([found.edge, found.mark, found.arrow])
    if pixel_noise > 0:
        if noise is None:
            raise ValueError("pixel_noise > 0 needs a noise generator")
        points = points + noise.normal(0.0, pixel_noise, size=points.shape)
    rays = intrinsics.pixel_to_ray(points)
    cone = silhouette_cone(rays[:-2])
    if cone is None:
        return None, 1
    return features_from_rays(cone[0], cone[1], rays[-2], rays[-1], arrow_angle)


# Layout of the one numeric parameter.
_K, _ARROW_ANGLE, _NOISE, _SEED = slice(0, 4), 4, 5, 6


@template_system("FeatureExtractor_", T_list=[float])
def FeatureExtractor_(T):
    class Impl(LeafSystem_[T]):
        """The image features y from the camera's colour image, once per frame.

        .. pydrake_system::

            name: FeatureExtractor
            input_ports:
            - color_image
            output_ports:
            - image_features
            - feature_status
            - capture_time

        ``color_image`` is an ``ImageRgba8U`` of the scene of
        :data:`SCENE_COLOURS` (from an ``RgbdSensor``). Every ``period``
        seconds from ``offset`` (and at t = 0 where ``offset`` is 0: see
        :mod:`geovs_drake.systems._held_frames` for the wait before a later first
        frame) the image is read and
        :func:`extract_features` gives y; ``image_features`` is the 13-vector
        ``[q1, q2, q3, lambda, s]`` of the frame taken ``latency_frames``
        periods ago, held between frames; ``feature_status`` is ``[valid,
        code, lost]``: on a failed frame the last good y is held, ``code`` says
        why (:data:`~geovs_drake.geometry.features.FEATURE_FAILURES`) and
        ``lost`` counts the failed frames in a row; ``valid`` drops to 0 when
        more than ``max_lost_frames`` have failed (or none has succeeded);
        ``capture_time`` [s] is when the held y's frame was taken (its read time
        less ``capture_delay``; NaN before a good frame). See
        :mod:`geovs_drake.systems._held_frames`.

        Double only: ``RgbdSensor`` does not convert to AutoDiffXd or
        Expression, and an image has no derivative to propagate.

        One numeric parameter vector: ``[fx, fy, cx, cy, arrow_angle,
        pixel_noise, seed]``: the intrinsics the extractor *believes* (a
        focal-length error is a difference between these and the renderer's),
        the marks' angle delta, and optional Gaussian noise [px per axis] on
        every extracted point, drawn from ``seed`` and the frame's index (so a
        run is reproducible and the noise of a frame does not depend on
        anything else).
        """

        def _construct(
            self,
            intrinsics: PinholeIntrinsics,
            marks: TargetMarks | None = None,
            period: float = 1.0 / 30.0,
            latency_frames: int = 0,
            max_lost_frames: int = 3,
            pixel_noise: float = 0.0,
            seed: int = 0,
            offset: float = 0.0,
            capture_delay: float = 0.0,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            _require_cv2()
            marks = marks or TargetMarks()
            if not (math.isfinite(pixel_noise) and pixel_noise >= 0):
                raise ValueError(f"pixel_noise must be finite and >= 0 [px], got {pixel_noise}")
            self._defaults = (
                intrinsics,
                marks,
                period,
                latency_frames,
                max_lost_frames,
                pixel_noise,
                seed,
                offset,
                capture_delay,
            )
            self._size = (intrinsics.width, intrinsics.height)
            self._period, self._offset = period, offset
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T](
                    list(intrinsics.K) + [marks.arrow_angle, float(pixel_noise), float(seed)]
                )
            )
            self.color_image_input = self.DeclareAbstractInputPort(
                "color_image", AbstractValue.Make(ImageRgba8U(*self._size))
            )
            (
                self.image_features_output,
                self.feature_status_output,
                self.capture_time_output,
            ) = declare_sampled_features(
                self, period, latency_frames, max_lost_frames, self._measure, offset, capture_delay
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def believed_intrinsics(self, context) -> PinholeIntrinsics:
            """The intrinsics the extractor lifts pixels with (the calibration it believes)."""
            p = context.get_numeric_parameter(self._params_index).get_value()
            return PinholeIntrinsics(*self._size, *p[_K].tolist())

        def set_believed_intrinsics(self, context, intrinsics: PinholeIntrinsics) -> None:
            """Set the believed intrinsics (same image size); for calibration sweeps."""
            if (intrinsics.width, intrinsics.height) != self._size:
                raise ValueError(
                    f"intrinsics are for a {intrinsics.width}x{intrinsics.height} image, the "
                    f"camera's is {self._size[0]}x{self._size[1]}"
                )
            v = context.get_mutable_numeric_parameter(self._params_index)
            full = v.CopyToVector()
            full[_K] = intrinsics.K
            v.SetFromVector(full)

        def _measure(self, context) -> tuple[tuple | None, int]:
            image = self.color_image_input.Eval(context)
            p = context.get_numeric_parameter(self._params_index).get_value()
            sigma = float(p[_NOISE])
            noise = None
            if sigma > 0:
                frame = frame_index(context.get_time(), self._period, self._offset)
                noise = np.random.default_rng([int(p[_SEED]), frame])
            y, code = extract_features(
                image.data, self.believed_intrinsics(context), float(p[_ARROW_ANGLE]), noise, sigma
            )
            return (y, FEATURE_OK) if y is not None else (None, code)

    return Impl


FeatureExtractor = FeatureExtractor_[None]
