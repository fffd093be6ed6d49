"""Sensors: how the loop sees the target (a loop is carrier + sensor + law, :mod:`.build`).

Every loop has the exact camera ``spherical_camera`` (y = c(H) of the true
pose): the truth the safe-domain monitor and the logs read. A sensor offers
the y the *law* acts on: the exact camera's own (``exact``), or a camera
model's measurement, sampled at the camera's rate and held
(``pinhole``: :class:`~geovs_drake.systems.PinholeFeatureSensor` on projected
points; ``rendered``: Drake's ``RgbdSensor`` through RenderEngineVtk into
:class:`~geovs_drake.systems.FeatureExtractor`). A camera model is the
subsystem ``feature_sensor``. :data:`SENSORS` registers one entry per sensor
variant (:mod:`geovs_drake.scenario.sensors`), keyed by its type.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    LightParameter,
    MakeRenderEngineVtk,
    RenderEngineVtkParams,
    Rgba,
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.systems.framework import DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.primitives import LogVectorOutput, ZeroOrderHold
from pydrake.systems.sensors import CameraConfig, CameraInfo, ImageRgba8U, RgbdSensor

from geovs_drake.geometry.pinhole import PinholeIntrinsics
from geovs_drake.loop.carriers import CarrierParts
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.scenario import Exact, Pinhole, Rendered
from geovs_drake.systems import (
    FeatureExtractor,
    FramePredictor,
    FrameWait,
    PinholeFeatureSensor,
    SelfMask,
)
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems.feature_extractor import SCENE_COLOURS

__all__ = [
    "PREDICTORS",
    "RENDERER_NAME",
    "SENSORS",
    "VTK_PRINCIPAL_POINT_SHIFT",
    "Sensor",
    "add_pinhole_sensor",
    "add_scene_renderer",
    "camera_config",
    "sampled_settings",
    "scene_lights",
    "vtk_camera_info",
]

#: The name of the VTK render engine the rendered loop adds to SceneGraph.
RENDERER_NAME = "geovs_vtk"
#: Where Drake's RenderEngineVtk (drake 1.51) puts the optical axis, in pixel-centre
#: coordinates, relative to ``CameraInfo``'s ``(center_x, center_y)``: half a pixel up
#: and left, OpenGL's convention of pixel corners at integers. Measured (a test renders
#: a small sphere on the optical axis and finds its centroid there).
VTK_PRINCIPAL_POINT_SHIFT = -0.5


@dataclass(frozen=True)
class Sensor:
    """A sensor: ``add(builder, resolved, carrier, camera)`` returns the port of the y
    the law acts on (``camera`` is the exact ``spherical_camera``); ``draws_marks``
    asks the carrier to draw the target in the extractor's colours."""

    add: Callable[[DiagramBuilder, ResolvedScenario, CarrierParts, LeafSystem], OutputPort]
    draws_marks: bool = False


def _exact(builder, resolved, carrier, camera) -> OutputPort:
    return camera.image_features_output


def sampled_settings(resolved: ResolvedScenario) -> dict:
    """The frame timing, noise and loss tolerance every camera model shares: its
    constructor's ``period``, ``latency_frames``, ``max_lost_frames``, ``pixel_noise``,
    ``seed``, ``offset`` (the first frame's read) and ``capture_delay`` (a frame is
    read ``output_delay`` after its capture). The loop's sensors and the LCM station's
    and controller's take them from here."""
    cam = resolved.config.sensor  # a CameraModel
    return dict(
        period=1.0 / cam.rate,
        latency_frames=int(cam.latency_frames),
        max_lost_frames=int(cam.max_lost_frames),
        pixel_noise=cam.pixel_noise,
        seed=int(cam.seed),
        offset=cam.first_frame_time,
        capture_delay=cam.output_delay,
    )


def _held(builder, resolved, carrier, held: OutputPort, capture_pose=None) -> OutputPort:
    """The held frame as it is (``prediction: none``)."""
    return held


def _odometry(builder, resolved, carrier, held: OutputPort, capture_pose=None) -> OutputPort:
    """The held frame moved by the carrier's pose since its capture (``prediction:
    odometry``): :class:`~geovs_drake.systems.FramePredictor` on the camera's clock. A
    camera whose frames arrive after their capture gives the body's pose then
    (``capture_pose``, ``[q, p]``, held with the frame); otherwise the frame was taken
    when it is read."""
    cam = resolved.config.sensor
    predictor = builder.AddNamedSystem(
        "frame_predictor",
        FramePredictor(
            radius=resolved.believed_radius,
            X_RC=carrier.X_RC,
            period=1.0 / cam.rate,
            latency_frames=int(cam.latency_frames),
            offset=cam.first_frame_time,
        ),
    )
    builder.Connect(held, predictor.image_features_input)
    builder.Connect(carrier.body_pose, predictor.body_pose_input)
    if capture_pose is not None:
        builder.Connect(capture_pose, predictor.capture_pose_input)
    return predictor.predicted_image_features_output


#: What the law sees between a camera's frames, by ``sensor.prediction``
#: (:data:`~geovs_drake.scenario.PREDICTIONS`): ``add(builder, resolved, carrier, held,
#: capture_pose)`` returns the y port the law reads (``capture_pose``: the body's pose
#: ``[q, p]`` at the held frame's capture, from a camera whose frames arrive after it;
#: else None).
PREDICTORS: dict[str, Callable[..., OutputPort]] = {
    "none": _held,
    "odometry": _odometry,
}


def _between_frames(
    builder, resolved, carrier, held: OutputPort, capture_pose: OutputPort | None = None
) -> OutputPort:
    return PREDICTORS[resolved.config.sensor.prediction](
        builder, resolved, carrier, held, capture_pose
    )


def _held_from_capture(builder, cam, port: OutputPort, model, name: str) -> OutputPort:
    """``port`` sampled at each capture (``capture_offset + k / rate``) and held: what a
    frame shows, and the body's pose it was taken from, until the frame is read
    ``output_delay`` later (``model``: the vector size or the abstract value)."""
    hold = builder.AddNamedSystem(name, ZeroOrderHold(1.0 / cam.rate, model, cam.capture_offset))
    builder.Connect(port, hold.get_input_port())
    return hold.get_output_port()


def _wait_for_first_frame(builder, resolved, sensor, y: OutputPort) -> OutputPort:
    """``y``, or the goal image before a camera's first frame arrives (after t = 0):
    :class:`~geovs_drake.systems.FrameWait`."""
    if resolved.config.sensor.first_frame_time == 0:
        return y
    wait = builder.AddNamedSystem("frame_wait", FrameWait(np.asarray(resolved.y_goal)))
    builder.Connect(y, wait.image_features_input)
    builder.Connect(sensor.feature_status_output, wait.feature_status_input)
    return wait.image_features_or_goal_output


def add_pinhole_sensor(
    builder: DiagramBuilder,
    resolved: ResolvedScenario,
    body_pose: OutputPort,
    X_WB: RigidTransform,
    X_RC: RigidTransform,
) -> tuple[PinholeFeatureSensor, OutputPort | None]:
    """The pinhole camera model, ``feature_sensor``, on the body whose pose ``[q, p]``
    is ``body_pose`` (the camera at ``X_RC`` on it, the target at ``X_WB``), and the
    body's pose at the held frame's capture (None unless ``output_delay`` > 0). The
    loop's pinhole sensor and the LCM station build it here."""
    config = resolved.config
    theta = resolved.domain.fov_half_angle
    sensor = builder.AddNamedSystem(
        "feature_sensor",
        PinholeFeatureSensor(
            radius=config.radius,
            intrinsics=config.sensor.intrinsics(theta),
            believed=config.sensor.believed_intrinsics(theta),
            X_WB=X_WB,
            X_RC=X_RC,
            **sampled_settings(resolved),
        ),
    )
    # A frame read output_delay after its capture shows the pose then (held, as the
    # rendered camera holds its image).
    cam = config.sensor
    capture_pose = None
    if cam.output_delay > 0:
        body_pose = capture_pose = _held_from_capture(
            builder, cam, body_pose, POSE_SIZE, "capture_pose"
        )
    builder.Connect(body_pose, sensor.body_pose_input)
    return sensor, capture_pose


def _pinhole(builder, resolved, carrier, camera) -> OutputPort:
    """The rendered loop's measurement (camera rate, latency, pixel noise, focal error,
    the same fit) on exactly projected points, without a renderer."""
    sensor, capture_pose = add_pinhole_sensor(
        builder, resolved, carrier.body_pose, carrier.X_WB, carrier.X_RC
    )
    y = _between_frames(builder, resolved, carrier, sensor.image_features_output, capture_pose)
    return _wait_for_first_frame(builder, resolved, sensor, y)


def vtk_camera_info(intrinsics: PinholeIntrinsics) -> CameraInfo:
    """The ``CameraInfo`` with which RenderEngineVtk renders an image that ``intrinsics``
    (pixel centres at integers, :mod:`geovs_drake.geometry.pinhole`) describes exactly."""
    return CameraInfo(
        intrinsics.width,
        intrinsics.height,
        intrinsics.fx,
        intrinsics.fy,
        intrinsics.cx - VTK_PRINCIPAL_POINT_SHIFT,
        intrinsics.cy - VTK_PRINCIPAL_POINT_SHIFT,
    )


def add_scene_renderer(scene_graph: SceneGraph) -> None:
    """The rendered camera's renderer, :data:`RENDERER_NAME`: Drake's RenderEngineVtk on
    EGL (headless; RenderEngineGl fails here), the extractor's background colour and
    :func:`scene_lights`. The loop's rendered sensor and the LCM station's and
    controller's image systems add it alike."""
    scene_graph.AddRenderer(
        RENDERER_NAME,
        MakeRenderEngineVtk(
            RenderEngineVtkParams(
                backend="EGL",
                default_clear_color=list(SCENE_COLOURS["background"]),
                lights=scene_lights(),
            )
        ),
    )


def scene_lights() -> list[LightParameter]:
    """A headlight and four side lights, all in the camera frame, intensity 0.5 each.

    Why not Drake's default headlight alone: it shades by the cosine between the
    normal and the view, so near the limb a mark turns black and the extractor
    loses it (a mark seen at 82 deg from face-on read 1 dark pixel). With side lights
    from +-x and +-y a diffuse surface gets between 0.5 and 0.87 of full light
    wherever it is seen, the limb included.
    """
    directions = ([0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0])
    return [
        LightParameter(type="directional", frame="camera", intensity=0.5, direction=d)
        for d in directions
    ]


def camera_config(resolved: ResolvedScenario) -> CameraConfig:
    """The rendered camera as Drake's ``CameraConfig``: its size and intrinsics
    (:meth:`~geovs_drake.scenario.CameraModel.intrinsics`, in RenderEngineVtk's pixel
    convention, :func:`vtk_camera_info`), clipping, renderer and frame clock (``fps``,
    ``capture_offset``, ``output_delay``). The label image is rendered for an arm,
    whose own pixels it masks."""
    config = resolved.config
    cam = config.sensor
    info = vtk_camera_info(cam.intrinsics(resolved.domain.fov_half_angle))
    # Clip well short of the nearest sphere of D and well beyond the farthest.
    d = config.domain
    near = 0.5 * config.radius * (1 / d.lam_max - 1)
    far = 2.0 * config.radius * (1 / d.lam_min + 1)
    return CameraConfig(
        width=info.width(),
        height=info.height(),
        focal=CameraConfig.FocalLength(x=info.focal_x(), y=info.focal_y()),
        center_x=info.center_x(),
        center_y=info.center_y(),
        clipping_near=near,
        clipping_far=far,
        z_near=1.01 * near,
        z_far=0.99 * far,
        renderer_name=RENDERER_NAME,
        background=Rgba(*SCENE_COLOURS["background"], 1.0),
        name="camera",
        fps=cam.rate,
        capture_offset=cam.capture_offset,
        output_delay=cam.output_delay,
        rgb=True,
        depth=False,
        label=config.carrier.traits.joints,  # the arm's own links are masked by label
    )


def _rendered(builder, resolved, carrier, camera) -> OutputPort:
    """SceneGraph -> Drake's camera (RenderEngineVtk, EGL backend: headless) -> the
    extractor, a frame every ``1 / sensor.rate`` s. The camera is built from
    :func:`camera_config`: Drake's ``RgbdSensor`` drawn at each capture
    (``capture_offset + k / fps``) and, where frames arrive ``output_delay`` later, held
    by a ``ZeroOrderHold`` until then, the timing of Drake's ``RgbdSensorAsync``. The
    camera's intrinsics are
    :meth:`~geovs_drake.scenario.CameraModel.intrinsics` (its inscribed cone is D's
    field of view, so no pose of D cuts the sphere), the extractor's those times
    ``1 + sensor.focal_error``. Double only (Drake's cameras do not convert)."""
    config = resolved.config
    cam = config.sensor
    theta = resolved.domain.fov_half_angle
    drake_camera = camera_config(resolved)
    add_scene_renderer(carrier.scene_graph)
    color_camera, depth_camera = drake_camera.MakeCameras()
    parent = carrier.plant.GetBodyFrameIdOrThrow(carrier.body.index())
    X_PC = carrier.X_RC if carrier.X_BodyC is None else carrier.X_BodyC
    rgbd = builder.AddNamedSystem(
        "rgbd_sensor", RgbdSensor(parent, X_PC, color_camera, depth_camera)
    )
    builder.Connect(carrier.scene_graph.get_query_output_port(), rgbd.query_object_input_port())
    color = rgbd.color_image_output_port()
    if carrier.arm is not None:  # the arm's own pixels out of its camera's view
        plant = carrier.plant
        mask = builder.AddNamedSystem(
            "self_mask",
            SelfMask(
                drake_camera.width,
                drake_camera.height,
                [int(i) for i in plant.GetBodyIndices(carrier.body.model_instance())],
            ),
        )
        builder.Connect(color, mask.color_image_input)
        builder.Connect(rgbd.label_image_output_port(), mask.label_image_input)
        color = mask.masked_color_image_output
    capture_pose = None
    if cam.output_delay > 0:
        # The frame taken at the capture and delivered output_delay later, as Drake's
        # RgbdSensorAsync does, but drawn here, on the simulation's thread: the async
        # sensor draws on a worker thread, where RenderEngineVtk's EGL context cannot be
        # made current ("Unable to eglMakeCurrent: 12290", EGL_BAD_ACCESS), and in the
        # servo loop its frames after the first came back without the sphere (measured,
        # docs/real-camera.md).
        model = AbstractValue.Make(ImageRgba8U(drake_camera.width, drake_camera.height))
        color = _held_from_capture(builder, cam, color, model, "frame_capture")
        capture_pose = _held_from_capture(
            builder, cam, carrier.body_pose, POSE_SIZE, "capture_pose"
        )
    sensor = builder.AddNamedSystem(
        "feature_sensor",
        FeatureExtractor(
            intrinsics=cam.believed_intrinsics(theta),
            **sampled_settings(resolved),
        ),
    )
    builder.Connect(color, sensor.color_image_input)
    y = _between_frames(builder, resolved, carrier, sensor.image_features_output, capture_pose)
    return _wait_for_first_frame(builder, resolved, sensor, y)


#: The sensors, by the type of ``config.sensor``.
SENSORS: dict[type, Sensor] = {
    Exact: Sensor(_exact),
    Pinhole: Sensor(_pinhole, draws_marks=True),
    Rendered: Sensor(_rendered, draws_marks=True),
}


def add_feature_loggers(builder: DiagramBuilder, sensor: LeafSystem, rate: float) -> None:
    """Loggers of a camera model's measured y and frame status."""
    for port, name in (
        (sensor.image_features_output, "log_measured_features"),
        (sensor.feature_status_output, "log_feature_status"),
    ):
        LogVectorOutput(port, builder, publish_period=1.0 / rate).set_name(name)
