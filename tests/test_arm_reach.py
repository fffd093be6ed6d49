"""An arm's workspace against its goal (issue 42): where to stand its base
(:func:`~geovs_drake.goal.arm.place_base`, ``geovs-drake place-base``), whether it can
follow a moving target (:mod:`geovs_drake.goal.target_reach`), and the monitor's stop
where it pins on a joint limit.

Independent truths: Drake's InverseKinematics (:func:`solve_joints`, all its seeds) and
the forward kinematics of Drake's MultibodyPlant for the goal's reach, the target's
closed-form pose exp(t xi^) for its path, and the joints' limits for the pin.
"""

from __future__ import annotations

import importlib.metadata

import numpy as np
import pytest
from pydrake.math import RigidTransform

from geovs_drake.cli import main
from geovs_drake.geometry.target_motion import se3_exp
from geovs_drake.goal.arm import (
    Unreachable,
    arm_model,
    joint_limit_margins,
    place_base,
    smallest_singular_values,
    solve_joints,
)
from geovs_drake.goal.target_reach import target_reach
from geovs_drake.scenario import (
    Arm,
    Kinematic,
    PoseConfig,
    ScenarioConfig,
    Twist,
    load_scenario,
)
from geovs_drake.simulation import simulate
from geovs_drake.simulation.monitor import PIN_MARGIN_RAD
from geovs_drake.systems.arm_model import CAMERA_FRAME, arm_plant


#: The user's arm of the issue: a URDF whose base stands at the world's origin, from
#: where the goal camera pose (-0.5, 0, 1) looking along +x is out of reach.
def _user_arm() -> Arm:
    return Arm(model="tests/data/stiff_6r.urdf", end_effector_frame="tool0")


#: How far the goal may move along each world axis [m] and stay reachable from the
#: placed base: "well inside" the workspace.
WORKSPACE_MARGIN_M = 0.1


def _X_WC_goal(config: ScenarioConfig) -> RigidTransform:
    return config.X_WB @ config.X_BC_goal


def _check_well_inside(config: ScenarioConfig) -> None:
    """Drake's IK reaches the goal from the config's base, its joints far from limits and
    singularities, and reaches it moved WORKSPACE_MARGIN_M along each world axis."""
    model = arm_model(config)
    X_WC = _X_WC_goal(config)
    q = solve_joints(model, X_WC)
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    X = plant.GetFrameByName(CAMERA_FRAME).CalcPoseInWorld(context)
    assert np.allclose(X.GetAsMatrix4(), X_WC.GetAsMatrix4(), atol=1e-9)
    assert np.min(joint_limit_margins(model, q)) > 1.0
    assert smallest_singular_values(model, q[None])[0] > 0.1
    for axis in range(3):
        for sign in (-1.0, 1.0):
            shift = np.zeros(3)
            shift[axis] = sign * WORKSPACE_MARGIN_M
            solve_joints(model, RigidTransform(shift) @ X_WC)  # raises if out of reach


@pytest.mark.parametrize("arm", [Arm, _user_arm], ids=["ur5", "user_urdf"])
def test_the_placed_base_puts_the_goal_well_inside_the_arm_s_workspace(arm):
    config = ScenarioConfig(carrier=arm())
    placed = place_base(config)
    config.carrier.base_pose = PoseConfig(
        xyz=list(placed.xyz_rpy[:3]), rpy=list(placed.xyz_rpy[3:])
    )
    _check_well_inside(config)
    # Upright: the base's z is the world's, as the model's gravity expects.
    assert np.allclose(placed.X_W_base.rotation().matrix(), np.eye(3), atol=1e-12)


def test_place_base_prints_the_line_a_user_pastes(capsys):
    # The issue's user: the URDF at the origin does not reach the goal.
    with pytest.raises(Unreachable):
        solve_joints(arm_model(ScenarioConfig(carrier=_user_arm())), _X_WC_goal(ScenarioConfig()))
    arm = "model: tests/data/stiff_6r.urdf, end_effector_frame: tool0"
    assert main(["place-base", "--scenario-text", f"carrier: !Arm {{{arm}}}"]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert line.startswith("base_pose: {xyz: [")
    config = load_scenario(None, overrides=[("pasted", f"carrier: !Arm {{{arm}, {line}}}")])
    q = solve_joints(arm_model(config), _X_WC_goal(config))
    assert np.min(joint_limit_margins(arm_model(config), q)) > 1.0
    # Not an arm: one line, exit code 2.
    assert main(["place-base"]) == 2
    assert "places an arm's base: the carrier here is free" in capsys.readouterr().err


# ------------------------------------------------------------------ a moving target
def _running_target(twist, duration: float) -> ScenarioConfig:
    return ScenarioConfig(
        carrier=Arm(),
        plant=Kinematic(),
        target_motion=Twist(twist=twist, feedforward="known"),
        duration=duration,
    )


def test_the_reach_check_names_when_the_goal_leaves_the_arm_s_workspace():
    # The target runs away along the line of sight at 0.5 m/s: within 2 s the goal leaves
    # the UR5's reach. Drake's IK (all its seeds) reaches the goal's closed-form pose
    # before the time the check names and not after.
    twist = np.array([0, 0, 0, 0, 0, -0.5])
    config = _running_target(twist, 2.0)
    reach = target_reach(config)
    assert reach is not None and 0.25 < reach.time < 1.75
    model = arm_model(config)

    def goal(t: float) -> RigidTransform:
        X_WB = config.X_WB.GetAsMatrix4() @ se3_exp(t * twist)
        return RigidTransform(X_WB) @ config.X_BC_goal

    solve_joints(model, goal(reach.time - 0.25))
    with pytest.raises(Unreachable):
        solve_joints(model, goal(reach.time + 0.25))
    # The slow circle the arms track (docs/moving-target.md) stays inside.
    assert target_reach(_running_target([0, 0, 0.1, 0.02, 0, 0], 10.0)) is None


def test_simulate_warns_before_a_run_the_arm_cannot_follow():
    lines: list[str] = []
    simulate(_running_target([0, 0, 0, 0, 0, 0.5], 0.3), on_warning=lines.append)
    assert not any("reach" in line for line in lines)  # 0.3 s: still inside
    simulate(_running_target([0, 0, 0, 0, 0, 0.5], 1.0), on_warning=lines.append)
    (line,) = [line for line in lines if "out of the arm's reach" in line]
    assert "elbow_joint" in line and "of the 1 s run" in line


#: The issue's run (kinematic Panda, twist 0.05,0.05,0,0.02,-0.02 with the known
#: feed-forward) as its log had it at t = 20 s: the target's pose then, and the joints.
ISSUE_TWIST = [0.05, 0.05, 0.0, 0.02, -0.02, 0.0]
ISSUE_JOINTS_AT_20_S = [-1.3031, 0.5237, 1.1818, -0.3568, 0.3527, 0.11, -0.7974]


def test_a_run_that_pins_on_a_joint_limit_stops_with_joint_limit():
    try:
        importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip('the Panda needs example-robot-data: pip install "geovs-drake[panda]"')
    base = ScenarioConfig()
    X_WB = RigidTransform(base.X_WB.GetAsMatrix4() @ se3_exp(20.0 * np.array(ISSUE_TWIST)))
    config = ScenarioConfig(
        carrier=Arm(model="panda", initial_joints=ISSUE_JOINTS_AT_20_S),
        plant=Kinematic(),
        target=PoseConfig.from_rigid_transform(X_WB),
        target_motion=Twist(twist=ISSUE_TWIST, feedforward="known"),
        duration=0.6,
    )
    result = simulate(config)
    # Before: its wrist sat at its limit and the steps collapsed (25 us each) to the end.
    assert result.status == "joint_limit" and "pinned at panda_joint6" in result.message
    assert result.sim_time_s < config.duration
    assert result.arm.joint_limit_margin[-1] < PIN_MARGIN_RAD
