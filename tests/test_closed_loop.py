"""Closed loops: Drake's Linearize against the closed form, monitors, Monte-Carlo (the CLI's
tests are in test_cli.py)."""

import copy
import json
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest
from pydrake.common.yaml import yaml_dump_typed
from pydrake.math import RigidTransform
from pydrake.multibody.tree import JacobianWrtVariable, RotationalInertia, SpatialInertia

from geovs_drake.analysis.linear.linearization import linearize_at_goal, navigation_hessian
from geovs_drake.analysis.studies.monte_carlo import (
    drake_monte_carlo,
    random_initial_poses,
    run_scenarios,
    scenarios_from_starts,
)
from geovs_drake.batch import run_batch
from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.loop import build_loop
from geovs_drake.loop.carriers import RIG_BODY_NAME
from geovs_drake.scenario import (
    Dynamic,
    Kinematic,
    Pbvs,
    Pinhole,
    PoseConfig,
    ScenarioConfig,
    load_scenario,
    variant_name,
)
from geovs_drake.scenario.traits import LawTraits
from geovs_drake.simulation import StartOutsideDomain, make_simulator, pose_error, simulate
from geovs_drake.simulation.result import convergence_tolerance

OFFSET = PoseConfig(xyz=[0.03, -0.02, 0.05], rpy=[0.1, 0.2, -0.3])


def _with_offset() -> ScenarioConfig:
    c = ScenarioConfig()
    c.carrier.camera_offset = copy.deepcopy(OFFSET)
    c.carrier.inertia_diagonal = [0.02, 0.03, 0.025]
    return c


# ---------------------------------------------------------------- Linearize
@pytest.mark.parametrize(
    "controller,config",
    [
        (Dynamic(), ScenarioConfig()),
        (Dynamic(), _with_offset()),
        (Kinematic(), ScenarioConfig()),
    ],
    ids=["dynamic", "dynamic-camera-off-com", "kinematic"],
)
def test_linearize_matches_closed_form_and_is_stable(controller, config):
    lin = linearize_at_goal(config, controller)
    n = 12 if isinstance(controller, Dynamic) else 6
    assert lin.A.shape == (n, n)
    # The quaternion norm is Drake's extra state: an eigenvector with eigenvalue 0,
    # and the minimal coordinates span an invariant subspace.
    assert abs(lin.quaternion_eigenvalue) < 1e-12
    assert lin.invariance_residual < 1e-12
    ev_full = np.linalg.eigvals(lin.A_drake)
    assert np.sum(np.abs(ev_full) < 1e-9) == 1
    # Same matrix as the closed form, entry by entry.
    np.testing.assert_allclose(lin.A, lin.A_closed, rtol=0, atol=1e-8 * np.max(np.abs(lin.A)))
    assert lin.max_real_part < -0.1, lin.eigenvalues


def test_kinematic_eigenvalues_are_minus_gain_times_nf_hessian():
    config = ScenarioConfig()
    lin = linearize_at_goal(config, Kinematic())
    nf = NavigationFunction(config.domain.to_domain(), config.goal_features())
    H = navigation_hessian(nf, config.goal_features())
    expected = np.sort(-config.control.kinematic_gain * np.linalg.eigvalsh(H))
    np.testing.assert_allclose(np.sort(lin.eigenvalues.real), expected, rtol=1e-9)
    np.testing.assert_allclose(lin.eigenvalues.imag, 0, atol=1e-9)


def test_diagrams_are_named_and_convert_to_autodiff():
    d = build_loop(ScenarioConfig(), log=False).diagram
    k = build_loop(ScenarioConfig(plant=Kinematic()), log=False).diagram
    assert d.get_name() == "dynamic_visual_servo" and k.get_name() == "kinematic_visual_servo"
    for name in ("plant", "spherical_camera", "navigation_controller", "image_jacobian_force"):
        d.GetSubsystemByName(name)
    d.ToAutoDiffXd()
    k.ToAutoDiffXd()
    assert "spherical_camera" in d.GetGraphvizString()


# ------------------------------------------------------------- simulations
@pytest.fixture(scope="module")
def default_dynamic_run():
    return simulate(ScenarioConfig(duration=15.0))


def test_default_dynamic_run_converges_with_decreasing_energy(default_dynamic_run):
    r = default_dynamic_run
    assert r.status == "converged", r.message
    assert r.converged
    assert np.all(r.margins >= 0) and np.all(r.visibility > 0)
    # Energy: E = 1/2 nu^T M nu + k_p phi from Drake's kinetic energy; it starts at
    # k_p phi(0) (at rest) and never rises beyond the integrator's tolerance.
    assert r.energy[0] == pytest.approx(r.config.control.potential_gain * r.phi[0])
    assert np.max(np.diff(r.energy)) <= r.lyapunov_tolerance
    assert r.lyapunov_monotone
    # The logged final pose agrees with the run's final state.
    dp, dr = pose_error(RigidTransform(r.X_BC[-1]), r.config.X_BC_goal)
    assert dp < 1e-3 and dr < 1e-3


@pytest.mark.parametrize(
    "controller,scheme,tolerance",
    # The resampling is a cubic Hermite between accepted steps: its error grows as h^4, so
    # RK5's longer steps (the dynamic loop's default) leave it about 2e-7 from the truth
    # at accuracy 1e-8, RK3's about 1e-9 (the dynamic loop on RK3: 1.3e-10, measured).
    [
        (Dynamic(), None, 1e-6),
        (Kinematic(), None, 1e-8),
    ],
    ids=["dynamic-rk5", "kinematic-rk3"],
)
def test_logs_match_drakes_own_loggers(controller, scheme, tolerance):
    """simulate() logs by resampling its recorded steps; Drake's LogVectorOutput on
    the same diagram (which cuts the steps at each sample) is the truth."""
    config = ScenarioConfig(plant=controller, duration=3.0)
    config.simulator.accuracy = 1e-8
    config.simulator.integration_scheme = scheme
    r = simulate(config)
    loop = build_loop(config, log=True)
    diagram = loop.diagram
    simulator, _ = make_simulator(loop)
    simulator.AdvanceTo(config.duration)
    root = simulator.get_context()
    worst = 0.0
    for name, ours in (
        ("log_image_features", r.image_features),
        ("log_phi", r.phi[:, None]),
        ("log_margins", r.margins),
        ("log_visibility", r.visibility[:, None]),
    ):
        log = diagram.GetSubsystemByName(name).FindLog(root)
        np.testing.assert_allclose(log.sample_times(), r.times, atol=1e-12)
        worst = max(worst, float(np.max(np.abs(log.data().T - ours))))
    print(f"\n{variant_name(controller)}: max |simulate() log - LogVectorOutput| = {worst:.1e}")
    assert worst < tolerance


def test_kinematic_run_decreases_phi_and_converges():
    r = simulate(ScenarioConfig(plant=Kinematic(), duration=15.0))
    assert r.status == "converged", r.message
    assert r.energy is None
    assert np.max(np.diff(r.phi)) <= r.lyapunov_tolerance


def test_camera_off_center_of_mass_converges():
    c = _with_offset()
    c.duration = 15.0
    r = simulate(c)
    assert r.status == "converged", r.message
    assert r.lyapunov_monotone


def test_bad_integrator_configuration_stops_at_the_boundary_not_in_nan():
    c = ScenarioConfig(duration=10.0)
    c.control.potential_gain = 200.0
    c.control.damping = [0.0] * 6
    c.simulator.integration_scheme = "explicit_euler"
    c.simulator.use_error_control = False
    c.simulator.max_step_size = 0.05
    r = simulate(c)
    assert r.status in ("left_domain", "lost_visibility"), r.message
    assert r.left_domain and not r.converged
    assert "left D" in r.message or "lost visibility" in r.message
    assert r.sim_time_s < c.duration
    assert np.all(np.isfinite(r.image_features)) and np.all(np.isfinite(r.phi))


@pytest.mark.parametrize("roll,near", [(np.pi, True), (np.pi - 0.03, True), (2.0, False)])
def test_a_start_near_the_saddle_gets_a_note(roll, near):
    """Rolled pi about the optical axis, the start sits on the NF's saddle (the arrow
    reversed): the run does not converge and says why; 1.7 deg off, it converges
    with the note; far from it, no note."""
    c = ScenarioConfig(initial=PoseConfig(xyz=[0.0, 0.0, -0.5], rpy=[0.0, 0.0, roll]))
    c.duration = 6.0
    r = simulate(c)
    assert r.summary()["near_saddle"] is near
    assert ("saddle" in r.message) is near and ("saddle" in r.one_line()) is near
    if roll == np.pi:
        assert r.status == "not_converged" and "is at the navigation function's saddle" in r.message
        # Independent: the image reached is the saddle's (the goal with q2 reversed).
        nf = NavigationFunction(c.domain.to_domain(), c.goal_features())
        np.testing.assert_allclose(r.image_features[-1], nf.saddle().to_vector(), atol=1e-6)
    else:
        assert r.status == "converged"


def test_start_outside_domain_raises_with_the_constraint():
    c = ScenarioConfig(initial=PoseConfig(xyz=[0.0, 0.0, -3.0]))
    with pytest.raises(StartOutsideDomain, match=r"lam_min margin = -0.01\d* < 0"):
        simulate(c)
    # Behind the target, looking at it: the marked point faces away.
    c = ScenarioConfig(initial=PoseConfig(xyz=[0.0, 0.0, 0.5], rpy=[np.pi, 0, 0]))
    with pytest.raises(StartOutsideDomain, match="pose not visible"):
        simulate(c)


def test_scenario_yaml_round_trip_and_partial_files(tmp_path):
    c = _with_offset()
    path = tmp_path / "s.yaml"
    path.write_text(yaml_dump_typed(c))
    c2 = load_scenario(path)
    assert yaml_dump_typed(c2) == yaml_dump_typed(c)
    c3 = load_scenario(data="plant: kinematic\nduration: 7.5\n")
    assert c3.plant == Kinematic() and c3.duration == 7.5
    assert c3.goal == ScenarioConfig().goal
    with pytest.raises(ValueError, match="controller must be one of nf.*, got 'pid'"):
        load_scenario(data="controller: pid\n").validate()
    # The old meaning of `controller` (the plant) is refused with the new spelling.
    with pytest.raises(ValueError, match="controller 'kinematic' names a plant: write plant"):
        load_scenario(data="controller: kinematic\n").validate()
    with pytest.raises(ValueError, match="plant must be one of dynamic, kinematic, got 'x'"):
        load_scenario(data="plant: x\n").validate()
    # A partial pose is the whole pose: rpy left out is zero, not the default start's roll.
    c4 = load_scenario(
        data="initial: {xyz: [0.05, 0.0, -0.7]}\n"
        "carrier: !FreeRig {camera_offset: {rpy: [0, 0, 1]}}\n"
    )
    assert c4.initial.xyz == [0.05, 0.0, -0.7] and c4.initial.rpy == [0.0, 0.0, 0.0]
    assert ScenarioConfig().initial.rpy != [0.0, 0.0, 0.0]
    assert c4.carrier.camera_offset.xyz == [0.0, 0.0, 0.0]
    assert c4.carrier.camera_offset.rpy == [0, 0, 1]
    assert c4.goal == ScenarioConfig().goal  # a pose the file does not give keeps its default


# ------------------------------------------------------------- Monte-Carlo
@pytest.mark.parametrize(
    "controller",
    # The dynamic plant's case spawns a process pool (9 s): marked slow for make test's
    # budget, the kinematic one stays.
    [pytest.param(Dynamic(), marks=pytest.mark.slow), Kinematic()],
    ids=variant_name,
)
def test_monte_carlo_random_starts_converge_inside_domain(controller):
    """2000 seeded random starts in D through the batch engine (the Drake systems'
    kernels): all converge, none leaves D, the Lyapunov function never rises; and
    the first 10 through the Drake loop itself (processes) end the same way."""
    config = ScenarioConfig(plant=controller, duration=12.0)
    n = 2000
    starts = random_initial_poses(np.random.default_rng(2026), n, config, shrink=0.97)
    X_BC = np.stack([s.to_rigid_transform().GetAsMatrix4() for s in starts])
    batch = run_batch(config, X_BC)
    print(
        f"\n{variant_name(controller)}: {batch.counts()}; slowest {np.max(batch.t_converged):.2f} s"
    )
    assert batch.counts()["converged"] == n
    assert np.min(batch.min_margins) > 0
    assert np.all(batch.monotone)
    # The process pool on one plant; the other runs in this process (spawning costs more
    # than the runs under make test's parallel workers).
    processes = 2 if isinstance(controller, Dynamic) else 1
    drake = run_scenarios(scenarios_from_starts(config, starts[:10]), processes=processes)
    assert [r["status"] for r in drake] == list(batch.status[:10])
    assert all(r["lyapunov_monotone"] and not r["left_domain"] for r in drake)
    # The pose error at the end, both ways, is far inside the 1 mm / 1 mrad tolerance.
    assert max(r["final_position_error_m"] for r in drake) < 1e-4
    assert np.max(batch.final_position_error_m) < 1e-4


def test_drake_monte_carlo_simulation_runs():
    config = ScenarioConfig(plant=Kinematic(), duration=12.0)
    config.simulator.accuracy = 1e-5
    out = drake_monte_carlo(config, num_samples=3, seed=5)
    assert len(out) == 3
    assert all(o["position_error_m"] < 1e-3 and o["min_margin"] > 0 for o in out)
    assert all(o["output"] == o["position_error_m"] for o in out)


# ------------------------------------------------------- initial velocity
MOVING = [1.0, -0.8, 1.5, 0.4, -0.3, 0.5]  # (Omega, V) in C [rad/s, m/s]


def _camera_spatial_inertia(config: ScenarioConfig) -> np.ndarray:
    """M_C: the rig's spatial inertia about Co, expressed in C, (rotational, translational)
    order; from config.carrier alone (mass and principal inertia about the CoM), by Drake's
    parallel-axis shift, so 1/2 (Omega, V)^T M_C (Omega, V) is the kinetic energy."""
    X_RC = config.X_RC
    M_R = SpatialInertia.MakeFromCentralInertia(
        config.carrier.mass, np.zeros(3), RotationalInertia(*config.carrier.inertia_diagonal)
    )
    return M_R.Shift(X_RC.translation()).ReExpress(X_RC.rotation().inverse()).CopyToFullMatrix6()


def _expected_initial_energy(config: ScenarioConfig) -> float:
    """E0 = 1/2 nu^T M nu + k_p phi(y0), without the plant or the servo's kernels."""
    twist = np.asarray(config.initial_velocity)
    kinetic = 0.5 * twist @ _camera_spatial_inertia(config) @ twist
    nf = NavigationFunction(
        config.domain.to_domain(), config.goal_features(), config.navigation.to_gains()
    )
    phi0 = float(nf.value(config.initial_features()))
    return float(kinetic + config.control.potential_gain * phi0)


@pytest.mark.parametrize("offset", [False, True], ids=["camera-at-com", "camera-off-com"])
def test_initial_velocity_is_the_cameras_body_twist_in_drake(offset):
    """After make_simulator, Drake's own kinematics give the camera frame C the
    configured (Omega, V) = G^-1 Gdot, G = X_BC (Eqs. 16-17): by the rig's spatial
    velocity Jacobian at Co re-expressed in C, and by differencing G along qdot."""
    config = _with_offset() if offset else ScenarioConfig()
    config.initial_velocity = list(MOVING)
    loop = build_loop(config, log=False)
    diagram = loop.diagram
    simulator, _ = make_simulator(loop)
    plant = diagram.GetSubsystemByName("plant")
    ctx = plant.GetMyContextFromRoot(simulator.get_context())
    rig = plant.GetBodyByName(RIG_BODY_NAME)
    X_RC = config.X_RC
    X_WC = plant.EvalBodyPoseInWorld(ctx, rig) @ X_RC
    X_WC_expected = config.X_WB @ config.X_BC_initial
    np.testing.assert_allclose(X_WC.GetAsMatrix4(), X_WC_expected.GetAsMatrix4(), atol=1e-12)
    J = plant.CalcJacobianSpatialVelocity(
        ctx,
        JacobianWrtVariable.kV,
        rig.body_frame(),
        X_RC.translation(),
        plant.world_frame(),
        plant.world_frame(),
    )
    V_WC_W = J @ plant.GetVelocities(ctx)
    R_CW = X_WC.rotation().inverse().matrix()
    twist_drake = np.concatenate([R_CW @ V_WC_W[:3], R_CW @ V_WC_W[3:]])
    np.testing.assert_allclose(twist_drake, MOVING, rtol=0, atol=1e-12)

    # G^-1 Gdot by central differences of the poses at q -/+ h qdot.
    q = plant.GetPositions(ctx)
    qdot = plant.MapVelocityToQDot(ctx, plant.GetVelocities(ctx))
    h = 1e-6

    def G(sign: float) -> np.ndarray:
        c = plant.CreateDefaultContext()
        plant.SetPositions(c, q + sign * h * qdot)
        X_WC_t = plant.EvalBodyPoseInWorld(c, rig) @ X_RC
        return (config.X_WB.inverse() @ X_WC_t).GetAsMatrix4()

    body = np.linalg.inv(G(0.0)) @ (G(1.0) - G(-1.0)) / (2 * h)
    omega_hat = body[:3, :3]
    np.testing.assert_allclose(omega_hat, -omega_hat.T, atol=1e-8)
    twist_fd = [omega_hat[2, 1], omega_hat[0, 2], omega_hat[1, 0], *body[:3, 3]]
    np.testing.assert_allclose(twist_fd, MOVING, rtol=0, atol=1e-7)


def test_moving_start_below_the_energy_bound_converges_inside_domain():
    config = _with_offset()
    config.initial_velocity = list(MOVING)
    config.duration = 15.0
    expected = _expected_initial_energy(config)
    at_rest = config.control.potential_gain * float(
        NavigationFunction(
            config.domain.to_domain(), config.goal_features(), config.navigation.to_gains()
        ).value(config.initial_features())
    )
    assert expected - at_rest > 0.2  # the start really moves
    assert expected < config.control.potential_gain
    r = simulate(config)
    assert r.status == "converged", r.message
    assert np.all(r.margins >= 0) and np.all(r.visibility > 0) and np.all(r.phi < 1)
    assert r.lyapunov_monotone
    s = r.summary()
    assert s["initial_energy"] == pytest.approx(expected, rel=1e-9)
    assert s["energy_bound"] == config.control.potential_gain
    assert s["energy_guarantee"] is True
    assert "does not cover" not in r.message
    assert "the energy guarantee covers this start" in r.one_line()


def test_start_above_the_energy_bound_runs_and_says_the_guarantee_does_not_cover_it():
    config = ScenarioConfig(duration=5.0, initial_velocity=[0.0, 0.0, 0.0, 3.0, 0.0, 0.0])
    expected = _expected_initial_energy(config)
    assert expected > 1.5 * config.control.potential_gain
    r = simulate(config)
    assert r.sim_time_s > 0
    s = r.summary()
    assert s["initial_energy"] == pytest.approx(expected, rel=1e-9)
    assert s["energy_guarantee"] is False
    note = f"(E0 = {expected:.4g} >= k_p = 4: the energy guarantee does not cover this start)"
    assert r.message.endswith(note), r.message
    assert "the energy guarantee does not cover this start" in r.one_line()


def test_kinematic_loop_rejects_an_initial_velocity_and_has_no_energy_fields():
    c = ScenarioConfig(plant=Kinematic(), initial_velocity=[0.0, 0.0, 0.0, 0.1, 0.0, 0.0])
    with pytest.raises(ValueError, match="initial_velocity applies to the dynamic loop only"):
        c.validate()
    with pytest.raises(ValueError, match="initial_velocity applies to the dynamic loop only"):
        simulate(c)
    for bad in ([0.0] * 5, [0.0] * 5 + [float("nan")], ["a"] * 6):
        with pytest.raises(ValueError, match=r"initial_velocity must be 6 finite numbers.*got"):
            ScenarioConfig(initial_velocity=bad).validate()
    s = simulate(ScenarioConfig(plant=Kinematic(), duration=2.0)).summary()
    for key in ("initial_energy", "energy_bound", "energy_guarantee", "max_energy"):
        assert s[key] is None, key
    json.loads(json.dumps(s, allow_nan=False))
    c = load_scenario(data="initial_velocity: [0.1, 0, 0, 0, 0.2, 0]\n")
    assert c.initial_velocity == [0.1, 0.0, 0.0, 0.0, 0.2, 0.0]
    c.validate()


@dataclass
class ConstantRoll:
    """A user's law variant (not one of the package's): a constant roll rate [rad/s]."""

    rate: float = 0.5

    traits: ClassVar[LawTraits] = LawTraits(
        navigation=False, commands="twist", plans=False, batch_kernel=False
    )


def _constant_roll(builder, resolved):
    """ConstantRoll's system: (Omega, V) = (0, 0, rate, 0, 0, 0), so the truth is analytic."""
    from pydrake.systems.framework import LeafSystem

    twist = np.array([0, 0, resolved.law.rate, 0, 0, 0])

    class ConstantTwist(LeafSystem):
        def __init__(self):
            super().__init__()
            self.DeclareVectorInputPort("image_features", 13)
            self.DeclareVectorOutputPort(
                "camera_velocity", 6, lambda context, out: out.SetFromVector(twist)
            )

    return builder.AddSystem(ConstantTwist())


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_a_law_of_ones_own_is_a_variant_and_a_laws_entry(plant, monkeypatch):
    """A law registered as its variant (LAWS[ConstantRoll] = twist_law(...)) runs the
    kinematic body directly and the rig through VelocityTrackingForce: a roll rate w
    about the optical axis from the goal gives X_BC(t) = X_BC* RotZ(w t) (kinematic) or
    RotZ(w (t - tau (1 - e^{-t/tau}))), tau = I_z / B_z (dynamic, first-order lag from
    rest). Unregistered, the variant is refused in one line that names LAWS."""
    from pydrake.math import RotationMatrix

    from geovs_drake.loop.laws import LAWS, twist_law

    w = 0.5
    config = ScenarioConfig(plant=plant, controller=ConstantRoll(rate=w), duration=1.0)
    config.initial = PoseConfig(list(config.goal.xyz), list(config.goal.rpy))
    with pytest.raises(ValueError, match=r"controller ConstantRoll has no law: register LAWS"):
        simulate(config)
    monkeypatch.setitem(LAWS, ConstantRoll, twist_law(_constant_roll))
    result = simulate(config)
    assert result.status == "not_converged" and result.energy is None
    assert result.summary()["controller"] == "ConstantRoll"
    t = result.sim_time_s
    angle = w * t
    if isinstance(plant, Dynamic):
        tau = config.carrier.inertia_diagonal[2] / config.control.tracking_gains[2]
        angle = w * (t - tau * (1 - np.exp(-t / tau)))
    expected = config.X_BC_goal.rotation() @ RotationMatrix.MakeZRotation(angle)
    np.testing.assert_allclose(result.final_X_BC.rotation().matrix(), expected.matrix(), atol=1e-6)
    np.testing.assert_allclose(
        result.final_X_BC.translation(), config.X_BC_goal.translation(), atol=1e-9
    )


def test_a_baseline_runs_through_the_camera_model():
    """The laws that command a twist take y from the camera model too: PBVS through
    the pinhole sensor (30 Hz frames, fits of projected points) converges."""
    config = ScenarioConfig(controller=Pbvs(), sensor=Pinhole(), duration=10.0)
    result = simulate(config)
    assert result.status == "converged", result.message
    assert result.summary()["sensor"] == "pinhole"


def test_a_camera_runs_convergence_time_is_read_at_its_own_tolerance():
    """A pinhole run counts as converged within the camera's coarser tolerance
    (convergence_tolerance); its convergence time is the first logged time from which
    the pose error stays within that same tolerance, never NaN for a converged run."""
    config = ScenarioConfig(sensor=Pinhole(), duration=12.0)
    r = simulate(config)
    assert r.status == "converged", r.message
    tol_p, tol_r = convergence_tolerance(r.resolved)
    assert (tol_p, tol_r) > (1e-3, 1e-3)  # coarser than the exact sensor's
    errors = np.array([pose_error(RigidTransform(X), config.X_BC_goal) for X in r.X_BC])
    inside = (errors[:, 0] <= tol_p) & (errors[:, 1] <= tol_r)
    k = int(np.searchsorted(r.times, r.convergence_time))
    assert np.isfinite(r.convergence_time) and np.all(inside[k:]) and not inside[k - 1]
