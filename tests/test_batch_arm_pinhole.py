"""The arm with the 30 Hz pinhole in the batch engine, and ``sweep --carrier arm --sensor
pinhole`` on it, against the Drake loop.

Truth: Drake's own Simulator on the loop ``build_loop`` assembles for the same scenario
(the PinholeFeatureSensor's periodic frames on the arm's camera pose, its latency line,
the FramePredictor on the same pose), its fifth-order integrator at accuracy 1e-10, and
the Drake engine's sweep rows (simulate() start by start). The batch engine reads the
systems' parameters from the diagram but measures, holds, predicts and integrates with
its own code.
"""

import copy

import numpy as np
import pytest
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

from geovs_drake.analysis import sweep
from geovs_drake.batch.arm_engine import run_arm_batch
from geovs_drake.batch.arm_rhs import arm_loop_parameters
from geovs_drake.goal.arm import arm_model, solve_joints
from geovs_drake.loop import build_loop, resolve
from geovs_drake.scenario import Arm, Kinematic, Pinhole, ScenarioConfig
from geovs_drake.simulation.result import convergence_tolerance

#: Both integrators run at 1e-10 (relative, per step). Over 0.2 s (six frames) the
#: states differ by 1e-9 to 2e-9 on the dynamic UR5 and by up to 3e-8 (held) and 8e-8
#: (odometry) on the kinematic one, whose joints run at their velocity limits
#: (KinematicArm's scale s <= 1, a kink the two integrators step across differently);
#: on the Panda 2e-8 (dynamic, its torques clamped) and 1e-7 (kinematic); measured.
#: 1e-6 leaves room and still catches a frame read at the wrong time or from the wrong
#: pose (a frame of latency more moves the held loop by 0.1 and more, test below).
STATE_TOLERANCE = 1e-6
#: As tests/test_batch_arm.py's: both engines at the sweep's accuracy.
FINAL_ERROR_TOLERANCE = 1e-6
DURATION = 0.2  # [s]: six 30 Hz frames, one of them late


def _config(
    plant: str, prediction: str, latency_frames: int = 1, model: str = "default"
) -> ScenarioConfig:
    sensor = Pinhole(prediction=prediction, latency_frames=latency_frames)
    config = ScenarioConfig(carrier=Arm(model=model), sensor=sensor)
    if plant == "kinematic":
        config.plant = Kinematic()
    return config


def _starts(config: ScenarioConfig, n: int) -> np.ndarray:
    """The default start's joints and ``n - 1`` others a few degrees from them."""
    q0 = np.asarray(solve_joints(arm_model(config), config.X_WB @ config.X_BC_initial), float)
    offsets = np.random.default_rng(4).normal(0.0, 0.05, (n - 1, len(q0)))
    return np.vstack([q0, q0 + offsets])


def _batch(config: ScenarioConfig, q0: np.ndarray, duration: float):
    resolved = resolve(config)
    p = arm_loop_parameters(resolved)
    goal = (resolved.config.X_WB @ resolved.config.X_BC_goal).GetAsMatrix4()
    return run_arm_batch(p, goal, q0, None, duration, 1e-10, convergence_tolerance(resolved))


def _drake_state_at(config: ScenarioConfig, x0: np.ndarray, t: float) -> np.ndarray:
    truth = copy.deepcopy(config)
    truth.simulator.integration_scheme = "runge_kutta5"
    truth.simulator.accuracy = 1e-10
    simulator = Simulator(build_loop(truth, log=False).diagram)
    ApplySimulatorConfig(truth.simulator.to_drake(), simulator)
    simulator.get_mutable_context().SetContinuousState(x0)
    simulator.AdvanceTo(t)
    return simulator.get_context().get_continuous_state_vector().CopyToVector()


@pytest.mark.parametrize(
    ("plant", "prediction", "model"),
    [
        ("dynamic", "odometry", "default"),
        ("kinematic", "none", "default"),
        pytest.param("dynamic", "none", "default", marks=pytest.mark.slow),
        pytest.param("kinematic", "odometry", "default", marks=pytest.mark.slow),
        # The Panda (redundant: ArmCamera's null-space damping), its torques saturated.
        pytest.param("dynamic", "odometry", "panda", marks=pytest.mark.slow),
        pytest.param("kinematic", "odometry", "panda", marks=pytest.mark.slow),
    ],
)
def test_arm_pinhole_batch_states_match_the_drake_loop(plant, prediction, model):
    """Two starts (UR5; the Panda among the slow ones), one frame of latency, 0.2 s: the
    batch states agree with Drake's loop to 1e-6 (the held frame, or odometry from the
    arm's own camera pose)."""
    config = _config(plant, prediction, model=model)
    q0 = _starts(config, 2)
    result = _batch(config, q0, DURATION)
    nv = q0.shape[1]
    X0 = np.hstack([q0, np.zeros_like(q0)]) if plant == "dynamic" else q0
    moved, worst = 0.0, 0.0
    for i in range(len(q0)):
        truth = _drake_state_at(config, X0[i], DURATION)
        worst = max(worst, float(np.max(np.abs(result.final_states[i] - truth))))
        moved = max(moved, float(np.max(np.abs(truth[:nv] - q0[i]))))
    print(
        f"\n{model} {plant} {prediction}: max |batch - Drake| {worst:.1e}, joints moved {moved:.2f}"
    )
    assert moved > 0.05  # the loop ran: the comparison is not of two resting arms
    assert worst < STATE_TOLERANCE
    assert list(result.status) == ["not_converged"] * len(q0)


def test_a_frame_of_latency_more_moves_the_arm_past_the_tolerance():
    """The tolerance's claim: the held frame two frames late ends more than 1e3 times
    STATE_TOLERANCE from one frame late (a frame read wrong would fail the test above).
    (With odometry the noiseless prediction undoes the latency: no test of the clock.)"""
    q0 = _starts(_config("dynamic", "none"), 1)
    one = _batch(_config("dynamic", "none"), q0, DURATION)
    two = _batch(_config("dynamic", "none", latency_frames=2), q0, DURATION)
    assert np.max(np.abs(one.final_states - two.final_states)) > 1e3 * STATE_TOLERANCE


@pytest.mark.parametrize(
    ("plant", "duration", "n"),
    [
        ("kinematic", 0.5, 2),
        # Converged starts: 10 s per start through simulate() (about 5 s each).
        pytest.param("dynamic", 10.0, 4, marks=pytest.mark.slow),
        pytest.param("kinematic", 10.0, 4, marks=pytest.mark.slow),
    ],
)
def test_the_arm_pinhole_sweep_on_the_batch_engine_gives_the_drake_engine_s_rows(
    plant, duration, n
):
    """``sweep --carrier arm --sensor pinhole`` (odometry, one frame late) on both
    engines: the same statuses and final errors within 1e-6 of the Drake engine's."""
    config = _config(plant, "odometry")
    config.simulator.accuracy = 1e-8
    starts = sweep.SampledStarts(n, seed=0, velocity="bounded" if config.dynamic else "none")
    batch = sweep.run_sweep(config, starts, duration, engine="batch", workers=1).table
    drake = sweep.run_sweep(config, starts, duration, engine="drake", workers=1).table
    assert list(batch.columns) == list(drake.columns)
    assert list(batch["status"]) == list(drake["status"])
    ran = batch["status"] != "unreachable"
    assert ran.any()
    for column in ("final_position_error_m", "final_rotation_error_rad"):
        diff = np.abs(batch[column][ran] - drake[column][ran]).max()
        print(f"\n{plant} {duration} s {column}: max |batch - Drake| = {diff:.1e}")
        assert diff < FINAL_ERROR_TOLERANCE
    if duration > 1.0:
        assert (batch["status"] == "converged").any()
