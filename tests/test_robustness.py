"""The robustness study's predictions against independent truths and short simulations.

Truths used: the closed-form stiffness of the linearisation (``closed_form_A``),
closed forms of the equilibrium a calibration error moves the loop to, Drake's
``Linearize`` eigenvalues for the fast-sampling limit, and the Drake loop itself
(does it leave D where the sampled linearisation says it is unstable?).
"""

import math

import numpy as np
import pytest

from geovs_drake.analysis.linear.linearization import (
    closed_form_A,
    linearize_at_goal,
    rig_spatial_inertia,
)
from geovs_drake.analysis.studies.robustness import (
    case_config,
    plot_robustness,
    potential_stiffness,
    predicted_equilibrium,
    robustness_sweep,
    sampled_spectral_radius,
    summarize_robustness,
)
from geovs_drake.loop import exact_twin, resolve
from geovs_drake.scenario import Dynamic, Pinhole, ScenarioConfig
from geovs_drake.simulation import simulate


def test_stiffness_of_the_measured_loop_is_the_closed_form():
    config = ScenarioConfig()
    K_closed = -rig_spatial_inertia(config) @ closed_form_A(resolve(config), Dynamic())[6:, :6]
    scale = np.max(np.abs(K_closed))
    assert np.max(np.abs(potential_stiffness(config) - K_closed)) < 1e-8 * scale
    # The pinhole sensor, noise-free, measures c(H): the same stiffness.
    pinhole = case_config(config, None, 0.0)
    assert np.max(np.abs(potential_stiffness(pinhole) - K_closed)) < 1e-6 * scale


@pytest.mark.parametrize("error", [-0.2, 0.1, 0.2])
def test_a_wrong_radius_moves_the_goal_distance_by_its_ratio(error):
    # lambda* = rho_believed / |d*| is matched with the true rho: |d| = |d*| / (1 + error).
    eq = predicted_equilibrium(case_config(ScenarioConfig(), "radius_error", error))
    assert eq["distance"] == pytest.approx(0.5 / (1 + error), abs=1e-9)
    assert eq["residual"] < 1e-9  # the whole goal image, not only lambda


@pytest.mark.parametrize("error", [-0.1, 0.05, 0.1])
def test_a_wrong_focal_length_moves_the_goal_distance(error):
    # On the axis the measured tan(gamma) is the true one / (1 + error).
    lam_star = 0.2
    gamma = math.atan((1 + error) * math.tan(math.asin(lam_star)))
    eq = predicted_equilibrium(case_config(ScenarioConfig(), "focal_error", error))
    assert eq["distance"] == pytest.approx(0.1 / math.sin(gamma), abs=1e-9)
    assert eq["residual"] < 1e-9


def test_fast_sampling_tends_to_the_continuous_loop():
    config = case_config(ScenarioConfig(), "rate", 4000.0)
    exact = exact_twin(config)
    exact.control.damping = list(config.sensor.damping)
    slowest = np.max(linearize_at_goal(exact).eigenvalues.real)
    radius = sampled_spectral_radius(config)
    assert config.sensor.rate * math.log(radius) == pytest.approx(slowest, rel=1e-2)


@pytest.fixture(scope="module")
def default_start_runs():
    """The default start through the 30 Hz pinhole loop for 2.5 s, the law on the held
    frame: the exact loop's damping (0.3), the camera's (0.6), and the camera's with one
    frame of latency; then that last one with the odometry predictor between frames."""
    runs = {}
    for name, damping, latency, prediction in (
        ("damping 0.3", [0.3] * 3 + [4.0] * 3, 0, "none"),
        ("damping 0.6", None, 0, "none"),
        ("latency 1", None, 1, "none"),
        ("latency 1 predicted", None, 1, "odometry"),
    ):
        held = ScenarioConfig(duration=2.5, sensor=Pinhole(prediction=prediction))
        config = case_config(held, "latency_frames", latency)
        if damping is not None:
            config.sensor.damping = damping
        runs[name] = (sampled_spectral_radius(config), simulate(config))
    return runs


def test_the_sampled_linearisation_predicts_which_loops_leave_the_domain(default_start_runs):
    for name, (radius, result) in default_start_runs.items():
        unstable = radius > 1
        assert unstable == (name in ("damping 0.3", "latency 1")), (name, radius)
        assert (result.status == "left_domain") == unstable, (name, result.message)


@pytest.mark.slow  # make test's budget; the study's other tests keep its small cases
def test_a_short_sweep_summarises_and_plots(tmp_path):
    rows = robustness_sweep(starts=1, duration=5.0, levels={"radius_error": (0.0, 0.2)}, seed=3)
    assert [(r.parameter, r.level, r.start) for r in rows] == [
        ("radius_error", 0.0, 0),
        ("radius_error", 0.2, 0),
    ]
    table = summarize_robustness(rows)
    wrong = table[1]
    assert wrong["predicted_position_error_m"] == pytest.approx(0.5 - 0.5 / 1.2, abs=1e-9)
    # It settles where the prediction says, to the camera's tolerance (5.9 mm).
    assert wrong["settled"] == 1
    assert abs(wrong["position_error_max_m"] - wrong["predicted_position_error_m"]) < 6e-3
    plot_robustness(table, tmp_path / "r.png")
    assert (tmp_path / "r.png").stat().st_size > 10_000
