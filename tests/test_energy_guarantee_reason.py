"""The energy guarantee's verdict in the JSON is the text's (issue 42, item 4): where a
warning line or the run's line says Appendix C's argument does not cover the run, the
JSON's ``energy_guarantee`` is null and ``energy_guarantee_reason`` says why, in the
same words as the line."""

from __future__ import annotations

import json

import pytest

from geovs_drake.scenario import Pinhole, ScenarioConfig, Twist, load_scenario
from geovs_drake.simulation import simulate

#: Long enough to start: the checks and the verdict belong to the start.
SHORT_S = 0.2


def _run(config: ScenarioConfig):
    """The run, its warning lines (as the command prints them), its JSON and its line."""
    warnings: list[str] = []
    result = simulate(config, on_warning=warnings.append)
    return result, warnings, json.loads(json.dumps(result.summary())), result.one_line()


def test_an_arm_past_its_effort_limits_claims_no_guarantee():
    """The UR5 at gain_scale 10 (the exact camera): its torques over E <= E0 pass
    wrist_2's effort limit, and the warning says the energy argument no longer covers
    the run; the JSON said energy_guarantee: true."""
    config = load_scenario(data=f"carrier: !Arm {{}}\nduration: {SHORT_S}\n")
    result, warnings, s, line = _run(config)
    effort = s["effort"]
    # The truth: the sampled torques over the run's level set, against the limits.
    assert effort["worst_ratio"] > 1 and s["initial_energy"] < s["energy_bound"]
    (warning,) = [w for w in warnings if "effort limit" in w]
    assert "the energy argument no longer covers the run" in warning
    assert s["energy_guarantee"] is None
    reason = s["energy_guarantee_reason"]
    assert reason.startswith("no energy guarantee: ") and effort["joint"] in reason
    assert (
        f"{effort['worst_ratio']:.2g} times" in reason
        and f"{effort['worst_ratio']:.2g} times" in warning
    )
    assert reason in line and "covers this start" not in line


@pytest.mark.parametrize("latency", [0, 1])
def test_a_held_frame_claims_no_guarantee_and_a_predicted_one_keeps_it(latency):
    """On the held frame the law's feedback is not continuous (Appendix C's premise);
    one frame late the sampled-data model even predicts the loop unstable (radius 1.21),
    and the warning says so. With the prediction the law reads the image now, and the
    verdict is E0 against k_p."""
    held = ScenarioConfig(
        duration=SHORT_S, sensor=Pinhole(prediction="none", latency_frames=latency)
    )
    _, warnings, s, line = _run(held)
    if latency:
        assert any("predicts the loop unstable" in w for w in warnings)
    assert s["energy_guarantee"] is None
    assert "held frame" in s["energy_guarantee_reason"]
    assert s["energy_guarantee_reason"] in line and "covers this start" not in line
    predicted = ScenarioConfig(duration=SHORT_S, sensor=Pinhole(latency_frames=latency))
    _, _, s, line = _run(predicted)
    assert s["energy_guarantee"] is (s["initial_energy"] < s["energy_bound"]) is True
    assert s["energy_guarantee_reason"] in line and "covers this start" in line


def test_a_moving_target_says_why_in_the_json_as_in_its_line():
    moving = ScenarioConfig(
        duration=SHORT_S,
        target_motion=Twist(twist=[0.0, 0.0, 0.0, 0.02, 0.0, 0.0], feedforward="estimated"),
    )
    _, _, s, line = _run(moving)
    assert s["energy_guarantee"] is None
    reason = "no energy guarantee: behind a moving target it needs the known twist"
    assert s["energy_guarantee_reason"] == reason and reason in line
    still = ScenarioConfig(duration=SHORT_S)
    _, _, s, line = _run(still)
    assert s["energy_guarantee"] is True and s["energy_guarantee_reason"] in line


@pytest.mark.slow
def test_cli_the_issues_run_json_and_text_agree(run_cli):
    """The issue's command, whole (12 s): stderr's warning and the JSON agree."""
    args = (
        "simulate",
        "--carrier",
        "arm",
        "--scenario-text",
        "sensor: !Pinhole {latency_frames: 1}",
    )
    run = run_cli(*args, "--json")
    assert run.code == 0, run.err
    s = json.loads(run.out)
    assert "the energy argument no longer covers the run" in run.err
    assert s["energy_guarantee"] is None and "effort limit" in s["energy_guarantee_reason"]
