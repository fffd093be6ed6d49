"""The arm in the batch engine, and ``sweep --carrier arm`` on it, against the Drake loop.

Truth: the Drake engine's rows (``simulate()`` start by start, the same IK and branch)
and simulate() on the default start; the batch engine reads only the systems'
parameters from the diagram and integrates with its own kernels.
"""

import numpy as np
import pandas as pd
import pytest

from geovs_drake.analysis import sweep
from geovs_drake.batch.arm_engine import run_arm_batch
from geovs_drake.batch.arm_rhs import arm_loop_parameters
from geovs_drake.loop import resolve
from geovs_drake.scenario import Arm, Exact, Kinematic, Pinhole, Rendered, ScenarioConfig
from geovs_drake.simulation import simulate
from geovs_drake.simulation.result import convergence_tolerance

#: Both engines integrate to the config's accuracy with different methods
#: (Bogacki-Shampine against Drake's RK3): at 1e-6 their final pose errors differ by
#: about 1e-9 on converged runs over 10 s (UR5 and Panda, measured) and by up to 1e-6 on
#: the kinematic arm still on its way at 1 s; at 1e-8 (the sweep test's) by 1e-8.
FINAL_ERROR_TOLERANCE = 1e-6


def _both_engines(config: ScenarioConfig, n: int, duration: float):
    starts = sweep.SampledStarts(n, seed=0, velocity="bounded" if config.dynamic else "none")
    batch = sweep.run_sweep(config, starts, duration, engine="batch", workers=1).table
    drake = sweep.run_sweep(config, starts, duration, engine="drake", workers=1).table
    return batch, drake


@pytest.mark.parametrize(
    # The dynamic arm's Drake runs at 1e-8 cost 8 s: marked slow for make test's budget.
    "plant",
    [pytest.param("dynamic", marks=pytest.mark.slow), "kinematic"],
)
def test_the_arm_sweep_on_the_batch_engine_gives_the_drake_engine_s_rows(plant):
    """Two UR5 starts (one the arm cannot reach), 0.5 s, both engines at accuracy 1e-8:
    the same statuses, the same columns, and final errors within 1e-6 of the Drake
    engine's."""
    config = ScenarioConfig(carrier=Arm())
    config.simulator.accuracy = 1e-8
    if plant == "kinematic":
        config.plant = Kinematic()
    batch, drake = _both_engines(config, 2, 0.5)
    assert list(batch.columns) == list(drake.columns)
    assert list(batch["status"]) == list(drake["status"])
    assert "unreachable" in set(batch["status"]) and len(set(batch["status"])) > 1
    ran = batch["status"] != "unreachable"
    for column in ("final_position_error_m", "final_rotation_error_rad"):
        diff = np.abs(batch[column][ran] - drake[column][ran]).max()
        print(f"\n{plant} {column}: max |batch - Drake| = {diff:.1e}")
        assert diff < FINAL_ERROR_TOLERANCE
    assert np.allclose(batch["initial_energy_ratio"][ran], drake["initial_energy_ratio"][ran])


@pytest.mark.slow
@pytest.mark.parametrize("model", ["default", "panda"])
def test_the_arm_engine_converges_as_simulate_on_the_default_start(model):
    """The default start, 10 s, UR5 and Panda, dynamic: simulate()'s status, and its
    final errors to 1e-6."""
    config = ScenarioConfig(carrier=Arm(model=model), duration=10.0)
    r = simulate(config)
    resolved = resolve(config)
    p = arm_loop_parameters(resolved)
    nv = p.tree.nv
    goal = (resolved.config.X_WB @ resolved.config.X_BC_goal).GetAsMatrix4()
    b = run_arm_batch(
        p, goal, r.states[0][None, :nv], None, 10.0, config.simulator.accuracy,
        convergence_tolerance(resolved),
    )  # fmt: skip
    assert b.status[0] == r.status
    assert abs(b.final_position_error_m[0] - r.final_errors[0]) < FINAL_ERROR_TOLERANCE
    assert abs(b.final_rotation_error_rad[0] - r.final_errors[1]) < FINAL_ERROR_TOLERANCE


def test_a_start_past_a_joint_limit_stops_joint_limit():
    """The default start's joints with the last joint a whole turn on, past its limit:
    the same camera pose (in D, the geometry says), so only the joint limit can stop it,
    at t = 0; the default start itself runs on."""
    from geovs_drake.goal.arm import arm_model, solve_joints

    config = ScenarioConfig(carrier=Arm())
    resolved = resolve(config)
    p = arm_loop_parameters(resolved)
    q0 = solve_joints(arm_model(config), config.X_WB @ config.X_BC_initial)
    lower, upper = p.tree.joint[-1, 3], p.tree.joint[-1, 4]
    turned = np.array(q0, dtype=float)
    turned[-1] += 2 * np.pi if turned[-1] + 2 * np.pi > upper else -2 * np.pi
    assert not lower <= turned[-1] <= upper
    goal = (resolved.config.X_WB @ resolved.config.X_BC_goal).GetAsMatrix4()
    b = run_arm_batch(
        p, goal, np.stack([q0, turned]), None, 0.05, 1e-6, convergence_tolerance(resolved)
    )
    assert list(b.status) == ["not_converged", "joint_limit"]
    assert b.t_stop[1] == 0.0 and b.min_joint_margin[1] < 0


def test_a_camera_on_the_arm_is_refused_by_the_batch_engine_with_the_remedy():
    """The rendered camera on the arm: the batch engine refuses it in one line naming
    --engine drake (the CLI's exit 2 is tested with the other bad inputs); the pinhole
    runs (tests/test_batch_arm_pinhole.py)."""
    with pytest.raises(sweep.SweepError, match="--engine drake"):
        sweep.run_sweep(
            ScenarioConfig(carrier=Arm(), sensor=Rendered()),
            sweep.SampledStarts(1),
            1.0,
            engine="batch",
            workers=1,
        )


@pytest.mark.parametrize(
    "gain_scale, clamped, sensor",
    [(10.0, True, Exact()), (1.0, False, Exact()), (10.0, True, Pinhole())],
    ids=["clamped", "inside", "clamped-pinhole"],
)
def test_the_batch_engine_s_clamp_flag_is_drake_s_torque_against_the_effort_limits(
    gain_scale, clamped, sensor
):
    """The UR5's default start, 0.1 s: at gain scale 10 (the default) its torque passes
    wrist 2's effort limit at t = 0 (docs/arm.md, "Torques inside the effort limits"), at
    1 it stays inside. The batch engine's ``torque_clamped`` is what Drake's diagram says:
    the arm's torque at the run's logged states against MultibodyPlant's effort limits
    (the run's ``torque_clamped_fraction``), with the exact sensor and the pinhole's
    frame clock (its own integrator, :mod:`geovs_drake.batch.arm_sampled`)."""
    config = ScenarioConfig(carrier=Arm(gain_scale=gain_scale), duration=0.1, sensor=sensor)
    r = simulate(config)
    assert (r.carrier_entries["torque_clamped_fraction"] > 0) is clamped
    resolved = resolve(config)
    p = arm_loop_parameters(resolved)
    goal = (resolved.config.X_WB @ resolved.config.X_BC_goal).GetAsMatrix4()
    nv = p.tree.nv
    b = run_arm_batch(
        p, goal, r.states[0][None, :nv], None, 0.1, 1e-6, convergence_tolerance(resolved)
    )
    assert bool(b.torque_clamped[0]) is clamped


@pytest.mark.parametrize("sensor", [Exact(), Pinhole()], ids=["exact", "pinhole"])
def test_the_arm_integrators_give_the_same_rows_on_one_thread_and_on_two(sensor):
    """The arm's batch integrators run their starts in slices on threads
    (``batch._threads.over_starts``): the slices' rows are those of one thread's run,
    bit for bit, the free engine's too (its pinhole integrator shares the slicing)."""
    for config in (ScenarioConfig(carrier=Arm(), sensor=sensor), ScenarioConfig(sensor=sensor)):
        starts = sweep.SampledStarts(6, seed=11, velocity="bounded")
        one = sweep.run_sweep(config, starts, 0.3, workers=1, chunk=6).table
        two = sweep.run_sweep(config, starts, 0.3, workers=2, chunk=6).table
        assert (one["status"] != "unreachable").any()
        pd.testing.assert_frame_equal(one, two)
