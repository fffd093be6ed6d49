"""The generated kernels: up to date, and one result for every number type.

Truths used: the hand-written scalar-style sources evaluated directly (the
kernels are generated from them, but through sympy's rewriting and common
subexpressions, then compiled by numba), Drake's AutoDiffXd and symbolic
Expression, numpy batches, central differences and the camera map's array API
on Drake's own RigidTransform algebra.
"""

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.math import RigidTransform
from pydrake.symbolic import Expression, Variable

from geovs_drake.analysis.studies.nf_study import random_features_in_domain
from geovs_drake.geometry import _codegen, kernels
from geovs_drake.geometry._ops import MATH
from geovs_drake.geometry.camera import camera_map, camera_map_inverse
from geovs_drake.geometry.domain import DEFAULT_DOMAIN
from geovs_drake.geometry.navigation import NavigationFunction, clearance_of
from geovs_drake.scenario import PoseConfig, ScenarioConfig
from geovs_drake.systems import ImageJacobianForce, SphericalCamera

RHO = 0.1
N = 1000
X_RC = RigidTransform(
    PoseConfig(xyz=[0.03, -0.02, 0.05], rpy=[0.1, -0.2, 0.3]).to_rigid_transform()
)


# sympy regenerates the module (4-8 s): make test's budget; the kernels' behaviour tests
# against the geometry and autodiff stay.
@pytest.mark.slow
def test_generated_module_is_up_to_date():
    """Regenerating from the sources gives the committed text, byte for byte."""
    assert _codegen.generate() == _codegen.TARGET.read_text(), (
        "run: python -m geovs_drake.geometry._codegen"
    )


@pytest.mark.slow  # sympy's simplification of the prediction: about 7 s of CPU
def test_the_batch_engines_generated_prediction_is_up_to_date():
    """The batch engine's own generated kernel (the held frame's odometry prediction)
    regenerates to the committed text, byte for byte."""
    from geovs_drake.batch import _codegen as batch_codegen

    assert batch_codegen.generate() == batch_codegen.TARGET.read_text(), (
        "run: python -m geovs_drake.batch._codegen"
    )


@pytest.fixture(scope="module")
def batch():
    """1000 random rig states whose images lie in D, with random velocities."""
    config = ScenarioConfig()
    rng = np.random.default_rng(2026)
    y = random_features_in_domain(rng, N, DEFAULT_DOMAIN, shrink=0.99)
    X_CB = camera_map_inverse(y, RHO)
    X_WB = config.X_WB
    states = np.empty((N, 13))
    for i in range(N):
        X_WR = X_WB @ RigidTransform(X_CB[i]).inverse() @ X_RC.inverse()
        q = X_WR.rotation().ToQuaternion()
        states[i, 0:4] = [q.w(), q.x(), q.y(), q.z()]
        states[i, 4:7] = X_WR.translation()
    states[:, 7:13] = rng.normal(scale=0.3, size=(N, 6))
    camera = SphericalCamera(radius=RHO, X_WB=X_WB, X_RC=X_RC)
    force = ImageJacobianForce(
        radius=RHO, potential_gain=3.0, damping=[0.3, 0.2, 0.4, 4, 5, 6], X_RC=X_RC
    )
    p_cam = camera.CreateDefaultContext().get_numeric_parameter(0).CopyToVector()
    p_force = force.CreateDefaultContext().get_numeric_parameter(0).CopyToVector()
    goal = camera_map(RigidTransform([0.0, 0.0, 0.5]), RHO)
    p_nav = NavigationFunction(DEFAULT_DOMAIN, goal).params
    return dict(states=states, X_CB=X_CB, p_cam=p_cam, p_force=p_force, p_nav=p_nav)


def _run_all(kernel_args) -> list[np.ndarray]:
    """Every kernel on one set of arguments: camera -> NF -> force, kinematic."""
    x, p_cam, p_nav, p_force = kernel_args
    cam = kernels.camera_image(x[0:7], p_cam)
    y = cam[1:14]
    nav = kernels.navigation(y, p_nav)
    force = kernels.servo_force(x, y, nav[1:8], p_force)
    kin = kernels.kinematic_velocity(y, nav[1:8], (RHO, 2.5))
    return [np.asarray(v, dtype=object) for v in (cam, nav, force, kin)]


def _values(a: np.ndarray) -> np.ndarray:
    return np.vectorize(lambda e: e.value() if isinstance(e, AutoDiffXd) else float(e))(a)


def _rel_err(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b) / np.maximum(1.0, np.abs(b))))


def test_float_autodiff_and_batch_paths_agree_on_1000_states_in_D(batch):
    states = batch["states"]
    args = (batch["p_cam"], tuple(batch["p_nav"]), batch["p_force"])
    # ndarray (N,): one call for the whole batch, numpy's ufuncs.
    batch_out = _run_all((tuple(states.T), *args))
    worst_ad = worst_batch = 0.0
    for i in range(N):
        x = states[i]
        flt = _run_all((x, *args))  # compiled by numba
        ad = _run_all((InitializeAutoDiff(x).ravel(), *args))  # generated Python, AutoDiffXd
        for f, a, b in zip(flt, ad, batch_out, strict=True):
            worst_ad = max(worst_ad, _rel_err(_values(a), f))
            worst_batch = max(worst_batch, _rel_err(np.array([v[i] for v in b]), f))
    print(f"\nfloat vs AutoDiffXd {worst_ad:.1e}, float vs ndarray (N,) {worst_batch:.1e}")
    assert worst_ad < 1e-12 and worst_batch < 1e-12


def test_compiled_kernels_run_the_generated_text(batch):
    """numba's float results equal the generated Python run on Python floats."""
    x = tuple(batch["states"][7].tolist())
    p_cam = tuple(batch["p_cam"].tolist())
    for name, args in (
        ("camera_image", (x[0:7], p_cam)),
        ("navigation", (tuple(kernels.camera_image(x[0:7], p_cam)[1:14]), batch["p_nav"])),
    ):
        k = getattr(kernels, name)
        np.testing.assert_allclose(k.compiled(*args), k.python(*args), rtol=1e-14, atol=1e-15)


def test_in_place_forms_write_the_kernels_outputs_to_the_last_bit(batch):
    """The float systems' in-place forms (camera y and nu, dphi, F_C) equal the whole
    kernels' outputs bitwise: the same operations, so a loop's run does not change
    with the form its systems call; an invisible pose gives its nu <= 0 too."""
    p_cam, p_nav, p_force = batch["p_cam"], tuple(batch["p_nav"]), batch["p_force"]
    behind = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5])  # the rig turned away from B
    poses = [*batch["states"][:50, 0:7], behind]
    for k, x in enumerate(poses):
        cam = kernels.camera_image(x, p_cam)
        y_out = np.full(13, 7.0)
        nu = kernels.camera_image_y_into(x, p_cam, y_out)
        assert nu == cam[0] and np.array_equal(y_out, cam[1:14], equal_nan=True)
        if k == len(poses) - 1:
            assert not nu > 0
            continue
        assert nu > 0
        y = np.array(cam[1:14])
        nav = kernels.navigation(y, p_nav)
        dphi = np.full(7, 7.0)
        assert kernels.navigation_dphi_into(y, p_nav, dphi) is None
        assert np.array_equal(dphi, nav[1:8])
        state = batch["states"][k]
        force = kernels.servo_force(state, y, dphi, p_force)
        wrench = np.full(6, 7.0)
        kernels.servo_force_wrench_into(state, y, dphi, p_force, wrench)
        assert np.array_equal(wrench, force[0:6])


def test_camera_kernel_matches_drakes_pose_algebra_and_the_sources(batch):
    """y from the rig state equals camera_map(X_CB) with X_CB from RigidTransforms,
    and the margins equal SafeDomain.margins on that y."""
    for i in range(0, N, 50):
        out = kernels.camera_image(batch["states"][i, 0:7], batch["p_cam"])
        y = camera_map(batch["X_CB"][i], RHO)
        np.testing.assert_allclose(out[1:14], y.to_vector(), atol=1e-12)
        assert out[0] > 0
        np.testing.assert_allclose(out[14:18], list(DEFAULT_DOMAIN.margins(y)), atol=1e-12)


def test_navigation_kernel_value_is_the_source_formula(batch):
    y = camera_map(batch["X_CB"][:200], RHO)
    comps = y.components()
    direct = clearance_of(comps, batch["p_nav"], np)
    generated = kernels.navigation(comps, batch["p_nav"])[0]
    np.testing.assert_allclose(generated, direct, rtol=1e-13)


def test_camera_kernel_derivatives_match_central_differences(batch):
    """AutoDiffXd through the generated kernel (what Linearize uses) vs differences."""
    worst = 0.0
    for i in range(0, N, 100):
        x = batch["states"][i, 0:7]
        J = np.array(
            [
                e.derivatives()
                for e in kernels.camera_image(InitializeAutoDiff(x).ravel(), batch["p_cam"])
            ]
        )
        h = 1e-6
        for k in range(7):
            e = np.zeros(7)
            e[k] = h
            fd = (
                np.array(kernels.camera_image(x + e, batch["p_cam"]))
                - np.array(kernels.camera_image(x - e, batch["p_cam"]))
            ) / (2 * h)
            worst = max(worst, _rel_err(J[:, k], fd))
    print(f"\ncamera kernel: AutoDiffXd vs central differences {worst:.1e}")
    assert worst < 1e-7


# Drake fills symbolic scratch matrices with NaN, which leaves the FPU's
# "invalid" flag set; numpy reports that flag after the next object-array op.
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_kernels_run_on_symbolic_expressions(batch):
    x = batch["states"][3]
    t = Variable("t")
    xe = x.astype(object)
    xe[4] = Expression(t) + x[4]
    cam = kernels.camera_image(xe[0:7], batch["p_cam"])
    env = {t: 0.0}
    np.testing.assert_allclose(
        [e.Evaluate(env) for e in cam], kernels.camera_image(x[0:7], batch["p_cam"]), atol=1e-13
    )


def test_kernels_outside_their_domain_give_nan_and_never_raise():
    """The compiled path must not raise ZeroDivisionError or a math domain error:
    the systems turn NaN into a rejected integrator step."""
    goal = camera_map(RigidTransform([0.0, 0.0, 0.5]), RHO)
    p = NavigationFunction(DEFAULT_DOMAIN, goal).params
    bad = goal.to_vector().copy()
    bad[9] = 1.5  # lambda > 1: sqrt(1 - lambda^2) is not real
    assert np.all(np.isnan(kernels.navigation(bad, p)[1:]))
    bad = goal.to_vector().copy()
    bad[0:3] = [0.0, 0.0, -1.0]  # q1 = -e3: the minimal rotation divides by 1 + q1.e3 = 0
    out = kernels.navigation(bad, p)
    assert not np.all(np.isfinite(out))


def test_domain_margins_source_matches_generated_kernel_margins(batch):
    """The margins of the generated camera kernel come from the same source as
    SafeDomain.margins: check the FOV margin against its definition directly."""
    out = np.array(kernels.camera_image(tuple(batch["states"][:, 0:7].T), batch["p_cam"]))
    lam, s3 = out[10], out[13]
    theta = DEFAULT_DOMAIN.fov_half_angle
    expected = s3 - np.cos(theta - np.arcsin(lam))
    np.testing.assert_allclose(out[14], expected, atol=1e-13)
    assert np.all(out[14:18] > 0)  # every sample lies in D
    assert MATH.sqrt is math.sqrt


def test_free_body_kernel_is_drakes_plant():
    """xdot and kinetic energy of the free rig against MultibodyPlant itself."""
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.tree import RotationalInertia, SpatialInertia

    body = (1.3, 0.02, 0.03, 0.025)
    plant = MultibodyPlant(0.0)
    plant.AddRigidBody(
        "rig",
        SpatialInertia.MakeFromCentralInertia(body[0], np.zeros(3), RotationalInertia(*body[1:])),
    )
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    plant.Finalize()
    ctx = plant.CreateDefaultContext()
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = rng.normal(size=4)
        x = np.concatenate([q / np.linalg.norm(q), rng.normal(size=3), rng.normal(size=6)])
        F = rng.normal(size=6)
        plant.SetPositionsAndVelocities(ctx, x)
        plant.get_applied_generalized_force_input_port().FixValue(ctx, F)
        out = kernels.free_body(x, F, np.array(body))
        np.testing.assert_allclose(
            out[0:13], plant.EvalTimeDerivatives(ctx).CopyToVector(), atol=1e-12
        )
        assert out[13] == pytest.approx(plant.CalcKineticEnergy(ctx), rel=1e-13)


def test_pose_error_kernel_matches_rigid_transform_errors():
    from geovs_drake.simulation import pose_error

    rng = np.random.default_rng(8)
    X_RC = RigidTransform(
        PoseConfig(xyz=[0.03, 0.0, 0.05], rpy=[0.2, 0.1, -0.3]).to_rigid_transform()
    )
    X_WC_goal = RigidTransform(
        PoseConfig(xyz=[0.1, 0.2, 0.9], rpy=[1.0, 0.2, 0.4]).to_rigid_transform()
    )
    p = np.concatenate(
        [
            X_RC.rotation().matrix().ravel(),
            X_RC.translation(),
            X_WC_goal.rotation().matrix().ravel(),
            X_WC_goal.translation(),
        ]
    )
    for scale in (1.0, 1e-3, 1e-6):
        pose = PoseConfig(
            xyz=list(scale * rng.normal(size=3)), rpy=list(scale * rng.normal(size=3))
        )
        X_WC = X_WC_goal @ pose.to_rigid_transform()
        X_WR = X_WC @ X_RC.inverse()
        q = X_WR.rotation().ToQuaternion()
        x = np.array([q.w(), q.x(), q.y(), q.z(), *X_WR.translation()])
        dp2, dR2 = kernels.pose_error(x, p)
        dp, dr = pose_error(X_WC, X_WC_goal)
        assert math.sqrt(dp2) == pytest.approx(dp, rel=1e-9, abs=1e-15)
        assert 2 * math.asin(math.sqrt(dR2 / 8)) == pytest.approx(dr, rel=1e-6, abs=1e-14)


def test_phi_keeps_its_digits_near_the_goal(batch):
    """phi = 1 - clearance rounds to 0 within 1e-16 of the goal; the kernel's phi (the
    telescoping sum of phi_of) does not, and both agree with the source formulas."""
    from geovs_drake.geometry.navigation import phi_of

    goal = camera_map(RigidTransform([0.0, 0.0, 0.5]), RHO)
    p = batch["p_nav"]
    for h in (1e-5, 1e-7, 1e-9):
        X = RigidTransform(PoseConfig(xyz=[h, 0.0, -0.5], rpy=[0, 0, h]).to_rigid_transform())
        y = camera_map(X.inverse(), RHO).to_vector()
        out = kernels.navigation(y, p)
        assert out[8] == pytest.approx(phi_of(tuple(y.tolist()), p, MATH), rel=1e-12)
        assert out[8] > 0  # a pose off the goal is not at the minimum
        assert out[8] == pytest.approx(1 - out[0], abs=5e-16)  # the same number, to rounding
    # phi ~ (quadratic in h): at h = 1e-9 it is ~1e-18, where 1 - clearance is 0 or eps.
    assert out[8] < 1e-15
    assert 0 <= kernels.navigation(goal.to_vector(), p)[8] < 1e-30  # rounding squared
