"""The joint-limit barrier on the dynamic arm (geometry.joint_barrier, ArmCamera).

Truths: central differences for the barrier's gradient, its definition at the limits
and away from them, AutoDiffXd of the system's own scalar conversion, and the energy
E = 1/2 v^T M v + k_p phi_total from Drake's kinetic energy along the Drake loop;
without the barrier's torque the same E rises, so the check can fail.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

from geovs_drake.geometry.joint_barrier import combine, joint_barrier, smooth_step
from geovs_drake.goal.arm import arm_model, joint_barrier_values
from geovs_drake.loop import resolve
from geovs_drake.scenario import Arm, ScenarioConfig
from geovs_drake.simulation import simulate
from geovs_drake.systems.arm_model import CAMERA_FRAME, arm_plant, camera_jacobian

LOWER, UPPER = np.array([-1.0, -2.0, -0.5]), np.array([1.0, 2.0, 3.0])
WIDTH = 0.4


def _assert_torque_gradient_is_central_differences(system, q: np.ndarray) -> None:
    """ArmCamera's torque at (q, v) with a fixed wrench, phi and k_p: its AutoDiffXd
    gradient in the state equals central differences of the float system."""
    ad = system.ToAutoDiffXd()
    v = np.array([0.1, -0.2, 0.3, 0.0, 0.1, -0.1])
    wrench, phi = np.array([0.5, -0.2, 0.1, 2.0, -1.0, 0.5]), np.array([0.3])

    def tau(sys, x):
        context = sys.CreateDefaultContext()
        sys.arm_state_input.FixValue(context, x)
        sys.wrench_C_input.FixValue(context, wrench)
        sys.phi_input.FixValue(context, phi)
        sys.potential_gain_input.FixValue(context, [4.0])
        return sys.actuation_output.Eval(context)

    x = np.concatenate([q, v])
    gradient = ExtractGradient(tau(ad, InitializeAutoDiff(x).ravel()))
    h = 1e-6
    fd = np.stack(
        [(tau(system, x + h * e) - tau(system, x - h * e)) / (2 * h) for e in np.eye(len(x))],
        axis=1,
    )
    assert np.allclose(gradient, fd, rtol=1e-6, atol=1e-5)


def _assert_barrier_gradient_is_central_differences(q: np.ndarray, width) -> None:
    """dphi_q/dq of the barrier (one width, or one per joint) at q equals its central
    differences."""
    _, grad = joint_barrier(q, LOWER, UPPER, width, min)
    h = 1e-7
    fd = [
        (
            joint_barrier(q + h * e, LOWER, UPPER, width, min)[0]
            - joint_barrier(q - h * e, LOWER, UPPER, width, min)[0]
        )
        / (2 * h)
        for e in np.eye(len(q))
    ]
    assert np.allclose(grad, fd, atol=1e-6), (q, grad, fd)


def test_the_barrier_is_zero_away_from_the_limits_and_one_at_them():
    phi, grad = joint_barrier([0.0, 0.0, 1.0], LOWER, UPPER, WIDTH, min)
    assert phi == 0.0 and np.allclose(grad, 0.0)
    for i in range(3):
        for q_i in (LOWER[i], UPPER[i]):
            q = np.array([0.0, 0.0, 1.0])
            q[i] = q_i
            assert joint_barrier(q, LOWER, UPPER, WIDTH, min)[0] == pytest.approx(1.0)
    inside = joint_barrier([0.9, 0.0, 1.0], LOWER, UPPER, WIDTH, min)[0]  # 0.1 from a limit
    assert 0.0 < inside < 1.0
    # C^2 where the step ends: value 1, slope 0, and the second difference / h^2 (the
    # second derivative) shrinks with h (it is h / w^3 from the inside).
    curvature = []
    for h in (1e-3, 1e-4):
        s = [smooth_step(WIDTH + k * h, WIDTH, min)[0] for k in (-1, 0, 1)]
        assert s[1] == 1.0 and smooth_step(WIDTH, WIDTH, min)[1] == 0.0
        curvature.append(abs(s[0] - 2 * s[1] + s[2]) / h**2)
    assert curvature[1] < 0.2 * curvature[0] and curvature[1] < 2e-3


def test_the_barrier_gradient_is_its_central_difference():
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.uniform(LOWER + 1e-3, UPPER - 1e-3)
        _assert_barrier_gradient_is_central_differences(q, WIDTH)
    assert combine(0.3, 0.0) == 0.3 and combine(0.0, 0.4) == 0.4 and combine(1.0, 0.2) == 1.0


def _elbow_swing(width: float) -> ScenarioConfig:
    """The default start with the elbow (limits +-pi) swung towards its limit, E0 < k_p.

    At the arm's default gains (gain_scale 10) this swing asks wrist 2 for 43.5 N m
    against its 28 N m effort limit; MultibodyPlant clamps the actuation and the energy
    balance is off by 0.09 J in the first 60 ms (the argument needs torques within the
    limits). With the free rig's gains (gain_scale 1) the torques stay within them.
    """
    # Logged at 1 kHz: the trapezoid rule must follow the first swing's transient.
    config = ScenarioConfig(carrier=Arm(), duration=3.0, log_rate=1000.0)
    config.carrier.gain_scale = 1.0
    config.carrier.initial_joint_velocity = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    config.carrier.joint_barrier_width = width
    return config


def _energy_balance(result, width: float) -> np.ndarray:
    """E(t) - E(0) + the energy dissipated by t, with E = 1/2 v^T M v + k_p phi_total
    (Drake's kinetic energy) and the dissipation (1 - phi_q) twist^T B twist + v^T B_q v
    (twist = J_C v), integrated by the trapezoid rule: 0 up to the rule's error where
    Edot is exactly minus the dissipation."""
    resolved = resolve(result.config)
    B, B_q = np.asarray(resolved.damping), resolved.config.carrier.joint_damping
    model = arm_model(resolved.config)
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)
    nq = plant.num_positions()
    k_p = result.energy_bound
    phi_q = joint_barrier_values(model, result.states[:, :nq], width)
    kinetic, dissipation = [], []
    for x, barrier in zip(result.states, phi_q, strict=True):
        plant.SetPositionsAndVelocities(context, x)
        twist = camera_jacobian(plant, context, camera) @ x[nq:]
        kinetic.append(plant.CalcKineticEnergy(context))
        dissipation.append((1 - barrier) * twist @ (B * twist) + B_q * x[nq:] @ x[nq:])
    E = np.asarray(kinetic) + k_p * combine(result.phi, phi_q)
    dissipation = np.asarray(dissipation)
    dt = np.diff(result.times)
    lost = np.concatenate([[0.0], np.cumsum(dt * 0.5 * (dissipation[1:] + dissipation[:-1]))])
    return E - E[0] + lost


def test_the_barrier_torque_keeps_the_energy_with_phi_total_balanced():
    width = 2.5  # the elbow's margin: 1.67 rad at the start (phi_q = 0.037 there)
    barred = simulate(_elbow_swing(width))
    summary = barred.arm.summary()
    assert summary["max_joint_barrier"] > 0.05  # the barrier was entered (0.080)
    assert barred.initial_energy < barred.energy_bound and barred.lyapunov_monotone
    # Edot = -dissipation along the barred loop, to the trapezoid rule's error (5e-6 J).
    balance = np.abs(_energy_balance(barred, width)).max()
    assert balance < 1e-4 * barred.initial_energy, balance
    # Without the barrier's torque the same E is off balance by k_p times the barrier
    # it enters (0.26 J: the check can fail), and the elbow comes nearer its limit
    # (1.29 rad against 1.42).
    free = simulate(_elbow_swing(0.0))
    assert np.abs(_energy_balance(free, width)).max() > 1000 * balance
    assert summary["min_joint_limit_margin"] > free.arm.summary()["min_joint_limit_margin"] + 0.1


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--plant", "kinematic"], "joint_barrier_width applies to the dynamic arm under the NF"),
        (["--controller", "ibvs"], "joint_barrier_width applies to the dynamic arm under the NF"),
    ],
)
def test_the_barrier_is_for_the_dynamic_arm_under_the_nf(argv, needle, run_cli):
    text = "carrier: !Arm {joint_barrier_width: 0.5}"
    run = run_cli("simulate", "--carrier", "arm", "--scenario-text", text, *argv)
    assert run.code == 2 and run.err.count("\n") == 1 and needle in run.err, run.err


def test_a_negative_barrier_width_is_one_line(run_cli):
    text = "carrier: !Arm {joint_barrier_width: -0.1}"
    run = run_cli("simulate", "--carrier", "arm", "--scenario-text", text)
    assert run.code == 2 and "carrier.joint_barrier_width" in run.err and "-0.1" in run.err, run.err


def test_the_barrier_torque_differentiates_by_autodiff_as_by_central_differences(arm_config):
    """ArmCamera with the barrier converts to AutoDiffXd (Drake's Linearize needs it);
    d tau / d q by AutoDiffXd against central differences of the float system, at a q
    inside the barrier."""

    from geovs_drake.systems import ArmCamera

    config = arm_config
    model = arm_model(config)
    system = ArmCamera(model=model, joint_barrier_width=2.5)
    q = np.array([-0.3, -0.25, 2.2, 1.87, 0.49, -1.08])  # the elbow 0.94 rad from its limit
    _assert_torque_gradient_is_central_differences(system, q)
    assert joint_barrier_values(model, q, 2.5)[0] > 0.1  # the barrier term is in play


def test_the_barrier_reads_the_nf_wrench_s_own_k_p(arm_config):
    """One k_p: the barrier's is the ImageJacobianForce's parameter, through a port, so a
    gain set in a context (set_potential_gain) moves the wrench and the barrier alike. At
    rest, doubling k_p doubles the NF wrench F_C, so the torque changes by
    (1 - phi_q) J_C^T F_C - k_p (1 - phi) dphi_q/dq (ArmCamera's law, written here)."""
    from geovs_drake.geometry.joint_barrier import joint_barrier
    from geovs_drake.loop import build_loop, resolve
    from geovs_drake.systems.arm_model import CAMERA_FRAME, arm_plant, camera_jacobian

    config = arm_config
    config.carrier.joint_barrier_width = 2.5
    loop = build_loop(resolve(config), log=False)
    diagram = loop.diagram
    arm, force = (diagram.GetSubsystemByName(n) for n in ("arm_camera", "image_jacobian_force"))
    root = diagram.CreateDefaultContext()
    q = np.array([-0.3, -0.25, 2.2, 1.87, 0.49, -1.08])  # inside the barrier, at rest
    loop.carrier.plant.SetPositions(loop.carrier.plant.GetMyMutableContextFromRoot(root), q)
    arm_context = arm.GetMyContextFromRoot(root)
    force_context = force.GetMyMutableContextFromRoot(root)
    k_p = arm.potential_gain_input.Eval(arm_context)[0]
    assert k_p == resolve(config).config.control.potential_gain
    tau = arm.actuation_output.Eval(arm_context).copy()
    F_C = force.wrench_C_output.Eval(force_context).copy()
    phi = arm.phi_input.Eval(arm_context)[0]
    force.set_potential_gain(force_context, 2 * k_p)
    assert arm.potential_gain_input.Eval(arm_context)[0] == 2 * k_p
    change = arm.actuation_output.Eval(arm_context) - tau

    plant = arm_plant(arm_model(config))
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    J = camera_jacobian(plant, context, plant.GetFrameByName(CAMERA_FRAME))
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    phi_q, dphi_q = joint_barrier(q, lower, upper, 2.5, min)
    assert phi_q > 0.1 and np.linalg.norm(F_C) > 0  # both terms in play
    expected = plant.MakeActuationMatrix().T @ (
        (1 - phi_q) * J.T @ F_C - k_p * (1 - phi) * np.asarray(dphi_q)
    )
    assert np.allclose(change, expected, rtol=1e-9, atol=1e-9 * np.max(np.abs(expected)))


def test_the_barrier_width_shrinks_the_goals_the_arm_can_reach(arm_config):
    """A goal whose joints lie within w of a limit is not a minimum of phi_total (phi_q >
    0 there): the count of reachable goals never grows with w, and at w = 0 it is every
    goal IK reaches; the default goal (1.98 rad from its nearest limit) stays reachable
    for the widths the docs suggest."""
    from geovs_drake.analysis.linear.arm_study import reachable_goals
    from geovs_drake.goal.arm import joint_limit_margins, solve_joints

    config = arm_config
    widths = (0.0, 0.5, 1.5, 2.5)
    goals = reachable_goals(config, widths, n=20)
    counts = [goals.reachable[w] for w in widths]
    assert goals.reachable[0.0] == goals.solvable <= goals.sampled == 20
    assert all(a >= b for a, b in zip(counts, counts[1:], strict=False)) and counts[-1] < counts[0]
    model = arm_model(config)
    q_goal = solve_joints(model, config.X_WB @ config.X_BC_goal)
    assert np.min(joint_limit_margins(model, q_goal)) > 1.5


# ------------------------------------------------------------------ per-joint widths
WIDTHS = (0.4, 1.2, 0.25)  # one per joint of LOWER, UPPER


def test_a_per_joint_width_is_each_joint_s_own_step():
    """Truth: the module docstring's step written here per joint, with each joint's own
    width, multiplied out; a joint 0.3 from its limit is in the barrier of width 0.4 but
    not of 0.25, so the widths' order matters and the check can fail."""

    def step(m, w):
        return 1 - (1 - min(m / w, 1.0)) ** 3

    rng = np.random.default_rng(3)
    for _ in range(20):
        q = rng.uniform(LOWER + 1e-3, UPPER - 1e-3)
        product = np.prod(
            [step(q[i] - LOWER[i], w) * step(UPPER[i] - q[i], w) for i, w in enumerate(WIDTHS)]
        )
        assert joint_barrier(q, LOWER, UPPER, WIDTHS, min)[0] == pytest.approx(1 - product)
    q = np.array([0.0, 0.0, 2.7])  # the third joint 0.3 from its upper limit
    assert joint_barrier(q, LOWER, UPPER, WIDTHS, min)[0] == 0.0
    assert joint_barrier(q, LOWER, UPPER, (0.4, 1.2, 0.4), min)[0] > 0.0
    # One number is that width for every joint.
    assert joint_barrier(q, LOWER, UPPER, 0.4, min) == joint_barrier(
        q, LOWER, UPPER, (0.4,) * 3, min
    )


def test_the_per_joint_barrier_gradient_is_its_central_difference():
    rng = np.random.default_rng(1)
    for _ in range(20):
        # Each joint 0.01 to 0.6 from a limit: inside its own width, or just outside it.
        margin = rng.uniform(0.01, 0.6, 3)
        q = np.where(rng.random(3) < 0.5, LOWER + margin, UPPER - margin)
        _assert_barrier_gradient_is_central_differences(q, WIDTHS)


def test_the_fraction_gives_each_joint_that_share_of_its_range():
    from geovs_drake.geometry.joint_barrier import joint_widths

    assert joint_widths(LOWER, UPPER, fraction=0.1) == pytest.approx((0.2, 0.4, 0.35))
    assert joint_widths(LOWER, UPPER, width=0.5) == (0.5, 0.5, 0.5)
    assert joint_widths(LOWER, UPPER) is None
    with pytest.raises(ValueError, match="3 finite widths > 0"):
        joint_barrier([0.0, 0.0, 1.0], LOWER, UPPER, (0.4, 0.0, 0.3), min)


@pytest.mark.parametrize(
    ("text", "argv", "needle"),
    [
        (
            "{joint_barrier_fraction: 0.1, joint_barrier_width: 0.5}",
            [],
            "carrier.joint_barrier_fraction and carrier.joint_barrier_width are exclusive",
        ),
        ("{joint_barrier_fraction: 0.5}", [], "joint_barrier_fraction = 0.5"),
        ("{joint_barrier_fraction: -0.1}", [], "joint_barrier_fraction = -0.1"),
        (
            "{joint_barrier_fraction: 0.1}",
            ["--controller", "ibvs"],
            "joint_barrier_fraction applies to the dynamic arm under the NF",
        ),
    ],
)
def test_a_bad_barrier_fraction_is_one_line(text, argv, needle, run_cli):
    run = run_cli("simulate", "--carrier", "arm", "--scenario-text", f"carrier: !Arm {text}", *argv)
    assert run.code == 2 and run.err.count("\n") == 1 and needle in run.err, run.err


def test_the_per_joint_barrier_torque_differentiates_by_autodiff_as_by_central_differences(
    arm_config,
):
    """ArmCamera with a width per joint (10 % of each range: 1.26 rad, the elbow 0.63)
    converts to AutoDiffXd; d tau / d q against central differences of the float system,
    at a q where the elbow and wrist 1 are inside their own widths."""

    from geovs_drake.geometry.joint_barrier import joint_widths
    from geovs_drake.systems import ArmCamera

    model = arm_model(arm_config)
    plant = arm_plant(model)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    widths = joint_widths(lower, upper, fraction=0.1)
    assert widths[2] == pytest.approx(0.2 * np.pi) and widths[0] == pytest.approx(0.4 * np.pi)
    system = ArmCamera(model=model, joint_barrier_width=widths)
    q = np.array([-0.3, -0.25, 2.7, 5.4, 0.49, -1.08])  # elbow 0.44, wrist 1 0.88 from limits
    _assert_torque_gradient_is_central_differences(system, q)
    _, dphi_q = joint_barrier(q, lower, upper, widths, min)
    # Both near their upper limits (phi_q grows towards them); joint 1 outside its width.
    assert dphi_q[2] > 0 and dphi_q[3] > 0 and dphi_q[0] == 0
