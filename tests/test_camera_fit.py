"""The run's gains against its camera (simulation.camera_fit, issue 31): the goal's
closed-form model split at the camera equals Drake's Linearize of the loop, its
predicted edge of stability is the simulated loop's, and a run whose gains the camera
cannot carry starts with one warning line naming the gain that would work."""

import json

import numpy as np
import pytest

from geovs_drake.analysis.linear.arm_study import linearize_arm_at_goal
from geovs_drake.analysis.linear.latency import sampled_model
from geovs_drake.scenario import Arm, Kinematic, Pinhole, PoseConfig, ScenarioConfig, resolve
from geovs_drake.simulation import simulate
from geovs_drake.simulation.camera_fit import GAIN_MARGIN, camera_fit, goal_sampled_model

#: A start a few millimetres and degrees off the goal: the linear model's regime.
NEAR_GOAL = PoseConfig(xyz=[0.01, -0.005, -0.51], rpy=[0.01, 0.0, 0.03])


@pytest.mark.parametrize("scale", [0.3, 1.0, 3.0])
@pytest.mark.parametrize("latency", [0, 1])
def test_the_free_rigs_closed_form_split_is_drakes_linearize_split(scale, latency):
    """The free rig: the spectral radius of the closed form's sampled loop equals the one
    built from Drake's Linearize of the whole diagram (analysis.linear.latency)."""
    config = ScenarioConfig(sensor=Pinhole())
    config.control.potential_gain *= scale
    config.sensor.damping = [scale * v for v in config.sensor.damping]
    closed = goal_sampled_model(resolve(config))
    drake = sampled_model(config)
    for rate in (15.0, 30.0, 60.0):
        assert closed.spectral_radius(rate, latency) == pytest.approx(
            drake.spectral_radius(rate, latency), rel=1e-8
        )


@pytest.mark.parametrize("plant", ["dynamic", "kinematic"])
def test_the_arms_closed_form_split_is_drakes_linearize_of_the_arm(plant):
    """The arm: the split's A_c + B_n C_xi is the continuous loop's A, which equals Drake's
    Linearize of the arm loop at the goal (dynamic, on (q, v)); the kinematic arm's is
    the kinematic body's in the camera's coordinates."""
    config = ScenarioConfig(carrier=Arm())
    if plant == "kinematic":
        config.plant = Kinematic()
        free = goal_sampled_model(resolve(ScenarioConfig(plant=Kinematic())))
        arm = goal_sampled_model(resolve(config))
        np.testing.assert_allclose(arm.C_xi, free.C_xi, rtol=0, atol=1e-12)
        return
    model = goal_sampled_model(resolve(config))
    drake = linearize_arm_at_goal(config).A_drake
    A = model.A_c + model.B_n @ model.C_xi
    np.testing.assert_allclose(A, drake, rtol=0, atol=1e-8 * np.abs(drake).max())


def test_the_predicted_edge_is_where_the_simulated_arm_loop_turns_unstable():
    """The UR5 with the pinhole camera one frame late: below the predicted largest stable
    gain scale the loop decays, above it it grows until it leaves D (issue 31's check:
    half the edge converges towards the goal, 1.5 times it does not)."""
    base = ScenarioConfig(carrier=Arm(), sensor=Pinhole(latency_frames=1))
    fit = camera_fit(resolve(base))
    edge = fit.largest_stable_gain
    assert fit.gain_name == "gain_scale" and fit.gain_value == 10.0
    assert not fit.stable and 0 < edge < 10.0  # the default gain_scale is beyond it
    errors = {}
    for factor in (0.5, 1.5):
        config = ScenarioConfig(
            carrier=Arm(gain_scale=factor * edge),
            sensor=Pinhole(latency_frames=1),
            initial=NEAR_GOAL,
            duration=8.0,
        )
        run = simulate(config)
        error = np.linalg.norm(run.X_BC[:, :3, 3] - config.X_BC_goal.translation(), axis=1)
        first, last = error[run.times < 2].max(), error[run.times > run.times[-1] - 2].max()
        errors[factor] = (run.status, first, last)
    status, first, last = errors[0.5]
    assert status in ("converged", "not_converged") and last < 0.5 * first, errors
    status, first, last = errors[1.5]
    assert status == "left_domain" or last > 2 * first, errors


def test_a_gain_the_camera_cannot_carry_gets_one_warning_line(run_cli):
    run = run_cli(
        "simulate", "--carrier", "arm", "--scenario-text", "sensor: !Pinhole {latency_frames: 1}",
        "--duration", "0.2", "--json",
    )  # fmt: skip
    fit = camera_fit(resolve(ScenarioConfig(carrier=Arm(), sensor=Pinhole(latency_frames=1))))
    edge = fit.largest_stable_gain
    warning = [line for line in run.err.splitlines() if "warning" in line]
    assert len(warning) == 1, run.err
    assert "the 30 Hz camera, 1 frames late, on the dynamic arm" in warning[0]
    assert "predicts the loop unstable" in warning[0]
    assert f"the largest stable gain_scale is {edge:.3g} (this run's: 10)" in warning[0]
    assert f"gain_scale {edge / GAIN_MARGIN:.3g} keeps a margin of 2" in warning[0]
    camera = json.loads(run.out)["camera"]
    assert camera["largest_stable_gain"] == {
        "field": "gain_scale",
        "value": pytest.approx(edge),
        "this_run": 10.0,
    }
    assert (
        camera["spectral_radius"] == pytest.approx(fit.spectral_radius) and fit.spectral_radius > 1
    )


@pytest.mark.parametrize(
    "config",
    [ScenarioConfig(sensor=Pinhole()), ScenarioConfig(carrier=Arm(), sensor=Pinhole())],
    ids=["free rig", "arm"],
)
def test_the_defaults_with_a_30_hz_camera_keep_the_margin_and_warn_nothing(config):
    fit = camera_fit(resolve(config))
    assert fit.stable and fit.margin >= GAIN_MARGIN and fit.warning() is None


def test_no_fit_without_a_camera_or_a_closed_form():
    from geovs_drake.scenario import FixedCamera, Ibvs

    assert camera_fit(resolve(ScenarioConfig())) is None  # the exact sensor
    assert camera_fit(resolve(ScenarioConfig(sensor=Pinhole(), controller=Ibvs()))) is None
    assert goal_sampled_model(resolve(ScenarioConfig(carrier=FixedCamera()))) is None


def test_the_kinematic_plant_takes_a_camera_and_the_warning_names_its_gain():
    """Cameras run on the kinematic plant too (issue 31, item 1): the free rig's default
    k = 4 at 30 Hz is beyond the hold's bound (its fastest mode, 126 1/s, times the
    frame), which the warning says with the kinematic gain that would work; at that
    gain the same start converges."""
    config = ScenarioConfig(plant=Kinematic(), sensor=Pinhole(), initial=NEAR_GOAL, duration=4.0)
    fit = camera_fit(resolve(config))
    assert not fit.stable and fit.gain_name == "control.kinematic_gain"
    assert f"control.kinematic_gain {fit.largest_stable_gain / GAIN_MARGIN:.3g}" in fit.warning()
    assert simulate(config).status == "left_domain"
    config.control.kinematic_gain = fit.largest_stable_gain / GAIN_MARGIN
    assert camera_fit(resolve(config)).warning() is None
    assert simulate(config).status == "converged"
