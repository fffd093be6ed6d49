"""The rendered camera over LCM (issue 34): the station renders the scene and publishes
its colour image (``lcmt_image_array``); the controller extracts y from it with the
arm's own pixels masked by a self-filter (the arm's model alone, drawn at the joints
of the frame's capture). The truths: the station's exact camera (y = c(X_CB) of its
true pose at the capture), the station's own label image of the scene, and its pose
error from the goal.

Station and controller share one Simulator on ``memq://`` (as tests/test_hardware.py).
"""

from __future__ import annotations

import importlib.metadata

import numpy as np
import pytest
from drake import lcmt_image_array
from pydrake.lcm import DrakeLcm
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.lcm import LcmInterfaceSystem, LcmSubscriberSystem

from geovs_drake.geometry.camera import camera_map
from geovs_drake.hardware.controller import build_controller
from geovs_drake.hardware.images import add_self_filter, decode_image_utime
from geovs_drake.hardware.run import load_setup, lockstep
from geovs_drake.hardware.station import build_station
from geovs_drake.simulation.result import pose_error

try:
    importlib.metadata.distribution("example-robot-data")
    importlib.metadata.distribution("opencv-python-headless")
except importlib.metadata.PackageNotFoundError:
    pytest.skip("needs the panda and vision extras", allow_module_level=True)

#: The issue's small move.
SMALL_MOVE = {"xyz": [0.05, -0.03, -0.55], "rpy": [0.1, -0.05, 0.3]}
RENDERED = "sensor: !Rendered {}"
#: The frame compared with the station's exact camera (its index at 30 Hz) and how long
#: after its capture the controller has extracted it [s] (the image arrives with the
#: next status step, y is extracted at the one after).
FRAME_K, AFTER_CAPTURE_S = 6, 0.003
#: The short run [s] and the factor by which the camera's distance to the goal must
#: have shrunk by its end (measured: 0.0654 m at 0, 0.0476 m at 0.3 s).
SHORT_RUN_S, SHORT_SHRINK = 0.3, 0.85
#: The extractor's accuracy on q1 (the sphere's direction, a unit vector) at 320x240
#: (measured: 3e-4 to 6e-4 at the small move's frames).
Q1_TOL = 2e-3
#: The image message: RGBA 8-bit, uncompressed, at the scenario's 320x240.
IMAGE_BYTES = 320 * 240 * 4
#: A hand-made Panda configuration with the hand in its own camera's view (the start
#: q0 with joint 4 at -0.07 rad and joint 6 at 0.611: 2002 px of 76800), and the IoU the
#: self-filter's arm mask must reach against the station's.
HAND_IN_VIEW = {3: -0.07, 5: 0.611}
MASK_IOU = 0.95
#: The IoU of the arm's pixels drawn as capsules against its collision shapes one by one:
#: the same solids, tessellated differently by RenderEngineVtk at the edges (measured:
#: 0.9985, 3 pixels of 1996 differ).
CAPSULE_IOU = 0.99
#: Microsecond slack on a stamp: Drake stamps int64(t * 1e6), a truncation.
STAMP_SLACK_US = 1


def _setup(duration: float):
    return load_setup(
        None,
        [("test", {"initial": SMALL_MOVE, "duration": duration}), ("rendered", RENDERED)],
        {"lcm_url": "memq://", "real_time_rate": 0.0, "command_rate": 1000.0},
    )


def _lockstep(duration: float):
    setup = _setup(duration)
    lcm = DrakeLcm("memq://")
    heard: list[tuple[int, int]] = []
    lcm.Subscribe(
        setup.hardware.channels.image,
        lambda data: heard.append((lcmt_image_array.decode(data).header.utime, len(data))),
    )
    both = lockstep(setup, lcm)
    return setup, both.station, both.controller, both.simulator, heard


def _arm_mask(label: np.ndarray, arm_labels: list[int]) -> np.ndarray:
    return np.isin(label[..., 0], arm_labels)


def test_the_controller_extracts_the_station_camera_y_from_images_and_servos():
    setup, station, controller, simulator, heard = _lockstep(SHORT_RUN_S)
    root = simulator.get_mutable_context()
    goal = setup.resolved.config.X_BC_goal
    start_error = pose_error(station.X_BC(root), goal)[0]
    period = station.frame_period
    capture = FRAME_K * period
    simulator.AdvanceTo(capture)
    # The station's truth at the capture: its exact camera and its own label image.
    y_true = camera_map(station.X_BC(root).inverse(), setup.resolved.config.radius).to_vector()
    station_label = station.camera.label_image_output_port().Eval(
        station.camera.GetMyContextFromRoot(root)
    )
    simulator.AdvanceTo(capture + AFTER_CAPTURE_S)
    tracker = controller.tracker.GetMyContextFromRoot(root)
    held_capture, y = controller.tracker.held_frame(tracker)
    assert held_capture == pytest.approx(capture, abs=STAMP_SLACK_US * 1e-6)
    assert np.linalg.norm(y[:3] - y_true[:3]) < Q1_TOL, (y[:3], y_true[:3])
    # The self-filter drew the arm at the capture's joints: no arm pixel here, as the
    # station's own label image says (the Panda's arm is out of view on this move).
    self_filter = controller.self_filter
    filter_label = self_filter.rgbd.label_image_output_port().Eval(
        self_filter.rgbd.GetMyContextFromRoot(root)
    )
    assert not _arm_mask(station_label.data, self_filter.labels).any()
    assert not _arm_mask(filter_label.data, self_filter.labels).any()
    end = SHORT_RUN_S + AFTER_CAPTURE_S  # the last frame's capture extracted
    simulator.AdvanceTo(end)
    error = pose_error(station.X_BC(root), goal)[0]
    assert error < SHORT_SHRINK * start_error, (start_error, error)
    publisher = controller.publisher.GetMyContextFromRoot(root)
    assert controller.publisher.stop_reason(publisher) == ""
    # One image a frame, stamped with its capture, of the camera's whole RGBA image.
    stamps = np.array([u for u, _ in heard])
    expected = np.arange(len(stamps)) * period * 1e6
    assert len(stamps) == int(end / period) + 1
    assert np.all(np.abs(stamps - expected) <= STAMP_SLACK_US)
    assert all(size > IMAGE_BYTES for _, size in heard)
    link = controller.tracker.link_output.Eval(tracker)
    assert link[1] == len(stamps) and link[2] == 0  # every frame extracted, none dropped


def test_the_self_filter_marks_the_arm_where_the_station_label_image_does():
    """At a hand-made configuration with the hand in view: the self-filter (the arm's
    model alone) and the station's camera (the whole scene) label the same pixels as
    the arm's."""
    setup = _setup(1.0)
    station = build_station(setup.resolved, setup.hardware, DrakeLcm("memq://"))
    q = station.q0.copy()
    for joint, value in HAND_IN_VIEW.items():
        q[joint] = value
    root = station.diagram.CreateDefaultContext()
    station.plant.SetPositions(station.plant.GetMyMutableContextFromRoot(root), q)
    station_label = station.camera.label_image_output_port().Eval(
        station.camera.GetMyContextFromRoot(root)
    )
    builder = DiagramBuilder()
    self_filter = add_self_filter(builder, setup.resolved, station.model)
    builder.ExportInput(self_filter.positions, "q")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    diagram.get_input_port(0).FixValue(context, q)
    filter_label = self_filter.rgbd.label_image_output_port().Eval(
        self_filter.rgbd.GetMyContextFromRoot(context)
    )
    truth = _arm_mask(station_label.data, self_filter.labels)
    mask = _arm_mask(filter_label.data, self_filter.labels)
    assert truth.sum() > 0
    iou = (truth & mask).sum() / (truth | mask).sum()
    assert iou > MASK_IOU, iou


def _hand_in_view_label(setup) -> tuple[np.ndarray, int, list[int]]:
    """The station camera's arm mask at HAND_IN_VIEW, its number of perceived arm
    geometries, and the arm's labels."""
    from pydrake.geometry import Role

    station = build_station(setup.resolved, setup.hardware, DrakeLcm("memq://"))
    plant = station.plant
    q = station.q0.copy()
    for joint, value in HAND_IN_VIEW.items():
        q[joint] = value
    root = station.diagram.CreateDefaultContext()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), q)
    label = station.camera.label_image_output_port().Eval(station.camera.GetMyContextFromRoot(root))
    instance = plant.GetModelInstanceByName("arm::panda")
    labels = [int(i) for i in plant.GetBodyIndices(instance)]
    scene = station.camera_scene  # the camera's own scene: its plant's frames
    frames = {scene.plant.GetBodyFrameIdOrThrow(i) for i in plant.GetBodyIndices(instance)}
    inspector = scene.scene_graph.model_inspector()
    perceived = [
        g
        for g in inspector.GetAllGeometryIds(Role.kPerception)
        if inspector.GetFrameId(g) in frames and "Mesh" not in type(inspector.GetShape(g)).__name__
    ]
    return _arm_mask(label.data, labels), len(perceived), labels


def test_the_arm_is_perceived_as_capsules_drawing_its_collision_shapes_pixels(monkeypatch):
    """Each of the Panda's cylinder-and-two-spheres is perceived as one Capsule (the same
    solid, a third of the renderer's pose updates): at a configuration with the hand in
    view the arm's pixels are those of the 39 collision shapes perceived one by one."""
    from geovs_drake.hardware import images

    setup = _setup(1.0)
    capsules, count, _ = _hand_in_view_label(setup)
    monkeypatch.setattr(images, "_capsules", lambda inspector, shapes: ([], set()))
    shapes, shape_count, _ = _hand_in_view_label(setup)
    assert (count, shape_count) == (13, 39)
    assert shapes.sum() > 1000
    iou = (shapes & capsules).sum() / (shapes | capsules).sum()
    assert iou > CAPSULE_IOU, iou


def test_the_rendered_controller_holds_no_world_and_reads_only_lcm():
    setup = _setup(1.0)
    controller = build_controller(setup.resolved, setup.hardware, DrakeLcm("memq://"))
    systems = controller.diagram.GetSystems()
    assert not any(isinstance(s, MultibodyPlant) for s in systems)
    sources = {s.get_name() for s in systems if s.num_input_ports() == 0}
    assert all(
        isinstance(s, LcmSubscriberSystem | LcmInterfaceSystem)
        for s in systems
        if s.num_input_ports() == 0
    )
    assert sources == {
        "lcm",
        "status_subscriber",
        "camera_subscriber",
        "camera_utime_subscriber",
    }
    # The self-filter's plant (out of the diagram) is the arm alone: every body but the
    # world is one of the arm's.
    plant = controller.self_filter.plant
    assert len(controller.self_filter.labels) == plant.num_bodies() - 1


def test_a_non_image_message_is_refused_by_the_header_reader():
    message = lcmt_image_array()
    message.header.utime = 123456
    assert decode_image_utime(message.encode())[0] == 123456
    with pytest.raises(ValueError, match="not an lcmt_image_array"):
        decode_image_utime(b"\0" * 32)


#: The longer run [s] and the distance [m] the camera must be within of the goal by
#: then.
LONG_RUN_S, LONG_RUN_M = 5.0, 0.01


@pytest.mark.slow
def test_the_rendered_lcm_loop_approaches_the_goal():
    setup, station, controller, simulator, _heard = _lockstep(LONG_RUN_S)
    simulator.AdvanceTo(LONG_RUN_S)
    root = simulator.get_context()
    error = pose_error(station.X_BC(root), setup.resolved.config.X_BC_goal)[0]
    assert error < LONG_RUN_M, error
    publisher = controller.publisher.GetMyContextFromRoot(root)
    assert controller.publisher.stop_reason(publisher) == ""


def _plant_scene_colour(setup, configurations: list[np.ndarray]) -> list[np.ndarray]:
    """The colour images of the station's camera as it was built on the plant's own
    SceneGraph (the loop's arm scene with the renderer added to it, the arm perceived
    as the station perceives it), at each of ``configurations``."""
    from geovs_drake.hardware import images
    from geovs_drake.loop.carriers import add_arm_scene
    from geovs_drake.loop.sensors import add_scene_renderer

    builder = DiagramBuilder()
    _, plant, scene_graph, link, X_LinkC = add_arm_scene(builder, setup.resolved, True, True)
    add_scene_renderer(scene_graph)
    images.perceive_collision_shapes(plant, scene_graph, link.model_instance())
    rgbd = images._rgbd(builder, "rgbd", setup.resolved, plant, scene_graph, link, X_LinkC)
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    frames = []
    for q in configurations:
        plant.SetPositions(plant.GetMyMutableContextFromRoot(root), q)
        image = rgbd.color_image_output_port().Eval(rgbd.GetMyContextFromRoot(root))
        frames.append(image.data.copy())  # the cached image is drawn over at the next q
    return frames


#: Configurations of the colour image check: the start, the hand in view, and the start
#: moved by these joint offsets [rad] (the target and the arm both in view).
CONFIGURATION_OFFSETS = (
    [0.1, -0.1, 0.05, 0.1, -0.05, 0.1, 0.2],
    [-0.08, 0.05, 0, -0.1, 0.1, -0.15, 0],
)


def test_the_station_camera_draws_its_own_scene_as_the_plants_scene_graph_did():
    """The station's camera renders a SceneGraph of its own, posed from the plant's state
    at its frames only (the plant has no SceneGraph: no geometry query at every
    derivative evaluation moves a renderer's geometry); its colour image is the one the
    camera drew on the plant's SceneGraph, pixel for pixel, at several configurations."""
    setup = _setup(1.0)
    station = build_station(setup.resolved, setup.hardware, DrakeLcm("memq://"))
    assert not station.plant.geometry_source_is_registered()
    assert station.camera_scene.scene_graph.RendererCount() == 1
    hand = station.q0.copy()
    for joint, value in HAND_IN_VIEW.items():
        hand[joint] = value
    configurations = [station.q0, hand, *(station.q0 + np.array(d) for d in CONFIGURATION_OFFSETS)]
    root = station.diagram.CreateDefaultContext()
    context = station.plant.GetMyMutableContextFromRoot(root)
    camera = station.camera.GetMyContextFromRoot(root)
    truths = _plant_scene_colour(setup, configurations)
    for q, truth in zip(configurations, truths, strict=True):
        station.plant.SetPositions(context, q)
        image = station.camera.color_image_output_port().Eval(camera).data
        assert (truth[..., :3] != truth[0, 0, :3]).any(axis=-1).sum() > 1000  # a scene drawn
        assert np.array_equal(image, truth), (q, (image != truth).any(axis=-1).sum())
