"""Property-based tests (hypothesis): the maps' identities on generated inputs.

Each property is an identity the geometry guarantees, checked on inputs
hypothesis draws (and shrinks on failure): the camera map against Drake's
RigidTransform algebra and its own inverse, the Jacobian against its closed-form
inverse, the navigation function's range and the tangency of its differential,
and the input checks' messages.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from geovs_drake import (
    DEFAULT_DOMAIN,
    ImageFeatures,
    NavigationFunction,
    camera_map,
    camera_map_inverse,
    image_jacobian,
    image_jacobian_inverse,
)
from geovs_drake.geometry.navigation import ModelCoordinates, features_from_model

RHO = 0.1
angles = st.floats(-math.pi, math.pi)
unit = st.floats(-0.97, 0.97)
SETTINGS = settings(max_examples=150, deadline=None)


@st.composite
def visible_poses(draw) -> RigidTransform:
    """X_CB with the target 1.5 to 50 radii away and the marked point facing the
    camera with some room (nu / rho > 0.05), where c^-1 is well conditioned."""
    distance = RHO * math.exp(draw(st.floats(math.log(1.5), math.log(50.0))))
    direction = np.array([draw(st.floats(-0.5, 0.5)), draw(st.floats(-0.5, 0.5)), 1.0])
    d = distance * direction / np.linalg.norm(direction)
    R = RollPitchYaw(draw(angles), draw(angles), draw(angles)).ToRotationMatrix()
    X = RigidTransform(R, d)
    r3 = R.matrix()[:, 2]
    nu = (d - RHO * r3) @ r3
    if not nu > 0.05 * RHO:
        # Turn the sphere so its marked point faces the camera: r3 along d, any roll.
        R = RotationMatrix.MakeFromOneVector(d, 2) @ RotationMatrix.MakeZRotation(draw(angles))
        X = RigidTransform(R, d)
    return X


@st.composite
def images_in_domain(draw) -> ImageFeatures:
    circle = draw(angles)
    m = ModelCoordinates(
        np.array([draw(unit)]),
        np.array([[draw(unit), draw(unit)]]) / math.sqrt(2),
        np.array([[draw(unit), draw(unit)]]) / math.sqrt(2),
        np.array([[math.cos(circle), math.sin(circle)]]),
    )
    return features_from_model(m, DEFAULT_DOMAIN)[0]


@SETTINGS
@given(visible_poses())
def test_camera_map_round_trip_and_geometry(X_CB):
    y = camera_map(X_CB, RHO)
    # The image: s points at the centre, lambda = rho / |d|, q1 at the marked point.
    d = X_CB.translation()
    np.testing.assert_allclose(y.s, d / np.linalg.norm(d), atol=1e-14)
    assert float(y.lam) == pytest.approx(RHO / np.linalg.norm(d), rel=1e-14)
    b = X_CB @ np.array([0.0, 0.0, -RHO])
    np.testing.assert_allclose(y.q1, b / np.linalg.norm(b), atol=1e-13)
    np.testing.assert_allclose(y.Q.T @ y.Q, np.eye(3), atol=1e-13)
    # c^-1 (Eq. 23) recovers the pose.
    X = camera_map_inverse(y, RHO)
    np.testing.assert_allclose(
        X.GetAsMatrix4(), X_CB.GetAsMatrix4(), atol=1e-9 * max(1, np.linalg.norm(d))
    )


@SETTINGS
@given(visible_poses())
def test_jacobian_closed_form_inverse_is_a_left_inverse(X_CB):
    y = camera_map(X_CB, RHO)
    C = image_jacobian(y, RHO)
    cond = np.linalg.cond(C)
    err = np.max(np.abs(image_jacobian_inverse(y, RHO) @ C - np.eye(6)))
    assert err < max(1e-10, 1e-14 * cond), (err, cond)


@SETTINGS
@given(images_in_domain())
def test_phi_in_unit_interval_and_dphi_tangent(y):
    nf = NavigationFunction(DEFAULT_DOMAIN, camera_map(RigidTransform([0.0, 0.0, 0.5]), RHO))
    phi, dphi = nf.value_and_differential(y)
    assert 0.0 <= float(phi) < 1.0
    assert float(nf.clearance(y)) == pytest.approx(1 - float(phi), abs=1e-15)
    assert abs(dphi[4:7] @ y.s) < 1e-12 * max(1.0, np.linalg.norm(dphi))
    assert DEFAULT_DOMAIN.contains(y)


@SETTINGS
@given(st.one_of(st.floats(-10, 0), st.floats(1, 10), st.just(math.nan)))
def test_lambda_outside_open_interval_is_named(lam):
    v = camera_map(RigidTransform([0.0, 0.0, 0.5]), RHO).to_vector()
    v[9] = lam
    message = "lambda has a non-finite entry" if math.isnan(lam) else r"lambda outside \(0, 1\)"
    with pytest.raises(ValueError, match=message):
        image_jacobian(v, RHO)


@SETTINGS
@given(st.sampled_from(["u", "w_fov", "w_occ"]), angles, images_in_domain())
def test_phi_is_one_on_each_face_of_D(face, angle, y):
    """On the boundary of D (one model coordinate on its unit sphere) phi = 1."""
    nf = NavigationFunction(DEFAULT_DOMAIN, camera_map(RigidTransform([0.0, 0.0, 0.5]), RHO))
    m = nf_model(y)
    if face == "u":
        m = m._replace(u=np.array([math.copysign(1.0, angle)]))
    else:
        m = m._replace(**{face: np.array([[math.cos(angle), math.sin(angle)]])})
    on_face = features_from_model(m, DEFAULT_DOMAIN)
    # On the face to rounding (a margin of +-1e-17): evaluate the formula there as it is.
    assert nf.value(on_face, extend=True).item() == pytest.approx(1.0, abs=1e-9)
    assert np.min(DEFAULT_DOMAIN.margins(on_face)) == pytest.approx(0.0, abs=1e-12)


def nf_model(y: ImageFeatures) -> ModelCoordinates:
    from geovs_drake.geometry.navigation import model_coordinates

    m = model_coordinates(ImageFeatures.from_vector(y.to_vector()[None]), DEFAULT_DOMAIN)
    return ModelCoordinates(*(np.asarray(v, dtype=float) for v in m))


yaml_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-5, 5),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
)
yaml_values = st.recursive(
    yaml_scalars,
    lambda children: st.one_of(
        st.lists(children, max_size=6), st.dictionaries(st.text(max_size=8), children, max_size=4)
    ),
    max_leaves=12,
)
FIELDS = ["radius", "goal", "initial", "domain", "rig", "control", "duration", "log_rate",
          "simulator", "plant", "controller", "initial_velocity", "navigation",
          "target", "mount", "path"]  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(st.sampled_from(FIELDS), yaml_values, max_size=4))
def test_config_loader_loads_or_names_the_problem_in_one_line(tree):
    """Random YAML: the loader (and validate) either accept it or raise a one-line
    ValueError, never another exception."""
    import yaml

    from geovs_drake.scenario import load_scenario

    text = yaml.safe_dump(tree)
    try:
        load_scenario(data=text).validate()
    except ValueError as e:
        assert "\n" not in str(e).strip(), str(e)
