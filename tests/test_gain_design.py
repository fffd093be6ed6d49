"""Gain design from the linearisation (analysis.gain_design).

Truths: Drake's ``Linearize`` of the designed loop (not the closed form the design
solves on), the batch engine's nonlinear loop for the decay of the tail.
"""

from __future__ import annotations

import numpy as np
import pytest

from geovs_drake.analysis.linear.gain_design import (
    SETTLING_FRACTION,
    decay_check,
    design_gains,
    root_locus,
)
from geovs_drake.analysis.linear.linearization import linearize
from geovs_drake.scenario import PLANT_VARIANTS, Dynamic, Kinematic, ScenarioConfig, variant_name
from geovs_drake.spectrum import assert_spectra_close

#: The request's tolerance on Drake's eigenvalues (the issue's 1e-6).
REQUEST_TOL = 1e-6


def _min_ratio(lam: np.ndarray) -> float:
    return float(np.min(-lam.real / np.abs(lam)))


@pytest.mark.parametrize(("settling_time", "zeta"), [(2.0, 0.7), (0.8, 0.3)])
def test_the_designed_dynamic_loop_meets_the_request_in_drakes_linearization(settling_time, zeta):
    design = design_gains(ScenarioConfig(), settling_time, zeta, run_start=False)
    lam = linearize(design.config).eigenvalues  # Drake's Linearize of the designed diagram
    sigma = -np.log(SETTLING_FRACTION) / settling_time
    assert -lam.real.max() == pytest.approx(sigma, rel=REQUEST_TOL)
    assert _min_ratio(lam) == pytest.approx(zeta, abs=REQUEST_TOL)
    # The design keeps the damping's diagonal profile and reports k_p as the energy bound.
    d0 = np.asarray(ScenarioConfig().control.damping)
    assert np.allclose(design.damping / design.damping[0], d0 / d0[0])
    assert design.achieved_settling_time == pytest.approx(settling_time, rel=1e-9)


def test_the_designed_kinematic_loop_settles_as_asked_and_costs_a_twist():
    design = design_gains(ScenarioConfig(plant=Kinematic()), settling_time=1.0)
    lam = linearize(design.config).eigenvalues
    assert -lam.real.max() == pytest.approx(-np.log(SETTLING_FRACTION), rel=REQUEST_TOL)
    # Real modes (a double one may split off the axis by rounding, not by more).
    assert np.max(np.abs(lam.imag)) <= 1e-9 * np.max(np.abs(lam))
    assert design.run_status == "converged"
    assert np.isfinite(design.peak_rate) and np.isfinite(design.peak_speed)


@pytest.mark.parametrize("plant", [Dynamic(), Kinematic()], ids=variant_name)
def test_the_tail_of_the_nonlinear_loop_decays_at_the_predicted_rate(plant):
    """Starts about the goal through the batch engine: the measured decay of the pose
    error against the slowest mode's rate (local, so it should agree closely)."""
    zeta = 0.7 if isinstance(plant, Dynamic) else None
    design = design_gains(ScenarioConfig(plant=plant), 1.5, zeta, run_start=False)
    check = decay_check(design, starts=16, seed=1)
    assert check.relative_difference == pytest.approx(0.0, abs=1e-3)
    assert np.all(np.abs(check.measured_rates / check.predicted_rate - 1) < 1e-2)
    assert np.all(np.isfinite(check.t_converged))


@pytest.mark.parametrize(
    ("plant", "settling_time", "zeta", "match"),
    [
        ("dynamic", 1.0, 0.0, "damping_ratio .* must be in \\(0, 1\\): damping_ratio = 0.0"),
        ("dynamic", 1.0, -0.5, "damping_ratio = -0.5"),
        ("dynamic", 1.0, 1.0, "damping_ratio = 1.0"),
        ("dynamic", 0.0, 0.5, "settling_time must be finite and > 0: settling_time = 0.0"),
        ("kinematic", 1.0, 0.7, "leave damping_ratio out"),
    ],
)
def test_a_request_out_of_range_is_one_line(plant, settling_time, zeta, match):
    with pytest.raises(ValueError, match=match):
        design_gains(
            ScenarioConfig(plant=PLANT_VARIANTS[plant]()), settling_time, zeta, run_start=False
        )


def test_the_root_locus_at_the_scenarios_gain_is_drakes_spectrum():
    config = ScenarioConfig()
    gains = np.array([1.0, config.control.potential_gain, 20.0])
    locus = root_locus(config, gains)
    assert locus.shape == (3, 12)
    drake = linearize(config).eigenvalues
    assert_spectra_close(locus[1], drake, rtol=1e-8, atol=1e-8)
    # Both in the canonical order: entry k is the same mode (the goal's spectrum holds a
    # repeated pair, whose np.sort_complex order was the BLAS kernel's).
    assert np.allclose(locus[1], drake, rtol=1e-8, atol=1e-8)
    # Stiffer is faster: |lambda| grows with k_p for the undamped-ish oscillatory pairs.
    assert np.abs(locus[2]).max() > np.abs(locus[0]).max()
    with pytest.raises(ValueError, match="gain must be one of"):
        root_locus(config, gains, gain="mass")
