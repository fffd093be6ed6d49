"""The rendered camera over LCM (issue 34): images on the bus, features in the controller.

Station side, :func:`add_image_camera`: the arm's camera (Drake's ``RgbdSensor``,
RenderEngineVtk with the rendered loop's lights and intrinsics) draws the scene (a
SceneGraph of its own, :func:`add_camera_scene`, posed from the plant's state at the
frames only), and
its colour image goes out as ``lcmt_image_array`` through Drake's
``ImageToLcmImageArrayT`` and ``LcmPublisherSystem``, a periodic publish at the
camera's clock (``capture_offset + k / rate``). Why that is the capture time exactly:
``ImageToLcmImageArrayT`` stamps ``header.utime`` with the context's time when the
message is made, and the ``RgbdSensor`` renders the scene as it is then; a publish
event at t sees the plant's state at t. A camera with a delay (``latency_frames``,
``output_delay``) makes the message at its capture, holds it in a line of
``latency_frames + 1`` zero-order holds on the camera's clock (the message, its stamp
included, as it was made), and sends it that much later. No label image goes out: a
real camera has none.

Controller side: ``LcmSubscriberSystem(lcmt_image_array)`` -> ``LcmImageArrayToImages``
-> the colour image, and beside it a subscriber that reads only the message's
``header.utime`` (:func:`decode_image_utime`: the capture time, which
``LcmImageArrayToImages`` drops). The arm's own pixels are masked by a robot
self-filter (:func:`add_self_filter`): a SceneGraph holding only the arm's model (no
world, no target), drawn by a ``RgbdSensor`` with the same camera on the flange into a
*label image* at the joints of the status at the frame's capture; ``SelfMask`` paints
them the background. :class:`ImageFeatureFrames` then extracts y from the masked image
(``FeatureExtractor``'s kernel, :func:`~geovs_drake.systems.feature_extractor.extract_features`)
once per new image and hands the frame to the controller's tracker in the layout of the
pinhole camera's message (:data:`~geovs_drake.hardware.messages.FRAME_VALUE_SIZE`).
"""

from __future__ import annotations

import math
import struct

import numpy as np
from drake import lcmt_image_array
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    Capsule,
    Cylinder,
    GeometryInstance,
    PerceptionProperties,
    RenderLabel,
    Rgba,
    SceneGraph,
    Sphere,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import (
    Context,
    DiagramBuilder,
    LeafSystem,
    OutputPort,
    TriggerType,
)
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import ZeroOrderHold
from pydrake.systems.rendering import MultibodyPositionToGeometryPose
from pydrake.systems.sensors import (
    ImageRgba8U,
    ImageToLcmImageArrayT,
    LcmImageArrayToImages,
    PixelType,
    RgbdSensor,
)

from geovs_drake.geometry.features import FEATURE_OK, TargetMarks
from geovs_drake.hardware.messages import (
    CAPTURE_SLACK_US,
    FRAME_INDEX,
    FRAME_SIZE,
    FRAME_STATUS,
    FRAME_UTIME,
    FRAME_VALUE_SIZE,
    FRAME_VALUE_START,
    FRAME_Y,
    US_PER_S,
    VectorSerializer,
    frame_vector_size,
)
from geovs_drake.loop.carriers import add_arm_scene
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.sensors import add_scene_renderer, camera_config, sampled_settings
from geovs_drake.systems import SelfMask
from geovs_drake.systems.arm_model import ArmModel, add_arm
from geovs_drake.systems.feature_extractor import extract_features

__all__ = [
    "CAPSULE_END_TOLERANCE",
    "COLOR_FRAME_NAME",
    "IMAGE_HISTORY",
    "CameraScene",
    "ImageFeatureFrames",
    "SelfFilter",
    "add_camera_scene",
    "add_image_camera",
    "add_self_filter",
    "perceive_collision_shapes",
    "check_rendered_over_lcm",
    "decode_image_utime",
    "subscribe_images",
]

#: The colour image's ``frame_name`` in ``lcmt_image_array``.
COLOR_FRAME_NAME = "camera"
#: How many statuses' joints :class:`ImageFeatureFrames` keeps beyond the camera's own
#: delay to find the joints at a frame's capture (at 1 kHz, 0.1 s: an image arrives
#: within a few ms of its send).
IMAGE_HISTORY = 100
#: ``lcmt_image_array``'s wire format: its fingerprint, then the nested ``lcmt_header``
#: (``seq`` int32, then ``utime`` int64).
_IMAGE_FINGERPRINT = lcmt_image_array._get_packed_fingerprint()
_HEADER = struct.Struct(">iq")


def check_rendered_over_lcm(drop_every_frame: int = 0) -> None:
    """ValueError in one line for a rendered camera the LCM link cannot give: dropped
    frames (``drop_every_frame`` is the pinhole channel's)."""
    if drop_every_frame > 0:
        raise ValueError("hardware.drop_every_frame is for the pinhole camera (lcmt_scope)")


#: The colour the arm's collision shapes are drawn in (RGBA): a dark grey that the
#: extractor takes for foreground (why the self-filter must mask it).
ARM_COLOUR = (0.3, 0.3, 0.3, 1.0)


#: How far a sphere's centre may lie from its cylinder's end, as a fraction of the
#: cylinder's length, and still close it into a capsule [1]: the Panda's files give the
#: hand's cylinder a roll of 1.57, not pi/2, which moves its ends by 6e-5 m.
CAPSULE_END_TOLERANCE = 0.01


def perceive_collision_shapes(plant: MultibodyPlant, scene_graph: SceneGraph, instance) -> int:
    """Give the arm's collision shapes (``instance``'s) the perception role, labelled
    with their body's index as MultibodyPlant labels a body: why, the Panda's visual
    meshes are .dae files, which RenderEngineVtk ignores, so without this the camera
    never sees the arm; its collision spheres and capsules enclose the links (a robot
    self-filter's usual padded model). Returns how many perceived shapes were made.

    A cylinder closed by two spheres of its radius at its ends (the Panda's capsules,
    three collision shapes each) is perceived as one ``Capsule``, the same solid: every
    perceived geometry costs the renderer a pose update at every geometry query of the
    plant (each derivative evaluation, whether a frame is drawn or not), which with the
    39 shapes cost the station 1.5 s per simulated second (docs/performance.md)."""
    inspector = scene_graph.model_inspector()
    count = 0
    for index in plant.GetBodyIndices(instance):
        body = plant.get_body(index)
        shapes = [
            g
            for g in plant.GetCollisionGeometriesForBody(body)
            if inspector.GetPerceptionProperties(g) is None
        ]
        capsules, closed = _capsules(inspector, shapes)
        frame = plant.GetBodyFrameIdOrThrow(index)
        for k, (X_FG, radius, length) in enumerate(capsules):
            instance_ = GeometryInstance(X_FG, Capsule(radius, length), f"{body.name()}_capsule{k}")
            new = scene_graph.RegisterGeometry(plant.get_source_id(), frame, instance_)
            scene_graph.AssignRole(plant.get_source_id(), new, _arm_perception(index))
        for geometry_id in shapes:
            if geometry_id not in closed:
                scene_graph.AssignRole(plant.get_source_id(), geometry_id, _arm_perception(index))
        count += len(capsules) + len(shapes) - len(closed)
    return count


def _arm_perception(index) -> PerceptionProperties:
    properties = PerceptionProperties()
    properties.AddProperty("label", "id", RenderLabel(int(index)))
    properties.AddProperty("phong", "diffuse", Rgba(*ARM_COLOUR))
    return properties


def _capsules(inspector, shapes: list) -> tuple[list[tuple[RigidTransform, float, float]], set]:
    """The capsules among one frame's ``shapes``: (X_FG of the cylinder, radius, length)
    for each cylinder with a sphere of its radius at each end; and the ids they replace."""
    spheres = [g for g in shapes if isinstance(inspector.GetShape(g), Sphere)]
    capsules, closed = [], set()
    for g in shapes:
        shape = inspector.GetShape(g)
        if not isinstance(shape, Cylinder):
            continue
        radius, length = shape.radius(), shape.length()
        X_FG = inspector.GetPoseInFrame(g)
        ends = [X_FG @ np.array([0.0, 0.0, sign * length / 2]) for sign in (1, -1)]
        caps = []
        for end in ends:
            for s in spheres:
                p = inspector.GetPoseInFrame(s).translation()
                if (
                    s not in closed
                    and s not in caps
                    and abs(inspector.GetShape(s).radius() - radius) <= 1e-12
                    and np.linalg.norm(p - end) <= CAPSULE_END_TOLERANCE * length
                ):
                    caps.append(s)
                    break
        if len(caps) == 2:
            capsules.append((X_FG, radius, length))
            closed.update([g, *caps])
    return capsules, closed


def _rgbd(
    builder: DiagramBuilder,
    name: str,
    resolved: ResolvedScenario,
    plant: MultibodyPlant,
    scene_graph: SceneGraph,
    body,
    X_LinkC: RigidTransform,
) -> RgbdSensor:
    """A RgbdSensor of the scenario's camera (:func:`~geovs_drake.loop.sensors.camera_config`)
    on ``body`` at ``X_LinkC``, rendering ``scene_graph`` (queried when read)."""
    color_camera, depth_camera = camera_config(resolved).MakeCameras()
    parent = plant.GetBodyFrameIdOrThrow(body.index())
    rgbd = builder.AddNamedSystem(name, RgbdSensor(parent, X_LinkC, color_camera, depth_camera))
    builder.Connect(scene_graph.get_query_output_port(), rgbd.query_object_input_port())
    return rgbd


class CameraScene:
    """The station camera's scene (:func:`add_camera_scene`): its ``scene_graph``, the
    ``plant`` whose geometry it holds, ``rgbd`` (the camera's RgbdSensor) and
    ``color_image``, the colour image's port in the station's diagram."""

    def __init__(self, scene_graph, plant, rgbd, color_image: OutputPort) -> None:
        self.scene_graph, self.plant, self.rgbd = scene_graph, plant, rgbd
        self.color_image = color_image


def add_camera_scene(
    builder: DiagramBuilder, resolved: ResolvedScenario, arm_state: OutputPort
) -> CameraScene:
    """The station's camera on a scene of its own: a subsystem ``camera_scene`` holding
    a SceneGraph with the station's scene (the arm and the target, as
    :func:`~geovs_drake.loop.carriers.add_arm_scene` registers them with the station's
    plant, in the same order: the same bodies' indices, the same labels), the arm
    perceived as :func:`perceive_collision_shapes` makes it, the renderer
    (:func:`~geovs_drake.loop.sensors.add_scene_renderer`), posed by
    ``MultibodyPositionToGeometryPose`` from the plant's state ``arm_state`` (q, v), and
    the camera's RgbdSensor. Its output ``color_image``.

    Why not the plant's own SceneGraph: a SceneGraph moves every perceived geometry in
    its renderers at each pose update, and the continuous plant asks for one at each
    derivative evaluation (its contact query: about 3 a step at 1 kHz), while the camera
    reads its scene 30 times a second. This scene is posed only when the camera reads it
    (docs/performance.md, "The rendered station")."""
    inner = DiagramBuilder()
    _model, plant, scene_graph, link, X_LinkC = add_arm_scene(inner, resolved, True, False)
    add_scene_renderer(scene_graph)
    perceive_collision_shapes(plant, scene_graph, link.model_instance())
    to_pose = inner.AddNamedSystem(
        "camera_scene_poses", MultibodyPositionToGeometryPose(plant, input_multibody_state=True)
    )
    inner.Connect(
        to_pose.get_output_port(), scene_graph.get_source_pose_port(plant.get_source_id())
    )
    rgbd = _rgbd(inner, "rgbd_sensor", resolved, plant, scene_graph, link, X_LinkC)
    inner.ExportInput(to_pose.get_input_port(), "arm_state")
    inner.ExportOutput(rgbd.color_image_output_port(), "color_image")
    diagram = builder.AddNamedSystem("camera_scene", inner.Build())
    builder.Connect(arm_state, diagram.get_input_port())
    return CameraScene(scene_graph, plant, rgbd, diagram.GetOutputPort("color_image"))


def add_image_camera(
    builder: DiagramBuilder,
    resolved: ResolvedScenario,
    arm_state: OutputPort,
    channel: str,
    interface: LcmInterfaceSystem,
    transport_delay: float = 0.0,
) -> tuple[CameraScene, float]:
    """The station's camera: the scene drawn on the arm's camera
    (:func:`add_camera_scene`, posed from the plant's state ``arm_state``) and its colour
    image published on ``channel`` as ``lcmt_image_array`` (``header.utime`` = the
    capture): at the camera's capture times, or, for a camera with a delay,
    ``latency_frames`` periods plus ``output_delay`` plus ``transport_delay`` after each
    capture. Returns the camera's scene and when the first image is sent [s]."""
    scene = add_camera_scene(builder, resolved, arm_state)
    to_lcm = builder.AddNamedSystem("image_to_lcm", ImageToLcmImageArrayT(do_compress=False))
    color_in = to_lcm.DeclareImageInputPort[PixelType.kRgba8U](COLOR_FRAME_NAME)
    builder.Connect(scene.color_image, color_in)
    cam = resolved.config.sensor
    period = sampled_settings(resolved)["period"]
    message = to_lcm.image_array_t_msg_output_port()
    first_send = cam.capture_offset
    if cam.latency_frames > 0 or cam.output_delay > 0:
        # The message made at each capture (its stamp the capture), then held one more
        # frame per latency frame: simultaneous updates read their input as it was, so
        # the k-th hold gives the capture k frames back. Sent output_delay later, and a
        # transport delay after the last hold's update (a publish at the update's own
        # time would send the frame before).
        model = message.Allocate()
        for k in range(int(cam.latency_frames) + 1):
            hold = builder.AddNamedSystem(
                f"image_line_{k}", ZeroOrderHold(period, model, cam.capture_offset)
            )
            builder.Connect(message, hold.get_input_port())
            message = hold.get_output_port()
        first_send += cam.latency_frames * period + cam.output_delay + transport_delay
    publisher = builder.AddNamedSystem(
        "camera_publisher",
        LcmPublisherSystem.Make(
            channel,
            lcmt_image_array,
            interface,
            use_cpp_serializer=True,
            publish_triggers={TriggerType.kPeriodic},
            publish_period=period,
            publish_offset=first_send,
        ),
    )
    builder.Connect(message, publisher.get_input_port())
    return scene, first_send


def decode_image_utime(data: bytes) -> np.ndarray:
    """``[header.utime]`` [us] of an encoded ``lcmt_image_array``, read from the wire
    format alone (the images are not decoded). ValueError if ``data`` is not one."""
    if data[: len(_IMAGE_FINGERPRINT)] != _IMAGE_FINGERPRINT:
        raise ValueError("not an lcmt_image_array (its fingerprint differs)")
    _seq, utime = _HEADER.unpack_from(data, len(_IMAGE_FINGERPRINT))
    return np.array([float(utime)])


def subscribe_images(
    builder: DiagramBuilder, channel: str, interface: LcmInterfaceSystem
) -> tuple[OutputPort, OutputPort]:
    """The image channel's colour image (``LcmImageArrayToImages``) and its capture
    ``utime`` [us] (a second subscriber reading the header alone; -1 before a first
    image)."""
    images = builder.AddNamedSystem(
        "camera_subscriber",
        LcmSubscriberSystem.Make(channel, lcmt_image_array, interface, use_cpp_serializer=True),
    )
    to_images = builder.AddNamedSystem("lcm_to_images", LcmImageArrayToImages())
    builder.Connect(images.get_output_port(), to_images.image_array_t_input_port())
    stamps = builder.AddNamedSystem(
        "camera_utime_subscriber",
        LcmSubscriberSystem(
            channel,
            VectorSerializer("lcmt_image_array.header", decode_image_utime, np.array([-1.0])),
            interface,
            0.0,
        ),
    )
    return to_images.color_image_output_port(), stamps.get_output_port()


class SelfFilter:
    """The robot self-filter: ``plant`` (the arm alone, out of the diagram), its
    ``scene_graph``, ``positions`` (MultibodyPositionToGeometryPose's input: the joints
    to draw), ``rgbd`` (whose ``label_image_output_port`` marks the arm's pixels with
    its bodies' indices) and ``labels`` (those indices)."""

    def __init__(self, plant, scene_graph, positions, rgbd, labels) -> None:
        self.plant, self.scene_graph, self.positions = plant, scene_graph, positions
        self.rgbd, self.labels = rgbd, labels


def add_self_filter(
    builder: DiagramBuilder, resolved: ResolvedScenario, model: ArmModel
) -> SelfFilter:
    """A SceneGraph holding the arm's model alone (its visual geometry, no target, no
    world), posed from joint positions by ``MultibodyPositionToGeometryPose``, drawn by
    the scenario's camera on the arm's camera frame: the label image of the arm's own
    pixels, as the station's camera sees them at the same joints."""
    scene_graph = builder.AddNamedSystem("self_filter_scene_graph", SceneGraph())
    # Kept out of the diagram (no state): it only registers the arm's geometry and
    # turns joints into the geometry's poses.
    plant = MultibodyPlant(time_step=0.0)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    instance, camera = add_arm(plant, model)
    plant.Finalize()
    perceive_collision_shapes(plant, scene_graph, instance)
    add_scene_renderer(scene_graph)
    to_pose = builder.AddNamedSystem(
        "self_filter_poses", MultibodyPositionToGeometryPose(plant, input_multibody_state=False)
    )
    builder.Connect(
        to_pose.get_output_port(), scene_graph.get_source_pose_port(plant.get_source_id())
    )
    rgbd = _rgbd(
        builder,
        "self_filter_camera",
        resolved,
        plant,
        scene_graph,
        camera.body(),
        camera.GetFixedPoseInBodyFrame(),
    )
    labels = [int(i) for i in plant.GetBodyIndices(instance)]
    return SelfFilter(plant, scene_graph, to_pose.get_input_port(), rgbd, labels)


def add_masked_image(
    builder: DiagramBuilder, color: OutputPort, self_filter: SelfFilter, width: int, height: int
) -> OutputPort:
    """``SelfMask``: ``color`` with the self-filter's arm pixels painted the background."""
    mask = builder.AddNamedSystem("self_mask", SelfMask(width, height, self_filter.labels))
    builder.Connect(color, mask.color_image_input)
    builder.Connect(self_filter.rgbd.label_image_output_port(), mask.label_image_input)
    return mask.masked_color_image_output


#: ImageFeatureFrames' state: the last image's utime handled [us], whether a good y has
#: come, frames failed in a row, the code of the last frame, the capture utime of the
#: held y [us] (a failed frame keeps the last good y and its capture), then y (13).
_S_UTIME, _S_HAS_Y, _S_LOST, _S_CODE, _S_CAPTURE = 0, 1, 2, 3, 4
_S_Y = slice(5, 5 + FRAME_Y.stop)
_S_SIZE = _S_Y.stop


class ImageFeatureFrames(LeafSystem):
    """The image channel's frames as the tracker's frames: y extracted once per new image.

    Inputs ``image_utime`` (the latest image's capture ``[utime]`` [us], -1 before
    one), ``masked_color_image`` (that image with the arm's pixels masked),
    ``status_utime`` [s] and ``arm_state`` (the latest status's). Every ``period`` (the
    status rate) it keeps each new status's joints by their utime (``history`` of
    them: the camera's delay and :data:`IMAGE_HISTORY` more), and on a new image
    extracts y from the masked image (``FeatureExtractor``'s kernel, ``intrinsics``
    the believed camera, optional ``pixel_noise`` drawn from ``seed`` and the frame's
    index as the extractor does);
    a failed frame keeps the last good y and counts one more lost, and the frame is
    not valid once more than ``max_lost_frames`` have failed in a row (or none has
    succeeded).

    Outputs: ``capture_positions``, the joints of the latest status not after the
    latest image's capture (the self-filter draws the arm there: the arm where the
    image shows it); ``frame``, the last image's frame as the vector of
    :func:`~geovs_drake.hardware.messages.frame_vector` (utime the capture of its y,
    which a failed frame's holds from the last good one; size; then y, ``[valid, code,
    lost]`` and the image's index ``round((capture - offset) / camera_period)``), NaN
    before the first image. Why not the ``FeatureExtractor`` system itself: it
    reads its input on its own clock, which in another process is not the camera's;
    this reads an image when it arrives.
    """

    def __init__(
        self,
        intrinsics,
        num_joints: int,
        period: float,
        camera_period: float,
        offset: float = 0.0,
        max_lost_frames: int = 3,
        pixel_noise: float = 0.0,
        seed: int = 0,
        marks: TargetMarks | None = None,
        history: int = IMAGE_HISTORY,
    ) -> None:
        super().__init__()
        self._history_size = history
        self._intrinsics = intrinsics
        self._nq = num_joints
        self._row = 1 + num_joints
        self._camera_period, self._offset = camera_period, offset
        self._max_lost = max_lost_frames
        self._noise, self._seed = pixel_noise, seed
        self._arrow_angle = (marks or TargetMarks()).arrow_angle
        size = (intrinsics.width, intrinsics.height)
        self.image_utime_input = self.DeclareAbstractInputPort(
            "image_utime", AbstractValue.Make(np.array([-1.0]))
        )
        self.masked_color_image_input = self.DeclareAbstractInputPort(
            "masked_color_image", AbstractValue.Make(ImageRgba8U(*size))
        )
        self.status_utime_input = self.DeclareVectorInputPort("status_utime", 1)
        self.arm_state_input = self.DeclareVectorInputPort("arm_state", 2 * num_joints)
        self._history = self.DeclareDiscreteState(np.full(history * self._row, -1.0))
        self._head = self.DeclareDiscreteState(1)
        initial = np.zeros(_S_SIZE)
        initial[_S_UTIME] = -1.0
        initial[_S_Y] = math.nan
        self._state = self.DeclareDiscreteState(initial)
        self._frame = self.DeclareDiscreteState(
            np.full(frame_vector_size(FRAME_VALUE_SIZE), math.nan)
        )
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.capture_positions_output = self.DeclareVectorOutputPort(
            "capture_positions",
            num_joints,
            self._capture_positions,
            prerequisites_of_calc={
                self.image_utime_input.ticket(),
                self.status_utime_input.ticket(),
                self.arm_state_input.ticket(),
                self.xd_ticket(),
            },
        )
        self.frame_output = self.DeclareAbstractOutputPort(
            "frame",
            lambda: AbstractValue.Make(np.full(frame_vector_size(FRAME_VALUE_SIZE), math.nan)),
            self._frame_out,
            prerequisites_of_calc={self.xd_ticket()},
        )

    def _rows(self, context: Context) -> np.ndarray:
        """The kept (utime [s], q) rows and the latest status's, if new."""
        rows = context.get_discrete_state(self._history).get_value().reshape(-1, self._row)
        utime = float(self.status_utime_input.Eval(context)[0])
        if utime > 0:
            q = self.arm_state_input.Eval(context)[: self._nq]
            rows = np.vstack([rows, np.concatenate([[utime], q])])
        return rows[rows[:, 0] >= 0]

    def _capture_positions(self, context: Context, output) -> None:
        capture = float(self.image_utime_input.Eval(context)[0]) / US_PER_S
        rows = self._rows(context)
        if len(rows) == 0:  # nothing yet: the arm's zero configuration (no image either)
            output.SetFromVector(np.zeros(self._nq))
            return
        before = rows[rows[:, 0] <= capture + CAPTURE_SLACK_US / US_PER_S]
        pick = before[np.argmax(before[:, 0])] if len(before) else rows[np.argmin(rows[:, 0])]
        output.SetFromVector(pick[1:])

    def _update(self, context: Context, discrete_state) -> None:
        utime = float(self.status_utime_input.Eval(context)[0])
        history = discrete_state.get_mutable_vector(self._history).get_mutable_value()
        head = int(context.get_discrete_state(self._head).get_value()[0])
        last = history[((head - 1) % self._history_size) * self._row]
        if utime > 0 and utime != last:
            row = head * self._row
            history[row] = utime
            history[row + 1 : row + self._row] = self.arm_state_input.Eval(context)[: self._nq]
            discrete_state.get_mutable_vector(self._head).SetAtIndex(
                0, (head + 1) % self._history_size
            )
        s = context.get_discrete_state(self._state).get_value().copy()
        image_utime = float(self.image_utime_input.Eval(context)[0])
        if image_utime < 0 or image_utime == s[_S_UTIME]:
            return
        if len(self._rows(context)) == 0:
            # No joints yet to draw the arm at (the first status, utime 0, counts as
            # none, as the tracker counts it): the image waits for the next status.
            return
        # A new image, masked at the joints of its capture (capture_positions reads this
        # update's inputs: the status that came with it counts).
        capture = image_utime / US_PER_S
        index = int(round((capture - self._offset) / self._camera_period))
        noise = None
        if self._noise > 0:
            noise = np.random.default_rng([self._seed, index])
        image = self.masked_color_image_input.Eval(context)
        y, code = extract_features(
            image.data, self._intrinsics, self._arrow_angle, noise, self._noise
        )
        s[_S_UTIME] = image_utime
        if y is None:
            s[_S_CODE], s[_S_LOST] = float(code), s[_S_LOST] + 1
        else:
            s[_S_Y], s[_S_HAS_Y], s[_S_CODE], s[_S_LOST] = y, 1.0, float(FEATURE_OK), 0.0
            s[_S_CAPTURE] = image_utime
        valid = 1.0 if s[_S_HAS_Y] > 0 and s[_S_LOST] <= self._max_lost else 0.0
        frame = np.empty(frame_vector_size(FRAME_VALUE_SIZE))
        # The held y's capture: a failed image's frame carries the last good y, taken then.
        frame[FRAME_UTIME] = s[_S_CAPTURE] if s[_S_HAS_Y] > 0 else image_utime
        frame[FRAME_SIZE] = FRAME_VALUE_SIZE
        value = frame[FRAME_VALUE_START:]
        value[FRAME_Y] = s[_S_Y]
        value[FRAME_STATUS] = [valid, s[_S_CODE], s[_S_LOST]]
        value[FRAME_INDEX] = index
        discrete_state.get_mutable_vector(self._state).SetFromVector(s)
        discrete_state.get_mutable_vector(self._frame).SetFromVector(frame)

    def _frame_out(self, context: Context, output: AbstractValue) -> None:
        output.set_value(context.get_discrete_state(self._frame).get_value().copy())
