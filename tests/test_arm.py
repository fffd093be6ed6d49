"""The camera on a robot arm: the shipped arm against the UR5's published kinematics,
IK against forward kinematics, the scene's reach, the energy along the dynamic arm's
loop, Drake's Linearize against the closed form through J_C, the kinematic arm, and
the command line's arm options.

Independent truths: the UR5's DH parameters (a closed-form forward kinematics written
here), Drake's own forward kinematics for IK, Drake's MultibodyPlant kinetic energy
1/2 v^T M(q) v for E, and Drake's ``Linearize`` for the closed form.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from geovs_drake.analysis.linear.arm_study import linearize_arm_at_goal
from geovs_drake.goal.arm import (
    Unreachable,
    _better_solution,
    arm_model,
    joint_limit_margins,
    smallest_singular_values,
    solve_joints,
)
from geovs_drake.loop import resolve
from geovs_drake.scenario import (
    Arm,
    Dynamic,
    Kinematic,
    Pinhole,
    PlantConfig,
    PoseConfig,
    ScenarioConfig,
    load_suite,
    variant_name,
)
from geovs_drake.simulation import simulate
from geovs_drake.systems.arm_model import CAMERA_FRAME, arm_plant, camera_jacobian

#: The UR5's published DH parameters [m, rad] (Universal Robots).
DH_A = (0.0, -0.425, -0.39225, 0.0, 0.0, 0.0)
DH_D = (0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823)
DH_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
SMALL_MOVE = PoseConfig(xyz=[0.05, -0.03, -0.55], rpy=[0.1, -0.05, 0.3])


def _dh_tool_position(q: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    for theta, a, d, alpha in zip(q, DH_A, DH_D, DH_ALPHA, strict=True):
        ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
        T = T @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0, sa, ca, d],
                [0, 0, 0, 1],
            ]
        )
    return T[:3, 3]


def _arm(plant: PlantConfig | None = None) -> ScenarioConfig:
    return ScenarioConfig(carrier=Arm(), plant=plant or Dynamic())


def test_the_shipped_arm_is_the_ur5_of_its_published_dh_parameters():
    """tool0's position for random joints equals the DH forward kinematics, up to the
    half-turn about z between the URDF's base_link and the DH base frame."""
    config = _arm()
    config.carrier.base_pose = PoseConfig()
    config.carrier.camera_offset = PoseConfig()
    plant = arm_plant(arm_model(config))
    context = plant.CreateDefaultContext()
    tool = plant.GetFrameByName("tool0")
    R_half = RotationMatrix.MakeZRotation(math.pi).matrix()
    rng = np.random.default_rng(1)
    for q in [np.zeros(6), *rng.uniform(-math.pi, math.pi, (20, 6))]:
        plant.SetPositions(context, q)
        p = tool.CalcPoseInWorld(context).translation()
        assert np.allclose(p, R_half @ _dh_tool_position(q), atol=1e-9), q
    masses = [
        plant.get_body(b).default_mass()
        for b in plant.GetBodyIndices(plant.GetModelInstanceByName("arm::ur5"))
    ]
    assert np.allclose(
        sorted(m for m in masses if m > 0), sorted([4.0, 3.7, 8.393, 2.275, 1.219, 1.219, 0.1879])
    )


def test_ik_reaches_the_pose_within_the_limits_and_the_scene_reaches_every_start():
    """Every start of the comparison suite, the default start, the goal and the small
    move: IK's joints put the camera there (Drake's FK, to 1e-9), inside the joint
    limits by more than 1 rad, away from singularities (sigma_min > 0.1)."""
    config = _arm()
    model = arm_model(config)
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)
    poses = [config.X_BC_goal, config.X_BC_initial, SMALL_MOVE.to_rigid_transform()]
    for s in load_suite().scenarios:
        rpy = [math.radians(v) for v in s.rpy_deg]
        poses.append(RigidTransform(RollPitchYaw(rpy), s.xyz))
    for X_BC in poses:
        X_WC = config.X_WB @ X_BC
        q = solve_joints(model, X_WC)
        plant.SetPositions(context, q)
        X = camera.CalcPoseInWorld(context)
        assert np.allclose(X.GetAsMatrix4(), X_WC.GetAsMatrix4(), atol=1e-9)
        assert np.min(joint_limit_margins(model, q)) > 1.0
        assert smallest_singular_values(model, q[None])[0] > 0.1


def test_ik_breaks_a_tie_by_the_solution_nearer_zero_whatever_the_order():
    """Two IK solutions 2 pi apart in a joint away from its limits have the same J_C and
    margin: their scores differ by rounding only (the UR5's goal, wrist 1 at -2.54 or
    +3.74 rad, swapped with the BLAS kernel). The pick must not follow rounding."""
    config = _arm()
    model = arm_model(config)
    q = solve_joints(model, config.X_WB @ config.X_BC_goal)
    shifted = q.copy()
    shifted[3] += 2 * math.pi
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)
    poses = []
    for joints in (q, shifted):
        plant.SetPositions(context, joints)
        poses.append(camera.CalcPoseInWorld(context).GetAsMatrix4())
    assert np.allclose(poses[0], poses[1], atol=1e-12)  # the same camera pose
    score = float(np.min(joint_limit_margins(model, q[None])))
    assert score == pytest.approx(float(np.min(joint_limit_margins(model, shifted[None]))))
    for eps in (-1e-15, 0.0, 1e-15):  # rounding's sign either way
        assert not _better_solution(shifted, score + eps, q, score)
        assert _better_solution(q, score + eps, shifted, score)
    # A real difference in score still wins, nearer zero or not.
    assert _better_solution(shifted, score + 1e-3, q, score)
    # And the goal's own joints are the branch nearer zero (|wrist 1| < pi).
    assert abs(q[3]) < math.pi


def test_a_pose_out_of_reach_names_the_closest_reach(run_cli):
    config = _arm()
    far = config.X_WB @ RigidTransform([0.0, 0.0, -3.0])  # 3 m out: beyond a 0.85-m arm
    with pytest.raises(Unreachable, match=r"closest reach found is [0-9.]+ m and"):
        solve_joints(arm_model(config), far)
    run = run_cli(
        "simulate", "--carrier", "arm", "--goal", "0,0,-0.5,0,0,0", "--initial-joints", "1,2"
    )
    assert run.code == 2 and run.err.count("\n") == 1
    assert "carrier.initial_joints must give the arm's 6 joints, got 2" in run.err


@pytest.mark.parametrize("start", ["default", "small_move"])
def test_the_dynamic_arm_converges_and_its_energy_never_rises(start):
    """E = 1/2 v^T M(q) v + k_p phi (Drake's kinetic energy of the arm, reflected rotor
    inertia included) never rises, from rest and from a random joint velocity with E0 <
    k_p; the run converges inside the joint limits."""
    config = _arm()
    if start == "small_move":
        config.initial = SMALL_MOVE
        config.carrier.initial_joint_velocity = [0.3, -0.2, 0.25, 0.4, -0.3, 0.5]
    result = simulate(config)
    assert result.status == "converged", result.message
    assert result.energy is not None and result.initial_energy < result.energy_bound
    assert result.lyapunov_monotone
    assert np.max(np.diff(result.energy)) <= result.lyapunov_tolerance
    assert result.energy[-1] < 1e-6 * result.energy[0]
    summary = result.summary()
    assert summary["min_joint_limit_margin"] > 0 and summary["lyapunov_monotone"] is True
    assert summary["min_jacobian_singular_value"] > 0


def test_linearize_of_the_arm_loop_at_the_goal_is_the_closed_form_through_J_C():
    lin = linearize_arm_at_goal(_arm())
    scale = np.max(np.abs(lin.A_closed))
    assert np.max(np.abs(lin.A_drake - lin.A_closed)) < 1e-8 * scale
    assert lin.max_real_part < 0 and lin.jacobian_singular_value > 0.1


def test_the_kinematic_arm_converges_from_the_small_move_and_reports_its_clipping():
    config = _arm(Kinematic())
    config.initial = SMALL_MOVE
    result = simulate(config)
    assert result.status == "converged", result.message
    summary = result.summary()
    assert 0 <= summary["joint_velocity_clipped"] < 1
    assert summary["min_joint_limit_margin"] > 0
    assert result.lyapunov_monotone  # phi, the kinematic loop's Lyapunov function


def test_a_joint_beyond_its_limit_stops_the_run_with_a_status():
    """Limits tightened around the start: the monitor stops the run and names the joint."""
    config = _arm(Kinematic())
    q0 = solve_joints(arm_model(config), config.X_WB @ config.X_BC_initial)
    config.carrier.initial_joints = q0.tolist()
    # A wrist limit 0.05 rad from the start, on the side the wrist turns (either side
    # is tried: the loop moves every joint).
    outcomes = []
    for joint in range(6):
        result = simulate(_with_limit(config, joint, q0))
        outcomes.append(result.status)
        if result.status == "joint_limit":
            assert "outside" in result.message and np.all(np.isfinite(result.X_BC))
            assert result.summary()["min_joint_limit_margin"] <= 0
            return
    pytest.fail(f"no joint reached a limit 0.05 rad away: {outcomes}")


def _with_limit(config: ScenarioConfig, joint: int, q0: np.ndarray) -> ScenarioConfig:
    """The config with a copy of the arm whose joint ``joint`` has limits q0 +- 0.05."""
    import copy
    import re
    import tempfile
    from pathlib import Path

    from geovs_drake.systems.arm_model import ARMS, DEFAULT_ARM

    text = Path(DEFAULT_ARM).read_text()
    names = re.findall(r'<joint name="(\w+)" type="revolute">', text)
    block = re.search(rf'<joint name="{names[joint]}".*?</joint>', text, re.S).group(0)
    lo, hi = q0[joint] - 0.05, q0[joint] + 0.05
    new = re.sub(r'lower="[^"]*" upper="[^"]*"', f'lower="{lo}" upper="{hi}"', block)
    path = Path(tempfile.mkdtemp()) / "arm.urdf"
    path.write_text(text.replace(block, new))
    c = copy.deepcopy(config)
    c.carrier.model = str(path)
    # A model file takes the frame, base and camera from the scenario: the shipped arm's.
    shipped = ARMS["default"]
    c.carrier.end_effector_frame = shipped.end_effector_frame
    c.carrier.base_pose = PoseConfig(
        xyz=list(shipped.base_xyz_rpy[:3]), rpy=list(shipped.base_xyz_rpy[3:])
    )
    c.carrier.camera_offset = PoseConfig(
        xyz=list(shipped.camera_xyz_rpy[:3]), rpy=list(shipped.camera_xyz_rpy[3:])
    )
    c.duration = 3.0
    return c


def test_cli_runs_the_arm_and_its_json_reports_the_arm(run_cli):
    run = run_cli(
        "simulate", "--carrier", "arm", "--plant", "kinematic", "--json", "--duration", "4",
        "--initial=0.05,-0.03,-0.55,0.1,-0.05,0.3",
    )  # fmt: skip
    summary = json.loads(run.out)
    assert summary["carrier"] == "arm"
    for key in ("min_joint_limit_margin", "min_jacobian_singular_value", "joint_velocity_clipped"):
        assert isinstance(summary[key], float), key


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--arm", "/no/such/arm.urdf"], "carrier.model /no/such/arm.urdf: no such file"),
        (["--arm", "my_arm.sdf"], "carrier.model my_arm.sdf: no such file"),
        (["--arm", "/"], "carrier.model /: is a folder, not a model file"),
        (["--arm", "ur10"], "carrier.model must be 'default', 'panda' or a model file's path"),
        (["--mount", "fixed"], "the carrier here is Arm, which carries the camera in its hand"),
        (["--initial-velocity", "0,0,0,0.1,0,0"], "give carrier.initial_joint_velocity instead"),
        (["--plant", "kinematic", "--initial-joint-velocity", "0,0,0,0,0,1"], "dynamic arm only"),
        (["--initial-joints", "1,x"], "expected numbers q1,q2,..."),
    ],
)
def test_cli_arm_bad_input_is_one_line_and_exit_2(argv, needle, run_cli):
    run = run_cli("simulate", "--carrier", "arm", *argv)
    assert run.code == 2, run.err
    assert run.err.count("\n") == 1 and needle in run.err, run.err
    assert "Traceback" not in run.err


def test_a_model_drake_cannot_load_or_without_the_frame_is_one_line(tmp_path, run_cli):
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='x'><link name='a'></robot>")
    run = run_cli("simulate", "--carrier", "arm", "--arm", str(broken))
    assert run.code == 2 and run.err.count("\n") == 1, run.err
    assert "carrier.end_effector_frame must name the frame the camera rides on" in run.err
    run = run_cli(
        "simulate", "--carrier", "arm", "--arm", str(broken),
        "--scenario-text", "{carrier: !Arm {end_effector_frame: a}}",
    )  # fmt: skip
    assert run.code == 2 and "Drake cannot load it" in run.err and run.err.count("\n") == 1
    text = "{carrier: !Arm {end_effector_frame: hand}}"
    run = run_cli("simulate", "--carrier", "arm", "--scenario-text", text)
    assert run.code == 2 and "'hand' is not a frame of" in run.err, run.err


def test_the_kinematic_arm_moves_the_camera_with_the_commanded_twist():
    """At a configuration off the singularities, the joint velocity it integrates moves
    the camera frame with the commanded body twist (Omega, V): central differences of
    Drake's forward kinematics along qdot, against nu (damped least squares: 1e-7)."""
    from geovs_drake.systems import KinematicArm

    config = _arm()
    model = arm_model(config)
    q0 = solve_joints(model, config.X_WB @ config.X_BC_goal)
    arm = KinematicArm(model=model, q0=q0)
    context = arm.CreateDefaultContext()
    nu = np.array([0.05, -0.02, 0.03, 0.01, 0.02, -0.015])
    arm.camera_velocity_input.FixValue(context, nu)
    qdot = arm.EvalTimeDerivatives(context).CopyToVector()
    assert arm.velocity_scale_output.Eval(context)[0] == 1.0  # far below the limits
    plant = arm_plant(model)
    pc = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)

    def X_WC(q):
        plant.SetPositions(pc, q)
        return camera.CalcPoseInWorld(pc)

    h = 1e-6
    X0, X1, X2 = X_WC(q0), X_WC(q0 - h * qdot), X_WC(q0 + h * qdot)
    # (Omega, V) = G^-1 Gdot: the rotation's and the origin's rates, expressed in C.
    R_dot = (X2.rotation().matrix() - X1.rotation().matrix()) / (2 * h)
    Omega_hat = X0.rotation().matrix().T @ R_dot
    Omega = np.array([Omega_hat[2, 1], Omega_hat[0, 2], Omega_hat[1, 0]])
    V = X0.rotation().matrix().T @ (X2.translation() - X1.translation()) / (2 * h)
    assert np.allclose(np.concatenate([Omega, V]), nu, atol=1e-7)


def test_the_arm_systems_kept_kinematics_follow_the_state():
    """The arm systems keep their last state's kinematics (one forward kinematics a state,
    shared by their ports): one context moved to another state and back, and a second
    context between, read their own state's camera pose (and, on the dynamic arm, its
    spatial velocity) as Drake's forward kinematics give it, and the kinematic arm's
    qdot is the one a fresh system gives."""
    from geovs_drake.systems import ArmCamera, KinematicArm

    model = arm_model(_arm())
    plant = arm_plant(model)
    pc = plant.CreateDefaultContext()
    camera, world = plant.GetFrameByName(CAMERA_FRAME), plant.world_frame()
    qa = np.array([0.3, -1.2, 1.4, -1.6, -1.5, 0.4])
    qb = qa + np.array([0.2, 0.1, -0.3, 0.25, 0.15, -0.2])
    v = np.array([0.05, -0.04, 0.06, 0.03, -0.05, 0.04])
    nu = np.array([0.05, -0.02, 0.03, 0.01, 0.02, -0.015])

    def truth(q):
        plant.SetPositionsAndVelocities(pc, np.concatenate([q, v]))
        X = camera.CalcPoseInWorld(pc)
        V = camera.CalcSpatialVelocity(pc, world, world)
        pose = np.concatenate([X.rotation().ToQuaternion().wxyz(), X.translation()])
        return pose, np.concatenate([pose, V.rotational(), V.translational()])

    def qdot_fresh(q):
        arm = KinematicArm(model=model, q0=q)
        context = arm.CreateDefaultContext()
        arm.camera_velocity_input.FixValue(context, nu)
        return arm.EvalTimeDerivatives(context).CopyToVector()

    kinematic, dynamic = KinematicArm(model=model, q0=qa), ArmCamera(model=model)
    contexts = [(kinematic.CreateDefaultContext(), dynamic.CreateDefaultContext()) for _ in "ab"]
    for k_context, d_context in contexts:
        kinematic.camera_velocity_input.FixValue(k_context, nu)
        dynamic.wrench_C_input.FixValue(d_context, np.zeros(6))
    for i, q in [(0, qa), (0, qb), (1, qa), (0, qa), (1, qb), (0, qb)]:
        k_context, d_context = contexts[i]
        kinematic.set_joints(k_context, q)
        dynamic.arm_state_input.FixValue(d_context, np.concatenate([q, v]))
        pose, state = truth(q)
        assert np.allclose(kinematic.camera_pose_output.Eval(k_context), pose, atol=1e-14)
        assert np.allclose(dynamic.camera_state_output.Eval(d_context), state, atol=1e-14)
        qdot = kinematic.EvalTimeDerivatives(k_context).CopyToVector()
        assert np.allclose(qdot, qdot_fresh(q), rtol=1e-12, atol=1e-15)


def test_the_singular_zone_s_damping_is_the_singularity_robust_inverse():
    """At a configuration near the wrist singularity (wrist 2 at 0.01 rad) qdot is
    J^T (J J^T + lambda^2 I)^-1 nu with lambda^2 = mu^2 + m^2 - sigma_min^2, written here
    with numpy's SVD; at the goal (sigma_min > m) lambda^2 = mu^2."""
    from geovs_drake.systems import KinematicArm

    config = _arm(Kinematic())
    model = arm_model(config)
    plant = arm_plant(model)
    pc = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)
    nu = np.array([0.05, -0.02, 0.03, 0.01, 0.02, -0.015])
    q_goal = solve_joints(model, config.X_WB @ config.X_BC_goal)
    near = q_goal.copy()
    near[4] = 0.01  # wrist 2 through 0: wrists 1 and 3 align
    m, mu = 0.05, 1e-4
    for q in (near, q_goal):
        arm = KinematicArm(model=model, q0=q, singularity_damping=m, null_space_gain=0.0)
        context = arm.CreateDefaultContext()
        arm.camera_velocity_input.FixValue(context, 1e-3 * nu)  # below the velocity limits
        qdot = arm.EvalTimeDerivatives(context).CopyToVector()
        plant.SetPositions(pc, q)
        J = camera_jacobian(plant, pc, camera)
        sigma = np.linalg.svd(J, compute_uv=False)[-1]
        lam2 = mu**2 + max(m**2 - sigma**2, 0.0)
        expected = J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(6), 1e-3 * nu)
        assert np.allclose(qdot, expected, rtol=1e-9, atol=1e-12)
        assert (sigma < m) == (q is near)


def test_the_kinematic_arms_compiled_shortcuts_agree_with_numpys_svd_and_max():
    """The kinematic arm skips the SVD where a Cholesky factor shows sigma_min(J_C) > m:
    never where numpy's SVD says sigma_min < m, on the UR5's J_C at wrist 2 from 1 rad
    down through the singularity and m on both sides of sigma_min; and its velocity
    ratio is numpy's max |qdot| / limit, NaN included."""
    from geovs_drake.systems.kinematic_arm import _clear_of_singular_zone, _largest_ratio

    model = arm_model(_arm(Kinematic()))
    plant = arm_plant(model)
    pc = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)
    q = solve_joints(model, _arm(Kinematic()).X_WB @ _arm(Kinematic()).X_BC_goal)
    skipped = 0
    for wrist in np.concatenate([np.geomspace(1.0, 1e-8, 40), [0.0, -1e-3]]):
        q[4] = wrist
        plant.SetPositions(pc, q)
        J = camera_jacobian(plant, pc, camera)
        sigma = np.linalg.svd(J, compute_uv=False)[-1]
        for m in sigma * np.array([0.5, 0.999, 1 - 1e-9, 1.0, 1 + 1e-9, 1.001, 2.0]):
            clear = _clear_of_singular_zone(J, m * m)
            assert not clear or sigma >= m, (wrist, sigma, m)
            skipped += clear
    assert skipped >= 40  # m well below a sigma_min not in rounding: skipped (not vacuous)
    rng = np.random.default_rng(7)
    for _ in range(20):
        v, b = rng.normal(size=6), rng.uniform(0.5, 3.0, 6)
        assert _largest_ratio(v, b) == np.max(np.abs(v) / b)
    v[2] = np.nan
    assert np.isnan(_largest_ratio(v, b))


def test_the_kinematic_arm_crosses_the_wrist_singularity_from_the_default_start():
    """From the default start the path passes sigma_min(J_C) < 0.01: with the singular
    zone damped (the default, m = 0.05) the arm converges; with the plain pseudo-inverse
    (m = 0) it spins its wrist over there and stops at wrist 3's limit."""
    damped = simulate(_arm(Kinematic()))
    assert damped.status == "converged", damped.message
    assert damped.summary()["min_jacobian_singular_value"] < 0.01
    assert damped.summary()["min_joint_limit_margin"] > 1.0
    plain = _arm(Kinematic())
    plain.carrier.singularity_damping = 0.0
    result = simulate(plain)
    assert result.status == "joint_limit" and "wrist_3_joint" in result.message


def test_the_arm_s_scene_fields_default_to_the_named_arm_s_and_a_file_s_pose_is_whole():
    """Unset, the frame, base and camera are the named arm's (ARMS); a file giving only
    the base's xyz gets rpy zero (not the UR5's -pi/2 yaw), and the named arm's camera."""
    from geovs_drake.scenario import load_scenario
    from geovs_drake.systems.arm_model import ARMS

    shipped = ARMS["default"]
    model = arm_model(_arm())
    assert model.end_effector_frame == shipped.end_effector_frame == "tool0"
    assert model.base_xyz_rpy == shipped.base_xyz_rpy
    assert model.camera_xyz_rpy == shipped.camera_xyz_rpy
    config = load_scenario(data="carrier: !Arm {base_pose: {xyz: [-0.8, 0.6, 1.0]}}")
    model = arm_model(config)
    assert model.base_xyz_rpy == (-0.8, 0.6, 1.0, 0.0, 0.0, 0.0)
    assert model.camera_xyz_rpy == shipped.camera_xyz_rpy
    with pytest.raises(ValueError, match=r"carrier.base_pose.xyz: expected a list of 3 numbers"):
        load_scenario(data="carrier: !Arm {base_pose: {xyz: [1, 2]}}")


def test_the_arm_enters_its_own_camera_s_view_and_the_rendered_camera_draws_it(run_cli):
    """From translation_and_roll the camera starts beside the arm's base, looking past
    it: the label image of the rendered camera shows the arm's links there (more than 5
    % of the frame), and none of them at the goal. The feature extractor took the arm's
    blob, cut by the image border, for the sphere, and the rendered loop stopped at t = 0;
    with the arm masked (SelfMask) it reads the sphere from the first frame on."""
    from geovs_drake.analysis.linear.arm_study import arm_pixels

    config = _arm()
    (start,) = [s for s in load_suite().scenarios if s.name == "translation_and_roll"]
    X_BC = RigidTransform(RollPitchYaw([math.radians(v) for v in start.rpy_deg]), start.xyz)
    model = arm_model(config)
    q = [solve_joints(model, config.X_WB @ X) for X in (X_BC, config.X_BC_goal)]
    pixels = arm_pixels(config, np.array(q))
    assert pixels[0] > 0.05 * 320 * 240 and pixels[1] == 0
    run = run_cli(
        "simulate", "--carrier", "arm", "--sensor", "rendered", "--camera-rate", "240",
        "--duration", "1", "--initial=0.25,-0.2,-1.3,0.0873,-0.0873,2.7925",
    )  # fmt: skip
    assert "cut by the image border" not in run.out and "at t = 0:" not in run.out, run.out


def test_a_model_file_s_package_uris_resolve_through_arm_packages(tmp_path, run_cli):
    """A URDF whose mesh is a package:// URI: without its folder the loop's plant (with a
    SceneGraph, which reads the mesh) fails in one line naming carrier.packages; with it
    the loop builds and draws the mesh; a folder that is not there is one line, exit 2."""
    from pydrake.geometry import Mesh

    from geovs_drake.loop import build_loop, resolve

    package = tmp_path / "my_arm_description"
    package.mkdir()
    (package / "tri.obj").write_text("v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n")
    inertial = (
        '<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" '
        'iyz="0" izz="0.01"/></inertial>'
    )
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(
        f"""<robot name="one_joint">
  <link name="base">{inertial}</link>
  <link name="tip">{inertial}<visual><geometry>
    <mesh filename="package://my_arm_description/tri.obj"/></geometry></visual></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="tip"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
  <transmission name="t"><type>transmission_interface/SimpleTransmission</type>
    <joint name="j"/><actuator name="m"/></transmission>
</robot>"""
    )
    config = _arm()
    config.carrier.model = str(urdf)
    config.carrier.end_effector_frame = "tip"
    config.carrier.initial_joints = [0.0]
    with pytest.raises(ValueError, match=r"unknown package 'my_arm_description' \(name its folder"):
        build_loop(resolve(config), log=False)
    config.carrier.packages = {"my_arm_description": str(package)}
    loop = build_loop(resolve(config), log=False)
    inspector = loop.carrier.scene_graph.model_inspector()
    shapes = [inspector.GetShape(g) for g in inspector.GetAllGeometryIds()]
    ours = [s for s in shapes if isinstance(s, Mesh) and str(s.source().path()).endswith("tri.obj")]
    assert len(ours) == 1 and loop.carrier.plant.num_actuators() == 1
    run = run_cli(
        "simulate", "--carrier", "arm", "--arm", str(urdf), "--scenario-text",
        "{carrier: !Arm {end_effector_frame: tip, "
        "packages: {my_arm_description: /no/such/folder}}}",
    )  # fmt: skip
    assert run.code == 2 and run.err.count("\n") == 1
    assert "carrier.packages.my_arm_description must be a folder, got '/no/such/folder'" in run.err


def _suite_start(name: str):
    return {s.name: s for s in load_suite(None).scenarios}[name].initial()


@pytest.mark.parametrize(
    "plant", [Dynamic(), pytest.param(Kinematic(), marks=pytest.mark.slow)], ids=variant_name
)
def test_roll_179_converges_on_the_ur5_inside_its_joint_limits(plant):
    """Issue 31: IK chose the start's 2 pi branch with no regard to the rotation to come,
    and from the suite's roll_179 the UR5's wrist 3 ran onto its limit (both plants)."""
    config = ScenarioConfig(carrier=Arm(), plant=plant, initial=_suite_start("roll_179"))
    config.duration = 20.0
    result = simulate(config)
    assert result.status == "converged", result.message
    assert result.summary()["min_joint_limit_margin"] > 0.5


def test_the_start_branch_keeps_the_pose_and_the_rotation_to_come_inside():
    """start_branch moves joints by whole turns only (forward kinematics: the same camera
    pose), stays inside the limits, and puts the estimated end inside too; at a half turn,
    whose way the start does not decide, it keeps IK's branch."""
    from geovs_drake.goal.arm import camera_jacobians, start_branch

    config = ScenarioConfig(carrier=Arm(), initial=_suite_start("roll_179"))
    model = arm_model(config)
    plant = arm_plant(model)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    X0, X1 = config.X_WB @ config.X_BC_initial, config.X_WB @ config.X_BC_goal
    found = solve_joints(model, X0)
    q = start_branch(model, found, X0, X1)
    turns = (q - found) / (2 * np.pi)
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-12)
    assert np.any(turns != 0)  # this start needed another branch
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    X = plant.GetFrameByName(CAMERA_FRAME).CalcPoseInWorld(context)
    np.testing.assert_allclose(X.GetAsMatrix4(), X0.GetAsMatrix4(), atol=1e-9)
    # The roll to come, 179 deg about the optical axis, carried to the joints: inside.
    error = X0.InvertAndCompose(X1)
    aa = error.rotation().ToAngleAxis()
    twist = np.concatenate([aa.axis() * aa.angle(), error.translation()])
    end = q + np.linalg.pinv(camera_jacobians(model, q[None])[0]) @ twist
    assert np.all(q >= lower) and np.all(q <= upper)
    assert np.all(end > lower + 0.5) and np.all(end < upper - 0.5), end
    # A half turn: IK's branch is kept.
    half = ScenarioConfig(carrier=Arm(), initial=_suite_start("roll_180"))
    H0 = half.X_WB @ half.X_BC_initial
    found = solve_joints(model, H0)
    np.testing.assert_array_equal(start_branch(model, found, H0, X1), found)


def test_the_arms_gain_scale_scales_a_cameras_damping_too():
    """Issue 31: resolve() scaled k_p and control.damping by the arm's gain_scale, but a
    loop with a camera damps with the camera's own B, which stayed unscaled: the UR5's
    30 Hz loop ran with ten times the stiffness and the free rig's damping, and left D."""
    config = ScenarioConfig(carrier=Arm(gain_scale=10.0), sensor=Pinhole())
    resolved = resolve(config)
    assert resolved.config.control.potential_gain == pytest.approx(10 * 4.0)
    assert list(resolved.damping) == pytest.approx([10 * v for v in Pinhole().damping])
    assert config.sensor.damping == Pinhole().damping  # the caller's config untouched


def test_the_ur5_converges_with_the_30_hz_pinhole_camera_from_the_small_move():
    config = ScenarioConfig(carrier=Arm(), sensor=Pinhole(), initial=_suite_start("small_move"))
    config.duration = 10.0
    result = simulate(config)
    assert result.status == "converged", result.message
    assert result.summary()["min_joint_limit_margin"] > 0


# 8 s: make test's budget; the rendered arm stays in it through its own view
# (test_the_arm_enters_its_own_camera_s_view_and_the_rendered_camera_draws_it) and the
# moving target's scene (tests/test_moving_target_arm.py).
@pytest.mark.slow
def test_the_ur5_converges_with_the_30_hz_rendered_camera_from_the_small_move():
    pytest.importorskip("cv2")
    from geovs_drake.scenario import Rendered

    config = ScenarioConfig(carrier=Arm(), sensor=Rendered(), initial=_suite_start("small_move"))
    config.duration = 6.0
    result = simulate(config)
    assert result.status == "converged", result.message
    assert result.summary()["min_joint_limit_margin"] > 0


def test_the_dynamic_arms_unset_integrator_is_rk5_the_kinematic_arms_rk3_a_given_one_kept():
    """The resolver fills an unset simulator.integration_scheme from the arm's traits: RK5
    on the dynamic plant, RK3 on the kinematic; a user's is kept; and the simulator runs
    the filled-in one (its steps and evaluations are those of the scheme given by name)."""
    from geovs_drake.loop.build import build_loop
    from geovs_drake.simulation.monitor import make_simulator

    def counts(plant: object, scheme: str | None) -> tuple[int, int]:
        config = ScenarioConfig(carrier=Arm(), plant=plant, duration=0.05)
        config.simulator.integration_scheme = scheme
        simulator = make_simulator(build_loop(config))[0]
        simulator.AdvanceTo(0.05)
        integrator = simulator.get_integrator()
        return integrator.get_num_steps_taken(), integrator.get_num_derivative_evaluations()

    for plant, scheme in ((Dynamic(), "runge_kutta5"), (Kinematic(), "runge_kutta3")):
        config = ScenarioConfig(carrier=Arm(), plant=plant)
        assert resolve(config).config.simulator.integration_scheme == scheme
        config.simulator.integration_scheme = "runge_kutta2"
        assert resolve(config).config.simulator.integration_scheme == "runge_kutta2"
    assert counts(Dynamic(), None) == counts(Dynamic(), "runge_kutta5")
    assert counts(Dynamic(), None) != counts(Dynamic(), "runge_kutta3")
