"""The camera study's margins (issue 42, item 2): a bound the search did not reach is
reported as such, not as the search's end, in the text and in the JSON of
``geovs-drake linearize``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from geovs_drake.goal.linear_model import LATENCY_SEARCH_FRAMES, MIN_RATE_HZ, SampledModel
from geovs_drake.scenario import Pinhole, ScenarioConfig

#: The rate of the scalar models below [Hz]; any would do.
RATE_HZ = 10.0


def _levin_may_margin(a: float) -> int:
    """The largest delay L with ``x_{n+1} = x_n - a x_{n-L}`` asymptotically stable: it is
    iff ``0 < a < 2 cos(L pi / (2L + 1))`` (Levin & May 1976), a bound that falls with L."""
    L = 0
    while a < 2 * math.cos((L + 1) * math.pi / (2 * L + 3)):
        L += 1
    return L


def _integrator(gain: float) -> SampledModel:
    """``xdot = -gain xi_held``, ``xi = x``: sampled at RATE_HZ, ``x_{k+1} = x_k - a
    x_{k-L}`` with ``a = gain / RATE_HZ``."""
    return SampledModel(A_c=np.zeros((1, 1)), B_n=np.ones((1, 1)), C_xi=-gain * np.ones((1, 1)))


@pytest.mark.parametrize("margin", [3, 40])
def test_the_latency_margin_is_levin_and_mays_and_the_searchs_end_is_not_one(margin):
    # a between the bounds of `margin` and `margin + 1` frames: the margin is exactly that.
    bound = [2 * math.cos(L * math.pi / (2 * L + 1)) for L in (margin, margin + 1)]
    a = math.sqrt(bound[0] * bound[1])
    assert _levin_may_margin(a) == margin
    model = _integrator(a * RATE_HZ)
    found = model.latency_bound(RATE_HZ, LATENCY_SEARCH_FRAMES)
    if margin <= LATENCY_SEARCH_FRAMES:
        assert found.value == margin and found.reason is None
    else:  # stable at every latency searched: the margin is beyond, not at, the end
        assert found.value is None
        assert found.reason == f"stable beyond {LATENCY_SEARCH_FRAMES} frames (the search's end)"
        assert model.spectral_radius(RATE_HZ, LATENCY_SEARCH_FRAMES + 1) < 1
        assert model.latency_margin(RATE_HZ, margin + 5) == margin


def test_a_loop_stable_at_every_rate_has_no_slowest_stable_rate():
    """``xdot = -c x - k xi_held`` with k < c: over a frame T, ``x_{k+1} = z(T) x_k``,
    ``z = e^{-cT} - k (1 - e^{-cT}) / c``, in (-k/c, 1) at every T: no rate is too slow."""
    c, k = 2.0, 1.0
    model = SampledModel(A_c=-c * np.ones((1, 1)), B_n=np.ones((1, 1)), C_xi=-k * np.ones((1, 1)))
    for rate in (MIN_RATE_HZ / 10, MIN_RATE_HZ, 1.0, 100.0):
        T = 1 / rate
        z = math.exp(-c * T) - k * (1 - math.exp(-c * T)) / c
        assert model.spectral_radius(rate, 0) == pytest.approx(abs(z), rel=1e-9) and abs(z) < 1
    found = model.rate_bound(0, 30.0)
    assert found.value is None
    assert found.reason == f"stable down to {MIN_RATE_HZ:g} Hz (the search's end)"


def test_cli_with_prediction_the_camera_is_stable_at_any_latency_and_rate(run_cli):
    """The issue's command: with the default prediction the model is the continuous
    loop's, whose radius exp(max Re(lambda) / rate) is below 1 at every latency and rate;
    the command said "stable up to 30 frames late; slowest stable rate 0.1 Hz"."""
    from geovs_drake.analysis.linear.linearization import linearize

    args = ("linearize", "--latency", "40", "--camera-rate", "5")
    run = run_cli(*args, "--json")
    assert run.code == 0, run.err
    camera = json.loads(run.out)["camera"]
    # The truth: Drake's Linearize of the continuous loop with the camera's damping.
    config = ScenarioConfig()
    config.control.damping = list(Pinhole().damping)
    slowest = float(np.max(np.linalg.eigvals(linearize(config).A).real))
    assert slowest < 0
    assert camera["spectral_radius"] == pytest.approx(math.exp(slowest / 5.0), rel=1e-8)
    assert camera["latency_margin_frames"] is None
    assert camera["latency_margin_reason"].startswith("stable at any latency")
    assert camera["slowest_stable_rate_hz"] is None
    assert camera["slowest_stable_rate_reason"].startswith("stable at any rate")
    text = run_cli(*args)
    assert text.code == 0, text.err
    line = text.out.strip().splitlines()[-1]
    assert camera["latency_margin_reason"] in line
    assert camera["slowest_stable_rate_reason"] in line
    assert "up to 30 frames" not in line and "0.1 Hz" not in line


@pytest.mark.slow
def test_cli_on_the_held_frame_a_margin_beyond_the_search_is_said_so(run_cli):
    """Soft gains at 1 kHz on the held frame: stable at every latency to 30 frames
    (the robustness study's independent model agrees at 31); 5 to 13 s."""
    from geovs_drake.analysis.studies.robustness import sampled_spectral_radius

    scenario = "{sensor: !Pinhole {prediction: none}, control: {potential_gain: 1.0}}"
    args = ("linearize", "--latency", "0", "--camera-rate", "1000", "--scenario-text", scenario)
    camera = json.loads(run_cli(*args, "--json").out)["camera"]
    config = ScenarioConfig(sensor=Pinhole(prediction="none", rate=1000.0, latency_frames=31))
    config.control.potential_gain = 1.0
    assert sampled_spectral_radius(config) < 1
    assert camera["latency_margin_frames"] is None
    reason = f"stable beyond {LATENCY_SEARCH_FRAMES} frames (the search's end)"
    assert camera["latency_margin_reason"] == reason
    assert reason in run_cli(*args).out
