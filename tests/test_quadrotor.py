"""The quadrotor carrier (issue 43): Drake's own dynamics at hover, the rotor allocation
against Drake's Propeller and its inverse, the closed loop's Linearize at hover against
finite differences, a short run, and the bad inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    ExternallyAppliedSpatialForce,
    Propeller,
    PropellerInfo,
)
from pydrake.multibody.tree import RotationalInertia, SpatialInertia
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Linearize

from geovs_drake.geometry.camera import camera_map
from geovs_drake.loop import resolve
from geovs_drake.loop.assembly import assemble_loop
from geovs_drake.loop.carriers.quadrotor import rotor_layout
from geovs_drake.scenario import Dynamic, Kinematic, Pbvs, PoseConfig, Quadrotor, ScenarioConfig
from geovs_drake.scenario.carriers import GRAVITY
from geovs_drake.simulation import simulate
from geovs_drake.systems.attitude_cascade import allocate, mixer
from geovs_drake.systems.level_view import LevelView

#: A level start near the default one: its position, the heading 0.3 rad off the goal's
#: (the default start's 2 rad roll about the optical axis would tilt the body 115 deg).
LEVEL_START = PoseConfig(xyz=[0.12, -0.08, -0.8], rpy=[0.0, 0.3, 0.0])


def _config(**fields) -> ScenarioConfig:
    config = ScenarioConfig(carrier=Quadrotor(), plant=Dynamic(), **fields)
    config.initial = fields.get("initial", LEVEL_START)
    return config


def _propeller_rig(quad: Quadrotor):
    """A plant with the quadrotor's body and Drake's Propellers alone (no cascade)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    body = plant.AddRigidBody(
        "quad",
        SpatialInertia.MakeFromCentralInertia(
            quad.mass, np.zeros(3), RotationalInertia(*quad.inertia_diagonal)
        ),
    )
    plant.Finalize()
    positions, ratios = rotor_layout(quad)
    infos = [
        PropellerInfo(body.index(), RigidTransform(p), 1.0, k)
        for p, k in zip(positions, ratios, strict=True)
    ]
    propellers = builder.AddSystem(Propeller(infos))
    builder.Connect(propellers.get_output_port(), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_body_poses_output_port(), propellers.get_body_poses_input_port())
    builder.ExportInput(propellers.get_command_input_port(), "thrusts")
    return builder.Build(), plant, propellers, body


def test_hover_at_a_quarter_of_the_weight_per_rotor_is_drakes_equilibrium():
    quad = Quadrotor()
    diagram, plant, _, _ = _propeller_rig(quad)
    context = diagram.CreateDefaultContext()
    weight = quad.mass * -plant.gravity_field().gravity_vector()[2]
    diagram.get_input_port(0).FixValue(context, [weight / 4] * 4)
    xdot = diagram.EvalTimeDerivatives(context).CopyToVector()
    assert np.allclose(xdot, 0.0, atol=1e-12)  # no acceleration, no turn
    diagram.get_input_port(0).FixValue(context, [weight / 4 * 1.1] * 4)
    assert diagram.EvalTimeDerivatives(context).CopyToVector()[-1] > 0.5  # climbs
    # The closed loop at its goal asks exactly that of each rotor.
    loop = assemble_loop(resolve(_config(initial=ScenarioConfig().goal)), log=False)
    root = loop.diagram.CreateDefaultContext()
    loop.carrier.set_initial_state(root)
    cascade = loop.diagram.GetSubsystemByName("attitude_cascade")
    u = cascade.rotor_thrusts_output.Eval(cascade.GetMyContextFromRoot(root))
    assert np.allclose(u, weight / 4, rtol=1e-9)
    assert np.abs(loop.diagram.EvalTimeDerivatives(root).CopyToVector()).max() < 1e-9


def test_mixer_is_drakes_propeller_wrench_and_allocation_its_inverse():
    quad = Quadrotor()
    diagram, plant, propellers, body = _propeller_rig(quad)
    context = diagram.CreateDefaultContext()
    M = mixer(*rotor_layout(quad))
    rng = np.random.default_rng(43)
    for u in rng.uniform(0.0, quad.max_rotor_thrust, (3, 4)):
        diagram.get_input_port(0).FixValue(context, u)
        forces = propellers.get_spatial_forces_output_port().Eval(
            propellers.GetMyContextFromRoot(context)
        )
        total = sum(
            (f.F_Bq_W.get_coeffs() for f in forces if isinstance(f, ExternallyAppliedSpatialForce)),
            np.zeros(6),
        )
        # At the identity pose, W is the body frame; each force acts at its rotor (p_BoBq),
        # so the moment about the centre of mass adds r x f.
        moment = sum(np.cross(f.p_BoBq_B, f.F_Bq_W.translational()) for f in forces)
        wrench = [total[5], *(total[0:3] + moment)]
        assert np.allclose(M @ u, wrench, atol=1e-12)
    M_inv = np.linalg.inv(M)
    hover = quad.mass * GRAVITY
    inside = [hover, 0.05, -0.04, 0.01]
    u, saturated = allocate(inside, M_inv, quad.max_rotor_thrust)
    assert not saturated and np.allclose(M @ u, inside)
    # A yaw torque past what the rotors carry: the thrust and tilt torques are kept, the
    # yaw given up (first), and the rotors stay in [0, T_max].
    u, saturated = allocate([hover, 0.2, 0.0, 0.5], M_inv, quad.max_rotor_thrust)
    assert saturated and np.all((np.array(u) >= -1e-12) & (np.array(u) <= quad.max_rotor_thrust))
    w = M @ u
    assert np.allclose(w[0:3], [hover, 0.2, 0.0]) and 0 < w[3] < 0.5
    # A tilt torque past them too: the thrust kept, the tilt torque scaled, no yaw.
    u, saturated = allocate([hover, 2.0, 0.0, 0.1], M_inv, quad.max_rotor_thrust)
    w = M @ u
    assert saturated and np.isclose(w[0], hover) and 0 < w[1] < 2.0 and np.isclose(w[3], 0.0)


@pytest.mark.parametrize("mount", ["forward", "down"])
def test_level_view_is_the_exact_image_of_the_camera_on_the_level_body(mount):
    quad = Quadrotor(mount=mount)
    X_RC = quad.X_RC
    view = LevelView(X_RC=X_RC)
    context = view.CreateDefaultContext()
    # A tilted, turned body, the target in front of its camera, marked side towards it.
    X_WR = RigidTransform(RollPitchYaw(0.15, -0.1, 0.7), [0.3, -0.2, 1.1])
    X_WC = X_WR @ X_RC
    X_WB = X_WC @ RigidTransform(RollPitchYaw(0.1, -0.05, 0.3), [0.03, -0.02, 0.6])
    y = camera_map(X_WC.inverse() @ X_WB, 0.1)
    x = np.concatenate(
        [X_WR.rotation().ToQuaternion().wxyz(), X_WR.translation(), [0.1, -0.2, 0.3, 0.4, 0, -0.1]]
    )
    view.get_input_port(0).FixValue(context, _vector(y))
    view.get_input_port(1).FixValue(context, x)
    # The truth: the camera map of C', C turned so that its body would be level, heading
    # kept, at C's own origin.
    R_level = RotationMatrix.MakeZRotation(RollPitchYaw(X_WR.rotation()).yaw_angle())
    X_WCp = RigidTransform(R_level @ X_RC.rotation(), X_WC.translation())
    expected = camera_map(X_WCp.inverse() @ X_WB, 0.1)
    got = view.level_image_features_output.Eval(context)
    assert np.allclose(got, _vector(expected), atol=1e-12)
    state = view.level_body_state_output.Eval(context)
    X_WRp = RigidTransform(Quaternion(state[0:4]), state[4:7])
    assert np.allclose((X_WRp @ X_RC).GetAsMatrix4(), X_WCp.GetAsMatrix4(), atol=1e-12)
    # C's origin moves at v + w x R p_RC, and so does C' on the virtual body.
    v_C = x[10:13] + np.cross(x[7:10], X_WR.rotation() @ X_RC.translation())
    v_Cp = state[10:13] + np.cross(state[7:10], X_WRp.rotation() @ X_RC.translation())
    assert np.allclose(v_C, v_Cp, atol=1e-12)


def _vector(y) -> np.ndarray:
    """y as the ports carry it: q1, q2, q3, lambda, s."""
    return np.concatenate([y.Q[:, 0], y.Q[:, 1], y.Q[:, 2], [float(y.lam)], y.s])


#: A landing pad: the target on the ground, its z axis down, so that the goal (0.5 m
#: along it, looking along it) is a camera looking down from above.
PAD = PoseConfig(xyz=[0.0, 0.0, 0.0], rpy=[np.pi, 0.0, 0.0])


@pytest.mark.parametrize("heading", ["goal", "nf"])
@pytest.mark.parametrize("mount", ["forward", "down"])
def test_linearize_at_hover_is_stable_and_matches_finite_differences(mount, heading):
    config = _config(initial=ScenarioConfig().goal)
    config.carrier = Quadrotor(mount=mount, heading=heading)
    if mount == "down":
        config.target = PAD
    loop = assemble_loop(resolve(config), log=False)
    diagram = loop.diagram
    context = diagram.CreateDefaultContext()
    loop.carrier.set_initial_state(context)
    x0 = context.get_continuous_state_vector().CopyToVector()
    A = Linearize(diagram, context).A()
    assert A.shape == (13, 13)

    def f(x):
        context.SetContinuousState(x)
        return diagram.EvalTimeDerivatives(context).CopyToVector()

    h = 1e-6
    A_fd = np.column_stack([(f(x0 + h * e) - f(x0 - h * e)) / (2 * h) for e in np.eye(len(x0))])
    assert np.allclose(A, A_fd, atol=1e-4 * np.abs(A).max())
    eigenvalues = np.linalg.eigvals(A)
    # The quaternion's norm is a structural zero (a direction the plant's state has and
    # the pose has not); every other mode decays.
    near_zero = np.abs(eigenvalues) < 1e-6
    assert near_zero.sum() == 1
    # With heading nf the forward camera's slowest mode is the NF's heading, -0.73 1/s.
    assert np.max(eigenvalues[~near_zero].real) < (-1.0 if heading == "goal" else -0.5)


def test_a_short_run_from_the_default_start_closes_in_and_stays_in_d():
    # The default start's body tilt (115 deg) dropped: initial_attitude level.
    result = simulate(ScenarioConfig(carrier=Quadrotor(), plant=Dynamic(), duration=1.5))
    s = result.summary()
    assert not result.left_domain and s["min_fov_margin"] > 0
    errors = result.position_errors
    assert errors[-1] < 0.6 * errors[0]
    assert s["energy_guarantee"] is None and "cascade" in s["energy_guarantee_reason"]
    assert 0.0 <= s["rotor_saturation_fraction"] <= 1.0 and s["max_tilt_deg"] <= 10.5


@pytest.mark.slow
def test_the_level_start_converges_within_30_s_and_stays_in_d():
    result = simulate(_config(duration=30.0))
    assert result.converged and not result.left_domain
    assert result.convergence_time < 30.0


def test_the_nf_heading_keeps_the_target_in_view_where_the_goals_turn_loses_it():
    # Sweep start 108 (seed 0): level, 0.44 m off, the target's bearing 28.6 deg off the
    # goal's heading. Lee's loop turns the body to the goal's heading at once and the
    # target leaves the 35 deg field of view (t = 0.14 s); with heading nf the NF's
    # torque turns it with the barrier's, and the run stays in D (it converges at 8.3 s).
    start = PoseConfig(xyz=[0.208, 0.002, -0.382], rpy=[0.0, -0.53, 0.0])
    results = {}
    for heading in ("goal", "nf"):
        config = _config(initial=start, duration=0.5)
        config.carrier = Quadrotor(heading=heading)
        results[heading] = simulate(config)
    assert results["goal"].left_domain and results["goal"].times[-1] < 0.3
    assert results["goal"].summary()["min_fov_margin"] < 0
    assert not results["nf"].left_domain and results["nf"].times[-1] == pytest.approx(0.5)
    assert results["nf"].summary()["min_fov_margin"] > 0.05


def test_linearize_command_reads_stable_with_the_finite_difference_check(run_cli):
    code, out, err = run_cli("linearize", "--carrier", "quadrotor", "--json")
    assert code == 0, err
    result = json.loads(out)
    assert result["stable"] and result["max_real_part"] < -1.0
    assert result["finite_difference_relative_error"] < 1e-6
    assert result["continuum_modes"] and "quaternion" in result["continuum"]
    # A study that needs a model at the goal: one line, exit 2.
    code, out, err = run_cli("linearize", "--carrier", "quadrotor", "--latency", "1")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--latency" in err


BAD_INPUTS = {
    "kinematic": (["--plant", "kinematic"], ["dynamic plant only", "Kinematic"]),
    "negative-mass": (["--scenario-text", "carrier: !Quadrotor {mass: -1}"], ["carrier.mass"]),
    "negative-inertia": (
        ["--scenario-text", "carrier: !Quadrotor {inertia_diagonal: [0.0015, -1, 0.0035]}"],
        ["carrier.inertia_diagonal"],
    ),
    "thrust-zero": (
        ["--scenario-text", "carrier: !Quadrotor {max_rotor_thrust: 0}"],
        ["carrier.max_rotor_thrust", "> 0"],
    ),
    "cannot-hover": (
        ["--scenario-text", "carrier: !Quadrotor {max_rotor_thrust: 1.9}"],
        ["cannot hover", "7.6 N <= m g = 7.603 N"],
    ),
    "goal-tilted": (["--goal=0,0,-0.5,0.2,0,0"], ["tilted by 11.5 deg"]),
    "mount-blind": (
        ["--scenario-text", "carrier: !Quadrotor {mount: down}"],
        ["mount down does not see the target", "90.0 deg off the optical axis"],
    ),
    "turning-target": (
        ["--target-twist=0,0,0.2,0.05,0,0"],
        ["translating target only", "turns by up to 0.2 rad"],
    ),
    "start-tilted": (
        ["--scenario-text", "carrier: !Quadrotor {initial_attitude: given}"],
        ["start tilts the quadrotor by 115 deg, past 66.4 deg"],
    ),
    "anchor-behind-a-moving-target": (
        ["--controller", "hamel_mahony", "--target-twist=0,0,0,0.05,0,0"],
        ["drives a quadrotor's rotors behind a still target only", "Twist()"],
    ),
    "level-start-blind": (
        ["--initial=0,0.35,-0.45,0.6,0,0"],  # in D as given (34.4 deg of tilt), not level
        ["start outside D: fov margin", "initial_attitude level", "a tilt of 34.4 deg"],
    ),
    "initial-attitude": (
        ["--scenario-text", "carrier: !Quadrotor {initial_attitude: upright}"],
        ["carrier.initial_attitude must be one of level, given", "'upright'"],
    ),
    "heading": (
        ["--scenario-text", "carrier: !Quadrotor {heading: target}"],
        ["carrier.heading must be one of goal, nf", "'target'"],
    ),
}


@pytest.mark.parametrize("name", list(BAD_INPUTS))
def test_each_bad_input_gets_one_line_and_exit_2(name, run_cli):
    argv, needles = BAD_INPUTS[name]
    given = name == "start-tilted" or any(a.startswith("--initial") for a in argv)
    start = [] if given else ["--initial=0.12,-0.08,-0.8,0,0.3,0"]
    code, out, err = run_cli("simulate", "--carrier", "quadrotor", *start, *argv)
    lines = err.strip().splitlines()
    assert code == 2 and out == "" and len(lines) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


def test_an_unset_integrator_is_the_carriers_and_a_given_one_is_kept() -> None:
    # The resolver fills simulator.integration_scheme from the carrier's traits where the
    # scenario leaves it unset (RK5 on the quadrotor and on the dynamic free rig and arm
    # under the NF's law, RK3 elsewhere); a user's is kept, and
    # the simulator runs the filled-in one: its steps are those of RK5 given by name.
    from geovs_drake.loop.build import build_loop
    from geovs_drake.simulation.monitor import make_simulator

    def counts(scheme: str | None) -> tuple[int, int]:
        config = ScenarioConfig(carrier=Quadrotor())
        config.simulator.integration_scheme = scheme
        simulator = make_simulator(build_loop(config))[0]
        simulator.AdvanceTo(0.02)
        integrator = simulator.get_integrator()
        return integrator.get_num_steps_taken(), integrator.get_num_derivative_evaluations()

    assert ScenarioConfig().simulator.integration_scheme is None
    assert resolve(ScenarioConfig()).config.simulator.integration_scheme == "runge_kutta5"
    kinematic = resolve(ScenarioConfig(plant=Kinematic()))
    assert kinematic.config.simulator.integration_scheme == "runge_kutta3"
    # The dynamic scheme is the NF law's: another law on the same plant keeps RK3.
    pbvs = resolve(ScenarioConfig(controller=Pbvs()))
    assert pbvs.config.simulator.integration_scheme == "runge_kutta3"
    quad = resolve(ScenarioConfig(carrier=Quadrotor()))
    assert quad.config.simulator.integration_scheme == "runge_kutta5"
    given = ScenarioConfig(carrier=Quadrotor())
    given.simulator.integration_scheme = "runge_kutta3"
    assert resolve(given).config.simulator.integration_scheme == "runge_kutta3"
    assert counts(None) == counts("runge_kutta5") != counts("runge_kutta3")
