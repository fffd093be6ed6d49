"""The sensor, one variant each (``ScenarioConfig.sensor``): how the loop sees the target.

In YAML a sensor is tagged with its class name, ``sensor: !Pinhole {rate: 15}``; a
scenario file's bare name (``sensor: pinhole``) reads as that variant with its
defaults. The loop takes each sensor's systems from
:data:`geovs_drake.loop.sensors.SENSORS`, keyed by the variant's type.
"""

import copy
import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, NamedTuple

from geovs_drake.geometry.pinhole import PinholeIntrinsics
from geovs_drake.scenario.pose import finite_numbers
from geovs_drake.scenario.traits import SensorTraits

__all__ = [
    "PREDICTIONS",
    "SENSOR_VARIANTS",
    "CameraModel",
    "Prediction",
    "Exact",
    "Pinhole",
    "Rendered",
    "SensorConfig",
    "camera_like",
    "check_sensor",
    "radius_error_of",
]


@dataclass
class Exact:
    """The camera map y = c(H) read continuously (the paper's spherical camera).

    ``radius_error`` (every sensor has it): the controller believes rho
    ``(1 + radius_error)`` times the true radius, in C(y) and in the goal image
    y* = c(X_CB*) (it moves the equilibrium's distance, not its image)."""

    radius_error: float = 0.0

    traits: ClassVar[SensorTraits] = SensorTraits(camera=False, renders=False, batch_kernel=True)


@dataclass
class CameraModel:
    """A camera: the fields :class:`Pinhole` and :class:`Rendered` share. It runs at
    ``rate`` frames per second with a zero-order hold, eye-in-hand, on either plant.

    The camera is a pinhole of ``resolution`` [W, H] px, square pixels, the principal
    point at the centre, and the focal length whose inscribed cone, ``border_px`` in
    from the image's edges, is the domain's field of view (:meth:`intrinsics`): every
    pose of D keeps the whole sphere in the image.

    Errors, for robustness studies: ``pixel_noise`` [px], Gaussian, per axis, on every
    extracted image point; ``focal_error``: the extractor believes the focal lengths
    ``(1 + focal_error)`` times the true ones; ``latency_frames``: the controller acts on
    the frame taken that many periods ago; ``max_lost_frames``: how many frames in a row
    may give no y (the last good y held) before the run stops with ``feature_lost``;
    ``radius_error`` as :class:`Exact`'s. ``seed`` draws the noise.

    ``prediction``: what the law sees between frames (:data:`PREDICTIONS`). ``"none"``:
    the held frame (a zero-order hold, late by the latency). ``"odometry"``: the held
    frame moved by the carrier's own motion since it was taken
    (:class:`~geovs_drake.systems.FramePredictor`, a Smith predictor: exact for a still
    target), which gives the law the continuous loop's stability at any rate and latency.

    The frame clock is Drake's ``CameraConfig``'s: frames are taken at
    ``capture_offset + k / rate`` [s] and reach the law ``output_delay`` [s] later, both
    shorter than a frame (a delay of a frame or more is ``latency_frames``, on top).
    Before the first frame arrives the law has no image: it holds (its y is the goal's,
    :class:`~geovs_drake.systems.FrameWait`, so only the damping acts) and
    ``feature_status`` says it is waiting, not lost.

    ``damping``: the damping B of a loop with a camera, rotational first, in place of
    ``control.damping``. Why a second one: the default gains give the exact loop a mode
    at 36 rad/s damped only 0.19 of critical; a 30 Hz zero-order hold delays the force
    by half a frame, 34 deg of phase at that frequency, and that mode grows: the default
    start leaves D at t = 1.6 s. Rotational damping 0.6 brings it home as fast as the
    exact loop (3.7 s). The damping reads the rig's own velocity, not the camera.
    """

    rate: float = 30.0
    resolution: list[int] = field(default_factory=lambda: [320, 240])
    border_px: float = 2.0
    pixel_noise: float = 0.0
    focal_error: float = 0.0
    latency_frames: int = 0
    max_lost_frames: int = 3
    radius_error: float = 0.0
    seed: int = 0
    prediction: str = "odometry"
    damping: list[float] = field(default_factory=lambda: [0.6, 0.6, 0.6, 4.0, 4.0, 4.0])
    capture_offset: float = 0.0
    output_delay: float = 0.0

    @property
    def first_frame_time(self) -> float:
        """When the first frame reaches the law [s]: 0 for a camera read at t = 0."""
        return self.capture_offset + self.output_delay

    @property
    def model_latency_frames(self) -> int:
        """The whole frames of latency the sampled-data model counts
        (:mod:`geovs_drake.goal.camera_fit`): ``latency_frames``, plus one for a
        sub-frame ``output_delay`` (rounded up: a longer delay only makes the sampled
        loop less stable, so the fit errs on the safe side)."""
        return int(self.latency_frames) + (1 if self.output_delay > 0 else 0)

    def intrinsics(self, fov_half_angle: float) -> PinholeIntrinsics:
        """The true camera: its inscribed cone (``border_px`` in) is ``fov_half_angle``."""
        width, height = (int(v) for v in self.resolution)
        return PinholeIntrinsics.for_fov(width, height, fov_half_angle, self.border_px)

    def believed_intrinsics(self, fov_half_angle: float) -> PinholeIntrinsics:
        """The camera the extractor believes in: focal lengths scaled by 1 + focal_error."""
        return self.intrinsics(fov_half_angle).scaled(1 + self.focal_error)


@dataclass
class Pinhole(CameraModel):
    """The camera's measurement on the exact image points of the sphere's marks, without
    rendering (:class:`~geovs_drake.systems.PinholeFeatureSensor`, for fast sweeps)."""

    traits: ClassVar[SensorTraits] = SensorTraits(camera=True, renders=False, batch_kernel=False)


@dataclass
class Rendered(CameraModel):
    """The scene drawn by Drake's RgbdSensor (RenderEngineVtk) every frame and y
    extracted from the colour image (:class:`~geovs_drake.systems.FeatureExtractor`)."""

    traits: ClassVar[SensorTraits] = SensorTraits(camera=True, renders=True, batch_kernel=False)


class Prediction(NamedTuple):
    """What a camera's law sees between frames: ``description``, and whether the loop's
    local model is the continuous one (``continuous``: the predictor removes the hold
    and the latency at the goal) or the sampled one."""

    description: str
    continuous: bool


#: The ``CameraModel.prediction`` of each name (the systems: ``loop.sensors.PREDICTORS``).
PREDICTIONS: dict[str, Prediction] = {
    "none": Prediction("the held frame, late by the latency", continuous=False),
    "odometry": Prediction(
        "the held frame moved by the carrier's motion since its capture", continuous=True
    ),
}

#: A sensor's configuration: one of the variants above.
SensorConfig = Exact | Pinhole | Rendered
#: The sensor of each name, as ``--sensor`` and a file's bare name give it.
SENSOR_VARIANTS: dict[str, type] = {"exact": Exact, "pinhole": Pinhole, "rendered": Rendered}


def camera_like(sensor: object, kind: type = Pinhole, **changes: Any) -> CameraModel:
    """A camera of ``kind`` (:class:`Pinhole` or :class:`Rendered`) with ``sensor``'s
    fields where ``kind`` has them (all of a camera's; the exact sensor's
    ``radius_error``), then ``changes``: the same camera seen through another model."""
    names = {f.name for f in dataclasses.fields(kind)}
    kept = {f.name: getattr(sensor, f.name) for f in dataclasses.fields(sensor) if f.name in names}
    return kind(**{**copy.deepcopy(kept), **changes})


def radius_error_of(sensor: object) -> float:
    """The sensor's ``radius_error`` (every variant here has one); 0 for a sensor of one's
    own that leaves it out."""
    return getattr(sensor, "radius_error", 0.0)


def check_sensor(sensor: object) -> None:
    """The sensor variant's own fields: ValueError naming the first bad one,
    ``sensor.<field>``, and its value."""
    value = radius_error_of(sensor)
    if not (isinstance(value, int | float) and math.isfinite(value) and -0.5 <= value <= 0.5):
        raise ValueError(f"sensor.radius_error must be in [-0.5, 0.5]: radius_error = {value}")
    if not isinstance(sensor, CameraModel):
        return
    if not (math.isfinite(sensor.rate) and sensor.rate > 0):
        raise ValueError(f"sensor.rate must be finite and > 0 [Hz]: rate = {sensor.rate}")
    size = finite_numbers(sensor.resolution, 2)
    if size is None or not all(v == int(v) and v >= 16 for v in size):
        raise ValueError(
            f"sensor.resolution must be 2 integers >= 16 [px], got {sensor.resolution!r}"
        )
    if not (math.isfinite(sensor.border_px) and 0 <= sensor.border_px < min(size) / 4):
        raise ValueError(
            f"sensor.border_px must be in [0, {min(size) / 4:g}) [px]: "
            f"border_px = {sensor.border_px}"
        )
    if not (math.isfinite(sensor.pixel_noise) and sensor.pixel_noise >= 0):
        raise ValueError(
            f"sensor.pixel_noise must be finite and >= 0 [px]: pixel_noise = {sensor.pixel_noise}"
        )
    if not (math.isfinite(sensor.focal_error) and -0.5 <= sensor.focal_error <= 0.5):
        raise ValueError(
            f"sensor.focal_error must be in [-0.5, 0.5]: focal_error = {sensor.focal_error}"
        )
    if sensor.prediction not in PREDICTIONS:
        raise ValueError(
            f"sensor.prediction must be one of {', '.join(PREDICTIONS)}, got {sensor.prediction!r}"
        )
    damping = finite_numbers(sensor.damping, 6)
    if damping is None or not all(v >= 0 for v in damping):
        raise ValueError(
            f"sensor.damping must be 6 finite non-negative numbers, got {sensor.damping!r}"
        )
    for name in ("latency_frames", "max_lost_frames"):
        value = getattr(sensor, name)
        if isinstance(value, bool) or not (value == int(value) and value >= 0):
            raise ValueError(f"sensor.{name} must be an integer >= 0, got {value!r}")
    period = 1.0 / sensor.rate
    for name in ("capture_offset", "output_delay"):
        value = getattr(sensor, name)
        if not (isinstance(value, int | float) and math.isfinite(value) and 0 <= value < period):
            raise ValueError(
                f"sensor.{name} must be in [0, 1/rate = {period:.4g}) [s] (a frame or more "
                f"of delay is latency_frames): {name} = {value}"
            )
