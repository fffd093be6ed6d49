"""The pinhole camera and the features measured from it, against the geometry itself.

Truths used: the intrinsic matrix (numpy's solve, not the formulas), brute force
over the image's border for the inscribed cone, sampled 3-D points on the
sphere's limb projected through the pinhole, central differences for the
AutoDiffXd derivative of pixel -> ray, and the exact camera map c(H).
"""

import math

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff

from geovs_drake import SafeDomain, camera_map, camera_map_inverse
from geovs_drake.analysis.studies.nf_study import random_features_in_domain
from geovs_drake.geometry.features import (
    FEATURE_FAILURES,
    TargetMarks,
    limb_points,
    pinhole_measurement,
    silhouette_cone,
)
from geovs_drake.geometry.pinhole import PinholeIntrinsics

RHO = 0.1
#: An off-centre, non-square camera: the tight side is not the obvious one.
CAMERA = PinholeIntrinsics(640, 480, fx=420.0, fy=380.0, cx=300.2, cy=250.7)


def test_pixel_ray_round_trips_and_matches_the_intrinsic_matrix():
    rng = np.random.default_rng(1)
    uv = rng.uniform([-0.5, -0.5], [639.5, 479.5], size=(500, 2))
    rays = CAMERA.pixel_to_ray(uv)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0, atol=1e-15)
    homogeneous = np.linalg.solve(CAMERA.matrix, np.column_stack([uv, np.ones(len(uv))]).T).T
    expected = homogeneous / np.linalg.norm(homogeneous, axis=-1, keepdims=True)
    np.testing.assert_allclose(rays, expected, atol=1e-14)
    np.testing.assert_allclose(CAMERA.ray_to_pixel(rays), uv, atol=1e-9)
    # And rays in front of the camera, not unit: the pixel's ray is their direction.
    r = rng.normal(size=(500, 3))
    r[:, 2] = np.abs(r[:, 2]) + 0.05
    back = CAMERA.pixel_to_ray(CAMERA.ray_to_pixel(r))
    np.testing.assert_allclose(back, r / np.linalg.norm(r, axis=-1, keepdims=True), atol=1e-12)


def test_pixel_to_ray_autodiff_matches_central_differences():
    uv = np.array([123.4, 321.9])
    rays = CAMERA.pixel_to_ray(InitializeAutoDiff(uv).ravel())
    J = ExtractGradient(rays)
    np.testing.assert_allclose(ExtractValue(rays).ravel(), CAMERA.pixel_to_ray(uv), atol=1e-15)
    h = 1e-4
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        fd = (CAMERA.pixel_to_ray(uv + e) - CAMERA.pixel_to_ray(uv - e)) / (2 * h)
        np.testing.assert_allclose(J[:, k], fd, atol=1e-10)


def test_inscribed_cone_is_the_nearest_point_of_the_image_border():
    # Brute force: the smallest angle between the optical axis and the ray of a
    # point on the image's border.
    for camera in (CAMERA, PinholeIntrinsics.for_fov(320, 240, math.radians(35.0))):
        w, h = camera.width, camera.height
        t = np.linspace(0.0, 1.0, 200001)
        border = np.concatenate(
            [
                np.column_stack([-0.5 + w * t, np.full_like(t, -0.5)]),
                np.column_stack([-0.5 + w * t, np.full_like(t, h - 0.5)]),
                np.column_stack([np.full_like(t, -0.5), -0.5 + h * t]),
                np.column_stack([np.full_like(t, w - 0.5), -0.5 + h * t]),
            ]
        )
        angles = np.arccos(camera.pixel_to_ray(border)[:, 2])
        assert camera.inscribed_half_angle() == pytest.approx(angles.min(), abs=1e-9)
    # for_fov builds the camera whose inscribed cone is the asked angle, border kept.
    camera = PinholeIntrinsics.for_fov(320, 240, math.radians(35.0), border_px=2.0)
    assert camera.inscribed_half_angle(border_px=2.0) == pytest.approx(math.radians(35.0), 1e-14)


def test_limb_points_touch_the_sphere_along_rays_from_the_camera():
    d = np.array([0.05, -0.1, 0.6])
    p = limb_points(d, RHO, 64)
    np.testing.assert_allclose(np.linalg.norm(p - d, axis=-1), RHO, atol=1e-15)
    np.testing.assert_allclose(np.sum((p - d) * p, axis=-1), 0.0, atol=1e-15)  # tangent rays


def _poses_in(domain: SafeDomain, n: int, seed: int) -> np.ndarray:
    y = random_features_in_domain(np.random.default_rng(seed), n, domain, shrink=1.0)
    return camera_map_inverse(y, RHO)


def _on_fov_face(domain: SafeDomain, lam: float, direction: np.ndarray) -> np.ndarray:
    """X_CB of a pose on D's FOV face: the silhouette touches the cone of half-angle theta
    on the side of ``direction`` (a unit vector in the image plane)."""
    alpha = domain.fov_half_angle - math.asin(lam)
    s = np.array([math.sin(alpha) * direction[0], math.sin(alpha) * direction[1], math.cos(alpha)])
    q2 = np.cross(s, [1.0, 0.0, 0.0])
    q2 /= np.linalg.norm(q2)
    y = np.concatenate([s, q2, np.cross(s, q2), [lam], s])
    return camera_map_inverse(y, RHO).GetAsMatrix4()


def _limb_pixels(camera: PinholeIntrinsics, X_CB: np.ndarray) -> np.ndarray:
    return camera.ray_to_pixel(limb_points(X_CB[:3, 3], RHO, 720))


def test_every_pose_of_the_domain_from_intrinsics_keeps_the_sphere_in_the_image():
    border = 1.5
    domain = SafeDomain.from_intrinsics(CAMERA, border_px=border)
    for X in _poses_in(domain, 300, seed=7):
        assert np.all(CAMERA.contains(_limb_pixels(CAMERA, X), border_px=border))
    # On the FOV face the silhouette touches the inscribed circle: for this camera
    # at the image's bottom edge ((H - 0.5 - cy) / fy is the nearest edge in
    # normalised units), and nowhere crosses it.
    down = np.array([0.0, 1.0])
    X = _on_fov_face(domain, 0.3, down)
    v = _limb_pixels(CAMERA, X)[:, 1]
    assert v.max() == pytest.approx(CAMERA.height - 0.5 - border, abs=1e-6)
    assert np.all(CAMERA.contains(_limb_pixels(CAMERA, X), border_px=border - 1e-6))
    # The check can fail: a domain 3% wider than the inscribed cone lets the sphere out.
    wider = SafeDomain(1.03 * domain.fov_half_angle, 0.05, 0.4, 0.1)
    X = _on_fov_face(wider, 0.3, down)
    assert not np.all(CAMERA.contains(_limb_pixels(CAMERA, X), border_px=border))


def test_bad_intrinsics_are_one_line_errors():
    cases = [
        (dict(width=0), "width must be an integer >= 1"),
        (dict(width=64.0), "width must be an integer >= 1"),
        (dict(fx=-1.0), "fx must be > 0"),
        (dict(fy=math.nan), "fy must be finite"),
        (dict(cx=700.0), "principal point must lie inside the image"),
        (dict(cy=-0.5), "principal point must lie inside the image"),
    ]
    base = dict(width=640, height=480, fx=400.0, fy=400.0, cx=319.5, cy=239.5)
    for change, message in cases:
        with pytest.raises(ValueError, match=message):
            PinholeIntrinsics(**{**base, **change})
    with pytest.raises(ValueError, match="not in front of the camera"):
        CAMERA.ray_to_pixel(np.array([0.0, 0.1, -1.0]))
    narrow = PinholeIntrinsics(100, 100, 400.0, 400.0, 49.5, 49.5)  # 7 deg
    with pytest.raises(ValueError, match="inscribed cone, 7.1"):
        SafeDomain.from_intrinsics(narrow, lam_max=0.4)


def test_features_from_exact_pinhole_points_are_the_camera_map():
    domain = SafeDomain.from_intrinsics(CAMERA, border_px=1.0)
    marks = TargetMarks()
    poses = _poses_in(domain, 200, seed=3)
    for X in poses:
        y, code = pinhole_measurement(X, RHO, marks, CAMERA, CAMERA)
        assert code == 0, FEATURE_FAILURES[code]
        np.testing.assert_allclose(y, camera_map(X, RHO).to_vector(), atol=1e-9)
    # The silhouette fit alone, on rays to the limb.
    X = poses[0]
    s, lam = silhouette_cone(CAMERA.pixel_to_ray(_limb_pixels(CAMERA, X)))
    exact = camera_map(X, RHO)
    np.testing.assert_allclose(s, exact.s, atol=1e-12)
    assert lam == pytest.approx(float(exact.lam), abs=1e-12)


def test_a_measurement_that_cannot_give_y_says_why():
    marks = TargetMarks()
    # The marked point facing away: seen from the other side of the sphere.
    X = np.eye(4)
    X[:3, 3] = [0.0, 0.0, 0.5]
    X[:3, :3] = np.diag([1.0, -1.0, -1.0])  # r3 = -e3: b_C = d + rho e3, behind the sphere
    y, code = pinhole_measurement(X, RHO, marks, CAMERA, CAMERA)
    assert y is None and "marked point not found" in FEATURE_FAILURES[code]
    # The sphere cut by the border: far off the optical axis.
    X = np.eye(4)
    X[:3, 3] = [0.3, 0.0, 0.5]
    y, code = pinhole_measurement(X, RHO, marks, CAMERA, CAMERA)
    assert y is None and FEATURE_FAILURES[code] == "sphere cut by the image border"
