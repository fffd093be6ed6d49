"""Property-based tests (hypothesis): the maps' identities on generated inputs.

Each property is an identity the geometry guarantees, checked on inputs
hypothesis draws (and shrinks on failure): the camera map against Drake's
RigidTransform algebra and its own inverse; the image Jacobian, its closed-form
inverse and its transpose against AutoDiffXd of the camera map along the
camera's body twist; SafeDomain's verdict against the 3-D geometry of the
sphere, the cone and the marked point; the navigation function's range on D
and its value on the faces; and the loader's messages on random YAML.

The number of examples each runs is set by its ``settings`` (``SETTINGS``: 150;
more where an example costs little) and listed on the docs' testing page (docs/testing.md).
"""

import math

import numpy as np
import pytest
from hypothesis import event, example, given, settings
from hypothesis import strategies as st
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.common.eigen_geometry import AngleAxis_
from pydrake.math import (
    RigidTransform,
    RigidTransform_,
    RollPitchYaw,
    RotationMatrix,
    RotationMatrix_,
)

from geovs_drake import (
    DEFAULT_DOMAIN,
    ImageFeatures,
    NavigationFunction,
    camera_map,
    camera_map_inverse,
    image_jacobian,
    image_jacobian_inverse,
    vee,
)
from geovs_drake.geometry._ops import MATH
from geovs_drake.geometry.camera import jacobian_rows, jacobian_transpose_times
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


twists = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6).map(np.array)


def _moved_along(X_BC: RigidTransform, twist: np.ndarray) -> RigidTransform_[AutoDiffXd]:
    """G(t) = G exp(t (Omega, V)^) with t an AutoDiffXd at 0: the camera moving with body
    twist (Omega, V) in its own frame (Eq. 17), by Drake's own RigidTransform algebra."""
    (t,) = InitializeAutoDiff(np.zeros(1)).ravel()
    Omega, V = twist[:3], twist[3:]
    n = float(np.linalg.norm(Omega))
    # Drake's AngleAxis refuses an axis whose norm's square underflows (hypothesis found
    # |Omega| ~ 1e-162); below 1e-100 rad/s the rotation is far under every tolerance.
    if n < 1e-100:
        n, axis = 0.0, np.array([1.0, 0.0, 0.0])
    else:
        axis = Omega / n
    R = RotationMatrix_[AutoDiffXd](AngleAxis_[AutoDiffXd](t * n, axis.astype(object)))
    # The translation of exp differs from t V only at second order: same tangent at t = 0.
    step = RigidTransform_[AutoDiffXd](R, np.array([t * v for v in V]))
    return X_BC.cast[AutoDiffXd]() @ step


def _image_velocity(y_ad: ImageFeatures) -> tuple[ImageFeatures, np.ndarray]:
    """y's value and (xi, lambda_dot, s_dot) from its AutoDiffXd derivatives (Eq. 13)."""
    value = np.vectorize(lambda e: e.value())
    slope = np.vectorize(lambda e: e.derivatives()[0] if e.derivatives().size else 0.0)
    v = y_ad.to_vector()
    y = ImageFeatures.from_vector(value(v).astype(float))
    dv = slope(v).astype(float)
    dQ = np.stack([dv[0:3], dv[3:6], dv[6:9]], axis=-1)
    xi = vee(dQ @ y.Q.T)
    return y, np.concatenate([xi, [dv[9]], dv[10:13]])


# Two rotation rates hypothesis found: one whose norm's square underflows, one just
# above the tolerance (a rate dropped as "too small" was wrong by itself).
@example(
    RigidTransform([0.0, 0.0, 0.27182818284590454]), np.array([0, 0, 2.2e-162, 0, 0, 0]), [0.0] * 7
)
@example(
    RigidTransform([0.0, 0.0, 0.27182818284590454]), np.array([0, 0, 7.26e-11, 0, 0, 0]), [0.0] * 7
)
@settings(max_examples=500, deadline=None)
@given(visible_poses(), twists, st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7))
def test_image_jacobian_matches_autodiff_along_body_twists(X_CB, twist, w):
    """C(y) (Eq. 14), Tc^-1 (Eq. 15, closed form) and C^T against AutoDiffXd of c(H) as the
    camera moves with body twist (Omega, V): ydot = C(y) (omega, v), (omega, v) = -(Omega, V)
    (Eq. 16)."""
    X_BC = X_CB.inverse()
    y, ydot = _image_velocity(camera_map(_moved_along(X_BC, twist).inverse(), RHO))
    omega_v = -twist
    C = image_jacobian(y, RHO)
    scale = max(1.0, np.linalg.norm(C, 2)) * max(1e-3, np.linalg.norm(twist))
    np.testing.assert_allclose(C @ omega_v, ydot, rtol=0, atol=1e-10 * scale)
    # Tc^-1 recovers the twist from the image velocity, to C's conditioning.
    cond = np.linalg.cond(C)
    np.testing.assert_allclose(
        image_jacobian_inverse(y, RHO) @ ydot, omega_v, rtol=0, atol=1e-12 * cond * scale
    )
    # C^T (the servo's force, Eq. 45) pairs with the twist as w does with ydot: the power.
    CT_w = np.array(jacobian_transpose_times(jacobian_rows(y.components(), RHO, MATH), tuple(w)))
    assert CT_w @ omega_v == pytest.approx(np.dot(w, ydot), abs=1e-10 * scale)


def _one_minus_cos(angle: float) -> float:
    return 2.0 * math.sin(0.5 * angle) ** 2  # 1 - cos without cancellation at small angles


def _angle(u: np.ndarray, v: np.ndarray) -> float:
    return math.atan2(np.linalg.norm(np.cross(u, v)), u @ v)


@st.composite
def poses_around_D(draw) -> RigidTransform:
    """X_CB whose images fall on both sides of every face of the default D: lambda in
    [0.03, 0.5] (D: [0.05, 0.4]), the sphere's centre up to 40 deg off the optical axis
    (D: 35 deg less its angular radius) and the sphere's z axis r3 tilted from the line of
    sight by up to 1.3 times the angle arccos(lambda) at which the marked point
    b = d - rho r3 reaches the limb (it crosses the occlusion margin, then hides)."""
    lam = draw(st.floats(0.03, 0.5))
    off_axis, azimuth = math.radians(draw(st.floats(0.0, 40.0))), draw(angles)
    s = np.array(
        [math.sin(off_axis) * math.cos(azimuth), math.sin(off_axis) * math.sin(azimuth)]
        + [math.cos(off_axis)]
    )
    tilt = draw(st.floats(0.0, 1.3)) * math.acos(lam)
    tilt_azimuth, roll = draw(angles), draw(angles)
    R_s = RotationMatrix.MakeFromOneVector(s, 2)  # its z column is s
    R_CB = R_s @ RotationMatrix.MakeZRotation(tilt_azimuth) @ RotationMatrix.MakeXRotation(tilt)
    return RigidTransform(R_CB @ RotationMatrix.MakeZRotation(roll), (RHO / lam) * s)


@settings(max_examples=1000, deadline=None)
@given(poses_around_D())
def test_safe_domain_verdict_is_the_geometry(X_CB):
    """SafeDomain against the 3-D scene: the sphere (centre d, radius rho), the FOV cone
    (half-angle theta about e3) and the marked point b. Visibility: the ray from the camera
    to b meets the sphere first at b. FOV: the angle from e3 to d plus the sphere's angular
    radius arcsin(rho / |d|) <= theta. Distance: lambda = rho / |d| in its bounds.
    Occlusion: b's angle phi from the centre's direction keeps 1 - cos phi <= (1 - kappa)
    (1 - cos(angular radius)), the relative margin from the limb. Each margin's sign, the
    verdict of contains() and phi (in [0, 1] inside D, refused outside) must agree."""
    D = DEFAULT_DOMAIN
    d = X_CB.translation()
    b = X_CB @ np.array([0.0, 0.0, -RHO])
    # The ray t b, t > 0, meets the sphere at t = 1 and at t2 = (|d|^2 - rho^2) / |b|^2
    # (product of the roots): b is the first hit iff t2 > 1.
    t2 = (d @ d - RHO**2) / (b @ b)
    if abs(t2 - 1) < 1e-9:  # b on the limb: too close to decide in double precision
        event("on a face, to rounding")
        return
    if t2 < 1:
        event("b hidden behind the sphere")
        with pytest.raises(ValueError, match="pose not visible"):
            camera_map(X_CB, RHO)
        return
    radius_angle = math.asin(RHO / np.linalg.norm(d))
    lam = RHO / np.linalg.norm(d)
    geometry = {
        "fov": D.fov_half_angle - (_angle(np.array([0.0, 0.0, 1.0]), d) + radius_angle),
        "lam_min": lam - D.lam_min,
        "lam_max": D.lam_max - lam,
        "occlusion": (1 - D.occlusion_margin) * _one_minus_cos(radius_angle)
        - _one_minus_cos(_angle(b, d)),
    }
    # Too close to a face to decide in double precision: skip (rare).
    tolerance = {"fov": 1e-9, "lam_min": 1e-12, "lam_max": 1e-12}
    tolerance["occlusion"] = 1e-9 * _one_minus_cos(radius_angle)
    if any(abs(geometry[k]) < tolerance[k] for k in geometry):
        event("on a face, to rounding")
        return
    y = camera_map(X_CB, RHO)
    margins = D.margins(y)._asdict()
    for name, value in geometry.items():
        assert (float(margins[name]) >= 0) == (value >= 0), (name, float(margins[name]), value)
    inside = all(v > 0 for v in geometry.values())
    assert bool(D.contains(y)) == inside
    nf = NavigationFunction(D, camera_map(RigidTransform([0.0, 0.0, 0.5]), RHO))
    if inside:
        event("inside D")
        assert 0.0 <= float(nf.value(y)) <= 1.0
    else:
        for name in (k for k in margins if geometry[k] < 0):
            event(f"outside D: {name} broken")
        first = next(k for k in margins if float(margins[k]) < 0)
        with pytest.raises(ValueError, match=f"y outside D: {first} margin = .* < 0"):
            nf.value(y)


@SETTINGS
@given(images_in_domain())
def test_phi_in_unit_interval_and_dphi_tangent(y):
    nf = NavigationFunction(DEFAULT_DOMAIN, camera_map(RigidTransform([0.0, 0.0, 0.5]), RHO))
    phi, dphi = nf.value_and_differential(y)
    assert 0.0 <= float(phi) < 1.0
    # To rounding: a few ulps of 1 (hypothesis found 1.3e-15 between the two paths).
    assert float(nf.clearance(y)) == pytest.approx(1 - float(phi), abs=1e-14)
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
#: The scenario's top-level keys, "path" (not a field) and the old spellings "rig" and
#: "mount" (refused in one line, naming the variant to write).
FIELDS = ["radius", "goal", "initial", "domain", "carrier", "control", "duration", "log_rate",
          "simulator", "plant", "sensor", "controller", "initial_velocity", "navigation",
          "target", "path", "rig", "mount"]  # fmt: skip


@settings(max_examples=150, deadline=None)  # each example builds a config: 5 s at 300
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


VALID_SCENARIO = """\
plant: !Kinematic {}
duration: 12
initial: {xyz: [0.05, 0, -0.7], rpy: [0, 0, 1]}
domain: {fov_half_angle_deg: 35, lam_min: 0.05}
control:
  damping: [0.3, 0.3, 0.3, 4, 4, 4]
simulator:
  integration_scheme: runge_kutta3
  accuracy: 1e-6
"""
edits = st.lists(
    st.tuples(
        st.floats(0.0, 1.0),  # where, as a fraction of the text
        st.integers(0, 3),  # how many characters to delete there
        st.text(alphabet=":-[]{},#\n 0123.eE'\"&*!|>%@`\t\\ab", max_size=3),  # what to insert
    ),
    min_size=1,
    max_size=4,
)


@settings(max_examples=500, deadline=None)
@given(edits)
def test_config_loader_on_damaged_yaml_text_names_the_problem_in_one_line(changes):
    """A valid scenario file with a few characters deleted or inserted (YAML syntax errors,
    broken flow lists, tabs, anchors, tags, wrong types): it loads and validates, or raises
    a one-line ValueError, never another exception."""
    from geovs_drake.scenario import load_scenario

    text = VALID_SCENARIO
    for where, delete, insert in changes:
        i = int(where * len(text))
        text = text[:i] + insert + text[i + delete :]
    try:
        load_scenario(data=text).validate()
        event("loads")
    except ValueError as e:
        message = str(e).strip()
        assert message and "\n" not in message, repr(message)
        kind = message.removeprefix("scenario: ").split(":")[0].split(" ")[0]
        event("one-line error: " + ("malformed YAML" if kind == "malformed" else "a field"))
