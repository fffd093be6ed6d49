"""The baselines' features and interaction matrices against the geometry itself:
each L against central differences (and AutoDiffXd) of its own features along
random camera twists, moved with Eq. (16)'s sign, G(e) = G exp(e (Omega, V)^)."""

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from geovs_drake.geometry import baselines as bl
from geovs_drake.geometry.camera import camera_map
from geovs_drake.geometry.so3 import so3_exp, so3_log
from geovs_drake.simulation import FeaturePointCheck

RHO = 0.1
SIDE = bl.DEFAULT_SQUARE_SIDE * RHO
P_B = bl.target_points(RHO, SIDE)
X_BC_GOAL = RigidTransform([0.0, 0.0, -0.5])
Y_GOAL = camera_map(X_BC_GOAL.inverse(), RHO).to_vector()


def _random_start(rng: np.random.Generator) -> RigidTransform:
    """X_BC: looking at the target from 0.4 to 1 m, tilted a little, any roll."""
    return RigidTransform(
        RollPitchYaw(*rng.uniform(-0.2, 0.2, 2), rng.uniform(-3.1, 3.1)),
        [*rng.uniform(-0.05, 0.05, 2), -rng.uniform(0.4, 1.0)],
    )


def _moved(X_BC: RigidTransform, twist: np.ndarray, e: float) -> RigidTransform:
    """A curve with G(0) = X_BC and G^-1 Gdot = (Omega, V) at e = 0 (Eq. 16)."""
    return X_BC @ RigidTransform(RotationMatrix(so3_exp(e * twist[:3])), e * twist[3:])


def _image(X_BC: RigidTransform) -> np.ndarray:
    return camera_map(X_BC.inverse(), RHO).to_vector()


def _features(y: np.ndarray) -> dict[str, np.ndarray]:
    s, _ = bl.ibvs_features(y, RHO, P_B)
    t, theta_u, _ = bl.pbvs_features(y, Y_GOAL, RHO)
    p, theta_u2 = bl.sphere_features(y, Y_GOAL, RHO)
    return {
        "ibvs": s,
        "pbvs": np.concatenate([t, theta_u]),
        "spherical": np.concatenate([p, theta_u2]),
    }


def _matrices(y: np.ndarray) -> dict[str, np.ndarray]:
    s, Z = bl.ibvs_features(y, RHO, P_B)
    t, theta_u, E = bl.pbvs_features(y, Y_GOAL, RHO)
    p, _ = bl.sphere_features(y, Y_GOAL, RHO)
    return {
        "ibvs": bl.point_interaction_matrix(s[0::2], s[1::2], Z),
        "pbvs": bl.pbvs_interaction(E, theta_u),
        "spherical": bl.sphere_interaction(p, theta_u, RHO),
    }


def test_ibvs_features_are_the_projections_of_the_points():
    """Independent: Drake's RigidTransform algebra puts the points in C, x = X / Z."""
    rng = np.random.default_rng(3)
    for _ in range(10):
        X_BC = _random_start(rng)
        s, Z = bl.ibvs_features(_image(X_BC), RHO, P_B)
        P_C = np.array([X_BC.inverse() @ p for p in P_B])
        np.testing.assert_allclose(s.reshape(4, 2), P_C[:, :2] / P_C[:, 2:], atol=1e-12)
        np.testing.assert_allclose(Z, P_C[:, 2], atol=1e-12)
    # The goal: b on the optical axis 0.4 m away, the square around the arrow.
    s, Z = bl.ibvs_features(Y_GOAL, RHO, P_B)
    np.testing.assert_allclose(
        s, [0, 0, 0, SIDE / 0.4, SIDE / 0.4, SIDE / 0.4, SIDE / 0.4, 0], atol=1e-15
    )
    np.testing.assert_allclose(Z, 0.4, atol=1e-15)


@pytest.mark.parametrize("law", ["ibvs", "pbvs", "spherical"])
def test_interaction_matrix_against_central_differences(law):
    """d/dt s = L (v, omega) with (v, omega) = vw_from_twist((Omega, V)), the camera
    moved along random twists; features through c(H) and c^-1, as the laws see them."""
    rng = np.random.default_rng({"ibvs": 1, "pbvs": 2, "spherical": 4}[law])
    h = 1e-6
    for _ in range(12):
        X_BC, twist = _random_start(rng), rng.normal(size=6)
        plus = _features(_image(_moved(X_BC, twist, h)))[law]
        minus = _features(_image(_moved(X_BC, twist, -h)))[law]
        L = _matrices(_image(X_BC))[law]
        np.testing.assert_allclose(
            (plus - minus) / (2 * h), L @ bl.vw_from_twist(twist), atol=1e-7 * (1 + np.abs(L).max())
        )


def test_interaction_matrices_against_autodiff():
    """The same through AutoDiffXd: the pose seeded on the 6 twist coordinates, the
    features' gradient is L's columns, reordered from (Omega, V) to (v, omega)."""
    rng = np.random.default_rng(5)
    for _ in range(4):
        X_BC = _random_start(rng)
        xi = InitializeAutoDiff(np.zeros(6)).ravel()
        R = X_BC.rotation().matrix() @ so3_exp(xi[:3])
        p = X_BC.translation() + X_BC.rotation().matrix() @ xi[3:]
        # X_CB = G^-1 as an AutoDiffXd 4x4, then y = c(X_CB).
        X_CB = np.zeros((4, 4), dtype=object)
        X_CB[:3, :3] = R.T
        X_CB[:3, 3] = -(R.T @ p)
        X_CB[3, :] = [AutoDiffXd(0.0), AutoDiffXd(0.0), AutoDiffXd(0.0), AutoDiffXd(1.0)]
        y = camera_map(X_CB, RHO).to_vector()
        y_float = ExtractValue(y).ravel()
        feats, mats = _features(y), _matrices(y_float)
        for law in ("ibvs", "pbvs", "spherical"):
            gradient = ExtractGradient(feats[law])  # d s / d (Omega, V)
            np.testing.assert_allclose(
                gradient, mats[law][:, [3, 4, 5, 0, 1, 2]], atol=1e-9, err_msg=law
            )


def test_so3_log_inverts_exp_everywhere():
    rng = np.random.default_rng(6)
    angles = [0.0, 1e-9, 1e-5, 0.3, 2.0, math.pi - 0.1, math.pi - 0.05, math.pi - 1e-9, math.pi]
    for angle in angles + list(rng.uniform(0, math.pi, 20)):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        R = so3_exp(angle * u)
        w = so3_log(R)
        np.testing.assert_allclose(so3_exp(w), R, atol=1e-12)
        assert np.linalg.norm(w) == pytest.approx(angle, abs=1e-12)
        if 1e-6 < angle < math.pi - 1e-6:
            np.testing.assert_allclose(w / angle, u, atol=1e-9)
    # A roll of exactly pi about the optical axis, as the conundrum's start has.
    w = so3_log(RotationMatrix.MakeZRotation(math.pi).matrix())
    np.testing.assert_allclose(np.abs(w), [0, 0, math.pi], atol=1e-15)


def test_closed_form_laws_are_minus_gain_times_inverse_interaction():
    """PBVS and the sphere law in closed form against -lambda L^-1 e by a linear solve;
    IBVS against numpy's pseudo-inverse, for each depth estimate, and on AutoDiffXd."""
    rng = np.random.default_rng(7)
    gain = 0.7
    for _ in range(5):
        y = _image(_random_start(rng))
        t, theta_u, E = bl.pbvs_features(y, Y_GOAL, RHO)
        expected = -gain * np.linalg.solve(bl.pbvs_interaction(E, theta_u), np.r_[t, theta_u])
        np.testing.assert_allclose(
            bl.pbvs_velocity(y, Y_GOAL, RHO, gain), bl.twist_from_vw(expected), atol=1e-12
        )
        p, theta_u = bl.sphere_features(y, Y_GOAL, RHO)
        e = np.r_[p - Y_GOAL[10:13] / Y_GOAL[9], theta_u]
        expected = -gain * np.linalg.solve(bl.sphere_interaction(p, theta_u, RHO), e)
        np.testing.assert_allclose(
            bl.spherical_velocity(y, Y_GOAL, RHO, gain), bl.twist_from_vw(expected), atol=1e-12
        )
        s, Z = bl.ibvs_features(y, RHO, P_B)
        s_goal, Z_goal = bl.ibvs_features(Y_GOAL, RHO, P_B)
        L_goal = bl.point_interaction_matrix(s_goal[0::2], s_goal[1::2], Z_goal)
        L_now = bl.point_interaction_matrix(s[0::2], s[1::2], Z)
        for depth, L in (("true", L_now), ("desired", L_goal), ("mean", (L_now + L_goal) / 2)):
            expected = bl.twist_from_vw(-gain * np.linalg.pinv(L) @ (s - s_goal))
            got = bl.ibvs_velocity(y, Y_GOAL, RHO, P_B, gain, depth)
            np.testing.assert_allclose(got, expected, atol=1e-12)
            ad = bl.ibvs_velocity(InitializeAutoDiff(y).ravel(), Y_GOAL, RHO, P_B, gain, depth)
            np.testing.assert_allclose(ExtractValue(ad).ravel(), expected, atol=1e-9)
    with pytest.raises(ValueError, match="ibvs depth must be one of"):
        bl.ibvs_velocity(y, Y_GOAL, RHO, P_B, gain, "median")


def test_feature_point_check_names_the_point_that_left_the_cone():
    """At the goal the corner b + side (a + n) is atan(sqrt(2) side / 0.4) off the axis;
    a field of view just narrower than that loses it, naming it and the angle."""
    corner = math.degrees(math.atan(math.sqrt(2) * SIDE / 0.4))
    state = np.r_[1.0, 0, 0, 0, X_BC_GOAL.translation()]  # the kinematic body: X_WC, X_WB = I
    names = bl.TARGET_POINT_NAMES
    wide = FeaturePointCheck(
        P_B, RigidTransform(), RigidTransform(), math.radians(corner + 0.1), names
    )
    assert wide.lost(state) is None
    narrow = FeaturePointCheck(
        P_B, RigidTransform(), RigidTransform(), math.radians(corner - 0.1), names
    )
    message = narrow.lost(state)
    assert "b + side (a + n)" in message and "outside the field of view" in message
    assert f"{corner:.4g} deg" in message
    # Turned around (the camera looking away): every point is behind it.
    behind = np.r_[0.0, 1.0, 0, 0, X_BC_GOAL.translation()]  # 180 deg about x
    assert "behind the camera" in wide.lost(behind)
