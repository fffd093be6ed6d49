"""The LeafSystems against the pure functions and against Drake's own multibody tools."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame, RotationalInertia, SpatialInertia

from geovs_drake import camera_map, image_jacobian, so3_exp, visibility
from geovs_drake.geometry import baselines
from geovs_drake.geometry.domain import DEFAULT_DOMAIN
from geovs_drake.geometry.navigation import NavigationFunction, navigation_differential
from geovs_drake.scenario import ScenarioConfig
from geovs_drake.systems import (
    IbvsController,
    ImageJacobianForce,
    KinematicController,
    KinematicRigidBody,
    NavigationController,
    PbvsController,
    SphericalCamera,
    SphericalFeatureController,
    VelocityTrackingForce,
)
from geovs_drake.systems.kinematic_rigid_body import pose_state

RHO = 0.1
X_WB = RigidTransform(RollPitchYaw(0.2, -0.1, 0.4), [0.3, -0.2, 1.0])
X_RC = RigidTransform(RollPitchYaw(0.1, 0.3, -0.2), [0.02, -0.03, 0.05])
GOAL = camera_map(RigidTransform([0, 0, 0.5]), RHO)


def _rig_pose_looking_at_target(rng: np.random.Generator) -> RigidTransform:
    """A rig pose X_WR whose camera sees the target inside D."""
    X_BC = RigidTransform(
        RollPitchYaw(rng.uniform(-0.1, 0.1, 2).tolist() + [rng.uniform(-3, 3)]),
        [rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), -rng.uniform(0.4, 1.0)],
    )
    return X_WB @ X_BC @ X_RC.inverse()


def _values(a) -> np.ndarray:
    return ExtractValue(np.asarray(a)).reshape(np.shape(a))


@pytest.fixture(scope="module")
def camera() -> SphericalCamera:
    return SphericalCamera(radius=RHO, X_WB=X_WB, X_RC=X_RC)


def test_spherical_camera_matches_geometry(camera):
    rng = np.random.default_rng(0)
    ctx = camera.CreateDefaultContext()
    for _ in range(20):
        X_WR = _rig_pose_looking_at_target(rng)
        camera.body_pose_input.FixValue(ctx, pose_state(X_WR))
        # Independent: Drake's RigidTransform algebra for H = X_CB.
        X_CB = (X_WR @ X_RC).inverse() @ X_WB
        y = camera_map(X_CB, RHO)
        np.testing.assert_allclose(
            camera.image_features_output.Eval(ctx), y.to_vector(), atol=1e-12
        )
        assert camera.visibility_output.Eval(ctx)[0] == pytest.approx(
            float(visibility(X_CB, RHO)), abs=1e-12
        )
        np.testing.assert_allclose(
            camera.domain_margins_output.Eval(ctx),
            [float(m) for m in DEFAULT_DOMAIN.margins(y)],
            atol=1e-12,
        )


def test_spherical_camera_autodiff_matches_central_differences(camera):
    cam_ad = camera.ToAutoDiffXd()
    ctx = cam_ad.CreateDefaultContext()
    x0 = pose_state(_rig_pose_looking_at_target(np.random.default_rng(1)))
    cam_ad.body_pose_input.FixValue(ctx, InitializeAutoDiff(x0).ravel())
    y_ad = cam_ad.image_features_output.Eval(ctx)
    J_ad = ExtractGradient(y_ad)
    ctx_f = camera.CreateDefaultContext()

    def y_of(x):
        camera.body_pose_input.FixValue(ctx_f, x)
        return camera.image_features_output.Eval(ctx_f).copy()

    np.testing.assert_allclose(ExtractValue(y_ad).ravel(), y_of(x0), atol=1e-14)
    h = 1e-6
    J_fd = np.stack([(y_of(x0 + h * e) - y_of(x0 - h * e)) / (2 * h) for e in np.eye(7)], -1)
    np.testing.assert_allclose(J_ad, J_fd, atol=1e-7 * np.max(np.abs(J_ad)))


def test_camera_outside_visibility_reports_violated_margins(camera):
    ctx = camera.CreateDefaultContext()
    # The camera behind the target's far side: the marked point faces away.
    X_WR = X_WB @ RigidTransform(RollPitchYaw(np.pi, 0, 0), [0, 0, 0.6]) @ X_RC.inverse()
    camera.body_pose_input.FixValue(ctx, pose_state(X_WR))
    nu = camera.visibility_output.Eval(ctx)[0]
    assert nu < 0
    np.testing.assert_array_equal(camera.domain_margins_output.Eval(ctx), np.full(4, nu))
    # The pure map raises; the system outputs NaN so that an integrator rejects
    # the trial step (the simulate() monitor stops any accepted invisible state).
    assert np.all(np.isnan(camera.image_features_output.Eval(ctx)))
    with pytest.raises(ValueError, match="pose not visible"):
        camera_map(camera.X_CB(ctx), RHO)


def test_navigation_controller_matches_pure_function_and_goal_is_a_parameter():
    nav = NavigationController(goal=GOAL)
    ctx = nav.CreateDefaultContext()
    y = camera_map(RigidTransform(RollPitchYaw(0.1, 0.05, 1.0), [0.04, -0.02, 0.7]), RHO)
    nav.image_features_input.FixValue(ctx, y.to_vector())
    phi, dphi = navigation_differential(y, GOAL, DEFAULT_DOMAIN)
    np.testing.assert_array_equal(nav.dphi_output.Eval(ctx), dphi)
    assert nav.phi_output.Eval(ctx)[0] == phi
    # Change the goal in the context, not the system.
    nav.set_goal(ctx, y)
    assert abs(nav.phi_output.Eval(ctx)[0]) < 1e-15
    with pytest.raises(ValueError, match="goal not in the interior of D"):
        nav.set_goal(ctx, camera_map(RigidTransform([0, 0, 3.0]), RHO))
    # AutoDiffXd: the same values, derivatives that match the pure function's.
    nav_ad = nav.ToAutoDiffXd()
    ctx_ad = nav_ad.CreateDefaultContext()
    v = InitializeAutoDiff(y.to_vector()).ravel()
    nav_ad.image_features_input.FixValue(ctx_ad, v)
    dphi_ad = nav_ad.dphi_output.Eval(ctx_ad)
    _, dphi_pure = navigation_differential(v, GOAL, DEFAULT_DOMAIN)
    np.testing.assert_allclose(ExtractValue(dphi_ad).ravel(), dphi, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(ExtractGradient(dphi_ad), ExtractGradient(dphi_pure), atol=1e-12)


def _drake_camera_velocity(x: np.ndarray) -> np.ndarray:
    """(Omega, V) of frame C by MultibodyPlant: the independent truth for the frames."""
    plant = MultibodyPlant(0.0)
    body = plant.AddRigidBody(
        "rig", SpatialInertia.MakeFromCentralInertia(1.0, np.zeros(3), RotationalInertia(1, 1, 1))
    )
    frame_C = plant.AddFrame(FixedOffsetFrame("C", body.body_frame(), X_RC))
    plant.Finalize()
    ctx = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(ctx, x)
    V_WC_C = frame_C.CalcSpatialVelocity(ctx, plant.world_frame(), frame_C)
    return np.concatenate([V_WC_C.rotational(), V_WC_C.translational()])


def test_image_jacobian_force_wrench_and_power():
    rng = np.random.default_rng(3)
    damping = np.array([0.3, 0.4, 0.5, 4.0, 5.0, 6.0])
    force = ImageJacobianForce(radius=RHO, potential_gain=2.5, damping=damping, X_RC=X_RC)
    ctx = force.CreateDefaultContext()
    for _ in range(10):
        X_WR = _rig_pose_looking_at_target(rng)
        q = pose_state(X_WR)
        x = np.concatenate([q, rng.normal(size=6)])
        y = camera_map((X_WR @ X_RC).inverse() @ X_WB, RHO)
        _, dphi = navigation_differential(y, GOAL, DEFAULT_DOMAIN)
        force.image_features_input.FixValue(ctx, y.to_vector())
        force.dphi_input.FixValue(ctx, dphi)
        force.body_state_input.FixValue(ctx, x)
        V_C = _drake_camera_velocity(x)
        expected = 2.5 * image_jacobian(y, RHO).T @ dphi - damping * V_C
        F_C = force.wrench_C_output.Eval(ctx)
        np.testing.assert_allclose(F_C, expected, atol=1e-12)
        # The generalized force is the same wrench for the plant: its power on any
        # generalized velocity v equals F_C . V_C(v). Six v's determine it.
        tau = force.generalized_force_output.Eval(ctx)
        for v in np.eye(6):
            V = _drake_camera_velocity(np.concatenate([q, v]))
            assert tau @ v == pytest.approx(F_C @ V, abs=1e-12)
    assert force.ToAutoDiffXd() is not None


def test_kinematic_controller_descends_phi_exactly():
    ctrl = KinematicController(radius=RHO, gain=1.7)
    ctx = ctrl.CreateDefaultContext()
    y = camera_map(RigidTransform(RollPitchYaw(0.1, 0.05, 1.0), [0.04, -0.02, 0.7]), RHO)
    _, dphi = navigation_differential(y, GOAL, DEFAULT_DOMAIN)
    ctrl.image_features_input.FixValue(ctx, y.to_vector())
    ctrl.dphi_input.FixValue(ctx, dphi)
    V_C = ctrl.camera_velocity_output.Eval(ctx)
    # Eq. (16): (omega, v) = -(Omega, V); then ydot = C (omega, v) must be -k grad phi.
    ydot = image_jacobian(y, RHO) @ (-V_C)
    np.testing.assert_allclose(ydot, -1.7 * dphi, atol=1e-12)
    ctrl_ad = ctrl.ToAutoDiffXd()
    ctx_ad = ctrl_ad.CreateDefaultContext()
    ctrl_ad.image_features_input.FixValue(ctx_ad, InitializeAutoDiff(y.to_vector()).ravel())
    ctrl_ad.dphi_input.FixValue(ctx_ad, dphi.astype(object) * AutoDiffXd(1.0))
    np.testing.assert_allclose(
        _values(ctrl_ad.camera_velocity_output.Eval(ctx_ad)), V_C, atol=1e-12
    )


def test_kinematic_rigid_body_integrates_body_velocity():
    X0 = RigidTransform(RollPitchYaw(0.3, -0.4, 1.2), [0.1, 0.2, -0.5])
    body = KinematicRigidBody(X_WC0=X0)
    ctx = body.CreateDefaultContext()
    u = np.array([0.3, -0.2, 0.5, 0.1, 0.4, -0.3])
    body.camera_velocity_input.FixValue(ctx, u)
    xdot = body.EvalTimeDerivatives(ctx).CopyToVector()
    # Independent: G(t) = G exp(t hat(Omega, V)) to first order, by central differences.
    h = 1e-6

    def pose_after(t):
        R = X0.rotation().matrix() @ so3_exp(t * u[:3])
        p = X0.translation() + X0.rotation().matrix() @ (t * u[3:])
        return pose_state(RigidTransform(RotationMatrix(R), p))

    np.testing.assert_allclose(xdot, (pose_after(h) - pose_after(-h)) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(body.body_pose_output.Eval(ctx), pose_state(X0))
    assert body.ToAutoDiffXd() is not None


def test_velocity_tracking_force_wrench_and_power():
    """F_C = B (nu_cmd - nu) with nu from Drake's own frame velocity; the plant's
    generalized force has the same power on every generalized velocity."""
    rng = np.random.default_rng(5)
    gains = np.array([0.4, 0.5, 0.6, 7.0, 8.0, 9.0])
    force = VelocityTrackingForce(gains=gains, X_RC=X_RC)
    ctx = force.CreateDefaultContext()
    for _ in range(10):
        q = pose_state(_rig_pose_looking_at_target(rng))
        x = np.concatenate([q, rng.normal(size=6)])
        command = rng.normal(size=6)
        force.body_state_input.FixValue(ctx, x)
        force.camera_velocity_command_input.FixValue(ctx, command)
        F_C = force.wrench_C_output.Eval(ctx)
        np.testing.assert_allclose(F_C, gains * (command - _drake_camera_velocity(x)), atol=1e-12)
        tau = force.generalized_force_output.Eval(ctx)
        for v in np.eye(6):
            V = _drake_camera_velocity(np.concatenate([q, v]))
            assert tau @ v == pytest.approx(F_C @ V, abs=1e-12)
    # The same numbers in AutoDiffXd, with the derivative along the command = B.
    force_ad = force.ToAutoDiffXd()
    ctx_ad = force_ad.CreateDefaultContext()
    force_ad.body_state_input.FixValue(ctx_ad, x.astype(object) * AutoDiffXd(1.0))
    force_ad.camera_velocity_command_input.FixValue(ctx_ad, InitializeAutoDiff(command).ravel())
    F_ad = force_ad.wrench_C_output.Eval(ctx_ad)
    np.testing.assert_allclose(_values(F_ad), F_C, atol=1e-12)
    np.testing.assert_allclose(ExtractGradient(np.asarray(F_ad)), np.diag(gains), atol=1e-12)
    assert force.ToSymbolic() is not None
    with pytest.raises(ValueError, match="tracking gains must be 6 finite numbers > 0"):
        VelocityTrackingForce(gains=[1, 1, 1, 1, 1, 0])


def test_navigation_function_in_system_equals_class():
    nav = NavigationController(goal=GOAL)
    nf = nav.navigation_function(nav.CreateDefaultContext())
    assert isinstance(nf, NavigationFunction)
    np.testing.assert_array_equal(nf.goal.to_vector(), GOAL.to_vector())


@pytest.mark.parametrize("law", ["ibvs-true", "ibvs-desired", "ibvs-mean", "pbvs", "spherical"])
def test_baseline_systems_match_their_laws_and_convert(law):
    """Each baseline's camera_velocity is its law in geometry.baselines, for floats and
    after ToAutoDiffXd (whose gradient is the law's, by central differences); an image
    outside I gives NaN, not an exception."""
    gain = 0.8
    if law.startswith("ibvs"):
        depth = law.split("-")[1]
        system = IbvsController(goal=GOAL, radius=RHO, gain=gain, depth=depth)
        points = baselines.target_points(RHO, baselines.DEFAULT_SQUARE_SIDE * RHO)

        def reference(y):
            return baselines.ibvs_velocity(y, GOAL.to_vector(), RHO, points, gain, depth)

        np.testing.assert_allclose(system.target_points_B(system.CreateDefaultContext()), points)
    else:
        cls, fn = {
            "pbvs": (PbvsController, baselines.pbvs_velocity),
            "spherical": (SphericalFeatureController, baselines.spherical_velocity),
        }[law]
        system = cls(goal=GOAL, radius=RHO, gain=gain)

        def reference(y):
            return fn(y, GOAL.to_vector(), RHO, gain)

    y = camera_map(RigidTransform(RollPitchYaw(0.1, -0.05, 1.0), [0.03, -0.02, 0.7]), RHO)
    y = y.to_vector()
    ctx = system.CreateDefaultContext()
    system.GetInputPort("image_features").FixValue(ctx, y)
    np.testing.assert_allclose(system.camera_velocity_output.Eval(ctx), reference(y), atol=1e-12)
    ad = system.ToAutoDiffXd()
    ad_ctx = ad.CreateDefaultContext()
    ad.GetInputPort("image_features").FixValue(ad_ctx, InitializeAutoDiff(y).ravel())
    out = ad.get_output_port().Eval(ad_ctx)
    np.testing.assert_allclose(_values(out).ravel(), reference(y), atol=1e-9)
    h = 1e-6
    numeric = np.stack(
        [(reference(y + h * e) - reference(y - h * e)) / (2 * h) for e in np.eye(13)], axis=1
    )
    np.testing.assert_allclose(
        ExtractGradient(out), numeric, atol=1e-5 * (1 + np.abs(numeric).max())
    )
    system.GetInputPort("image_features").FixValue(ctx, np.full(13, np.nan))
    assert np.all(np.isnan(system.camera_velocity_output.Eval(ctx)))
    with pytest.raises(ValueError, match="gain must be finite and > 0"):
        type(system)(goal=GOAL, radius=RHO, gain=0.0)
    with pytest.raises(ValueError, match="not a rotation|not in I|not a unit"):
        type(system)(goal=np.r_[GOAL.to_vector()[:12], 2.0], radius=RHO)


def test_ibvs_controller_refuses_an_unknown_depth_and_a_bad_side():
    with pytest.raises(ValueError, match="ibvs depth must be one of true, desired, mean"):
        IbvsController(goal=GOAL, depth="exact")
    with pytest.raises(ValueError, match="square side must be finite and > 0"):
        IbvsController(goal=GOAL, side=-0.1)


@pytest.mark.parametrize("name", ["IbvsController", "PbvsController", "SphericalFeatureController"])
def test_baseline_laws_convert_to_autodiff_with_the_same_values(name):
    """Each baseline law's system in AutoDiffXd gives its float command, and the
    derivative along y is that of central differences of the float system."""
    import geovs_drake.systems as systems

    law = getattr(systems, name)(goal=GOAL, radius=RHO, gain=0.7)
    y = camera_map(RigidTransform(RollPitchYaw(0.1, -0.05, 0.8), [0.03, -0.02, 0.6]), RHO)
    ctx = law.CreateDefaultContext()
    law.GetInputPort("image_features").FixValue(ctx, y.to_vector())
    command = law.GetOutputPort("camera_velocity").Eval(ctx).copy()
    law_ad = law.ToAutoDiffXd()
    ctx_ad = law_ad.CreateDefaultContext()
    law_ad.GetInputPort("image_features").FixValue(ctx_ad, InitializeAutoDiff(y.to_vector()))
    out = law_ad.GetOutputPort("camera_velocity").Eval(ctx_ad)
    np.testing.assert_allclose(_values(out), command, atol=1e-12)
    # Along lambda (entry 9 of y: stays in I for a small step) by central differences.
    h, k = 1e-6, 9
    values = []
    for sign in (1, -1):
        yk = y.to_vector().copy()
        yk[k] += sign * h
        law.GetInputPort("image_features").FixValue(ctx, yk)
        values.append(law.GetOutputPort("camera_velocity").Eval(ctx).copy())
    np.testing.assert_allclose(
        ExtractGradient(np.asarray(out))[:, k], (values[0] - values[1]) / (2 * h), atol=1e-6
    )


def test_the_wire_it_yourself_example_of_the_python_page_reaches_the_goal():
    """docs/python.md's "Wire it yourself" block, run as written: the user's own
    DiagramBuilder of a free body, SphericalCamera, NavigationController and
    ImageJacobianForce (the plant's state port into both body_state inputs, no
    Demultiplexer) brings the camera to the goal pose within 1 mm and 1 mrad in 10 s."""
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "python.md").read_text()
    section = page.split("### Wire it yourself")[1]
    (code,) = re.findall(r"```python\n(.*?)```", section, re.S)[:1]
    namespace: dict = {}
    exec(compile(code, "python.md", "exec"), namespace)
    X_BC, config = namespace["X_BC"], namespace["config"]
    goal = config.X_BC_goal
    assert np.linalg.norm(X_BC.translation() - goal.translation()) < 1e-3
    R_err = X_BC.rotation().inverse() @ goal.rotation()
    assert abs(R_err.ToAngleAxis().angle()) < 1e-3


def test_the_camera_reads_its_pose_from_body_pose_or_a_free_bodys_state_alike():
    """SphericalCamera's two pose inputs give the same y: body_pose (7) and body_state (13,
    a free body's [q, p, w, v], whatever its velocity); neither is one clear error."""
    config = ScenarioConfig()
    camera = SphericalCamera(radius=config.radius, X_WB=config.X_WB)
    X_WR = config.X_WB @ config.X_BC_initial
    pose = np.concatenate([X_WR.rotation().ToQuaternion().wxyz(), X_WR.translation()])
    by_pose, by_state = camera.CreateDefaultContext(), camera.CreateDefaultContext()
    camera.body_pose_input.FixValue(by_pose, pose)
    camera.body_state_input.FixValue(by_state, np.concatenate([pose, [0.3, -0.1, 0.2, 1, 2, 3]]))
    y = camera.image_features_output.Eval(by_pose)
    np.testing.assert_array_equal(camera.image_features_output.Eval(by_state), y)
    np.testing.assert_allclose(
        y, camera_map(X_WR.inverse() @ config.X_WB, config.radius), atol=1e-12
    )
    with pytest.raises(ValueError, match="connect \\(or fix\\) body_pose or body_state"):
        camera.image_features_output.Eval(camera.CreateDefaultContext())


def test_the_controllers_fast_image_check_passes_only_what_image_violation_passes():
    """The NF controller's compiled check of y in I (Eq. 9) may send a y on to the full
    check, never pass one image_violation refuses: near each of I's boundaries (the
    silhouette, lambda in (0, 1), Q a rotation, s a unit vector, finite) both are asked,
    and the images of generic visible poses pass it."""
    from geovs_drake.geometry.camera import image_violation
    from geovs_drake.sampling import random_visible_poses
    from geovs_drake.systems.navigation_controller import _surely_in_image

    rng = np.random.default_rng(20261128)
    poses = np.concatenate(
        [
            random_visible_poses(rng, 60, RHO, (1.001, 100.0)),
            random_visible_poses(rng, 60, RHO, (1.001, 100.0), (1e-9, 1e-6)),
        ]
    )
    images = [camera_map(RigidTransform(X), RHO).to_vector() for X in poses]
    assert sum(_surely_in_image(y) for y in images[:60]) >= 57  # not vacuous
    tried, refused = 0, 0
    for y in images:
        for k in range(13):
            for delta in (0.0, 1e-12, -1e-12, 1e-9, -1e-9, 1e-6, 0.5, -1.0, np.nan):
                z = y.copy()
                z[k] += delta
                if k == 9 and delta == -1.0:
                    z[k] = 1.0  # lambda on the open interval's ends
                tried += 1
                truth = image_violation(tuple(z.tolist())) is None
                refused += not truth
                assert truth or not _surely_in_image(z), (k, delta, z)
    assert refused > tried // 4  # the boundaries were reached
