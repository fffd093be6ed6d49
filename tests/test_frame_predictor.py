"""The image between frames (issue 31): FramePredictor moves the held frame by the
carrier's own motion since its capture. Checked against the geometry (the camera map of
the moved pose) and against the exact camera in a running loop, on the free rig and on
the arm, with latency."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from pydrake.math import RigidTransform, RollPitchYaw

from geovs_drake.geometry._ops import MATH
from geovs_drake.geometry.camera import camera_map, visibility
from geovs_drake.geometry.prediction import predicted_image
from geovs_drake.loop import build_loop
from geovs_drake.scenario import Arm, Pinhole, PoseConfig, ScenarioConfig
from geovs_drake.systems import FramePredictor

RHO = 0.1


def _rows(X: RigidTransform) -> tuple[tuple, tuple]:
    return tuple(X.rotation().matrix().ravel()), tuple(X.translation())


def _pose(values) -> RigidTransform:
    return RigidTransform(RollPitchYaw(values[:3]), values[3:])


small = st.floats(-0.3, 0.3)


@settings(max_examples=60, deadline=None)
@given(st.lists(small, min_size=6, max_size=6), st.lists(small, min_size=6, max_size=6))
def test_the_prediction_is_the_camera_map_of_the_moved_pose(then, motion):
    """A frame y = c(X_CB) taken from X_WR, seen after the rig moved to X_WR': the
    prediction is c(X_C'B) with X_C'B = (X_WR' X_RC)^-1 X_WR X_RC X_CB (the geometry)."""
    X_RC = _pose([0.1, -0.2, 0.3, 0.01, 0.02, -0.03])
    X_WB = RigidTransform([0.0, 0.0, 0.6])
    X_WR = _pose(then)
    X_WR_now = X_WR @ _pose(motion)
    X_CB, X_CB_now = ((X @ X_RC).inverse() @ X_WB for X in (X_WR, X_WR_now))
    assume(visibility(X_CB, RHO) > 1e-3 and visibility(X_CB_now, RHO) > 1e-3)  # both seen
    y = camera_map(X_CB, RHO).to_vector()
    expected = camera_map(X_CB_now, RHO).to_vector()
    R_then, p_then = _rows(X_WR)
    R_now, p_now = _rows(X_WR_now)
    R_RC, p_RC = _rows(X_RC)
    got = predicted_image(tuple(y), RHO, R_then, p_then, R_now, p_now, R_RC, p_RC, MATH)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    if np.linalg.norm(motion) > 1e-3:  # the held frame itself is not the image now
        assert np.abs(y - expected).max() > 1e-6


def _between_frames(config: ScenarioConfig, t: float) -> dict:
    """The held y, the predicted y and the exact camera's y at time t of a run."""
    from pydrake.systems.analysis import Simulator

    loop = build_loop(config, log=False)
    simulator = Simulator(loop.diagram)
    context = simulator.get_mutable_context()
    loop.carrier.set_initial_state(context)
    simulator.Initialize()
    simulator.AdvanceTo(t)
    sub = loop.diagram.GetMutableSubsystemContext
    sensor = loop.feature_sensor
    predictor = loop.diagram.GetSubsystemByName("frame_predictor")
    return {
        "held": sensor.image_features_output.Eval(sub(sensor, context)),
        "predicted": loop.features.Eval(sub(predictor, context)),
        "exact": loop.camera.image_features_output.Eval(sub(loop.camera, context)),
    }


@pytest.mark.parametrize(
    "carrier", [pytest.param("free", id="free rig"), pytest.param("arm", id="arm")]
)
def test_between_frames_the_predictor_is_the_exact_camera_and_the_held_frame_is_not(carrier):
    """Two frames late at 30 Hz, half-way between frames, on the move: the law's y is the
    exact camera's to rounding, the held frame (taken 2.5 frames ago) is off by more than
    1e-3."""
    config = ScenarioConfig(
        sensor=Pinhole(latency_frames=2),
        initial=PoseConfig(xyz=[0.05, -0.03, -0.55], rpy=[0.1, -0.05, 0.3]),
    )
    if carrier == "arm":
        config.carrier = Arm()
    assert config.sensor.prediction == "odometry"  # the default
    y = _between_frames(config, 0.5 / 30 + 10 / 30)
    np.testing.assert_allclose(y["predicted"], y["exact"], rtol=0, atol=1e-9)
    assert np.abs(y["held"] - y["exact"]).max() > 1e-3


def test_without_prediction_the_law_reads_the_held_frame():
    config = ScenarioConfig(sensor=Pinhole(prediction="none"))
    loop = build_loop(config, log=False)
    assert not loop.diagram.HasSubsystemNamed("frame_predictor")
    assert loop.features == loop.feature_sensor.image_features_output


def test_no_frame_yet_gives_nan_and_bad_settings_are_one_line():
    predictor = FramePredictor(radius=RHO)
    context = predictor.CreateDefaultContext()
    predictor.image_features_input.FixValue(context, np.full(13, np.nan))
    predictor.body_pose_input.FixValue(context, [1.0, 0, 0, 0, 0, 0, 0])
    assert np.isnan(predictor.predicted_image_features_output.Eval(context)).all()
    with pytest.raises(ValueError, match="radius must be finite and > 0: radius = -1"):
        FramePredictor(radius=-1.0)
    with pytest.raises(ValueError, match="latency_frames must be an integer >= 0, got -1"):
        FramePredictor(radius=RHO, latency_frames=-1)


def test_a_prediction_that_is_not_known_is_one_line():
    with pytest.raises(ValueError, match="sensor.prediction must be one of none, odometry"):
        ScenarioConfig(sensor=Pinhole(prediction="kalman")).validate()
