"""The loop closed through a camera: rendering convention, extraction accuracy, the sampled
sensors' hold, latency and failure status, and the rendered closed loop.

Truths used: the pinhole projection of a sphere on the optical axis (where a renderer
must put it), the exact camera map c(H) at the rendered pose, the exact projection of
the marks (for tolerances in pixels), and the noise-free pinhole loop, which makes the
same measurement without a renderer.
"""

import copy
import json
import math

import numpy as np
import pytest
from pydrake.geometry import (
    ClippingRange,
    ColorRenderCamera,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import RgbdSensor

from geovs_drake.analysis.studies.camera_accuracy import feature_accuracy
from geovs_drake.cli import exit_code_of, main
from geovs_drake.geometry.camera import camera_map, camera_map_inverse
from geovs_drake.geometry.features import FEATURE_FAILURES, TargetMarks
from geovs_drake.geometry.pinhole import PinholeIntrinsics
from geovs_drake.loop import build_loop
from geovs_drake.loop.sensors import vtk_camera_info
from geovs_drake.loop.state import initial_rig_state
from geovs_drake.scenario import Pinhole, Rendered, ScenarioConfig
from geovs_drake.simulation import make_simulator, simulate
from geovs_drake.systems import FeatureExtractor, PinholeFeatureSensor
from geovs_drake.systems.feature_extractor import extract_features
from geovs_drake.systems.kinematic_rigid_body import pose_state

RES = (320, 240)


def test_vtk_renders_the_optical_axis_at_the_principal_point():
    """A sphere straight ahead lands, centroid for centroid, on (cx, cy) of the intrinsics
    (pixel centres at integers) that ``vtk_camera_info`` hands the renderer."""
    camera = PinholeIntrinsics(161, 120, 150.0, 150.0, 70.3, 61.8)  # off-centre, odd width
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    scene_graph.AddRenderer(
        "vtk",
        MakeRenderEngineVtk(RenderEngineVtkParams(backend="EGL", default_clear_color=[0, 0, 1])),
    )
    plant.RegisterVisualGeometry(
        plant.world_body(), RigidTransform([0, 0, 1.0]), Sphere(0.05), "ball", [1, 1, 1, 1]
    )
    plant.Finalize()
    core = RenderCameraCore(
        "vtk", vtk_camera_info(camera), ClippingRange(0.1, 10.0), RigidTransform()
    )
    sensor = builder.AddSystem(
        RgbdSensor(
            scene_graph.world_frame_id(),
            RigidTransform(),
            ColorRenderCamera(core, False),
            DepthRenderCamera(core, DepthRange(0.11, 9.0)),
        )
    )
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    diagram = builder.Build()
    context = sensor.GetMyContextFromRoot(diagram.CreateDefaultContext())
    rgba = np.asarray(sensor.color_image_output_port().Eval(context).data, dtype=float)
    coverage = 1 - np.clip(rgba[..., 2] - np.maximum(rgba[..., 0], rgba[..., 1]), 0, 255) / 255
    v, u = np.mgrid[0 : camera.height, 0 : camera.width]
    centroid = np.array([(coverage * u).sum(), (coverage * v).sum()]) / coverage.sum()
    np.testing.assert_allclose(centroid, [camera.cx, camera.cy], atol=0.02)


def test_extracted_features_match_the_camera_map_to_a_fraction_of_a_pixel():
    """20 poses in D at 320x240; tolerances in pixels of this camera (1/f rad each)."""
    result = feature_accuracy(n=20, resolution=RES, seed=11, shrink=0.9)
    ok = result.codes == 0
    assert ok.sum() >= 16, result.summary()["failures"]
    camera = Pinhole().intrinsics(math.radians(35.0))
    f = camera.fx
    exact, errors = result.exact[ok], {k: v[ok] for k, v in result.errors.items()}
    # lambda: the silhouette's radius r = f tan(arcsin lambda) [px] within 0.2 px.
    radius_px = f * np.tan(np.arcsin(exact[:, 9]))
    assert np.all(errors["lambda_rel"] * radius_px <= 0.2)
    # s from hundreds of edge points: 0.2 px; q1 from one centroid: 0.75 px.
    assert np.all(errors["s_rad"] * f <= 0.2)
    assert np.all(errors["q1_rad"] * f <= 0.75)
    # q2 from the two marks' centroids: 0.75 px over their separation in the image.
    X_CB = camera_map_inverse(exact, 0.1)
    b_B, m_B = TargetMarks().points_B(0.1)
    b = X_CB[:, :3, 3] + X_CB[:, :3, :3] @ b_B
    m = X_CB[:, :3, 3] + X_CB[:, :3, :3] @ m_B
    separation = np.linalg.norm(camera.ray_to_pixel(b) - camera.ray_to_pixel(m), axis=-1)
    assert np.all(errors["q2_rad"] * separation <= 0.75)
    # The failures are the marks too small to find, never a wrong y.
    assert set(result.codes[~ok]) <= {3, 4}


def test_a_frame_without_the_target_is_a_status_not_a_y():
    camera = PinholeIntrinsics.for_fov(*RES, math.radians(35.0), 2.0)
    blank = np.zeros((RES[1], RES[0], 4), dtype=np.uint8)
    blank[..., 2] = 255  # the background alone
    assert extract_features(blank, camera, 0.2) == (None, 1)
    cut = blank.copy()
    cut[100:140, 0:30, :3] = 200  # grey touching the left border
    y, code = extract_features(cut, camera, 0.2)
    assert y is None and FEATURE_FAILURES[code] == "sphere cut by the image border"


def _pinhole_sensor(latency: int) -> PinholeFeatureSensor:
    camera = PinholeIntrinsics.for_fov(*RES, math.radians(35.0), 2.0)
    return PinholeFeatureSensor(radius=0.1, intrinsics=camera, period=0.1, latency_frames=latency)


def test_latency_delays_the_held_y_by_whole_frames():
    sensor = _pinhole_sensor(latency=2)
    simulator = Simulator(sensor)
    context = simulator.get_mutable_context()
    rng = np.random.default_rng(3)
    # Camera poses X_WC (the target at the origin of W): a wander in front of it.
    poses = [
        RigidTransform([rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02), -0.6 + 0.02 * k])
        for k in range(6)
    ]
    expected = [camera_map(X.inverse(), 0.1).to_vector() for X in poses]
    outputs = []
    for k, X in enumerate(poses):
        sensor.body_pose_input.FixValue(context, pose_state(X))
        if k == 0:
            simulator.Initialize()
        else:
            simulator.AdvanceTo(0.1 * k)
        outputs.append(sensor.image_features_output.Eval(context).copy())
        assert list(sensor.feature_status_output.Eval(context)) == [1.0, 0.0, 0.0]
    # Frame k holds the measurement of frame k - 2 (the first frame fills the line).
    for k in range(6):
        np.testing.assert_allclose(outputs[k], expected[max(0, k - 2)], atol=1e-9)


def test_a_lost_feature_holds_the_last_y_and_stops_the_run():
    sensor = _pinhole_sensor(latency=0)  # max_lost_frames = 3 by default
    simulator = Simulator(sensor)
    context = simulator.get_mutable_context()
    seen = RigidTransform([0.0, 0.0, -0.6])
    sensor.body_pose_input.FixValue(context, pose_state(seen))
    simulator.Initialize()
    good = sensor.image_features_output.Eval(context).copy()
    # Turned to face away: the marked point is behind the sphere.
    away = RigidTransform(RotationMatrix.MakeXRotation(math.pi), [0.0, 0.0, 0.6])
    sensor.body_pose_input.FixValue(context, pose_state(away))
    for k in range(1, 5):
        simulator.AdvanceTo(0.1 * k)
        valid, code, lost = sensor.feature_status_output.Eval(context)
        assert "marked point not found" in FEATURE_FAILURES[int(code)] and lost == k
        assert valid == (1.0 if k <= 3 else 0.0)  # usable through 3 lost frames, not 4
        np.testing.assert_array_equal(sensor.image_features_output.Eval(context), good)
    # Seen again: valid, nothing lost, a new y.
    sensor.body_pose_input.FixValue(context, pose_state(seen @ RigidTransform([0.01, 0, 0])))
    simulator.AdvanceTo(0.5)
    assert list(sensor.feature_status_output.Eval(context)) == [1.0, 0.0, 0.0]
    assert not np.array_equal(sensor.image_features_output.Eval(context), good)
    # In a loop the monitor stops the run and names why: an arrow mark 1.5 rad from b
    # is past the limb seen from the default start.
    config = ScenarioConfig(sensor=Pinhole())
    loop = build_loop(config, log=False)
    diagram = loop.diagram
    simulator, monitor = make_simulator(loop)
    sensor = diagram.GetSubsystemByName("feature_sensor")
    params = sensor.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    p = params.get_mutable_numeric_parameter(0)
    values = p.CopyToVector()
    values[33] = 1.5  # arrow_angle
    p.SetFromVector(values)
    simulator.Initialize()
    status, message = monitor.termination()
    assert status == "feature_lost" and "arrow mark not found" in message  # never seen


@pytest.fixture(scope="module")
def short_runs():
    """The default start, 1.2 s, through the rendered and the noise-free pinhole loops."""
    config = ScenarioConfig(duration=1.2)
    runs = {}
    for name, sensor in (("rendered", Rendered()), ("pinhole", Pinhole())):
        c = copy.deepcopy(config)
        c.sensor = sensor
        runs[name] = simulate(c)
    return runs


def test_the_rendered_loop_follows_the_pinhole_loop(short_runs):
    rendered, pinhole = short_runs["rendered"], short_runs["pinhole"]
    assert rendered.status == pinhole.status == "not_converged"  # 1.2 s: on its way
    assert rendered.phi[-1] < 0.5 * rendered.phi[0]
    # Same measurement, with and without a renderer: the trajectories agree to what the
    # camera resolves (measured: 0.6 mm and 0.01 rad; the exact loop is 31 mm and 0.7 rad
    # away from both, its damping differs).
    dp = np.linalg.norm(rendered.X_BC[:, :3, 3] - pinhole.X_BC[:, :3, 3], axis=-1)
    assert dp.max() < 2e-3
    R = np.einsum("nji,njk->nik", rendered.X_BC[:, :3, :3], pinhole.X_BC[:, :3, :3])
    angle = np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1, 1))
    assert angle.max() < 0.03


def test_the_rendered_diagram_is_named_and_wired():
    config = ScenarioConfig(sensor=Rendered(rate=15.0, resolution=[160, 120]))
    diagram = build_loop(config).diagram
    assert diagram.get_name() == "rendered_visual_servo"
    extractor = diagram.GetSubsystemByName("feature_sensor")
    root = diagram.CreateDefaultContext()
    plant = diagram.GetSubsystemByName("plant")
    plant.SetPositionsAndVelocities(
        plant.GetMyMutableContextFromRoot(root), initial_rig_state(config)
    )
    rgbd = diagram.GetSubsystemByName("rgbd_sensor")
    image = rgbd.color_image_output_port().Eval(rgbd.GetMyContextFromRoot(root))
    assert (image.width(), image.height()) == (160, 120)
    # The camera's own drawing is not in its image: the corners are background.
    data = np.asarray(image.data)
    assert np.all(data[[0, 0, -1, -1], [0, -1, 0, -1], :3] == [0, 0, 255])
    believed = extractor.believed_intrinsics(extractor.GetMyContextFromRoot(root))
    y, code = extract_features(data, believed, TargetMarks().arrow_angle)
    assert code == 0
    np.testing.assert_allclose(y[9], config.initial_features().lam, rtol=0.02)


def test_docstrings_list_ports():
    camera = PinholeIntrinsics.for_fov(*RES, math.radians(35.0), 2.0)
    for system in (FeatureExtractor(intrinsics=camera), _pinhole_sensor(latency=1)):
        doc = type(system).__doc__
        assert ".. pydrake_system::" in doc
        for port in [system.get_input_port(i) for i in range(system.num_input_ports())] + [
            system.get_output_port(i) for i in range(system.num_output_ports())
        ]:
            assert f"- {port.get_name()}" in doc


# ------------------------------------------------------------------ the CLI
def test_simulate_with_a_camera_from_the_command_line(capsys):
    code = main(["simulate", "--sensor", "pinhole", "--duration", "4", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads(out)
    assert summary["sensor"] == "pinhole" and summary["status"] == "converged"
    assert summary["camera"]["resolution"] == [320, 240] and summary["camera"]["rate_hz"] == 30
    # The camera's tolerance (2 px at the goal's 0.5 m, 5 pixel angles), not 1 mm / 1 mrad.
    f = Pinhole().intrinsics(math.radians(35.0)).fx
    assert summary["tolerance_position_m"] == pytest.approx(2 * 0.5 / f)
    assert summary["tolerance_rotation_rad"] == pytest.approx(5 / f)
    code = main(["simulate", "--sensor", "rendered", "--duration", "0.3", "--camera-rate", "20"])
    out, err = capsys.readouterr()
    assert code == 3, err  # ran, not converged in 0.3 s
    assert out.startswith("nf on the dynamic plant, rendered camera 320x240 at 20 Hz: ")


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--resolution", "320"], "expected WxH"),
        (["--resolution", "8x8"], "expected WxH"),
        (["--sensor", "pinhole", "--camera-rate", "0"], "--camera-rate must be"),
        (["--sensor", "webcam"], "invalid choice"),
    ],
)
def test_bad_camera_options_are_one_line_errors(argv, needle, capsys):
    try:
        code = main(["simulate", *argv])
    except SystemExit as e:  # argparse's own errors
        code = e.code
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and needle in err, err


def test_feature_lost_exits_3():
    assert exit_code_of("feature_lost") == 3


def test_the_kinematic_free_rig_draws_its_scene_for_the_rendered_camera():
    """The velocity-commanded free rig with the rendered camera (it had no scene to
    render: a traceback): a plant with no dynamics draws the scene at the body's pose,
    and the loop converges from the small move as the pinhole's does."""
    from geovs_drake.scenario import load_scenario
    from geovs_drake.simulation import simulate

    text = "{plant: !Kinematic {}, initial: {xyz: [0.05, -0.03, -0.55], rpy: [0.1, -0.05, 0.3]}, "
    results = {
        kind: simulate(load_scenario(data=text + f"sensor: !{kind} {{}}, duration: 3}}"))
        for kind in ("Rendered", "Pinhole")
    }
    rendered, pinhole = results["Rendered"], results["Pinhole"]
    assert rendered.status == pinhole.status == "converged", rendered.message
    # The rendered camera's y is the pinhole's within the extractor's error: the same
    # path to within a few millimetres.
    assert np.abs(rendered.position_errors - pinhole.position_errors).max() < 5e-3
