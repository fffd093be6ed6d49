"""The safe domain and the navigation function: Definition 1, shown numerically."""

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.symbolic import Expression, Variable

from geovs_drake import ImageFeatures, camera_map, so3_exp
from geovs_drake.analysis.studies.nf_study import (
    chart_basis,
    chart_hessian,
    critical_point_search,
    gradient_descent,
    random_features_in_domain,
)
from geovs_drake.geometry.domain import DEFAULT_DOMAIN, SafeDomain
from geovs_drake.geometry.navigation import (
    NavigationFunction,
    NavigationGains,
    features_from_model,
    model_coordinates,
    navigation_differential,
    navigation_value,
)
from geovs_drake.sampling import random_unit_vectors

RHO = 0.1
GOAL_POSE = RigidTransform([0.0, 0.0, 0.5])


@pytest.fixture(scope="module")
def goal() -> ImageFeatures:
    return camera_map(GOAL_POSE, RHO)


@pytest.fixture(scope="module")
def nf(goal) -> NavigationFunction:
    return NavigationFunction(DEFAULT_DOMAIN, goal)


@pytest.fixture(scope="module")
def samples(nf) -> ImageFeatures:
    return random_features_in_domain(np.random.default_rng(42), 2000, nf, shrink=0.999)


def _single(y: ImageFeatures) -> ImageFeatures:
    return ImageFeatures(y.Q[None], np.asarray(y.lam)[None], y.s[None])


# ------------------------------------------------------------------ domain
def test_default_goal_is_the_contract(goal):
    np.testing.assert_allclose(goal.q1, [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(goal.q2, [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(goal.s, [0, 0, 1], atol=1e-15)
    assert goal.lam == pytest.approx(0.2)
    assert DEFAULT_DOMAIN.contains(goal)


def test_fov_margin_matches_sampled_silhouette():
    """The FOV face is where the silhouette's extreme direction touches the cone."""
    rng = np.random.default_rng(1)
    th = DEFAULT_DOMAIN.fov_half_angle
    for _ in range(30):
        lam = rng.uniform(0.05, 0.4)
        alpha = rng.uniform(0, 0.6)
        s = np.array([np.sin(alpha), 0.0, np.cos(alpha)])
        # The silhouette: directions at angle arcsin(lambda) from s.
        gamma = np.arcsin(lam)
        t = np.linspace(0, 2 * np.pi, 20001)
        u = np.cos(gamma) * s[None] + np.sin(gamma) * (
            np.cos(t)[:, None] * np.array([np.cos(alpha), 0, -np.sin(alpha)])
            + np.sin(t)[:, None] * np.array([0, 1.0, 0])
        )
        worst_angle = np.max(np.arccos(np.clip(u[:, 2], -1, 1)))
        # The marked point at the silhouette's centre (q1 = s), so y lies in I.
        q2 = np.array([0.0, 1.0, 0.0])
        y = ImageFeatures(np.stack([s, q2, np.cross(s, q2)], axis=-1), np.asarray(lam), s)
        margin = DEFAULT_DOMAIN.margins(y).fov
        assert (margin >= 0) == (worst_angle <= th) or abs(worst_angle - th) < 1e-6
        # The errata's f(y) = sqrt(1 - lam^2)(s.e3) - lam sqrt(1 - (s.e3)^2).
        f = np.sqrt(1 - lam**2) * s[2] - lam * np.sqrt(1 - s[2] ** 2)
        assert f == pytest.approx(np.cos(worst_angle), abs=1e-8)
        assert np.sign(f - np.cos(th)) == np.sign(margin)


def test_occlusion_margin_definition():
    lam = 0.05
    c_lam = np.sqrt(1 - lam**2)
    for frac in (0.05, 0.2, 0.6):
        # q1 at cosine c_lam + frac (1 - c_lam) from s: margin (frac - kappa)(1 - c_lam).
        c = c_lam + frac * (1 - c_lam)
        q1 = np.array([np.sqrt(1 - c**2), 0.0, c])
        q2 = np.array([0.0, 1.0, 0.0])
        Q = np.stack([q1, q2, np.cross(q1, q2)], axis=-1)
        m = DEFAULT_DOMAIN.margins(ImageFeatures(Q, np.asarray(lam), np.array([0, 0, 1.0])))
        assert m.occlusion == pytest.approx((frac - 0.1) * (1 - c_lam), rel=1e-9)


@pytest.mark.parametrize(
    "kwargs,message",
    [
        (dict(lam_min=0.0), r"need 0 < lam_min < lam_max < 1, got lam_min = 0.0"),
        (dict(lam_min=0.5, lam_max=0.4), r"need 0 < lam_min < lam_max < 1"),
        (dict(lam_max=1.0), r"need 0 < lam_min < lam_max < 1"),
        (
            dict(fov_half_angle=0.3),
            r"need arcsin\(lam_max\) < fov_half_angle < pi/2, got arcsin\(0.4\) = 0.411517 rad "
            r"\(23.58 deg\) and fov_half_angle = 0.3 rad \(17.19 deg\)",
        ),
        (dict(fov_half_angle=1.6), r"need arcsin\(lam_max\) < fov_half_angle < pi/2"),
        (dict(occlusion_margin=0.0), r"need 0 < occlusion_margin < 1, got 0.0"),
        (dict(occlusion_margin=1.0), r"need 0 < occlusion_margin < 1"),
        (dict(lam_min=math.nan), r"lam_min = nan is not finite"),
    ],
)
def test_infeasible_domain_raises(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SafeDomain(**kwargs)


@pytest.mark.parametrize(
    "kwargs,message",
    [
        (dict(k_lam=0.0), "k_lam must be finite and > 0"),
        (dict(k_occ=math.inf), "k_occ must be finite and > 0"),
        (dict(circle_weight=1.0), r"circle_weight must be in \(0, 1\)"),
    ],
)
def test_bad_gains_raise(kwargs, message):
    with pytest.raises(ValueError, match=message):
        NavigationGains(**kwargs)


def test_goal_outside_domain_raises(goal):
    far = camera_map(RigidTransform([0, 0, 3.0]), RHO)  # lambda = 0.033 < lam_min
    with pytest.raises(ValueError, match=r"goal not in the interior of D: lam_min margin = -0.01"):
        NavigationFunction(DEFAULT_DOMAIN, far)


# ------------------------------------------------------------- model chart
def test_samples_lie_in_domain_and_model_chart_round_trips(nf, samples):
    assert np.all(nf.domain.contains(samples))
    m = model_coordinates(samples, nf.domain)
    y2 = features_from_model(m, nf.domain)
    np.testing.assert_allclose(y2.to_vector(), samples.to_vector(), atol=1e-12)
    assert np.all(np.abs(m.u) <= 1)
    assert np.all(np.sum(m.w_fov**2, -1) <= 1) and np.all(np.sum(m.w_occ**2, -1) <= 1)
    np.testing.assert_allclose(np.sum(m.circle**2, -1), 1, atol=1e-12)


# ----------------------------------------------------------- Definition 1
def test_minimum_is_zero_at_goal_only(nf, goal, samples):
    assert nf.value(goal) == 0.0
    phi = nf.value(samples)
    dist = np.max(np.abs(samples.to_vector() - goal.to_vector()), axis=-1)
    assert np.all(phi[dist > 1e-9] > 0)
    assert np.all((phi >= 0) & (phi < 1))


def _face_samples(nf: NavigationFunction, face: str, delta: float, n: int) -> ImageFeatures:
    """Images whose margin on ``face`` is exactly ``delta``, all else inside."""
    rng = np.random.default_rng(hash(face) % 2**32)
    d = nf.domain
    y = random_features_in_domain(rng, n, d, shrink=0.9)
    m = model_coordinates(y, d)
    lam = np.asarray(y.lam)
    if face in ("lam_min", "lam_max"):
        lam = d.lam_min + delta if face == "lam_min" else d.lam_max - delta
        lam = np.full(n, lam)
        u = (2 * lam - d.lam_min - d.lam_max) / (d.lam_max - d.lam_min)
        m = m._replace(u=u)
    elif face == "fov":
        cos_fov, sin_fov = d.fov_cap(lam)
        r = np.sqrt(1 - (cos_fov + delta) ** 2) / sin_fov
        direction = random_unit_vectors(rng, n)[:, :2]
        direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
        m = m._replace(w_fov=r[:, None] * direction)
    elif face == "occlusion":
        cos_occ, sin2_occ = d.occlusion_cap(lam)
        r = np.sqrt(1 - (cos_occ + delta) ** 2) / np.sqrt(sin2_occ)
        direction = random_unit_vectors(rng, n)[:, :2]
        direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
        m = m._replace(w_occ=r[:, None] * direction)
    return features_from_model(m, d)


def _boundary_tolerance(nf: NavigationFunction, face: str, delta: float) -> float:
    """Bound on 1 - phi at margin delta on ``face``, from the construction.

    1 - phi = prod_j (1 - phi_j) <= 1 - phi_i = k beta / (g + k beta) <= k beta / g.
    beta on each face, at margin delta (cosines of angles in [0, pi/2)):
      lambda: beta = 1 - u^2 <= 2 (1 - |u|) = 4 delta / (lam_max - lam_min);
      FOV: beta = (s3^2 - cos^2 rho) / sin^2 rho <= 2 delta / sin^2 rho, rho smallest at lam_max;
      occlusion: the same with the occlusion cap, smallest at lam_min.
    g >= (1 - |w*| - (1 - |w|))^2 >= (1 - |w*| - beta)^2.
    """
    d, gains = nf.domain, nf.gains
    m_goal = model_coordinates(nf.goal, d)
    if face in ("lam_min", "lam_max"):
        beta, k, wg = 4 * delta / (d.lam_max - d.lam_min), gains.k_lam, abs(float(m_goal.u))
    elif face == "fov":
        beta = 2 * delta / float(d.fov_cap(d.lam_max)[1]) ** 2
        k, wg = gains.k_fov, float(np.linalg.norm(m_goal.w_fov))
    else:
        beta = 2 * delta / float(d.occlusion_cap(d.lam_min)[1])
        k, wg = gains.k_occ, float(np.linalg.norm(m_goal.w_occ))
    return k * beta / (1 - wg - beta) ** 2


@pytest.mark.parametrize("face", ["lam_min", "lam_max", "fov", "occlusion"])
def test_phi_tends_to_one_uniformly_at_each_face(nf, face):
    delta = 1e-6
    y = _face_samples(nf, face, delta, 500)
    margins = nf.domain.margins(y)
    np.testing.assert_allclose(getattr(margins, face), delta, rtol=1e-6, atol=1e-15)
    assert np.all(margins.minimum() > 0)
    tol = _boundary_tolerance(nf, face, delta)
    assert tol < 1e-2  # the bound is informative, not vacuous
    phi = nf.value(y)
    print(
        f"\n{face}: tol {tol:.2e}, min phi {phi.min():.8f}, uses {(1 - phi).max() / tol:.0%} of tol"
    )
    assert np.all(phi >= 1 - tol), (np.min(phi), tol)
    assert np.all(phi < 1)
    # The same at 1e-9: 1 - phi shrinks in proportion to the margin.
    y9 = _face_samples(nf, face, 1e-9, 200)
    assert np.all(nf.clearance(y9) <= _boundary_tolerance(nf, face, 1e-9))


def _random_curve(rng: np.random.Generator, y: ImageFeatures) -> np.ndarray:
    """A random tangent (xi, lambda_dot, s_dot) at y with s_dot orthogonal to s."""
    t = rng.normal(size=7)
    t[4:7] -= (t[4:7] @ y.s) * y.s
    return t


def _along(y: ImageFeatures, t: np.ndarray, h: object) -> ImageFeatures:
    """y moved by h along t: Q <- exp(h hat(xi)) Q, lambda <- lambda + h lambda_dot,
    s <- normalize(s + h s_dot)."""
    Q = so3_exp(h * t[0:3]) @ y.Q
    s = y.s + h * t[4:7]
    s = s / np.sqrt(np.sum(s * s))
    return ImageFeatures(Q, np.asarray(y.lam + h * t[3]), s)


def test_differential_matches_central_differences(nf, samples):
    rng = np.random.default_rng(9)
    worst = 0.0
    for i in range(0, 2000, 20):
        y = samples[i]
        t = _random_curve(rng, y)

        # Central differences with one Richardson step (error O(h^4)): samples
        # reach within 1e-3 of the boundary, where phi bends hard.
        def central(h, y=y, t=t):
            return (nf.value(_along(y, t, h)) - nf.value(_along(y, t, -h))) / (2 * h)

        fd = (4 * central(5e-6) - central(1e-5)) / 3
        dphi = nf.differential(y)
        assert abs(dphi[4:7] @ y.s) < 1e-13
        worst = max(worst, abs(fd - dphi @ t) / max(1.0, np.linalg.norm(dphi)))
    print(f"\ndphi vs central differences: worst {worst:.2e}")
    assert worst < 1e-7, worst


def test_differential_matches_autodiff(nf, samples):
    for i in range(0, 2000, 50):
        y = samples[i]
        # Chart: delta in R^6 -> (exp(hat(d0:3)) Q, lambda + d3, normalize(s + B d4:6)).
        B = chart_basis(y.s)
        d = InitializeAutoDiff(np.zeros(6)).ravel()
        s = y.s + B @ d[4:6]
        s = s / np.sqrt(np.sum(s * s))
        ya = ImageFeatures(so3_exp(d[0:3]) @ y.Q, np.asarray(y.lam + d[3]), s)
        phi_a = np.asarray(nf.value(ya)).item()
        grad_ad = phi_a.derivatives()
        dphi = nf.differential(y)
        expected = np.concatenate([dphi[0:4], B.T @ dphi[4:7]])
        np.testing.assert_allclose(grad_ad, expected, rtol=1e-10, atol=1e-12)


# Drake fills symbolic scratch matrices with NaN, which leaves the FPU's
# "invalid" flag set; numpy reports that flag after the next object-array op.
# The values are checked below.
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_differential_runs_on_autodiff_and_symbolic(nf, goal):
    y = camera_map(RigidTransform(RollPitchYaw(0.1, -0.05, 0.2), [0.03, -0.02, 0.45]), RHO)
    phi, dphi = nf.value_and_differential(y)
    ya = camera_map(
        RigidTransform(RollPitchYaw(0.1, -0.05, 0.2), [0.03, -0.02, 0.45]).cast[AutoDiffXd](), RHO
    )
    phi_a, dphi_a = navigation_differential(ya, goal, nf.domain, nf.gains)
    assert isinstance(np.asarray(phi_a).item(), AutoDiffXd)
    np.testing.assert_allclose([e.value() for e in dphi_a], dphi, rtol=1e-13)
    x = Variable("x")
    v = y.to_vector().astype(object)
    v[9] = Expression(x)
    phi_e, dphi_e = navigation_differential(v, goal, nf.domain, nf.gains)
    env = {x: float(y.lam)}
    assert np.asarray(phi_e).item().Evaluate(env) == pytest.approx(float(phi), rel=1e-13)
    np.testing.assert_allclose([e.Evaluate(env) for e in dphi_e], dphi, rtol=1e-12, atol=1e-14)


def test_hessian_at_goal_is_positive_definite(nf, goal):
    """Morse minimum: the chart Hessian by AutoDiffXd and by central differences."""
    B = chart_basis(goal.s)
    d = InitializeAutoDiff(np.zeros(6)).ravel()
    s = goal.s + B @ d[4:6]
    s = s / np.sqrt(np.sum(s * s))
    ya = ImageFeatures(so3_exp(d[0:3]) @ goal.Q, np.asarray(goal.lam + d[3]), s)
    _, dphi = navigation_differential(ya, goal, nf.domain, nf.gains)
    F = np.concatenate([dphi[0:4], B.T @ dphi[4:7]])
    H_ad = np.stack([f.derivatives() for f in F])
    H_fd = chart_hessian(nf, _single(goal))[0]
    np.testing.assert_allclose(H_ad, H_ad.T, atol=1e-10)
    np.testing.assert_allclose(H_ad, H_fd, atol=1e-6 * np.max(np.abs(H_ad)))
    ev = np.linalg.eigvalsh(0.5 * (H_ad + H_ad.T))
    assert np.all(ev > 0.1), ev
    # The construction predicts the roll eigenvalue c_w / 2 and the lambda one
    # 2 / (k_lam beta*) (du/dlambda)^2.
    assert ev[0] == pytest.approx(nf.gains.circle_weight / 2, rel=1e-6)
    u = float(model_coordinates(goal, nf.domain).u)
    dudl = 2 / (nf.domain.lam_max - nf.domain.lam_min)
    assert np.any(np.isclose(ev, 2 / (nf.gains.k_lam * (1 - u**2)) * dudl**2, rtol=1e-6))


def test_gradient_descent_from_random_starts_reaches_goal(nf, goal):
    starts = random_features_in_domain(np.random.default_rng(2026), 1000, nf, shrink=0.99)
    result = gradient_descent(nf, starts)
    err = np.max(np.abs(result.y.to_vector() - goal.to_vector()), axis=-1)
    not_converged = int(np.sum(err > 1e-6))
    print(
        f"\ngradient descent: 1000 starts, {not_converged} not at y* "
        f"(max error {err.max():.2e}, {result.iterations} iterations)"
    )
    assert not_converged == 0
    assert result.phi_monotone
    assert np.all(nf.domain.contains(result.y))


def test_critical_point_search_finds_minimum_and_one_saddle(nf, goal):
    starts = random_features_in_domain(np.random.default_rng(7), 300, nf, shrink=0.95)
    found = critical_point_search(nf, starts)
    summary = [(round(p.phi, 6), p.signature) for p in found.points]
    print(
        f"\ncritical points from {found.starts} starts ({found.converged} converged, "
        f"{found.stalled} stalled, {found.left_domain} left D): {summary}"
    )
    assert found.converged > 0.5 * found.starts
    assert summary == [(0.0, (6, 0, 0)), (round(nf.gains.circle_weight, 6), (5, 1, 0))]
    np.testing.assert_allclose(found.points[0].y.to_vector(), goal.to_vector(), atol=1e-8)
    np.testing.assert_allclose(found.points[1].y.to_vector(), nf.saddle().to_vector(), atol=1e-8)
    # The saddle is y* with the arrow reversed: q1, lambda, s as at y*, q2 -> -q2.
    saddle = nf.saddle()
    np.testing.assert_allclose(saddle.q1, goal.q1, atol=1e-12)
    np.testing.assert_allclose(saddle.q2, -goal.q2, atol=1e-12)


def test_goal_changes_without_rebuild(goal):
    nf = NavigationFunction(DEFAULT_DOMAIN, goal)
    other = camera_map(RigidTransform(RollPitchYaw(0, 0, 0.7), [0.05, 0.0, 0.6]), RHO)
    assert nf.value(other) > 0
    nf.goal = other
    assert nf.value(other) == 0.0
    assert nf.value(goal) > 0
    np.testing.assert_allclose(nf.differential(other), 0, atol=1e-14)


def test_pure_functions_match_class(nf, samples):
    y = samples[:50]
    np.testing.assert_array_equal(navigation_value(y, nf.goal, nf.domain, nf.gains), nf.value(y))


def test_phi_outside_domain_raises_naming_the_face(nf, goal):
    """Outside D the formula is no navigation function: the functions refuse it."""
    far = camera_map(RigidTransform([0.0, 0.0, 2.5]), RHO)  # lambda = 0.04 < lam_min
    with pytest.raises(ValueError, match=r"y outside D: lam_min margin = -0.01\d* < 0"):
        nf.value(far)
    with pytest.raises(ValueError, match="y outside D: lam_min margin"):
        navigation_differential(far, goal, nf.domain, nf.gains)
    batch = ImageFeatures.from_vector(np.stack([goal.to_vector(), far.to_vector()]))
    with pytest.raises(ValueError, match=r"y outside D: lam_min margin = .* at batch index \(1,\)"):
        nf.clearance(batch)
    # Out of the field of view: the sphere's edge beyond the 35 deg cone.
    wide = camera_map(RigidTransform([0.35, 0.0, 0.5]), RHO)
    assert DEFAULT_DOMAIN.margins(wide).fov < 0
    with pytest.raises(ValueError, match="y outside D: fov margin"):
        nf.value(wide)
