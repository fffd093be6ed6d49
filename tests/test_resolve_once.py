"""Resolve once (issue 41): one run of the arm with the 30 Hz pinhole and ``gain_scale:
auto`` works out its scenario's values once. Counted by Python's own profiler over the
whole of ``simulate()``, so that a second derivation anywhere (the loop, the simulator,
the reports) shows; and the values the resolver derived are the ones the run used."""

import cProfile
import pstats

import pytest

from geovs_drake.goal import camera_fit, step_limit
from geovs_drake.loop import resolver
from geovs_drake.scenario import Arm, Pinhole, PoseConfig, ScenarioConfig, schema
from geovs_drake.simulation import simulate

SMALL_MOVE = PoseConfig(xyz=[0.05, -0.03, -0.55], rpy=[0.1, -0.05, 0.3])


def _calls(stats: pstats.Stats, module, name: str) -> int:
    """How many times the profiled run called ``module``'s function ``name``."""
    path = module.__file__
    return sum(
        calls
        for (filename, _, function), (calls, *_rest) in stats.stats.items()
        if filename == path and function == name
    )


def test_one_arm_run_with_the_pinhole_resolves_its_scenario_once():
    config = ScenarioConfig(
        carrier=Arm(), sensor=Pinhole(rate=30.0), initial=SMALL_MOVE, duration=0.1
    )
    assert config.carrier.gain_scale == "auto"
    profile = cProfile.Profile()
    result = profile.runcall(simulate, config)
    stats = pstats.Stats(profile)
    counts = {
        "resolve": _calls(stats, resolver, "resolve"),
        "validate": _calls(stats, schema, "validate"),
        "camera_fit": _calls(stats, camera_fit, "camera_fit"),
        "to_domain (D)": _calls(stats, schema, "to_domain"),
        "goal_features (y*)": _calls(stats, schema, "goal_features"),
        "step_limit": _calls(stats, step_limit, "step_limit"),
    }
    assert counts == dict.fromkeys(counts, 1), counts
    # The run read what the resolver derived: the fitted gain scale, the camera fit at
    # it and the step limit the simulator ran with.
    assert result.resolved.gain_scale == pytest.approx(10.0)
    assert result.camera_fit is result.resolved.camera_fit
    assert result.summary()["max_step_size"] == result.resolved.step_limit.max_step_size
