"""A moving target behind an arm (issue 32): the arm stays in the world, the target is
drawn moving in its scene, and the loop reads the camera from the target's frame
(:class:`~geovs_drake.systems.TargetFrame`)."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from geovs_drake.geometry.target_motion import adjoint, se3_exp, se3_log
from geovs_drake.loop import build_loop
from geovs_drake.loop.arm import arm_model
from geovs_drake.loop.carriers import TARGET_BODY_NAME
from geovs_drake.scenario import Arm, Dynamic, Kinematic, ScenarioConfig, Twist
from geovs_drake.simulation import simulate
from geovs_drake.systems import ArmCamera
from geovs_drake.systems._arm_model import CAMERA_FRAME, arm_plant, camera_jacobian
from geovs_drake.systems.target_frame import TargetFrame
from geovs_drake.systems.target_motion import matrix_of_pose, pose_of_matrix

#: The issue's slow circle for the arms: radius v / omega = 0.2 m about the target's z.
SLOW_CIRCLE = [0.0, 0.0, 0.1, 0.02, 0.0, 0.0]


def _arm_config(model: str, plant, duration: float, feedforward: str = "estimated"):
    return ScenarioConfig(
        carrier=Arm(model=model),
        plant=plant,
        target_motion=Twist(twist=SLOW_CIRCLE, feedforward=feedforward),
        duration=duration,
    )


def _pose(rpy, p) -> RigidTransform:
    return RigidTransform(RollPitchYaw(rpy), p)


# --------------------------------------------------------------------- TargetFrame
def test_target_frame_is_the_relative_pose_and_its_twist_the_relative_twist():
    """body_pose is X_WB0 X_WB(t)^-1 X_WR; body_state's twist, with the true target twist
    believed, is the relative pose's own rate (central differences of X_BR(t))."""
    X_WB0 = _pose([0.1, -0.2, 0.3], [0.2, 0.1, 0.4])
    xi = np.array([0.1, -0.3, 0.2, 0.05, 0.02, -0.04])  # the target's body twist
    V_R = np.array([-0.2, 0.1, 0.3, 0.1, -0.05, 0.02])  # R's own body twist in the world
    X_WR0 = _pose([0.5, 0.2, -0.4], [0.6, -0.3, 0.9]).GetAsMatrix4()

    def X_WB(t):
        return X_WB0.GetAsMatrix4() @ se3_exp(t * xi)

    def X_WR(t):
        return X_WR0 @ se3_exp(t * V_R)

    system = TargetFrame(X_WB0=X_WB0)
    context = system.CreateDefaultContext()
    t, h = 0.7, 1e-5
    system.world_pose_input.FixValue(context, pose_of_matrix(X_WR(t)))
    R_WR = X_WR(t)[:3, :3]
    world_velocity = np.concatenate([R_WR @ V_R[:3], R_WR @ V_R[3:]])
    system.world_state_input.FixValue(
        context, np.concatenate([pose_of_matrix(X_WR(t)), world_velocity])
    )
    system.target_pose_input.FixValue(context, pose_of_matrix(X_WB(t)))
    system.twist_estimate_input.FixValue(context, xi)
    X_BR = np.linalg.inv(X_WB(t)) @ X_WR(t)
    X_WpR = matrix_of_pose(system.body_pose_output.Eval(context))
    np.testing.assert_allclose(X_WpR, X_WB0.GetAsMatrix4() @ X_BR, atol=1e-12)
    # The relative body twist from the geometry: log(X_BR(t)^-1 X_BR(t + h)) ... over 2h.
    X_BR_plus = np.linalg.inv(X_WB(t + h)) @ X_WR(t + h)
    X_BR_minus = np.linalg.inv(X_WB(t - h)) @ X_WR(t - h)
    V_rel = se3_log(np.linalg.inv(X_BR_minus) @ X_BR_plus) / (2 * h)
    state = system.body_state_output.Eval(context)
    R = X_WpR[:3, :3]
    np.testing.assert_allclose(R.T @ state[7:10], V_rel[:3], atol=1e-7)
    np.testing.assert_allclose(R.T @ state[10:13], V_rel[3:], atol=1e-7)
    # The feed-forward twist is the target's carried to R.
    np.testing.assert_allclose(
        system.feedforward_twist_output.Eval(context),
        adjoint(np.linalg.inv(X_BR)) @ xi,
        atol=1e-12,
    )


def test_the_arm_s_joint_damping_lets_the_feedforward_twist_pass():
    """With the feed-forward twist equal to the camera's own twist J_C v, the joint
    damping brakes nothing: the torque is the one of the arm at rest (the damped pseudo-
    inverse's mu^2 aside); unconnected, the damping acts on v."""
    model = arm_model(ScenarioConfig(carrier=Arm()))
    plant = arm_plant(model)
    damping = 2.0
    system = ArmCamera(model=model, joint_damping=np.full(plant.num_velocities(), damping))
    context = system.CreateDefaultContext()
    q = np.array([0.3, -1.2, 1.4, -1.6, -1.5, 0.4])
    v = np.array([0.1, -0.05, 0.08, 0.02, -0.1, 0.06])
    system.wrench_C_input.FixValue(context, np.zeros(6))
    system.arm_state_input.FixValue(context, np.concatenate([q, 0 * v]))
    at_rest = system.actuation_output.Eval(context).copy()
    system.arm_state_input.FixValue(context, np.concatenate([q, v]))
    braked = system.actuation_output.Eval(context).copy()
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    J_C = camera_jacobian(plant, plant_context, plant.GetFrameByName(CAMERA_FRAME))
    system.feedforward_twist_input.FixValue(context, J_C @ v)
    passed = system.actuation_output.Eval(context)
    np.testing.assert_allclose(passed, at_rest, atol=1e-4)
    assert np.max(np.abs(braked - at_rest)) > 0.1  # the damping did act without it


# --------------------------------------------------------------------- the scene
def test_the_rendered_scene_draws_the_target_at_its_moving_pose():
    """The arm's scene (the renderer's and Meshcat's) holds the target on its own body,
    posed at X_WB(t) as time goes, and the goal's ghost on it."""
    from geovs_drake.scenario import Rendered

    config = _arm_config("default", Kinematic(), 1.0)
    config.sensor = Rendered()
    loop = build_loop(config)
    diagram = loop.diagram
    context = diagram.CreateDefaultContext()
    scene_graph = loop.carrier.scene_graph
    motion = diagram.GetSubsystemByName("target_motion")
    inspector = scene_graph.model_inspector()
    sphere = next(
        g
        for g in inspector.GetAllGeometryIds()
        if inspector.GetName(g).endswith("target_sphere")
        and inspector.GetName(inspector.GetFrameId(g)).endswith(TARGET_BODY_NAME)
    )
    for t in (0.0, 2.5, 7.0):
        context.SetTime(t)
        query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
        X_WG = query.GetPoseInWorld(sphere).GetAsMatrix4()
        np.testing.assert_allclose(X_WG, motion.X_WB(t), atol=1e-9)
    assert np.linalg.norm(motion.X_WB(7.0)[:3, 3] - motion.X_WB(0.0)[:3, 3]) > 0.1


# --------------------------------------------------------------------- the loop
def test_the_ur5_tracks_the_slow_circle_and_its_log_is_the_relative_pose():
    """The issue's arm case, shortened: the kinematic UR5 with the estimated feed-forward
    stays in D and in its joint limits, closes on the moving goal, and the logged X_BC
    is X_WB(t)^-1 X_WC(q(t)) from the arm's own kinematics."""
    result = simulate(_arm_config("default", Kinematic(), 6.0))
    assert not result.left_domain and result.status in ("converged", "not_converged")
    errors = result.position_errors
    assert errors[-1] < 0.05 * errors[0], result.message
    model = arm_model(result.config)
    plant = arm_plant(model)
    plant_context = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)
    X_WB0 = result.config.X_WB.GetAsMatrix4()
    xi = np.asarray(SLOW_CIRCLE)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    nq = plant.num_positions()
    for k in range(0, len(result.times), 25):
        q = result.states[k, :nq]
        assert np.all((lower <= q) & (q <= upper))
        plant.SetPositions(plant_context, q)
        X_WC = camera.CalcPoseInWorld(plant_context).GetAsMatrix4()
        X_BC = np.linalg.inv(X_WB0 @ se3_exp(result.times[k] * xi)) @ X_WC
        np.testing.assert_allclose(result.X_BC[k], X_BC, atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=["kinematic", "dynamic"])
@pytest.mark.parametrize("model", ["default", "panda"])
def test_both_arms_track_the_slow_circle_for_20_s(model, plant):
    """The issue's must-show: 0,0,0.1,0.02,0,0 for 20 s with estimated feed-forward, in D
    and inside the joint limits (the monitor stops a run at either)."""
    result = simulate(_arm_config(model, plant, 20.0))
    assert result.status in ("converged", "not_converged"), result.message
    assert not result.left_domain
    # The kinematic arms follow to rounding; the dynamic ones within a millimetre
    # (their inertia along the circle is not fed forward: docs/moving-target.md).
    bound = 1e-6 if isinstance(plant, Kinematic) else 2e-3
    assert result.steady_tracking_error <= bound, result.message
