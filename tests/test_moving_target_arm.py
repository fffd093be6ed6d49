"""A moving target behind an arm (issue 32): the arm stays in the world, the target is
drawn moving in its scene, and the loop reads the camera from the target's frame
(:class:`~geovs_drake.systems.TargetFrame`)."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.tree import JacobianWrtVariable, MultibodyForces

from geovs_drake.geometry.target_motion import adjoint, se3_exp, se3_log
from geovs_drake.goal.arm import arm_model
from geovs_drake.loop import build_loop
from geovs_drake.loop.carriers import TARGET_BODY_NAME
from geovs_drake.scenario import Arm, Dynamic, Kinematic, ScenarioConfig, Twist
from geovs_drake.simulation import simulate
from geovs_drake.systems import ArmCamera
from geovs_drake.systems.arm_model import CAMERA_FRAME, arm_plant, camera_jacobian
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


def _arm_at(q, v, damping: float, V_ff=None):
    """The UR5's ArmCamera at (q, v), no wrench, the feed-forward twist V_ff (None: none);
    returns its joint torque (in the plant's velocity order) and the plant with a context."""
    model = arm_model(ScenarioConfig(carrier=Arm()))
    system = ArmCamera(model=model, joint_damping=np.full(len(v), damping))
    context = system.CreateDefaultContext()
    system.arm_state_input.FixValue(context, np.concatenate([q, v]))
    system.wrench_C_input.FixValue(context, np.zeros(6))
    if V_ff is not None:
        system.feedforward_twist_input.FixValue(context, V_ff)
    return system._B @ system.actuation_output.Eval(context)


#: A well-conditioned UR5 pose (J_C's singular values 2.0 down to 0.22) and a joint rate.
Q_ARM = np.array([0.3, -1.2, 1.4, -1.6, -1.5, 0.4])
V_ARM = np.array([0.05, -0.04, 0.06, 0.03, -0.05, 0.04])


def _camera_terms(q, v):
    """(plant, context, J_C, the body twist's rate at zero joint acceleration J_C' v) from
    Drake's bias acceleration, independently of ArmCamera's central difference."""
    plant = arm_plant(arm_model(ScenarioConfig(carrier=Arm())))
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    plant.SetVelocities(context, v)
    camera = plant.GetFrameByName(CAMERA_FRAME)
    J_C = camera_jacobian(plant, context, camera)
    bias = plant.CalcBiasSpatialAcceleration(
        context, JacobianWrtVariable.kV, camera, np.zeros(3), plant.world_frame(), camera
    )
    V = J_C @ v  # expressed in C: its rate as a body twist less omega x v
    Jdot_v = np.concatenate([bias.rotational(), bias.translational() - np.cross(V[:3], V[3:])])
    return plant, context, J_C, Jdot_v


def test_the_arm_s_feedforward_is_the_torque_of_the_motion_that_follows_the_target():
    """At a steady track (the camera's twist J_C v is the believed target's, V_ff), the
    feed-forward is Drake's inverse dynamics of that motion: the joint acceleration that
    keeps the camera's body twist constant (J_C a = -J_C' v, J_C' v from Drake's bias
    acceleration), M a + C(q, v) v, gravity compensated on top; the damped inverse's mu
    (0.01 against J_C's 0.22) leaves below 2 %."""
    plant, context, J_C, Jdot_v = _camera_terms(Q_ARM, V_ARM)
    a = np.linalg.solve(J_C, -Jdot_v)
    tau_motion = plant.CalcInverseDynamics(context, a, MultibodyForces(plant))
    expected = tau_motion - plant.CalcGravityGeneralizedForces(context)
    tau = _arm_at(Q_ARM, V_ARM, 0.0, J_C @ V_ARM)
    np.testing.assert_allclose(tau, expected, atol=0.02 * np.max(np.abs(tau_motion)))
    # Without the feed-forward, the arm's torque is gravity's compensation alone.
    gravity = -plant.CalcGravityGeneralizedForces(context)
    np.testing.assert_allclose(_arm_at(Q_ARM, V_ARM, 0.0), gravity, atol=1e-9)
    # A zero believed twist adds nothing at all.
    np.testing.assert_allclose(_arm_at(Q_ARM, V_ARM, 0.0, np.zeros(6)), gravity, atol=1e-12)


def test_the_arm_s_joint_damping_lets_the_feedforward_motion_pass():
    """The joint damping acts on v - v_ff: following the target (V_ff = J_C v), the
    damping's torque vanishes (to the damped inverse's mu), where without the
    feed-forward it brakes the motion."""
    _, _, J_C, _ = _camera_terms(Q_ARM, V_ARM)
    V_ff = J_C @ V_ARM
    damped, undamped = (_arm_at(Q_ARM, V_ARM, b, V_ff) for b in (2.0, 0.0))
    braking = 2.0 * np.abs(V_ARM).max()
    assert np.max(np.abs(damped - undamped)) < 0.02 * braking
    without = _arm_at(Q_ARM, V_ARM, 2.0) - _arm_at(Q_ARM, V_ARM, 0.0)
    np.testing.assert_allclose(without, -2.0 * V_ARM, atol=1e-12)


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
    # The kinematic arms follow to rounding; the dynamic ones (their feed-forward's
    # inverse damped near a singularity: docs/moving-target.md) within 0.2 mm.
    bound = 1e-6 if isinstance(plant, Kinematic) else 2e-4
    assert result.steady_tracking_error <= bound, result.message


def test_meshcat_draws_the_free_rig_and_its_moving_target_in_the_world():
    """The free rig runs in the target's frame, but Meshcat's scene is the world's: the
    target at X_WB(t) and the rig at its world pose, X_WB(t) X_WB(0)^-1 X_W'R (so the
    camera's relative pose is the loop's), on both plants."""
    from pydrake.geometry import Meshcat

    meshcat = Meshcat()
    for plant in (Dynamic(), Kinematic()):
        config = ScenarioConfig(plant=plant, target_motion=Twist(twist=SLOW_CIRCLE))
        loop = build_loop(config, meshcat=meshcat)
        diagram = loop.diagram
        context = diagram.CreateDefaultContext()
        loop.carrier.set_initial_state(context)
        scene_graph = diagram.GetSubsystemByName("world_scene_graph")
        inspector = scene_graph.model_inspector()
        frames = {  # the bodies' frames, by name
            inspector.GetName(inspector.GetFrameId(g)).split("::")[-1]: inspector.GetFrameId(g)
            for g in inspector.GetAllGeometryIds()
        }
        motion = diagram.GetSubsystemByName("target_motion")
        for t in (0.0, 5.0):
            context.SetTime(t)
            query = scene_graph.get_query_output_port().Eval(
                scene_graph.GetMyContextFromRoot(context)
            )
            X_WB = query.GetPoseInWorld(frames[TARGET_BODY_NAME]).GetAsMatrix4()
            np.testing.assert_allclose(X_WB, motion.X_WB(t), atol=1e-9)
            X_WR = query.GetPoseInWorld(frames["camera_rig"]).GetAsMatrix4()
            owner = loop.carrier.body_pose.get_system()
            X_WpR = matrix_of_pose(loop.carrier.body_pose.Eval(owner.GetMyContextFromRoot(context)))
            expected = motion.X_WB(t) @ config.X_WB.inverse().GetAsMatrix4() @ X_WpR
            np.testing.assert_allclose(X_WR, expected, atol=1e-9)
