"""The float systems' memo of their last calculation (:mod:`geovs_drake.systems._memo`).

Independent truth: the same loop run with every memo off (each call computes), step by
step; and, for the AutoDiffXd path, the chain rule (a seed twice as large gives a
derivative twice as large, which a memo keyed on the values alone would not).
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd

from geovs_drake.loop import resolve
from geovs_drake.loop.build import assemble_loop
from geovs_drake.scenario import Arm, Dynamic, Exact, Pinhole, PoseConfig, ScenarioConfig
from geovs_drake.simulation.monitor import make_simulator
from geovs_drake.systems import NavigationController, _memo

SMALL_MOVE = PoseConfig(xyz=[0.05, -0.03, -0.55], rpy=[0.1, -0.05, 0.3])


def _run(sensor, duration: float) -> tuple:
    """The dynamic UR5's recorded steps over ``duration`` and its systems' memo hits."""
    config = ScenarioConfig(
        carrier=Arm(), plant=Dynamic(), sensor=sensor, duration=duration, initial=SMALL_MOVE
    )
    loop = assemble_loop(resolve(config), log=False)
    simulator, monitor = make_simulator(loop, record=True)
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    integrator = simulator.get_integrator()
    hits = {s.get_name(): s._memo.hits for s in loop.diagram.GetSystems() if hasattr(s, "_memo")}
    counts = (simulator.get_num_steps_taken(), integrator.get_num_derivative_evaluations())
    return np.array(monitor.times), np.array(monitor.states), counts, hits


@pytest.mark.parametrize(
    "sensor, duration, memos",
    [
        (Exact(), 0.3, ("arm_camera", "spherical_camera", "navigation_controller")),
        (Pinhole(), 0.2, ("arm_camera", "frame_predictor", "image_jacobian_force")),
    ],
)
def test_memo_gives_the_same_run(monkeypatch, sensor, duration, memos) -> None:
    """RK5's repeated first stage is recalled (hits > 0, one evaluation in seven at most),
    and the run is the one every call computes, bit for bit: the same steps and states."""
    times, states, counts, hits = _run(sensor, duration)
    monkeypatch.setattr(_memo, "ENABLED", False)
    times_off, states_off, counts_off, hits_off = _run(sensor, duration)
    assert counts == counts_off
    np.testing.assert_array_equal(times, times_off)
    np.testing.assert_array_equal(states, states_off)
    for name in memos:
        assert 0 < hits[name] <= counts[1] / 7 + 1, (name, hits, counts)
    assert not any(hits_off.values())


def test_autodiff_path_computes_each_call() -> None:
    """The AutoDiffXd NF is not memoised: the same y's values with a doubled seed give a
    doubled derivative of dphi (a values-keyed memo would return the first); the float
    NF recalls the same y given again (a hit) with the same dphi."""
    config = ScenarioConfig(carrier=Arm(), initial=SMALL_MOVE)
    y_goal = resolve(config).y_goal
    float_nf = NavigationController(y_goal)
    float_context = float_nf.CreateDefaultContext()
    values = []
    for _ in range(2):  # FixValue marks dphi out of date: the second Eval calculates again
        float_nf.get_input_port(0).FixValue(float_context, np.asarray(y_goal, dtype=float))
        values.append(float_nf.dphi_output.Eval(float_context).copy())
    assert float_nf._memo.hits == 1
    np.testing.assert_array_equal(values[0], values[1])
    nf = float_nf.ToAutoDiffXd()
    context = nf.CreateDefaultContext()
    y = np.asarray(y_goal, dtype=float)  # in I (a perturbed y may not be)
    derivatives = []
    for seed in (1.0, 2.0):
        y_ad = np.array([AutoDiffXd(v, [seed * (k + 1)]) for k, v in enumerate(y)])
        nf.get_input_port(0).FixValue(context, y_ad)
        dphi = nf.dphi_output.Eval(context)
        # An entry that does not depend on y carries no derivative vector (zero).
        derivatives.append(np.array([sum(d.derivatives()) for d in dphi]))
    assert np.any(np.abs(derivatives[0]) > 1e-6)
    np.testing.assert_allclose(derivatives[1], 2.0 * derivatives[0], rtol=1e-12, atol=1e-15)
    assert nf._memo.hits == 0
