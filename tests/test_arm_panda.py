"""The 7-axis Franka Panda as the camera's carrier (``--arm panda``): its model made
ready for the continuous loop, its scene, both loops from the default start and the
small move, the damping of its self-motion, and Drake's Linearize at the goal.

Independent truths: the Panda's published modified-DH parameters (Franka's, a
forward kinematics written here) for the loaded chain, Drake's MultibodyPlant for
the actuators, the reflected inertias and the collision candidates, Drake's kinetic
energy for E, and Drake's ``Linearize`` for the closed form. The model comes from
``example-robot-data`` (the ``panda`` extra, which ``make test`` installs); without
it these tests are skipped with that reason.
"""

from __future__ import annotations

import copy
import importlib.metadata
import json
import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from geovs_drake.analysis.linear.arm_study import linearize_arm_at_goal
from geovs_drake.goal.arm import (
    arm_model,
    camera_jacobians,
    joint_limit_margins,
    smallest_singular_values,
    solve_joints,
)
from geovs_drake.scenario import (
    Arm,
    Dynamic,
    Kinematic,
    PlantConfig,
    PoseConfig,
    ScenarioConfig,
    load_suite,
    variant_name,
)
from geovs_drake.simulation import simulate
from geovs_drake.systems.arm_model import (
    PANDA_REFLECTED_INERTIA,
    ArmError,
    ArmModel,
    arm_plant,
)

try:
    importlib.metadata.distribution("example-robot-data")
except importlib.metadata.PackageNotFoundError:
    pytest.skip(
        'the Panda needs example-robot-data: pip install "geovs-drake[panda]" (make test '
        "installs it)",
        allow_module_level=True,
    )

SMALL_MOVE = PoseConfig(xyz=[0.05, -0.03, -0.55], rpy=[0.1, -0.05, 0.3])
#: Franka's modified (Craig) DH parameters of the Panda [m, rad], the flange 0.107 m on.
DH_A = (0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088)
DH_D = (0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0)
DH_ALPHA = (0.0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, math.pi / 2)
FLANGE_D = 0.107


def _panda(plant: PlantConfig | None = None) -> ScenarioConfig:
    return ScenarioConfig(carrier=Arm(model="panda"), plant=plant or Dynamic())


def _flange(q: np.ndarray) -> np.ndarray:
    """The flange's pose (4 x 4) in the base by Franka's modified DH parameters."""
    T = np.eye(4)
    for theta, a, d, alpha in zip(q, DH_A, DH_D, DH_ALPHA, strict=True):
        ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
        T = T @ np.array(
            [[ct, -st, 0, a], [st * ca, ct * ca, -sa, -d * sa], [st * sa, ct * sa, ca, d * ca],
             [0, 0, 0, 1]]
        )  # fmt: skip
    return T @ np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, FLANGE_D], [0, 0, 0, 1]])


def test_the_panda_is_made_ready_for_the_continuous_loop():
    """Its chain is Franka's DH (link8, random joints, to 1e-9); the fingers are welded
    (7 joints, no prismatic one); each joint has an actuator with the file's effort
    limit and Franka's reflected inertia; the loop's SceneGraph has collision geometry
    (the Panda's spheres) but no pair it would test: the loop models no contact."""
    config = _panda()
    config.carrier.base_pose = PoseConfig()
    model = arm_model(config)
    plant = arm_plant(model)
    assert plant.num_positions() == 7 and plant.time_step() == 0
    context = plant.CreateDefaultContext()
    link8 = plant.GetFrameByName("panda_link8")
    rng = np.random.default_rng(2)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    for q in rng.uniform(lower, upper, (20, 7)):
        plant.SetPositions(context, q)
        X = link8.CalcPoseInWorld(context).GetAsMatrix4()
        assert np.allclose(X, _flange(q), atol=1e-9), q
    actuators = [plant.get_joint_actuator(i) for i in plant.GetJointActuatorIndices()]
    assert [a.effort_limit() for a in actuators] == [87.0] * 4 + [12.0] * 3
    assert np.allclose([a.default_reflected_inertia() for a in actuators], PANDA_REFLECTED_INERTIA)

    from geovs_drake.loop import build_loop, resolve

    loop = build_loop(resolve(_panda()), log=False)
    inspector = loop.carrier.scene_graph.model_inspector()
    assert inspector.num_geometries() > 20  # the Panda's collision spheres are there
    assert inspector.GetCollisionCandidates() == set()


def test_a_joint_the_model_lacks_is_one_line():
    good = arm_model(_panda())
    bad = ArmModel(
        good.path, good.end_effector_frame, good.base_xyz_rpy, good.camera_xyz_rpy,
        welded_joints=("no_such_joint",), packages=good.packages,
    )  # fmt: skip
    with pytest.raises(ArmError, match="it has no joint 'no_such_joint'"):
        arm_plant(bad)


def test_the_panda_scene_reaches_every_start_with_margins():
    """The goal, the default start, the small move and every start of the comparison
    suite: IK within the limits, every joint more than 0.5 rad from its limits, away
    from singularities (sigma_min(J_C) > 0.05)."""
    config = _panda()
    model = arm_model(config)
    poses = [config.X_BC_goal, config.X_BC_initial, SMALL_MOVE.to_rigid_transform()]
    for s in load_suite().scenarios:
        poses.append(RigidTransform(RollPitchYaw([math.radians(v) for v in s.rpy_deg]), s.xyz))
    for X_BC in poses:
        q = solve_joints(model, config.X_WB @ X_BC)
        assert np.min(joint_limit_margins(model, q)) > 0.5
        assert smallest_singular_values(model, q[None])[0] > 0.05


@pytest.mark.parametrize("plant", [Dynamic(), Kinematic()], ids=variant_name)
@pytest.mark.parametrize("start", ["default", "small_move"])
def test_the_panda_converges(plant, start):
    config = _panda(plant)
    if start == "small_move":
        config.initial = SMALL_MOVE
    result = simulate(config)
    assert result.status == "converged", result.message
    summary = result.summary()
    assert summary["min_joint_limit_margin"] > 0 and summary["min_jacobian_singular_value"] > 0
    if config.dynamic:
        assert summary["lyapunov_monotone"] is True
        assert np.max(np.diff(result.energy)) <= result.lyapunov_tolerance
        # The self-motion settled too: the joints, not only the camera, are at rest.
        assert summary["final_self_motion_speed"] < 1e-3
    else:
        assert 0 <= summary["joint_velocity_clipped"] < 1
        assert "final_self_motion_speed" not in summary


def _self_motion_run(null_space_damping: float):
    """The Panda at rest at the goal's pose, its joints moving at 0.5 rad/s along J_C's
    null space (the camera still), no joint damping: only the null-space term can
    take the self-motion's energy."""
    config = _panda()
    config.duration = 5.0
    model = arm_model(config)
    q = solve_joints(model, config.X_WB @ config.X_BC_goal)
    (J,) = camera_jacobians(model, q)
    n = np.linalg.svd(J)[2][-1]  # J n = 0
    n *= np.sign(n[np.argmax(np.abs(n))])  # SVD's sign is rounding's: fix it, largest entry > 0
    assert np.max(np.abs(J @ n)) < 1e-12
    config.initial = copy.deepcopy(config.goal)
    config.carrier.initial_joints = q.tolist()
    config.carrier.initial_joint_velocity = (0.5 * n).tolist()
    config.carrier.joint_damping = 0.0
    config.carrier.null_space_damping = null_space_damping
    return simulate(config)


def test_the_null_space_damping_settles_the_self_motion():
    """With d = 2 the self-motion's energy falls below 1e-4 of its start and the joints
    stop (less than 1e-3 rad in the last second); without it (d = 0) it keeps most of
    its energy and the joints keep turning: the term, not the camera's damping, settles
    a redundant arm."""
    damped, free = _self_motion_run(2.0), _self_motion_run(0.0)
    last_second = damped.times >= damped.times[-1] - 1.0
    q = damped.arm.joint_positions
    assert damped.status == "converged" and damped.lyapunov_monotone
    assert damped.energy[-1] < 1e-4 * damped.energy[0]
    assert np.max(np.abs(q[last_second] - q[-1])) < 1e-3
    assert damped.arm.self_motion_speed[0] == pytest.approx(0.5, rel=1e-3)
    assert damped.arm.self_motion_speed[-1] < 1e-3
    q = free.arm.joint_positions
    assert free.energy[-1] > 0.5 * free.energy[0]
    assert np.max(np.abs(q[last_second] - q[-1])) > 0.1


def test_linearize_of_the_panda_loop_is_the_closed_form_with_one_neutral_mode():
    """Drake's A against the closed form through J_C, the null-space damping included,
    to 1e-8; one eigenvalue is 0 (moving along the self-motion costs no potential: the
    goal is a curve of joint configurations, not a point), every other is stable."""
    lin = linearize_arm_at_goal(_panda())
    scale = np.max(np.abs(lin.A_closed))
    assert np.max(np.abs(lin.A_drake - lin.A_closed)) < 1e-8 * scale
    eigenvalues = lin.eigenvalues
    neutral = np.abs(eigenvalues) < 1e-8 * scale
    assert np.count_nonzero(neutral) == 1
    assert np.max(eigenvalues[~neutral].real) < 0


def test_cli_runs_the_panda_and_names_a_missing_extra(run_cli, monkeypatch):
    run = run_cli(
        "simulate", "--carrier", "arm", "--arm", "panda", "--json",
        "--initial=0.05,-0.03,-0.55,0.1,-0.05,0.3",
    )  # fmt: skip
    assert run.code == 0, run.err
    summary = json.loads(run.out)
    assert summary["status"] == "converged"
    assert isinstance(summary["final_self_motion_speed"], float)

    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "distribution", missing)
    run = run_cli("simulate", "--carrier", "arm", "--arm", "panda")
    assert run.code == 2 and run.err.count("\n") == 1, run.err
    assert 'needs example-robot-data: pip install "geovs-drake[panda]"' in run.err
