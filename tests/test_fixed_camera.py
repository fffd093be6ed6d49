"""The fixed camera (eye-to-hand): Eq. (16)'s G = H^-1 against Drake's own frame tools."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import Meshcat, Role
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    JacobianWrtVariable,
    RotationalInertia,
    SpatialInertia,
)

from geovs_drake.geometry.rigid import camera_body_velocity
from geovs_drake.loop import build_loop
from geovs_drake.loop.carriers import TARGET_BODY_NAME
from geovs_drake.loop.state import fixed_camera_pose, initial_rig_state
from geovs_drake.scenario import (
    FixedCamera,
    FreeRig,
    Kinematic,
    Nf,
    PathFollowing,
    Pinhole,
    PoseConfig,
    Rendered,
    ScenarioConfig,
)
from geovs_drake.simulation import simulate
from geovs_drake.systems import FixedCameraKinematicMount, FixedCameraMount

X_WC = RigidTransform(RollPitchYaw(0.3, -0.2, 1.1), [0.4, -0.3, 1.2])


def _plant_with_fixed_camera(X_WC: RigidTransform = X_WC):
    """A free target B and a frame C fixed in the world at X_WC: the truth."""
    plant = MultibodyPlant(0.0)
    body = plant.AddRigidBody(
        "target",
        SpatialInertia.MakeFromCentralInertia(1.0, np.zeros(3), RotationalInertia(1, 1, 1)),
    )
    frame_C = plant.AddFrame(FixedOffsetFrame("C", plant.world_frame(), X_WC))
    plant.Finalize()
    return plant, body.body_frame(), frame_C


def _random_state(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return np.concatenate([q / np.linalg.norm(q), rng.normal(size=3), rng.normal(size=6)])


def test_mount_relative_state_and_reaction_wrench_against_drake():
    """camera_state is (X_BC, V_BC in B) from Drake's frames; the reaction wrench is
    J^T (-F_C) for Drake's Jacobian of the point of B at Co (expressed in C), and it
    delivers the power F_C . (Omega, V) with (Omega, V) = V_BC expressed in C."""
    plant, frame_B, frame_C = _plant_with_fixed_camera()
    ctx = plant.CreateDefaultContext()
    mount = FixedCameraMount(X_WC=X_WC)
    mctx = mount.CreateDefaultContext()
    rng = np.random.default_rng(0)
    for _ in range(10):
        x = _random_state(rng)
        plant.SetPositionsAndVelocities(ctx, x)
        mount.target_state_input.FixValue(mctx, x)
        F_C = rng.normal(size=6)
        mount.wrench_C_input.FixValue(mctx, F_C)
        state = mount.camera_state_output.Eval(mctx)
        X_BC = plant.CalcRelativeTransform(ctx, frame_B, frame_C)
        R = X_BC.rotation().matrix()
        q = Quaternion(state[0:4] / np.linalg.norm(state[0:4]))
        np.testing.assert_allclose(q.rotation(), R, atol=1e-12)
        np.testing.assert_allclose(state[4:7], X_BC.translation(), atol=1e-12)
        V_BC_B = frame_C.CalcSpatialVelocity(ctx, frame_B, frame_B)
        np.testing.assert_allclose(state[7:10], V_BC_B.rotational(), atol=1e-12)
        np.testing.assert_allclose(state[10:13], V_BC_B.translational(), atol=1e-12)
        # (Omega, V) as the eye-in-hand systems form it from this state = Drake's V_BC_C.
        R_BC = tuple(R.ravel())
        twist = camera_body_velocity(R_BC, R_BC, tuple(state[7:10]), tuple(state[10:13]), (0,) * 3)
        V_BC_C = frame_C.CalcSpatialVelocity(ctx, frame_B, frame_C).get_coeffs()
        np.testing.assert_allclose(twist, V_BC_C, atol=1e-12)
        tau = mount.generalized_force_output.Eval(mctx)
        p_BCo = X_BC.translation()
        J = plant.CalcJacobianSpatialVelocity(
            ctx, JacobianWrtVariable.kV, frame_B, p_BCo, plant.world_frame(), frame_C
        )
        np.testing.assert_allclose(tau, J.T @ (-F_C), atol=1e-12)
        assert tau @ x[7:13] == pytest.approx(F_C @ V_BC_C, abs=1e-12)
    # AutoDiffXd conversion gives the same numbers.
    mount_ad = mount.ToAutoDiffXd()
    actx = mount_ad.CreateDefaultContext()
    mount_ad.target_state_input.FixValue(actx, x.astype(object) * AutoDiffXd(1))
    mount_ad.wrench_C_input.FixValue(actx, F_C.astype(object) * AutoDiffXd(1))
    out = [v.value() for v in mount_ad.generalized_force_output.Eval(actx)]
    np.testing.assert_allclose(out, tau, atol=1e-14)


def test_kinematic_mount_commands_the_target_twist_that_gives_the_camera_its_twist():
    """The target moving with the body twist the mount puts out gives the camera exactly
    the commanded (Omega, V) relative to it (Drake's V_BC expressed in C)."""
    plant, frame_B, frame_C = _plant_with_fixed_camera()
    ctx = plant.CreateDefaultContext()
    mount = FixedCameraKinematicMount(X_WC=X_WC)
    mctx = mount.CreateDefaultContext()
    rng = np.random.default_rng(1)
    for _ in range(10):
        x = _random_state(rng)[0:7]
        twist = rng.normal(size=6)
        mount.target_pose_input.FixValue(mctx, x)
        mount.camera_velocity_input.FixValue(mctx, twist)
        nu_B = mount.target_velocity_output.Eval(mctx)
        plant.SetPositions(ctx, x)
        R_WB = plant.CalcRelativeTransform(ctx, plant.world_frame(), frame_B).rotation()
        plant.SetVelocities(ctx, np.concatenate([R_WB @ nu_B[0:3], R_WB @ nu_B[3:6]]))
        V_BC_C = frame_C.CalcSpatialVelocity(ctx, frame_B, frame_C).get_coeffs()
        np.testing.assert_allclose(V_BC_C, twist, atol=1e-12)
        X_BC = plant.CalcRelativeTransform(ctx, frame_B, frame_C)
        pose = mount.camera_pose_output.Eval(mctx)
        np.testing.assert_allclose(pose[4:7], X_BC.translation(), atol=1e-12)


def test_initial_target_state_gives_the_camera_the_configured_relative_twist():
    config = ScenarioConfig(
        carrier=FixedCamera(), initial_velocity=[0.1, -0.2, 0.05, 0.03, 0.02, -0.04]
    )
    plant, frame_B, frame_C = _plant_with_fixed_camera(fixed_camera_pose(config))
    ctx = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(ctx, initial_rig_state(config))
    np.testing.assert_allclose(
        plant.CalcRelativeTransform(ctx, frame_B, frame_C).GetAsMatrix4(),
        config.X_BC_initial.GetAsMatrix4(),
        atol=1e-12,
    )
    V_BC_C = frame_C.CalcSpatialVelocity(ctx, frame_B, frame_C).get_coeffs()
    np.testing.assert_allclose(V_BC_C, config.initial_velocity, atol=1e-12)


@pytest.mark.parametrize(
    "controller,accuracy", [(Nf(), 1e-13), (PathFollowing(duration=3.0), 1e-14)]
)
def test_kinematic_fixed_camera_sees_the_eye_in_hand_image_trajectory(controller, accuracy):
    """Eq. (16): for the same initial relative pose the fixed camera's image y(t) is the
    eye-in-hand camera's, to 1e-9 (runge_kutta5 at a tight accuracy: the two loops
    integrate different states, the camera's pose and the target's, so they agree
    to the integrator's error)."""
    images = {}
    for mount, carrier in (("hand", FreeRig()), ("fixed", FixedCamera())):
        config = ScenarioConfig(plant=Kinematic(), controller=controller, carrier=carrier)
        config.duration = 4.0
        config.simulator.integration_scheme = "runge_kutta5"
        config.simulator.accuracy = accuracy
        result = simulate(config)
        assert result.status in ("converged", "not_converged"), result.message
        images[mount] = result.image_features
    assert images["hand"].shape == images["fixed"].shape
    assert np.max(np.abs(images["hand"][-1] - images["hand"][0])) > 0.1  # it moved
    np.testing.assert_allclose(images["fixed"], images["hand"], rtol=0, atol=1e-9)


def test_dynamic_fixed_camera_converges_with_decreasing_energy():
    """The default scenario, the target sphere driven (rig's mass model): converges,
    E = 1/2 nu^T M nu + k_p phi never rises, the target moves and the camera does not."""
    config = ScenarioConfig(carrier=FixedCamera(), duration=15.0)
    result = simulate(config)
    assert result.status == "converged", result.message
    assert result.lyapunov_monotone and result.energy_guarantee
    assert np.all(result.margins >= 0)
    assert result.energy[0] == pytest.approx(config.control.potential_gain * result.phi[0])
    # The target ends where it stands in the eye-in-hand scene, the camera where it was.
    X_WB_final = fixed_camera_pose(config) @ result.final_X_BC.inverse()
    np.testing.assert_allclose(X_WB_final.translation(), config.X_WB.translation(), atol=2e-3)


def test_fixed_camera_scene_has_a_still_camera_and_a_moving_sphere():
    """In SceneGraph the camera's geometry hangs on the world frame and the sphere's on
    the free target body; simulate draws it in Meshcat."""
    config = ScenarioConfig(carrier=FixedCamera(), duration=0.5)
    meshcat = Meshcat()
    diagram = build_loop(config, meshcat=meshcat, log=False).diagram
    plant = diagram.GetSubsystemByName("plant")
    scene_graph = diagram.GetSubsystemByName("scene_graph")
    inspector = scene_graph.model_inspector()
    frame_of = {
        inspector.GetName(g): inspector.GetFrameId(g)
        for g in inspector.GetAllGeometryIds(Role.kIllustration)
    }
    world = plant.GetBodyFrameIdOrThrow(plant.world_body().index())
    target = plant.GetBodyFrameIdOrThrow(plant.GetBodyByName(TARGET_BODY_NAME).index())
    assert frame_of["camera_box"] == world and frame_of["camera_fov_cone"] == world
    assert frame_of["target_sphere"] == target and frame_of["marked_point"] == target
    assert frame_of["goal_target_sphere"] == world
    result = simulate(config, meshcat=meshcat)
    assert meshcat.HasPath(f"/drake/visualizer/{TARGET_BODY_NAME}")
    assert result.status == "not_converged"  # 0.5 s: under way
    with pytest.raises(
        ValueError, match=r"meshcat needs a carrier with geometry \(the kinematic FixedCamera"
    ):
        build_loop(ScenarioConfig(carrier=FixedCamera(), plant=Kinematic()), meshcat)


def test_tools_built_for_the_eye_in_hand_loop_refuse_the_fixed_camera():
    from geovs_drake.analysis.linear.linearization import linearize_at_goal
    from geovs_drake.batch.engine import loop_parameters

    config = ScenarioConfig(carrier=FixedCamera())
    with pytest.raises(
        ValueError, match="batch engine runs the eye-in-hand free rig only: carrier = FixedCamera"
    ):
        loop_parameters(config)
    with pytest.raises(
        ValueError,
        match=r"closed form is the eye-in-hand free rig's \(carrier FreeRig\), got carrier "
        "FixedCamera",
    ):
        linearize_at_goal(config)


def test_the_fixed_camera_s_pinhole_sees_the_eye_in_hand_pinhole_s_frames():
    """A camera model on the fixed camera (eye-to-hand): the same relative poses give the
    same frames, so the kinematic loop's measured y(t) is the eye-in-hand one's (both
    exact pinhole measurements of the same relative pose, to the integrators' error)."""
    frames = {}
    for mount, carrier in (("hand", FreeRig()), ("fixed", FixedCamera())):
        config = ScenarioConfig(plant=Kinematic(), carrier=carrier, sensor=Pinhole(), duration=3.0)
        config.simulator.integration_scheme = "runge_kutta5"
        config.simulator.accuracy = 1e-13
        result = simulate(config)
        assert result.status in ("converged", "not_converged"), result.message
        frames[mount] = result.image_features
    assert np.max(np.abs(frames["hand"][-1] - frames["hand"][0])) > 0.1  # it moved
    np.testing.assert_allclose(frames["fixed"], frames["hand"], rtol=0, atol=1e-8)


def test_the_fixed_camera_renders_the_target_the_rig_moves():
    """The rendered camera stands in the world at X_WC and sees the target the dynamic
    rig carries (its marks in the extractor's colours, the goal's ghost and the camera's
    own drawing out of its view): the loop converges within the camera's resolution."""
    config = ScenarioConfig(
        carrier=FixedCamera(),
        sensor=Rendered(),
        initial=PoseConfig([0.03, -0.02, -0.58], [0.05, -0.03, 0.26]),  # the small move
        duration=3.0,
    )
    result = simulate(config)
    assert result.status == "converged", result.message
    assert np.all(result.margins >= 0)
