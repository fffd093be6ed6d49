"""The camera map, its inverse and the image Jacobian against independent truths.

Truths used: the geometry (Drake's RigidTransform moving sampled sphere points,
projected by the spherical camera), AutoDiffXd, and central differences.
"""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.symbolic import Expression, Variable

from geovs_drake import (
    ImageFeatures,
    camera_map,
    camera_map_inverse,
    hat,
    image_jacobian,
    image_jacobian_inverse,
    so3_exp,
    validate_features,
    vee,
    visibility,
)
from geovs_drake.sampling import (
    random_features_in_image_space,
    random_unit_vectors,
    random_visible_poses,
)

RHO = 0.1


def _pose_error(X1: np.ndarray, X2: np.ndarray) -> np.ndarray:
    """Max |rotation entry error| and translation error relative to |d|."""
    rot = np.max(np.abs(X1[..., :3, :3] - X2[..., :3, :3]), axis=(-2, -1))
    trans = np.linalg.norm(X1[..., :3, 3] - X2[..., :3, 3], axis=-1) / np.linalg.norm(
        X2[..., :3, 3], axis=-1
    )
    return np.maximum(rot, trans)


@pytest.fixture(scope="module")
def poses() -> np.ndarray:
    rng = np.random.default_rng(20261121)
    generic = random_visible_poses(rng, 4000, RHO, (1.001, 1000.0))
    # Within nu / rho in [1e-4, 1e-3] of the visibility boundary. Beyond 100 rho
    # such a pose's image is within rounding of the boundary of I (its margin
    # lambda^2 - sin^2 phi ~ lambda^4 (nu/rho)^2 < 1e-18), so double precision
    # cannot even tell it is visible; those are left out on purpose.
    near_boundary = random_visible_poses(rng, 1000, RHO, (1.001, 100.0), (1e-4, 1e-3))
    return np.concatenate([generic, near_boundary])


def _inverse_condition(y: ImageFeatures) -> np.ndarray:
    """||Tc^-1||_2 = 1 / sigma_min(C): how much c^-1 amplifies rounding in y."""
    return 1.0 / np.linalg.svd(image_jacobian(y, RHO), compute_uv=False)[..., -1]


def _check_round_trip(err: np.ndarray, cond: np.ndarray) -> None:
    eps = np.finfo(float).eps
    ok = cond < 1e6
    print(
        f"\nround trip: max {err.max():.2e}, median {np.median(err):.2e}; "
        f"where ||Tc^-1|| < 1e6 ({ok.sum()}/{len(err)}): max {err[ok].max():.2e}; "
        f"max err / (eps ||Tc^-1||) = {np.max(err / (eps * cond)):.1f}"
    )
    # Backward stability: never worse than the conditioning forces ...
    assert np.all(err <= np.maximum(1e-9, 50 * eps * cond)), np.max(err / (eps * cond))
    # ... and 1e-9 wherever the conditioning allows it.
    assert np.sum(ok) > 0.7 * len(err)
    assert np.max(err[ok]) < 1e-9, np.max(err[ok])


def test_round_trip_pose(poses):
    y = camera_map(poses, RHO)
    X = camera_map_inverse(y, RHO)
    _check_round_trip(_pose_error(X, poses), _inverse_condition(y))


def test_round_trip_generic_poses_to_1e9(poses):
    y = camera_map(poses[:4000], RHO)
    err = _pose_error(camera_map_inverse(y, RHO), poses[:4000])
    # Out to 1000 rho, with nu uniform over its visible range.
    print(f"\ngeneric round trip: median {np.median(err):.2e}, 99.9% {np.quantile(err, 0.999):.2e}")
    assert np.quantile(err, 0.999) < 1e-9
    assert np.median(err) < 1e-13


def test_round_trip_features():
    rng = np.random.default_rng(11)
    v = random_features_in_image_space(rng, 5000, (1e-3, 0.999))
    y = ImageFeatures.from_vector(v)
    v2 = camera_map(camera_map_inverse(y, RHO), RHO).to_vector()
    err = np.max(np.abs(v2 - v), axis=-1)
    _check_round_trip(err, _inverse_condition(y))


def test_to_from_vector_round_trip(poses):
    y = camera_map(poses[:10], RHO)
    v = y.to_vector()
    assert v.shape == (10, 13)
    np.testing.assert_array_equal(ImageFeatures.from_vector(v).to_vector(), v)
    np.testing.assert_array_equal(v[:, 0:3], y.Q[:, :, 0])
    np.testing.assert_array_equal(v[:, 9], y.lam)


def test_camera_map_lands_in_image_space(poses):
    """Claim 1, second part: c(V) is inside I, checked by its defining inequalities."""
    y = camera_map(poses, RHO)
    Q = y.Q
    assert np.max(np.abs(np.swapaxes(Q, -1, -2) @ Q - np.eye(3))) < 1e-12
    assert np.all(np.linalg.det(Q) > 0)
    assert np.all((y.lam > 0) & (y.lam < 1))
    assert np.max(np.abs(np.linalg.norm(y.s, axis=-1) - 1)) < 1e-12
    # q1.s > sqrt(1 - lambda^2) <=> q1.s > 0 and |q1 x s|^2 < lambda^2 (unit
    # vectors); the second form does not round to a false negative at small lambda.
    assert np.all(np.sum(y.q1 * y.s, axis=-1) > 0)
    assert np.all(np.sum(np.cross(y.q1, y.s) ** 2, axis=-1) < y.lam**2)
    validate_features(y)


def test_visibility_matches_geometry(poses):
    """nu > 0 iff the ray to b meets the sphere first at b: (b - o_c).(o_b - b) > 0."""
    nu = visibility(poses, RHO)
    b = poses[:, :3, 3] - RHO * poses[:, :3, 2]
    expected = np.sum(b * (poses[:, :3, 3] - b), axis=-1) / RHO
    # The geometric form cancels |b|^2 ~ |d|^2 against itself: compare to that scale.
    scale = np.sum(poses[:, :3, 3] ** 2, axis=-1) / RHO
    assert np.all(np.abs(nu - expected) <= 1e-14 * scale)
    assert np.all(nu > 0)


def _body_points_in_camera(X: np.ndarray, p_B: np.ndarray) -> np.ndarray:
    return RigidTransform(X).multiply(p_B.T).T


def test_silhouette_matches_projected_sphere():
    """s and lambda from the support function of projected sphere points."""
    rng = np.random.default_rng(3)
    X_all = random_visible_poses(rng, 12, RHO, (1.05, 30.0))
    p_B = RHO * random_unit_vectors(rng, 200_000)
    for X in X_all:
        y = camera_map(X, RHO)
        u = _body_points_in_camera(X, p_B)
        u /= np.linalg.norm(u, axis=-1, keepdims=True)
        gamma = np.arcsin(y.lam)  # the silhouette's angular radius
        for n in random_unit_vectors(rng, 25):
            sampled = np.max(u @ n)
            angle = np.arccos(np.clip(n @ y.s, -1, 1))
            predicted = 1.0 if angle <= gamma else np.cos(angle - gamma)
            # Samples never leave the predicted disc and come within sampling
            # resolution of its edge.
            assert sampled <= predicted + 1e-12
            assert predicted - sampled < 2e-4 * max(1.0, y.lam * 10)


def test_q1_is_direction_of_marked_point(poses):
    for X in poses[::250]:
        b_C = _body_points_in_camera(X, np.array([[0.0, 0.0, -RHO]]))[0]
        y = camera_map(X, RHO)
        np.testing.assert_allclose(y.q1, b_C / np.linalg.norm(b_C), atol=1e-12)


def test_q2_is_direction_arrow_leaves_q1():
    rng = np.random.default_rng(5)
    for X in random_visible_poses(rng, 40, RHO, (1.01, 100.0), (1e-2, 1.0)):
        y = camera_map(X, RHO)
        t = 1e-6 * RHO
        ends = _body_points_in_camera(X, np.array([[0.0, t, -RHO], [0.0, -t, -RHO]]))
        u = ends / np.linalg.norm(ends, axis=-1, keepdims=True)
        du = (u[0] - u[1]) / (2 * t)
        np.testing.assert_allclose(y.q2, du / np.linalg.norm(du), atol=1e-6)
        np.testing.assert_allclose(y.q3, np.cross(y.q1, y.q2), atol=1e-15)


def _tangent_of_features(Q: np.ndarray, dQ: np.ndarray, dlam, ds) -> np.ndarray:
    """(xi, lambda_dot, s_dot) from a derivative of (Q, lambda, s); Eq. (13)."""
    xi = vee(dQ @ Q.T)
    # dQ Q^T must be skew for a rotation curve.
    assert np.max(np.abs(dQ @ Q.T + (dQ @ Q.T).T)) < 1e-6 * max(1, np.max(np.abs(dQ)))
    return np.concatenate([xi, [dlam], ds])


def _perturbed_pose(X: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """X_CB moved along the right-trivialised velocity eps = (omega, v) (Eq. 11).

    R(eps) = exp(hat(omega)) R, d(eps) = exp(hat(omega)) d + v; the tangent at
    eps = 0 is (omega, v) exactly.
    """
    E = so3_exp(eps[:3])
    out = np.zeros((4, 4), dtype=E.dtype)
    out[:3, :3] = E @ X[:3, :3]
    out[:3, 3] = E @ X[:3, 3] + eps[3:]
    out[3, 3] = 1.0
    return out


def _jacobian_by_autodiff(X: np.ndarray) -> np.ndarray:
    eps = InitializeAutoDiff(np.zeros(6)).ravel()
    ya = camera_map(_perturbed_pose(X, eps), RHO)
    Q = np.vectorize(lambda e: e.value())(ya.Q)
    grads = []
    for k in range(6):
        dQ = np.vectorize(lambda e, k=k: e.derivatives()[k])(ya.Q)
        dlam = np.asarray(ya.lam).item().derivatives()[k]
        ds = np.array([e.derivatives()[k] for e in ya.s])
        grads.append(_tangent_of_features(Q, dQ, dlam, ds))
    return np.stack(grads, axis=-1)


def _jacobian_by_central_differences(X: np.ndarray, h: float = 1e-6) -> np.ndarray:
    y0 = camera_map(X, RHO)
    cols = []
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        yp, ym = camera_map(_perturbed_pose(X, e), RHO), camera_map(_perturbed_pose(X, -e), RHO)
        cols.append(
            _tangent_of_features(
                y0.Q, (yp.Q - ym.Q) / (2 * h), (yp.lam - ym.lam) / (2 * h), (yp.s - ym.s) / (2 * h)
            )
        )
    return np.stack(cols, axis=-1)


@pytest.fixture(scope="module")
def jacobian_poses() -> np.ndarray:
    rng = np.random.default_rng(17)
    return np.concatenate(
        [
            random_visible_poses(rng, 150, RHO, (1.01, 100.0)),
            random_visible_poses(rng, 50, RHO, (1.01, 10.0), (1e-3, 1e-2)),
        ]
    )


def _rel(A: np.ndarray, B: np.ndarray) -> float:
    return np.linalg.norm(A - B) / np.linalg.norm(B)


def test_image_jacobian_matches_autodiff(jacobian_poses):
    worst = max(
        _rel(image_jacobian(camera_map(X, RHO), RHO), _jacobian_by_autodiff(X))
        for X in jacobian_poses
    )
    print(f"\nC vs AutoDiffXd: worst relative error {worst:.2e}")
    assert worst < 1e-8, worst


def test_image_jacobian_matches_central_differences(jacobian_poses):
    rels = []
    for X in jacobian_poses[:150]:
        # Step scaled with the distance, so it is small against every feature scale.
        h = 1e-6 * min(1.0, np.linalg.norm(X[:3, 3]))
        rels.append(
            _rel(image_jacobian(camera_map(X, RHO), RHO), _jacobian_by_central_differences(X, h))
        )
    print(f"\nC vs central differences: worst relative error {max(rels):.2e}")
    assert max(rels) < 1e-8, max(rels)


def test_left_inverse_and_range(poses):
    y = camera_map(poses[::5], RHO)
    C = image_jacobian(y, RHO)
    Ti = image_jacobian_inverse(y, RHO)
    assert C.shape == (1000, 7, 6) and Ti.shape == (1000, 6, 7)
    eps = np.finfo(float).eps
    cond = 1.0 / np.linalg.svd(C, compute_uv=False)[..., -1]
    err = np.max(np.abs(Ti @ C - np.eye(6)), axis=(-2, -1))
    assert np.all(err <= np.maximum(1e-9, 100 * eps * cond * np.linalg.norm(C, 2, axis=(-2, -1))))
    kappa = cond * np.linalg.norm(C, 2, axis=(-2, -1))  # sigma_max / sigma_min
    assert np.max(err[kappa < 1e6]) < 1e-9
    # The closed form (no solve) against numpy's SVD pseudo-inverse of C.
    well = kappa < 1e6
    pinv = np.linalg.pinv(C[well])
    pinv_err = np.abs(pinv - Ti[well]) / np.linalg.norm(pinv, 2, axis=(-2, -1))[:, None, None]
    print(f"\nTc^-1 closed form vs pinv(C): worst {np.max(pinv_err):.1e} ({well.sum()} poses)")
    assert np.max(pinv_err) < 1e-9
    # Independent of the SVD: the normal-equations form of Eq. (15) agrees
    # where C^T C is well conditioned.
    # Forming C^T C squares kappa: compare where kappa^2 eps stays below 1e-8.
    ok = kappa < 1e4
    assert np.sum(ok) > 200
    CtC = np.swapaxes(C, -1, -2) @ C
    Ti_normal = np.linalg.solve(CtC[ok], np.swapaxes(C, -1, -2)[ok])
    scale = np.linalg.norm(Ti[ok], 2, axis=(-2, -1))[:, None, None]
    assert np.max(np.abs(Ti_normal - Ti[ok]) / scale) < 1e-8
    # The range of C lies in {s . s_dot = 0} ...
    sC = np.einsum("ni,nij->nj", y.s, C[:, 4:7, :])
    scale = np.linalg.norm(C, axis=(-2, -1))
    assert np.max(np.abs(sC) / scale[:, None]) < 1e-14
    # ... and has dimension 6, so it is all of that hyperplane.
    sv = np.linalg.svd(C, compute_uv=False)
    assert np.all(sv[:, -1] > 0)
    generic = slice(0, 800)  # poses[::5][:800] come from the generic sample
    assert np.all(sv[generic, -1] > 1e-11 * sv[generic, 0])
    # A vector with s . s_dot != 0 is not in the range: C Tc^-1 projects it away.
    w = np.zeros((1000, 7))
    w[:, 4:7] = y.s
    leak = np.linalg.norm(np.einsum("nij,nj->ni", C @ Ti, w), axis=-1)
    assert np.max(leak[kappa < 1e6]) < 1e-9


def test_batch_equals_single(poses):
    Xb = poses[:7]
    yb = camera_map(Xb, RHO)
    Cb = image_jacobian(yb, RHO)
    for i, X in enumerate(Xb):
        y = camera_map(RigidTransform(X), RHO)
        np.testing.assert_array_equal(y.to_vector(), yb.to_vector()[i])
        np.testing.assert_allclose(image_jacobian(y, RHO), Cb[i], rtol=0, atol=1e-15)
        np.testing.assert_allclose(
            camera_map_inverse(y, RHO).GetAsMatrix4(), camera_map_inverse(yb, RHO)[i], atol=1e-15
        )


def _evaluate(a: np.ndarray, env: dict | None = None) -> np.ndarray:
    return np.vectorize(
        lambda e: e.Evaluate(env or {}) if isinstance(e, Expression) else float(e),
        otypes=[float],
    )(a)


# Drake fills symbolic scratch matrices with NaN, which leaves the FPU's
# "invalid" flag set; numpy reports that flag after the next object-array op.
# The values are checked below.
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_scalar_generic_autodiff_and_symbolic():
    X = RigidTransform(RollPitchYaw(0.3, -0.2, 0.5), [0.05, -0.03, 0.6])
    y = camera_map(X, RHO)
    ya = camera_map(X.cast[AutoDiffXd](), RHO)
    np.testing.assert_allclose(np.vectorize(lambda e: e.value())(ya.to_vector()), y.to_vector())
    # Symbolic: a free variable in the pose, substituted afterwards.
    t = Variable("t")
    Xe = X.cast[Expression]().GetAsMatrix4()
    Xe[0, 3] = Xe[0, 3] + t
    ye = camera_map(Xe, RHO)
    env = {t: 0.0}
    np.testing.assert_allclose(_evaluate(ye.to_vector(), env), y.to_vector(), atol=1e-15)
    Ce = image_jacobian(camera_map(X.cast[Expression](), RHO), RHO)
    np.testing.assert_allclose(_evaluate(Ce), image_jacobian(y, RHO), atol=1e-14)
    Xinv = camera_map_inverse(ya, RHO)
    np.testing.assert_allclose(
        np.vectorize(lambda e: e.value())(Xinv.GetAsMatrix4()), X.GetAsMatrix4(), atol=1e-12
    )
    Ti = image_jacobian_inverse(ya, RHO)
    assert Ti.shape == (6, 7) and isinstance(Ti[0, 0], AutoDiffXd)


def test_hat_vee_exp():
    rng = np.random.default_rng(0)
    w = rng.normal(size=(50, 3))
    x = rng.normal(size=(50, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", hat(w), x), np.cross(w, x), atol=1e-14)
    np.testing.assert_allclose(vee(hat(w)), w)
    R = so3_exp(w)

    for wi, Ri in zip(w, R, strict=True):
        th = np.linalg.norm(wi)
        expected = RotationMatrix(AngleAxis(th, wi / th)).matrix()
        np.testing.assert_allclose(Ri, expected, atol=1e-13)
    np.testing.assert_allclose(so3_exp(np.zeros(3)), np.eye(3))


# ---------------------------------------------------------------- bad input
GOAL = RigidTransform([0.0, 0.0, 0.5])


def _y_goal() -> np.ndarray:
    return camera_map(GOAL, RHO).to_vector()


def test_invisible_pose_raises():
    X = RigidTransform(RollPitchYaw(np.pi, 0, 0), [0, 0, 0.5])  # marked point faces away
    with pytest.raises(ValueError, match=r"pose not visible: nu\(H\) = -0\.6 <= 0"):
        camera_map(X, RHO)
    batch = np.stack([GOAL.GetAsMatrix4(), X.GetAsMatrix4()])
    with pytest.raises(ValueError, match=r"nu\(H\) = -0\.6 <= 0 at batch index \(1,\)"):
        camera_map(batch, RHO)


@pytest.mark.parametrize("radius", [0.0, -0.1, np.nan])
def test_bad_radius_raises(radius):
    with pytest.raises(ValueError, match="radius must be finite and > 0"):
        camera_map(GOAL, radius)


def test_non_rotation_pose_raises():
    X = GOAL.GetAsMatrix4()
    X[0, 0] = 1.001
    with pytest.raises(ValueError, match=r"X_CB rotation is not a rotation"):
        camera_map(X, RHO)


@pytest.mark.parametrize(
    "index,value,message",
    [
        (9, 1.2, r"lambda outside \(0, 1\): lambda = 1\.2"),
        (9, 0.0, r"lambda outside \(0, 1\): lambda = 0"),
        (0, 0.1, r"Q is not a rotation: max\|Q\^T Q - I\|"),
        (10, 0.01, r"s is not a unit vector"),
        (5, np.nan, r"q2 has a non-finite entry: y\[5\] = nan"),
        (9, np.nan, r"lambda has a non-finite entry"),
    ],
)
def test_bad_features_raise(index, value, message):
    v = _y_goal()
    v[index] = value
    with pytest.raises(ValueError, match=message):
        image_jacobian(v, RHO)


def test_marked_point_outside_silhouette_raises():
    # q1 rotated 0.3 rad away from s, with lambda = 0.2 (cap half-angle 0.201).
    R = so3_exp(np.array([0.3, 0.0, 0.0]))
    Q = R @ camera_map(GOAL, RHO).Q
    y = ImageFeatures(Q, np.asarray(0.2), np.array([0.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match=r"y not in I: q1\.s - sqrt\(1 - lambda\^2\) = -0\.02"):
        camera_map_inverse(y, RHO)


def test_wrong_shapes_raise():
    with pytest.raises(ValueError, match=r"\(\.\.\., 13\)"):
        image_jacobian(np.zeros(12), RHO)
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, 4\)"):
        camera_map(np.eye(3), RHO)
    with pytest.raises(ValueError, match="shapes are inconsistent"):
        validate_features(ImageFeatures(np.eye(3), np.zeros(2), np.zeros(3)))


def test_autodiff_values_are_checked():
    X = RigidTransform(RollPitchYaw(np.pi, 0, 0), [0, 0, 0.5]).cast[AutoDiffXd]()
    with pytest.raises(ValueError, match="pose not visible"):
        camera_map(X, RHO)


def test_image_features_are_a_13_vector_to_numpy_and_to_a_port():
    """A user's ``np.round(config.goal_features(), 3)`` and a port's FixValue take y as
    the systems' 13-vector ``[q1, q2, q3, lambda, s]`` (it raised a TypeError)."""
    from geovs_drake.scenario import ScenarioConfig
    from geovs_drake.systems import NavigationController

    config = ScenarioConfig()
    y = config.goal_features()
    np.testing.assert_array_equal(np.round(y, 3), np.round(y.to_vector(), 3))
    assert np.asarray(y, dtype=np.float32).dtype == np.float32
    batch = camera_map(np.stack([config.X_BC_goal.inverse().GetAsMatrix4()] * 2), config.radius)
    assert np.asarray(batch).shape == (2, 13)
    nav = NavigationController(goal=y, domain=config.domain.to_domain())
    context = nav.CreateDefaultContext()
    nav.image_features_input.FixValue(context, y)
    assert nav.phi_output.Eval(context)[0] == pytest.approx(0.0, abs=1e-12)
