"""The integrator's step limit from the goal's fastest mode (simulation.step_limit).

Truths: RK3's stability region on the negative real axis ends at the real root of
1 + z + z^2/2 + z^3/6 = -1 (z = -2.5127), numpy's roots of that polynomial; the
closed-form A is checked against Drake's Linearize in test_closed_loop.py; and the
runs themselves, which must reach the goal to rounding and stay there.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator, SimulatorConfig
from pydrake.systems.primitives import LinearSystem

from geovs_drake.goal.linear_model import closed_form_A
from geovs_drake.goal.step_limit import STABILITY_MARGIN, STABILITY_POLYNOMIALS
from geovs_drake.loop import resolve
from geovs_drake.scenario import (
    DEFAULT_MAX_STEP,
    Arm,
    Dynamic,
    FixedCamera,
    Kinematic,
    PoseConfig,
    ScenarioConfig,
    variant_name,
)
from geovs_drake.simulation import simulate

#: The issue's small start, from which the kinematic loop stalled at 1e-7 m.
NEAR = PoseConfig(xyz=[0.02, -0.01, -0.52], rpy=[0.02, -0.01, 0.1])


def test_the_stable_step_of_a_real_mode_is_rk3s_real_axis_bound():
    config = ScenarioConfig(plant=Kinematic())
    limit = resolve(config).step_limit
    eigenvalues = np.linalg.eigvals(closed_form_A(resolve(config)))
    assert np.allclose(eigenvalues.imag, 0) and limit.fastest_mode == pytest.approx(
        eigenvalues.real.min()
    )
    roots = np.roots([1 / 6, 1 / 2, 1, 2])  # R(z) = -1: the edge of the real interval
    edge = roots[np.abs(roots.imag) < 1e-12].real[0]
    assert limit.stable_step == pytest.approx(edge / limit.fastest_mode.real, rel=1e-9)
    assert limit.automatic and limit.max_step_size == pytest.approx(
        STABILITY_MARGIN * limit.stable_step
    )
    # RK3 on the real axis: h |lambda| = 0.8 x 2.51 = 2.0 at the automatic limit.
    assert limit.max_step_size * abs(limit.fastest_mode) == pytest.approx(
        STABILITY_MARGIN * -edge, rel=1e-9
    )
    assert DEFAULT_MAX_STEP > limit.stable_step  # the old fixed 0.05 s was beyond it


@pytest.mark.parametrize("scheme", ["runge_kutta2", "runge_kutta3", "runge_kutta5"])
def test_each_stability_polynomial_is_drakes_own_step_on_a_linear_mode(scheme):
    """One fixed step of Drake's integrator on x' = lambda x (a complex mode as a real
    2x2 block) multiplies x by the scheme's R(h lambda), to rounding."""
    lam, h = complex(-21.0, 60.0), 0.04  # the dynamic UR5's goal mode, its step's size
    A = np.array([[lam.real, -lam.imag], [lam.imag, lam.real]])
    system = LinearSystem(A, np.zeros((2, 0)), np.zeros((0, 2)), np.zeros((0, 0)))
    simulator = Simulator(system)
    fixed = SimulatorConfig(integration_scheme=scheme, max_step_size=h, use_error_control=False)
    ApplySimulatorConfig(fixed, simulator)
    simulator.get_mutable_context().SetContinuousState([1.0, 0.0])
    simulator.AdvanceTo(h)
    x = simulator.get_context().get_continuous_state_vector().CopyToVector()
    R = np.polyval(STABILITY_POLYNOMIALS[scheme][::-1], h * lam)
    assert complex(x[0], x[1]) == pytest.approx(R, abs=1e-13)


def test_a_limit_the_user_sets_is_used_as_given():
    config = ScenarioConfig(plant=Kinematic())
    # Not set: None, automatic; Drake's struct gets Drake's own default for it.
    assert config.simulator.max_step_size is None and resolve(config).step_limit.automatic
    assert config.simulator.to_drake().max_step_size == SimulatorConfig().max_step_size
    # Any value is the user's, Drake's default 0.1 too (it used to read as "not set").
    config.simulator.max_step_size = SimulatorConfig().max_step_size
    assert resolve(config).step_limit.max_step_size == 0.1
    config.simulator.max_step_size = DEFAULT_MAX_STEP  # the old default, now explicit
    limit = resolve(config).step_limit
    assert not limit.automatic and limit.max_step_size == DEFAULT_MAX_STEP
    assert limit.beyond_bound and "outside runge_kutta3's" in limit.warning("runge_kutta3")
    config.simulator.max_step_size = 0.01  # inside the bound: nothing to say
    assert resolve(config).step_limit.warning("runge_kutta3") is None


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_both_loops_reach_the_goal_to_rounding_and_stay(plant):
    """From the small start the pose error is below 1e-12 m from 20 s on, to 40 s (the
    kinematic loop used to stall at 3e-8 m and drift to 3e-7 m with a 0.05 s limit)."""
    config = ScenarioConfig(plant=plant, duration=40.0, initial=NEAR)
    result = simulate(config)
    error = np.linalg.norm(result.X_BC[:, :3, 3] - config.X_BC_goal.translation(), axis=1)
    after = error[np.searchsorted(result.times, 20.0) :]
    assert np.max(after) < 1e-12, np.max(after)
    summary = result.summary()
    assert summary["max_step_automatic"] and summary["max_step_size"] <= DEFAULT_MAX_STEP
    assert summary["fastest_mode"][0] < 0
    assert result.step_warning is None  # the default settings: nothing to warn about


def test_a_users_step_beyond_the_bound_gets_one_line(run_cli):
    run = run_cli(
        "simulate", "--plant", "kinematic", "--duration", "1", "--json",
        "--scenario-text", "{simulator: {max_step_size: 0.05}}",
    )  # fmt: skip
    warning = [line for line in run.err.splitlines() if "warning" in line]
    assert len(warning) == 1 and "outside runge_kutta3's stability region" in warning[0]
    assert "h |lambda| = 3.54" in warning[0]  # 0.05 s x 70.8 1/s, beyond RK3's 2.51
    summary = json.loads(run.out)
    assert summary["max_step_size"] == 0.05 and not summary["max_step_automatic"]


def test_no_warning_for_the_automatic_limit(run_cli):
    run = run_cli("simulate", "--plant", "kinematic", "--duration", "1", "--json")
    assert "warning" not in run.err


@pytest.mark.parametrize("carrier", [Arm(), FixedCamera()], ids=variant_name)
def test_the_closed_forms_readers_refuse_a_loop_it_does_not_model_alike(carrier):
    """The closed form is the eye-in-hand free rig's: linearize_at_goal, linearize and
    design_gains refuse the arm and the fixed camera in one line naming the carrier
    (one rule, linear_model.closed_form_refusal). The step limit falls back on its cap
    for the fixed camera (no stability bound from a model that is not the loop's); the
    dynamic arm has its own goal model (step_limit.arm_goal_A, test_stiff_arm.py)."""
    from geovs_drake.analysis.linear.gain_design import design_gains
    from geovs_drake.analysis.linear.linearization import linearize, linearize_at_goal

    config = ScenarioConfig(carrier=carrier)
    got = f"(carrier FreeRig), got carrier {type(carrier).__name__}"
    for who, call in (
        ("linearize_at_goal", lambda: linearize_at_goal(config)),
        ("linearize", lambda: linearize(config)),
        ("design_gains", lambda: design_gains(config, 2.0, 0.7, run_start=False)),
    ):
        with pytest.raises(ValueError) as error:
            call()
        assert str(error.value) == f"{who}: the closed form is the eye-in-hand free rig's {got}"
    limit = resolve(config).step_limit
    if isinstance(carrier, Arm):
        assert limit.stable_step is not None and limit.max_step_size <= DEFAULT_MAX_STEP
    else:
        assert limit.stable_step is None and limit.max_step_size == DEFAULT_MAX_STEP


def test_the_step_limit_reads_from_yaml_unset_or_a_value_and_a_bad_one_is_one_line():
    from geovs_drake.scenario import load_scenario

    assert load_scenario(data="simulator: {max_step_size: null}").simulator.max_step_size is None
    assert load_scenario(data="simulator: {max_step_size: 0.02}").simulator.max_step_size == 0.02
    for bad in ("0", "-0.1", ".nan"):
        with pytest.raises(
            ValueError, match=r"simulator.max_step_size must be finite and > 0 \[s\], or unset"
        ) as e:
            load_scenario(data=f"simulator: {{max_step_size: {bad}}}").validate()
        assert len(str(e.value).splitlines()) == 1
