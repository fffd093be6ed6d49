"""The camera's frame clock (issue 31): Drake's CameraConfig timing, ``capture_offset`` and
``output_delay``. A frame taken at ``capture_offset + k / rate`` reaches the law
``output_delay`` later; before the first, the loop waits. Checked against the exact
camera (the geometry) at the capture and at the read, in running loops."""

import math

import numpy as np
import pytest

from geovs_drake.goal.camera_fit import camera_fit
from geovs_drake.loop import build_loop, resolve
from geovs_drake.loop.sensors import camera_config, vtk_camera_info
from geovs_drake.scenario import load_scenario
from geovs_drake.simulation import simulate
from geovs_drake.simulation.monitor import make_simulator
from geovs_drake.systems import FrameWait

#: A start that moves fast (so that a frame's capture and its read show different images).
MOVING = "initial_velocity: [0.2, -0.1, 0.3, 0.05, 0.02, -0.03]"
CAPTURE_OFFSET, OUTPUT_DELAY = 0.01, 0.02
#: Half a millisecond: before and after an event, far from the next.
JUST = 5e-4


def _loop(sensor: str, start: str = MOVING, **fields):
    text = ", ".join(f"{k}: {v}" for k, v in fields.items())
    loop = build_loop(load_scenario(data=f"{{{start}, sensor: !{sensor} {{{text}}}}}"), log=False)
    simulator, _ = make_simulator(loop)
    return loop, simulator


def _eval(port, root):
    return np.array(port.Eval(port.get_system().GetMyContextFromRoot(root)))


def test_a_frame_read_after_its_delay_shows_the_pose_at_its_capture():
    """The pinhole's y read at c + d + k T is the exact camera's y at c + k T (to
    rounding), not the one at the read; before the first read the loop is waiting."""
    loop, simulator = _loop(
        "Pinhole", capture_offset=CAPTURE_OFFSET, output_delay=OUTPUT_DELAY, prediction="none"
    )
    root = simulator.get_mutable_context()
    sensor, exact = loop.feature_sensor, loop.camera.image_features_output
    period = 1.0 / loop.resolved.config.sensor.rate
    for k in range(3):
        simulator.AdvanceTo(CAPTURE_OFFSET + k * period)
        at_capture = _eval(exact, root)
        if k == 0:  # taken, not yet arrived: waiting
            simulator.AdvanceTo(CAPTURE_OFFSET + OUTPUT_DELAY - JUST)
            np.testing.assert_array_equal(_eval(sensor.feature_status_output, root), [0, 0, 0])
            assert np.all(np.isnan(_eval(sensor.image_features_output, root)))
        simulator.AdvanceTo(CAPTURE_OFFSET + OUTPUT_DELAY + k * period + JUST)
        y, now = _eval(sensor.image_features_output, root), _eval(exact, root)
        np.testing.assert_allclose(y, at_capture, rtol=0, atol=1e-12)
        assert np.abs(y - now).max() > 1e-3  # the rig has moved since the capture
        np.testing.assert_array_equal(_eval(sensor.feature_status_output, root), [1, 0, 0])


@pytest.mark.parametrize(
    ("capture_offset", "output_delay", "latency_frames"), [(0.01, 0.02, 0), (0.0, 0.005, 2)]
)
def test_the_predictor_moves_each_frame_from_its_capture(
    capture_offset, output_delay, latency_frames
):
    """With odometry prediction the law's y is the exact camera's at every time once a
    frame has arrived (a Smith predictor is exact for a still target): the predictor
    moves each frame from the pose held with it, not the pose at its read; before the
    first frame the law sees the goal image (FrameWait)."""
    loop, simulator = _loop(
        "Pinhole",
        capture_offset=capture_offset,
        output_delay=output_delay,
        latency_frames=latency_frames,
    )
    root = simulator.get_mutable_context()
    period = 1.0 / loop.resolved.config.sensor.rate
    first = capture_offset + output_delay + latency_frames * period
    goal = np.asarray(loop.resolved.y_goal)
    for t in np.arange(0.003, 0.3, 0.0071):  # never on an event
        simulator.AdvanceTo(t)
        law_y, exact = _eval(loop.features, root), _eval(loop.camera.image_features_output, root)
        if t < first:
            np.testing.assert_array_equal(law_y, goal)
        else:
            np.testing.assert_allclose(law_y, exact, rtol=0, atol=1e-12)


def test_the_rendered_frame_is_drawn_at_its_capture():
    """The rendered camera draws at the capture and the extractor reads that image
    output_delay later: its marked point is the one at the capture, not at the read."""
    # Turning at 1 rad/s: 30 mrad between the capture and the read, 50 times the
    # extractor's error on q1 (about 0.1 px, 6e-4 rad at 320x240).
    spin = "initial_velocity: [1.0, -0.5, 0.5, 0.05, 0.02, -0.03]"
    delay = 0.03
    loop, simulator = _loop(
        "Rendered", spin, capture_offset=CAPTURE_OFFSET, output_delay=delay, prediction="none"
    )
    root = simulator.get_mutable_context()
    q1 = slice(0, 3)  # the marked point's direction, the extractor's sharpest output
    period = 1.0 / loop.resolved.config.sensor.rate
    for k in range(2):
        simulator.AdvanceTo(CAPTURE_OFFSET + k * period)
        at_capture = _eval(loop.camera.image_features_output, root)[q1]
        simulator.AdvanceTo(CAPTURE_OFFSET + delay + k * period + JUST)
        y = _eval(loop.feature_sensor.image_features_output, root)[q1]
        now = _eval(loop.camera.image_features_output, root)[q1]
        assert np.linalg.norm(y - at_capture) < 0.2 * np.linalg.norm(y - now)


def test_the_camera_config_is_the_camera_the_renderer_draws():
    """Drake's CameraConfig of the scenario makes the camera of vtk_camera_info (the
    intrinsics in RenderEngineVtk's pixel convention) with the scenario's clock."""
    text = "{sensor: !Rendered {rate: 15, capture_offset: 0.02, output_delay: 0.01}}"
    resolved = resolve(load_scenario(data=text))
    config = camera_config(resolved)
    color, _ = config.MakeCameras()
    got = color.core().intrinsics()
    cam = resolved.config.sensor
    want = vtk_camera_info(cam.intrinsics(resolved.domain.fov_half_angle))
    assert (got.width(), got.height()) == (want.width(), want.height())
    for name in ("focal_x", "focal_y", "center_x", "center_y"):
        assert getattr(got, name)() == pytest.approx(getattr(want, name)(), abs=1e-12)
    assert (config.fps, config.capture_offset, config.output_delay) == (15, 0.02, 0.01)


def test_frame_wait_gives_the_goal_until_the_first_frame():
    wait = FrameWait(np.arange(13.0))
    context = wait.CreateDefaultContext()
    y = np.linspace(-1, 1, 13)
    wait.image_features_input.FixValue(context, np.full(13, math.nan))
    for status, want in (([0, 0, 0], np.arange(13.0)), ([1, 0, 0], y), ([0, 2, 4], y)):
        if status != [0, 0, 0]:
            wait.image_features_input.FixValue(context, y)
        wait.feature_status_input.FixValue(context, status)
        np.testing.assert_array_equal(wait.image_features_or_goal_output.Eval(context), want)


def test_the_gain_fit_counts_a_sub_frame_delay_as_a_frame():
    """The sampled-data model has whole frames of latency: an output delay is counted
    as one more (the safe side: more delay, less margin)."""
    base = "{sensor: !Pinhole {prediction: none, latency_frames: 1%s}}"
    plain = resolve(load_scenario(data=base % "")).camera_fit
    delayed = resolve(load_scenario(data=base % ", output_delay: 0.01")).camera_fit
    two = camera_fit(resolve(load_scenario(data=base.replace("1%s", "2") % ())))
    assert (plain.latency_frames, delayed.latency_frames) == (1, 2)
    assert delayed.spectral_radius == pytest.approx(two.spectral_radius, rel=1e-12)
    assert delayed.spectral_radius > plain.spectral_radius


def test_a_loop_that_waits_for_its_first_frame_converges():
    """The pinhole loop, first frame 30 ms late, from the default start: it holds, then
    converges as the camera's loop does, inside D."""
    text = "{sensor: !Pinhole {capture_offset: 0.01, output_delay: 0.02}, duration: 6}"
    result = simulate(load_scenario(data=text))
    assert result.status == "converged", result.message
    assert result.lyapunov_monotone


@pytest.mark.parametrize(
    ("field", "value"), [("output_delay", 0.04), ("capture_offset", -0.01), ("output_delay", "nan")]
)
def test_a_delay_of_a_frame_or_more_is_one_line(run_cli, field, value):
    run = run_cli("simulate", "--sensor", "pinhole", "--scenario-text",
                  f"{{sensor: !Pinhole {{{field}: {value}}}}}")  # fmt: skip
    assert run.code == 2
    lines = run.err.strip().splitlines()
    assert len(lines) == 1 and f"sensor.{field} must be in [0, 1/rate = 0.03333)" in lines[0]


def test_the_estimator_refuses_a_frame_clock_it_cannot_pair(run_cli):
    """The moving target's estimator pairs frames with poses on the k / rate clock: a
    delayed frame clock is one line naming the fields and the remedy."""
    text = (
        "{sensor: !Pinhole {output_delay: 0.01}, target_motion: !Twist "
        "{twist: [0, 0, 0.2, 0.05, 0, 0], feedforward: estimated}}"
    )
    run = run_cli("simulate", "--scenario-text", text)
    assert run.code == 2
    lines = run.err.strip().splitlines()
    assert len(lines) == 1 and "set sensor.capture_offset and sensor.output_delay to 0" in lines[0]
    assert "output_delay = 0.01" in lines[0]
    known = load_scenario(data=text.replace("estimated", "known"))  # needs no frames
    known.validate()
    assert known.target_motion.feedforward == "known"
