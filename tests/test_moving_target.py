"""A moving target (issue 32): its motion, the loop in its frame, the feed-forward, the
estimator, and the lag the linear model predicts without feed-forward."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from geovs_drake.geometry.so3 import hat
from geovs_drake.geometry.target_motion import (
    adjoint,
    frame_wrench,
    se3_exp,
    se3_log,
    target_pose,
)
from geovs_drake.goal.linear_model import tracking_lag, tracking_lag_range
from geovs_drake.loop import build_loop, resolve
from geovs_drake.scenario import Dynamic, Kinematic, ScenarioConfig, Still, Twist, load_scenario
from geovs_drake.simulation import simulate
from geovs_drake.systems.target_motion import TargetMotion, matrix_of_pose, pose_of_matrix

#: The issue's target: a circle of radius v / omega = 0.25 m in the target's x-y plane.
XI_B = [0.0, 0.0, 0.2, 0.05, 0.0, 0.0]
#: The issue's bounds on the steady tracking error [m] (largest over the run's last quarter).
KNOWN_BOUND_M, ESTIMATED_BOUND_M, PINHOLE_BOUND_M = 1e-6, 1e-5, 3e-3
#: How far the lag without feed-forward may be from the linear model's prediction.
LAG_TOLERANCE = 0.15
#: The issue's duration [s] (the slow tests) and the short cases' (the suite).
FULL_S, SHORT_S = 40.0, 12.0


def _twist_matrix(xi: np.ndarray) -> np.ndarray:
    """xi^ in se(3), (omega, v)."""
    out = np.zeros((4, 4))
    out[:3, :3] = hat(xi[:3])
    out[:3, 3] = xi[3:]
    return out


def _expm(A: np.ndarray) -> np.ndarray:
    """The matrix exponential by scaling and squaring of its Taylor series: an independent
    truth for the closed form (no scipy here)."""
    k = max(0, int(np.ceil(np.log2(max(np.linalg.norm(A, 1), 1e-300)))) + 4)
    B, term, out = A / 2**k, np.eye(len(A)), np.eye(len(A))
    for n in range(1, 25):
        term = term @ B / n
        out = out + term
    for _ in range(k):
        out = out @ out
    return out


def _config(plant, feedforward: str, duration: float, **kwargs) -> ScenarioConfig:
    return ScenarioConfig(
        plant=plant,
        duration=duration,
        target_motion=Twist(twist=list(XI_B), feedforward=feedforward),
        **kwargs,
    )


# ------------------------------------------------------------------ the geometry
@pytest.mark.parametrize(
    "xi",
    [
        [0.0, 0.0, 0.2, 0.05, 0.0, 0.0],
        [0.3, -1.2, 0.7, 0.4, -0.2, 0.9],
        [1e-7, 0.0, -2e-7, 0.1, 0.2, 0.3],
        [0.0] * 6,
    ],
)
def test_se3_exp_is_the_matrix_exponential_and_log_inverts_it(xi):
    xi = np.asarray(xi)
    X = se3_exp(xi)
    np.testing.assert_allclose(X, _expm(_twist_matrix(xi)), atol=1e-13)
    np.testing.assert_allclose(se3_log(X), xi, atol=1e-12)


def test_target_pose_follows_the_body_twist():
    X_WB0 = RigidTransform(RollPitchYaw(0.3, -0.2, 1.1), [0.5, -0.1, 1.0]).GetAsMatrix4()
    xi = np.array(XI_B)
    for t in (0.0, 1.7, 31.4):
        np.testing.assert_allclose(
            target_pose(X_WB0, xi, t), X_WB0 @ _expm(t * _twist_matrix(xi)), atol=1e-12
        )
    # d/dt X_WB = X_WB xi^ (a body twist), by central differences.
    t, h = 2.0, 1e-6
    dX = (target_pose(X_WB0, xi, t + h) - target_pose(X_WB0, xi, t - h)) / (2 * h)
    np.testing.assert_allclose(dX, target_pose(X_WB0, xi, t) @ _twist_matrix(xi), atol=1e-8)


def test_adjoint_carries_a_twist_between_frames():
    X = RigidTransform(RollPitchYaw(0.4, 0.1, -0.7), [0.2, -0.3, 0.5]).GetAsMatrix4()
    xi = np.array([0.3, -0.2, 0.5, 0.1, 0.7, -0.4])
    # Ad_X xi^ = X xi^ X^-1 (the definition).
    np.testing.assert_allclose(
        _twist_matrix(adjoint(X) @ xi), X @ _twist_matrix(xi) @ np.linalg.inv(X), atol=1e-14
    )


def test_frame_wrench_is_the_world_dynamics_seen_from_the_target():
    """F_frame = M V_r' + C(V_r) - F: V_r' from the world's Newton-Euler and the target's
    twist carried to R, differentiated by central differences along the motion."""
    rng = np.random.default_rng(3)
    J, m = np.diag([0.02, 0.03, 0.025]), 1.3
    M = np.block([[J, np.zeros((3, 3))], [np.zeros((3, 3)), m * np.eye(3)]])
    X_BR = RigidTransform(RollPitchYaw(0.2, -0.4, 0.9), [0.1, 0.2, -0.6]).GetAsMatrix4()
    V_r = rng.normal(size=6)
    xi, xi_dot = rng.normal(size=6), rng.normal(size=6)
    F = rng.normal(size=6)

    def bias(V):
        return np.concatenate([np.cross(V[:3], J @ V[:3]), m * np.cross(V[:3], V[3:])])

    def xi_R(t):  # Ad_{X_RB(t)} xi_B(t), R moving relative to B with V_r, xi_B with xi_dot
        X = X_BR @ se3_exp(t * V_r)
        return adjoint(np.linalg.inv(X)) @ (xi + t * xi_dot)

    h = 1e-6
    rate = (xi_R(h) - xi_R(-h)) / (2 * h)
    V = V_r + xi_R(0.0)
    V_dot = np.linalg.solve(M, F - bias(V))  # the world's Newton-Euler in the body frame
    expected = M @ (V_dot - rate) + bias(V_r) - F
    Ad_RB = adjoint(np.linalg.inv(X_BR))
    got = frame_wrench(V_r, Ad_RB @ xi, Ad_RB @ xi_dot, J, m)
    np.testing.assert_allclose(got, expected, atol=1e-8)


# ------------------------------------------------------------------ the scenario
def test_target_motion_loads_from_yaml_and_checks_its_fields():
    config = load_scenario(data="target_motion: !Twist {twist: [0, 0, 0.2, 0.05, 0, 0]}")
    assert config.target_motion == Twist(twist=list(XI_B))
    assert config.target_motion.feedforward == "estimated"
    assert isinstance(load_scenario().target_motion, Still)
    for motion, needle in (
        (Twist(twist=[0.0, 0.2]), "target_motion.twist must be 6 finite numbers"),
        (Twist(twist=list(XI_B), feedforward="psychic"), "target_motion.feedforward"),
        (Twist(twist=list(XI_B), pose_noise=0.0), "target_motion.pose_noise"),
    ):
        with pytest.raises(ValueError, match=needle):
            ScenarioConfig(target_motion=motion).validate()


def test_a_still_target_adds_nothing_to_the_loop():
    names = {s.get_name() for s in build_loop(ScenarioConfig()).diagram.GetSystems()}
    assert not {n for n in names if "target" in n}
    moving = build_loop(_config(Dynamic(), "estimated", 1.0)).diagram
    assert {"target_motion", "target_relative_wrench", "target_twist_estimator"} <= {
        s.get_name() for s in moving.GetSystems()
    }


def test_target_motion_system_gives_the_closed_form_pose_and_the_world_pose():
    X_WB0 = ScenarioConfig().X_WB
    system = TargetMotion(X_WB0=X_WB0, twist=np.array(XI_B))
    context = system.CreateDefaultContext()
    X_WpR = RigidTransform(RollPitchYaw(0.1, 0.2, 0.3), [0.3, 0.4, 1.2]).GetAsMatrix4()
    system.body_pose_input.FixValue(context, pose_of_matrix(X_WpR))
    t = 3.3
    context.SetTime(t)
    X_WB = X_WB0.GetAsMatrix4() @ _expm(t * _twist_matrix(np.array(XI_B)))
    np.testing.assert_allclose(
        matrix_of_pose(system.target_pose_output.Eval(context)), X_WB, atol=1e-12
    )
    # The body keeps its pose relative to the target: X_BR = X_WB0^-1 X_W'R.
    X_WR = matrix_of_pose(system.world_body_pose_output.Eval(context))
    np.testing.assert_allclose(
        np.linalg.solve(X_WB, X_WR), np.linalg.solve(X_WB0.GetAsMatrix4(), X_WpR), atol=1e-12
    )


# ------------------------------------------------------------------ the loop
def test_kinematic_known_feedforward_tracks_as_a_still_target_converges():
    moving = simulate(_config(Kinematic(), "known", SHORT_S))
    still = simulate(ScenarioConfig(plant=Kinematic(), duration=SHORT_S))
    assert moving.status == "converged"
    # The relative pose evolves as for a still target (Eq. 17 in the target's frame).
    n = min(len(moving.X_BC), len(still.X_BC))
    np.testing.assert_allclose(moving.X_BC[:n], still.X_BC[:n], atol=1e-9)
    assert moving.steady_tracking_error <= KNOWN_BOUND_M


def test_dynamic_known_feedforward_keeps_the_relative_energy_monotone():
    result = simulate(_config(Dynamic(), "known", 2.0))  # the transient: E falls most
    assert result.energy is not None  # relative kinetic energy + k_p phi
    assert result.lyapunov_monotone, float(np.max(np.diff(result.energy)))
    assert result.status != "left_domain"


def test_estimator_converges_to_the_true_twist_with_the_exact_sensor():
    result = simulate(_config(Kinematic(), "estimated", SHORT_S))
    trace = result.target
    assert trace is not None and len(trace.times) > 100
    assert trace.estimation_error[-1] < 1e-6
    # The filter's own uncertainty shrinks from its prior.
    assert np.all(trace.covariance_diagonal[-1, 6:] < 1e-3 * trace.covariance_diagonal[1, 6:])
    assert result.steady_tracking_error <= ESTIMATED_BOUND_M


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=["kinematic", "dynamic"])
def test_lag_without_feedforward_is_the_linear_models(plant):
    # From the goal (the slow test starts from the default start): the lag builds up in
    # a few of the loop's time constants, with the integrator's large steps.
    start = ScenarioConfig().goal
    result = simulate(_config(plant, "none", SHORT_S, initial=start))
    assert not result.left_domain
    predicted = result.predicted_steady_error
    assert predicted == pytest.approx(np.linalg.norm(tracking_lag(result.resolved, XI_B)[3:]))
    assert abs(result.steady_tracking_error - predicted) <= LAG_TOLERANCE * predicted


def test_tracking_lag_of_the_kinematic_loop_is_A_inverse_times_the_carried_twist():
    """The kinematic closed form at its simplest: a pure translation of the target along
    the goal's optical axis is carried to C unchanged, eps_ss = A^-1 (0, v)."""
    from geovs_drake.goal.linear_model import closed_form_A

    config = ScenarioConfig(plant=Kinematic())
    xi = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.02])  # along z_B = the goal's optical axis
    resolved = resolve(config)
    np.testing.assert_allclose(
        tracking_lag(resolved, xi), np.linalg.solve(closed_form_A(resolved), xi), atol=1e-15
    )


# ------------------------------------------------------------------ the command line
def test_cli_target_twist_of_the_wrong_length_is_one_line_exit_2(run_cli):
    run = run_cli("simulate", "--target-twist", "0,0,0.2,0.05,0")
    assert run.code == 2
    assert run.err.count("\n") == 1 and "expected 6 finite numbers" in run.err


def test_cli_feedforward_needs_a_moving_target(run_cli):
    run = run_cli("simulate", "--feedforward", "known")
    assert run.code == 2
    assert "applies to a moving target" in run.err


def test_cli_json_reports_the_tracking_errors(run_cli):
    import json

    run = run_cli(
        "simulate",
        "--plant",
        "kinematic",
        "--duration",
        "2",
        "--feedforward",
        "none",
        "--target-twist",
        ",".join(str(v) for v in XI_B),
        "--json",
    )
    summary = json.loads(run.out)
    assert summary["target_motion"]["feedforward"] == "none"
    assert summary["predicted_steady_error_m"] == pytest.approx(0.009, rel=0.01)
    assert summary["max_tracking_error_m"] >= summary["steady_tracking_error_m"] > 0
    # Where that lag holds: the goal camera rides with the target at v + omega x p_BC*
    # (C* is B's axes, 0.5 m back along z), here 0.05 m/s, turning about its own axis.
    p_BC = np.array([0.0, 0.0, -0.5])
    v_C = np.asarray(XI_B[3:]) + np.cross(XI_B[:3], p_BC)
    span = summary["predicted_steady_error_range"]
    assert span["speed_m_s"] == pytest.approx(np.linalg.norm(v_C), abs=1e-12)
    assert span["turn_across_view_rad_s"] == pytest.approx(np.linalg.norm(XI_B[:2]), abs=1e-12)
    assert span["holds"] and span["within"] == 0.05


def test_a_still_target_has_no_tracking_errors(run_cli):
    import json

    run = run_cli("simulate", "--plant", "kinematic", "--duration", "0.5", "--json")
    summary = json.loads(run.out)
    # The start is 0.33 m off the goal: no tracking error, there is no target motion.
    for key in ("steady_tracking_error_m", "max_tracking_error_m", "predicted_steady_error_range"):
        assert summary[key] is None, key


def test_the_issue_s_twist_turns_across_the_view_at_the_range_s_bound():
    # 0, 0.1, 0, 0, 0, 0.04: predicted 4.3 % low on the dynamic rig (issue 42), inside the
    # 5 % range at its turn bound; twice as fast is outside it on the dynamic rig.
    twist = np.array([0.0, 0.1, 0.0, 0.0, 0.0, 0.04])
    v_C = twist[3:] + np.cross(twist[:3], [0.0, 0.0, -0.5])
    span = tracking_lag_range(ScenarioConfig(plant=Dynamic()), twist)
    assert span["speed_m_s"] == pytest.approx(np.linalg.norm(v_C), abs=1e-12)
    assert span["turn_across_view_rad_s"] == pytest.approx(0.1, abs=1e-12) and span["holds"]
    assert not tracking_lag_range(ScenarioConfig(plant=Dynamic()), 2 * twist)["holds"]
    assert tracking_lag_range(ScenarioConfig(plant=Kinematic()), 2 * twist)["holds"]


@pytest.mark.slow
@pytest.mark.parametrize("scale, inside", [(4.0, True), (8.0, False)])
def test_the_lag_holds_within_5_percent_inside_its_range_and_not_beyond(scale, inside):
    # The turn across the view on the kinematic rig: 0.2 rad/s inside (3.5 % measured),
    # 0.4 rad/s outside (6.8 %); 40 s from the default start, no feed-forward.
    twist = scale * np.array([0.0, 0.05, 0.0, 0.0, 0.0, 0.02])
    config = ScenarioConfig(
        plant=Kinematic(), target_motion=Twist(twist=twist.tolist(), feedforward="none")
    )
    config.duration = 40.0
    result = simulate(config)
    span = result.summary()["predicted_steady_error_range"]
    assert span["holds"] == inside
    error = abs(result.steady_tracking_error / result.predicted_steady_error - 1)
    assert (error <= span["within"]) == inside


# ------------------------------------------------------------------ the issue's numbers
@pytest.mark.slow
@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=["kinematic", "dynamic"])
def test_issue_numbers_from_the_default_start(plant):
    known = simulate(_config(plant, "known", FULL_S))
    estimated = simulate(_config(plant, "estimated", FULL_S))
    none = simulate(_config(plant, "none", FULL_S))
    for result in (known, estimated, none):
        assert not result.left_domain and result.status != "feature_lost", result.message
    assert known.steady_tracking_error <= KNOWN_BOUND_M
    assert estimated.steady_tracking_error <= ESTIMATED_BOUND_M
    predicted = none.predicted_steady_error
    assert abs(none.steady_tracking_error - predicted) <= LAG_TOLERANCE * predicted


@pytest.mark.slow
def test_dynamic_pinhole_at_30_hz_with_estimated_feedforward():
    from geovs_drake.scenario import Pinhole

    result = simulate(_config(Dynamic(), "estimated", FULL_S, sensor=Pinhole(rate=30.0)))
    assert not result.left_domain and result.status != "feature_lost", result.message
    assert result.steady_tracking_error <= PINHOLE_BOUND_M


# ------------------------------------------------------------------ the systems' docs
@pytest.mark.parametrize(
    "module",
    [
        "target_frame",
        "target_motion",
        "target_relative_twist",
        "target_relative_wrench",
        "target_twist_estimator",
    ],
)
def test_port_block_lists_the_declared_ports_in_order(module):
    """As tests/test_docs.py checks the exported systems: the docstring's port block is
    the system's ports, in order (these systems are not yet in systems.__all__)."""
    import importlib
    import re

    mod = importlib.import_module(f"geovs_drake.systems.{module}")
    name = "".join(part.capitalize() for part in module.split("_"))
    system = getattr(mod, name)()
    block = re.search(r"\.\. pydrake_system::\n\n((?:[ \t]+\S.*\n)+)", type(system).__doc__)
    lines = [line.strip() for line in block.group(1).splitlines()]
    assert lines[0] == f"name: {name}"
    inputs = lines[lines.index("input_ports:") + 1 : lines.index("output_ports:")]
    outputs = lines[lines.index("output_ports:") + 1 :]
    assert [s.removeprefix("- ") for s in inputs] == [
        system.get_input_port(i).get_name() for i in range(system.num_input_ports())
    ]
    assert [s.removeprefix("- ") for s in outputs] == [
        system.get_output_port(i).get_name() for i in range(system.num_output_ports())
    ]


# -------------------------------------------------- the transfer from target motion
def _sine_target(amplitude: float, frequency: float, duration: float) -> list[list[float]]:
    """Knots (every 0.05 s) of a target sliding along its x axis, a sin(2 pi f t)."""
    times = np.arange(0.0, duration + 1e-9, 0.05)
    return [[t, 1, 0, 0, 0, amplitude * np.sin(2 * np.pi * frequency * t), 0, 0] for t in times]


def _predicted_peak(config, frequency: float, xi_hat: np.ndarray) -> float:
    """The largest |position error| over a period of eps(t) = Re(G xi_hat e^{jwt})."""
    from geovs_drake.goal.linear_model import tracking_transfer

    response = tracking_transfer(resolve(config), [frequency])[0] @ xi_hat
    phases = np.linspace(0.0, 2 * np.pi, 721)
    return max(np.linalg.norm(np.real(response * np.exp(1j * p))[3:]) for p in phases)


def test_the_transfer_at_zero_frequency_is_the_lag():
    """tracking_transfer at f = 0 is tracking_lag per unit twist for a pure translation
    (no centripetal wrench), on both plants; far above the loop's bandwidth the camera
    cannot follow at all, and the error is the target's own displacement, -nu_B / s
    (s G(s) -> -Ad_{X_C*B})."""
    from geovs_drake.goal.linear_model import tracking_transfer, velocity_adjoint

    xi = np.array([0.0, 0.0, 0.0, 0.05, 0.02, 0.0])
    fast = 1e4  # [Hz]: the next term is A / s, A up to about 60 / s here
    for plant in (Kinematic(), Dynamic()):
        config = ScenarioConfig(plant=plant)
        G = tracking_transfer(resolve(config), [0.0, fast])
        np.testing.assert_allclose(G[0].real @ xi, tracking_lag(resolve(config), xi), atol=1e-15)
        assert np.all(np.abs(G[0].imag) < 1e-15)
        Ad = velocity_adjoint(config.X_BC_goal.inverse())
        np.testing.assert_allclose(2j * np.pi * fast * G[1], -Ad, atol=0.01 * np.abs(Ad).max())


# 2 s each: make test's budget; notebook 06 (run by make docs) asserts the dynamic case.
@pytest.mark.slow
@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=["kinematic", "dynamic"])
def test_a_sliding_target_is_lagged_as_the_transfer_predicts(plant):
    """A target sliding a sin(2 pi f t) (a trajectory target, no feed-forward): once the
    start has died out, the simulated relative position error peaks where the
    linearised transfer says (0.1 Hz, 5 cm: 5.6 mm kinematic, 17.4 mm dynamic)."""
    from geovs_drake.scenario import Trajectory

    amplitude, frequency, duration = 0.05, 0.1, 40.0
    config = ScenarioConfig(
        plant=plant,
        duration=duration - 0.1,
        target_motion=Trajectory(
            poses=_sine_target(amplitude, frequency, duration), feedforward="none"
        ),
    )
    result = simulate(config)
    assert not result.left_domain, result.message
    last_period = result.times >= result.times[-1] - 1.0 / frequency
    simulated = result.position_errors[last_period].max()
    xi_hat = np.array([0.0, 0.0, 0.0, amplitude * 2 * np.pi * frequency, 0.0, 0.0])
    assert simulated == pytest.approx(_predicted_peak(config, frequency, xi_hat), rel=0.01)


def test_the_energy_guarantee_is_claimed_only_where_it_holds():
    """Appendix C's energy covers a moving target's loop on the free rig with the known
    twist (the relative dynamics are a still target's); behind an estimated twist the
    run claims no guarantee, in its JSON nor in its line."""
    known = simulate(_config(Dynamic(), "known", 1.0))
    estimated = simulate(_config(Dynamic(), "estimated", 1.0))
    assert known.energy_applies and known.energy_guarantee is True
    assert not estimated.energy_applies and estimated.energy_guarantee is None
    assert estimated.summary()["energy_guarantee"] is None
    assert "no energy guarantee: behind a moving target" in estimated.one_line()
    assert "the energy guarantee covers this start" in known.one_line()
