"""The camera's rate and latency predicted from the linearisation (analysis.latency).

Truths: the closed form of the continuous part (the rig's kinematics and its damping),
the robustness study's own model of the loop (its stiffness from central differences of
the image Jacobian and the NF's differential, not from Drake's Linearize; the two share
only the hold and the delay, Drake's DiscreteTimeApproximation), and the pinhole-sensor
loop simulated.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geovs_drake.analysis.linear.latency import (
    latency_margin,
    latency_study,
    sampled_model,
    slowest_stable_rate,
    spectral_radius,
)
from geovs_drake.analysis.linear.linearization import rig_spatial_inertia
from geovs_drake.analysis.studies.robustness import sampled_spectral_radius, soft_gains
from geovs_drake.scenario import Kinematic, Pinhole, ScenarioConfig


def _camera_config() -> ScenarioConfig:
    """The 30 Hz pinhole camera on the held frame (no prediction): the sampled loop."""
    return ScenarioConfig(sensor=Pinhole(prediction="none"))


def test_the_continuous_part_is_the_rigs_kinematics_and_damping():
    config = _camera_config()
    model = sampled_model(config)
    M = rig_spatial_inertia(config)
    expected = np.zeros((12, 12))
    expected[:6, 6:] = np.eye(6)
    expected[6:, 6:] = -np.linalg.solve(M, np.diag(config.sensor.damping))
    assert np.allclose(model.A_c, expected, atol=1e-9 * np.abs(expected).max())
    # The kinematic body keeps nothing continuous: its twist is all the law's.
    kinematic = sampled_model(ScenarioConfig(plant=Kinematic()))
    assert np.abs(kinematic.A_c).max() < 1e-9 * np.abs(kinematic.B_n @ kinematic.C_xi).max()


@pytest.mark.parametrize("latency", [0, 1, 3])
def test_the_radius_is_the_robustness_studys_independent_model(latency):
    for config in (_camera_config(), soft_gains(_camera_config())):
        c = copy.deepcopy(config)
        c.sensor.latency_frames = latency
        assert spectral_radius(c) == pytest.approx(sampled_spectral_radius(c), rel=1e-8)


def test_margins_one_frame_for_the_default_gains_three_for_the_soft_ones():
    """The robustness study measured it: one frame of latency at 30 Hz leaves D with the
    default gains, the soft gains take 3."""
    config = _camera_config()
    assert latency_margin(config) == 0
    assert latency_margin(soft_gains(config)) == 3
    rate = slowest_stable_rate(config, 0)
    assert 1.0 < rate < 30.0
    model = sampled_model(config)
    assert model.spectral_radius(rate * 1.001, 0) < 1 <= model.spectral_radius(rate * 0.999, 0)
    assert np.isnan(slowest_stable_rate(config, 1))  # 30 Hz itself is unstable there


def test_with_prediction_the_model_is_the_continuous_loops_at_any_latency():
    """The odometry predictor: the robustness study's model and this module's agree, the
    radius is exp(max Re(lambda) / rate) of the continuous loop, and no latency up to the
    search's end is unstable."""
    config = ScenarioConfig(sensor=Pinhole(prediction="odometry"))
    held = sampled_model(config)
    slowest = np.max(np.linalg.eigvals(held.A_c + held.B_n @ held.C_xi).real)
    for latency in (0, 1, 3):
        c = copy.deepcopy(config)
        c.sensor.latency_frames = latency
        assert spectral_radius(c) == pytest.approx(np.exp(slowest / 30.0), rel=1e-9)
        assert spectral_radius(c) == pytest.approx(sampled_spectral_radius(c), rel=1e-8)
    assert latency_margin(config, max_frames=10) is None  # stable at any latency


def test_bad_camera_settings_are_one_line():
    model = sampled_model(_camera_config())
    with pytest.raises(ValueError, match="latency_frames = -1"):
        model.spectral_radius(30.0, -1)
    with pytest.raises(ValueError, match="rate = 0.0"):
        model.spectral_radius(0.0, 0)


def test_the_pinhole_loop_agrees_with_the_prediction_in_a_small_case():
    config = _camera_config()
    cases = latency_study(
        {"default": config, "soft": soft_gains(config)},
        rates=(30.0,),
        latencies=(1,),
        duration=6.0,
    )
    assert [(c.gains, c.predicted_stable, c.status) for c in cases] == [
        ("default", False, "left_domain"),
        ("soft", True, cases[1].status),
    ]
    assert cases[0].agrees


@pytest.mark.slow
def test_the_pinhole_loop_agrees_with_the_prediction_over_latency_and_two_rates():
    """The whole check (latency 0..6 frames, 30 and 60 Hz, default and soft gains): every
    one of the 28 cases agrees (measured: the closest to the boundary are 0.990 and 1.017,
    soft gains at 30 Hz, 3 and 4 frames; the unstable soft case at 4 frames ends
    not_converged at 15 s, growing, the others leave D)."""
    config = _camera_config()
    cases = latency_study({"default": config, "soft": soft_gains(config)})
    assert len(cases) == 28
    assert all(c.agrees for c in cases), [c for c in cases if not c.agrees]


def test_prediction_between_frames_carries_the_gains_the_held_frame_cannot():
    """The map's small case (issue 31): the default gains one frame late at 30 Hz leave D
    on the held frame, as the sampled model predicts; with the odometry predictor the
    model is the continuous loop's (stable) and the same run converges."""
    cases = latency_study(
        {"default": _camera_config()},
        rates=(30.0,),
        latencies=(1,),
        duration=6.0,
        predictions=("none", "odometry"),
    )
    outcome = {c.prediction: (c.predicted_stable, c.status) for c in cases}
    assert outcome == {"none": (False, "left_domain"), "odometry": (True, "converged")}
    assert all(c.agrees for c in cases)


def test_a_prediction_the_study_does_not_know_is_one_line():
    with pytest.raises(ValueError, match="predictions must be in none, odometry: got 'smith'"):
        latency_study({"default": _camera_config()}, predictions=("smith",))


def test_the_arms_map_in_a_small_case_prediction_is_where_they_differ():
    """camera_map's smallest cell (issue 31's maps): the UR5 at gain_scale 10, 30 Hz, one
    frame late, 6 s. On the held frame the goal model says unstable and the run leaves D;
    with the predictor it says stable and the run converges; the table writes both."""
    from geovs_drake.analysis.linear.latency import camera_map, map_table
    from geovs_drake.scenario import Arm

    cases = camera_map(
        ScenarioConfig(carrier=Arm(), sensor=Pinhole()),
        (10.0,),
        rates=(30.0,),
        latencies=(1,),
        duration=6.0,
    )
    outcome = {c.prediction: (c.predicted_stable, c.status) for c in cases}
    assert outcome == {"none": (False, "left_domain"), "odometry": (True, "converged")}
    table = map_table(cases)
    assert "prediction: none" in table and "| 10 | 1 | left D (1.32" in table
    assert "prediction: odometry" in table and "| 10 | 1 | ok (0.975)" in table
    with pytest.raises(ValueError, match="camera_map scales an arm's gain_scale"):
        camera_map(ScenarioConfig(), (1.0,))
