"""Following a planned image path (Sec. 4, Eq. 18): the formulas, the planner, the loop."""

import copy

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, InitializeAutoDiff
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.analysis import Simulator

from geovs_drake import camera_map, image_jacobian
from geovs_drake.analysis.studies.path_following import model_error_study, tracking_errors
from geovs_drake.cli import main
from geovs_drake.geometry._ops import DRAKE, MATH
from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.image_path import (
    QUINTIC_TIME_LAW,
    exp_image,
    image_distance,
    image_error,
    image_rate,
    tracking_rate,
)
from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.geometry.servo import path_following_velocity
from geovs_drake.loop import build_loop
from geovs_drake.planning import PathPlanningError, plan_for_scenario, plan_path
from geovs_drake.scenario import (
    Kinematic,
    PathFollowing,
    PoseConfig,
    ScenarioConfig,
    load_scenario,
)
from geovs_drake.simulation import simulate
from geovs_drake.systems import PathFollowingController

RHO = 0.1
#: A start whose geodesic to y* leaves D: 0.25 m to the side, looking back at the
#: sphere, turned 166 deg about the optical axis (the marked point sweeps across
#: the silhouette's edge while s travels straight).
DETOUR_START = PoseConfig(xyz=[0.25, 0.0, -0.7], rpy=[-0.4, 0.0, 2.9])


def _random_images(rng: np.random.Generator, n: int) -> list[ImageFeatures]:
    out = []
    for _ in range(n):
        X_CB = RigidTransform(
            RollPitchYaw(*rng.uniform(-0.3, 0.3, 2), rng.uniform(-3, 3)),
            [*rng.uniform(-0.1, 0.1, 2), rng.uniform(0.4, 1.0)],
        )
        out.append(camera_map(X_CB, RHO))
    return out


def _vec(y: ImageFeatures) -> tuple:
    return tuple(y.to_vector().tolist())


# ------------------------------------------------------------------ the formulas
def test_image_error_is_the_log_map_of_each_factor():
    """Against Drake's angle-axis of Q_d Q^T, and against the sphere itself: the s-part
    is tangent at s, as long as the arc, and its geodesic (exp_image) lands on s_d."""
    rng = np.random.default_rng(0)
    ys = _random_images(rng, 12)
    for y, y_d in zip(ys[:-1], ys[1:], strict=True):
        e = np.array(image_error(_vec(y), _vec(y_d), MATH))
        aa = RotationMatrix(y_d.Q @ y.Q.T).ToAngleAxis()
        np.testing.assert_allclose(e[0:3], aa.angle() * aa.axis(), atol=1e-12)
        assert e[3] == pytest.approx(float(y_d.lam - y.lam), abs=1e-15)
        assert e[4:7] @ y.s == pytest.approx(0, abs=1e-15)
        arc = np.arccos(np.clip(y.s @ y_d.s, -1, 1))
        assert np.linalg.norm(e[4:7]) == pytest.approx(arc, rel=1e-9)
        there = exp_image(y, e)
        np.testing.assert_allclose(there.s, y_d.s, atol=1e-12)
        np.testing.assert_allclose(there.Q, y_d.Q, atol=1e-12)
        np.testing.assert_allclose(image_distance(there, y_d), 0, atol=1e-12)
        np.testing.assert_allclose(
            image_distance(y, y_d), [aa.angle(), abs(e[3]), arc], rtol=1e-9, atol=1e-15
        )


def test_image_error_is_smooth_through_zero_in_autodiff():
    """At y = y_d (the follower's operating point, where the series branch runs):
    log_y(exp_y(t v)) = t v, so along y_d(t) = y + t dy/dt (AutoDiffXd, exact to first
    order) the derivative of the error is v; nearby, central differences of the
    closed form agree."""
    y = _random_images(np.random.default_rng(1), 1)[0]
    w, lam_dot = np.array([0.3, -0.2, 0.5]), 0.02
    u = np.cross(np.array([0.1, 0.4, -0.2]), y.s)  # tangent at s
    v = np.concatenate([w, [lam_dot], u])
    ydot = np.concatenate([np.cross(w, y.Q.T).ravel(), [lam_dot], u])
    t = AutoDiffXd(0.0, np.array([1.0]))
    y_d = tuple(a + t * b for a, b in zip(y.to_vector(), ydot, strict=True))
    e = image_error(tuple(AutoDiffXd(a) for a in _vec(y)), y_d, DRAKE)
    np.testing.assert_allclose([x.value() for x in e], 0, atol=1e-15)
    np.testing.assert_allclose([x.derivatives()[0] for x in e], v, atol=1e-12)

    def error_at(h: float) -> np.ndarray:
        return np.array(image_error(_vec(y), _vec(exp_image(y, h * v)), MATH))

    np.testing.assert_allclose((error_at(1e-4) - error_at(-1e-4)) / 2e-4, v, atol=1e-9)


def test_tracking_rate_moves_the_image_exactly_at_y_equal_y_d():
    """Eq. (18): -C(y) (Omega, V) = ydot_cmd (the camera's twist is minus H's, Eq. 16),
    with C from the image Jacobian; at y = y_d and k = 0, ydot_cmd = (xi_d, ...) of
    ydot_d, whose xi is (Qdot Q^T)^vee by central differences of a rotating Q."""
    rng = np.random.default_rng(2)
    for y, y_d in zip(*[iter(_random_images(rng, 8))] * 2, strict=True):
        w, lam_dot, v = rng.normal(size=3), rng.normal(), rng.normal(size=3)
        # A curve through y_d with Qdot = hat(w) Q, s_dot tangent.
        s_dot = v - (v @ y_d.s) * y_d.s
        ydot = np.concatenate([np.cross(w, y_d.Q.T).ravel(), [lam_dot], s_dot])
        rate = np.array(image_rate(_vec(y_d), tuple(ydot)))
        np.testing.assert_allclose(rate, np.concatenate([w, [lam_dot], s_dot]), atol=1e-12)
        for yy in (y_d, y):
            for k in (0.0, 1.5):
                cmd = np.array(tracking_rate(_vec(yy), _vec(y_d), tuple(ydot), k, MATH))
                twist = np.array(
                    path_following_velocity(_vec(yy), _vec(y_d), tuple(ydot), RHO, k, MATH)
                )
                np.testing.assert_allclose(-image_jacobian(yy, RHO) @ twist, cmd, atol=1e-9)
                if yy is y_d:
                    np.testing.assert_allclose(cmd, rate, atol=1e-12)
                assert cmd[4:7] @ yy.s == pytest.approx(0, abs=1e-12)


def test_path_following_controller_system_matches_formula_and_autodiff():
    rng = np.random.default_rng(3)
    y, y_d = _random_images(rng, 2)
    ydot = rng.normal(size=13)
    law = PathFollowingController(radius=RHO, gain=0.7)
    ctx = law.CreateDefaultContext()
    law.image_features_input.FixValue(ctx, y.to_vector())
    desired = np.concatenate([y_d.to_vector(), ydot])
    law.desired_image_input.FixValue(ctx, desired)
    out = law.camera_velocity_output.Eval(ctx)
    expected = path_following_velocity(_vec(y), _vec(y_d), tuple(ydot), RHO, 0.7, MATH)
    np.testing.assert_allclose(out, expected, atol=1e-14)
    np.testing.assert_allclose(
        law.image_error_output.Eval(ctx), image_error(_vec(y), _vec(y_d), MATH), atol=1e-14
    )
    # AutoDiffXd along the desired input, at y = y_d (zero error), against central
    # differences of the float system.
    law.image_features_input.FixValue(ctx, y_d.to_vector())
    law_ad = law.ToAutoDiffXd()
    ctx_ad = law_ad.CreateDefaultContext()
    law_ad.image_features_input.FixValue(ctx_ad, y_d.to_vector().astype(object) * AutoDiffXd(1))
    law_ad.desired_image_input.FixValue(ctx_ad, InitializeAutoDiff(desired).ravel())
    J = ExtractGradient(np.asarray(law_ad.camera_velocity_output.Eval(ctx_ad)))
    h = 1e-6
    for j in (0, 4, 9, 11, 13, 20, 25):
        e = np.zeros(26)
        e[j] = h
        law.desired_image_input.FixValue(ctx, desired + e)
        plus = law.camera_velocity_output.Eval(ctx).copy()
        law.desired_image_input.FixValue(ctx, desired - e)
        minus = law.camera_velocity_output.Eval(ctx).copy()
        np.testing.assert_allclose(J[:, j], (plus - minus) / (2 * h), atol=2e-6)
    # Outside I (a trial stage past the limb, here lambda > 1) or NaN: NaN, no exception.
    for bad in (np.concatenate([y.to_vector()[:9], [1.5], y.s]), np.full(13, np.nan)):
        law.image_features_input.FixValue(ctx, bad)
        assert np.all(np.isnan(law.camera_velocity_output.Eval(ctx)))
        assert np.all(np.isnan(law.image_error_output.Eval(ctx)))
    with pytest.raises(ValueError, match="feedback gain must be finite and >= 0"):
        PathFollowingController(gain=-1.0)


# ------------------------------------------------------------------ the planner
def test_geodesic_plan_ends_at_rest_and_moves_each_factor_by_the_time_law():
    """y_d(0) = y(0), y_d(T) = y*, zero velocity at both ends; along the way each
    factor's distance from the start is h(t/T) times its total (a geodesic timed by
    the quintic law), and the trajectory's derivative is its central difference."""
    config = ScenarioConfig()
    plan = plan_for_scenario(config)
    T = PathFollowing().duration  # the NF's scenario: the path law's defaults
    assert plan.kind == "geodesic" and plan.min_margin > 0 and plan.geodesic_exit is None
    y0, goal = config.initial_features(), config.goal_features()
    times = np.linspace(0, T, 9)
    Y, Ydot = plan.desired(times)
    np.testing.assert_allclose(Y[0], y0.to_vector(), atol=1e-14)
    np.testing.assert_allclose(Y[-1], goal.to_vector(), atol=1e-14)
    np.testing.assert_allclose(Ydot[[0, -1]], 0, atol=1e-15)
    total = image_distance(y0, goal)
    so_far = image_distance(ImageFeatures.from_vector(np.tile(y0.to_vector(), (9, 1))),
                            ImageFeatures.from_vector(Y))  # fmt: skip
    h = np.polynomial.polynomial.polyval(times / T, QUINTIC_TIME_LAW)
    np.testing.assert_allclose(so_far, np.outer(h, total), atol=1e-12)
    for t in times[1:-1]:
        fd = (plan.trajectory.value(t + 1e-6) - plan.trajectory.value(t - 1e-6))[:, 0] / 2e-6
        np.testing.assert_allclose(plan.trajectory.EvalDerivative(t, 1)[:, 0], fd, atol=1e-8)
    later, later_dot = plan.desired(np.array([T + 1.0]))
    np.testing.assert_allclose(later[0], goal.to_vector(), atol=1e-14)
    assert np.all(later_dot == 0)


def test_a_geodesic_that_leaves_D_is_reported_and_the_gradient_flow_path_stays_in_D():
    config = ScenarioConfig(initial=copy.deepcopy(DETOUR_START))
    domain, start, goal = (
        config.domain.to_domain(),
        config.initial_features(),
        config.goal_features(),
    )
    assert bool(domain.contains(start))
    T = PathFollowing().duration
    with pytest.raises(PathPlanningError, match=r"leaves D at t = [\d.]+ s through its occlusion"):
        plan_path(start, goal, domain, T)
    # Independently: the geodesic does leave D (SafeDomain.contains on the same path).
    nf = NavigationFunction(domain, goal, config.navigation.to_gains())
    plan = plan_path(start, goal, domain, T, nf)
    exit_ = plan.geodesic_exit
    assert plan.kind == "gradient_flow" and exit_ is not None and exit_.margin == "occlusion"
    assert 0 < exit_.time < exit_.worst_time < exit_.back_in_time < T
    assert "leaves D at t =" in plan.message and "gradient flow" in plan.message
    # The fallback path: from y(0) to y*, inside D on a grid twice as fine as the
    # planner's own (and offset from it).
    times = np.linspace(0, T, 2 * 20 * plan.knots + 1)
    Y, _ = plan.desired(times)
    assert np.all(domain.contains(ImageFeatures.from_vector(Y)))
    np.testing.assert_allclose(Y[0], start.to_vector(), atol=1e-14)
    np.testing.assert_allclose(Y[-1], goal.to_vector(), atol=1e-14)
    # phi decreases along it (it follows -grad phi); the last knots close in on y*.
    phi = nf.value(ImageFeatures.from_vector(Y))
    assert np.all(np.diff(phi) <= 1e-12) and phi[-1] < 1e-20
    # And the loop that follows it (kinematic, feedback) stays in D: the monitor's margins.
    config.plant = Kinematic()
    config.controller = PathFollowing()
    config.duration = T + 2
    result = simulate(config)
    assert result.status == "converged" and np.min(result.margins) > 0
    assert "gradient flow" in result.message


def test_a_start_that_is_the_goal_or_outside_D_is_refused():
    config = ScenarioConfig()
    domain, goal = config.domain.to_domain(), config.goal_features()
    with pytest.raises(PathPlanningError, match="the start image is the goal"):
        plan_path(goal, goal, domain, 5.0)
    with pytest.raises(ValueError, match="path duration must be finite and > 0"):
        plan_path(config.initial_features(), goal, domain, 0.0)


# ------------------------------------------------------------------ the loops
def test_open_loop_tracks_the_plan_to_integrator_accuracy_on_the_exact_model():
    """Eq. (18) as written (k = 0), kinematic plant, exact rho: the image follows y_d(t)
    within 1e-6 (every factor) along the whole path, at accuracy 1e-8."""
    config = ScenarioConfig(
        plant=Kinematic(), controller=PathFollowing(feedback_gain=0.0), duration=9.0
    )
    config.simulator.accuracy = 1e-8
    result = simulate(config)
    errors = tracking_errors(result, plan_for_scenario(config))
    assert result.status == "converged"
    assert np.max(errors) < 1e-6, np.max(errors, axis=0)
    assert np.max(errors) > 0  # the measurement is live: the integrator's error shows


def test_feedback_shrinks_each_geodesic_error_as_exp_minus_k_t():
    """Start off the plan (the body rotated 0.1 rad and moved 3 cm): with feedback gain k
    on the exact kinematic model each factor's distance to y_d is e^{-k t} times its
    initial value, while y_d moves (Drake's loggers against the plan)."""
    k = 1.5
    config = ScenarioConfig(
        plant=Kinematic(), controller=PathFollowing(feedback_gain=k), duration=3.0
    )
    config.simulator.accuracy = 1e-10
    plan = plan_for_scenario(config)
    diagram = build_loop(config, log=True).diagram
    simulator = Simulator(diagram)
    config_sim = config.simulator
    simulator.get_mutable_integrator().set_target_accuracy(config_sim.accuracy)
    body = diagram.GetSubsystemByName("kinematic_rigid_body")
    nudge = RigidTransform(RollPitchYaw(0.05, -0.06, 0.06), [0.03, -0.02, 0.02])
    X_WC0 = config.X_WB @ config.X_BC_initial @ nudge
    body.set_pose(body.GetMyMutableContextFromRoot(simulator.get_mutable_context()), X_WC0)
    simulator.AdvanceTo(config.duration)
    log = diagram.GetSubsystemByName("log_image_features").FindLog(simulator.get_context())
    times, Y = log.sample_times(), log.data().T
    desired, _ = plan.desired(times)
    d = image_distance(ImageFeatures.from_vector(Y), ImageFeatures.from_vector(desired))
    assert np.all(d[0] > 1e-3)
    np.testing.assert_allclose(d, d[0] * np.exp(-k * times)[:, None], rtol=1e-6, atol=1e-12)


def test_model_error_open_loop_drifts_feedback_tracks():
    """rho off by 10% (kinematic) and the velocity-tracking lag (dynamic): open loop ends
    off the goal, feedback converges; the exact open loop tracks."""
    runs = model_error_study(ScenarioConfig(duration=10.0), radius_scale=1.1, gain=2.0)
    exact, rho_open, rho_fb, dyn_open, dyn_fb = runs.values()
    assert np.max(exact.errors) < 1e-5 and exact.result.status == "converged"
    for open_loop, feedback in ((rho_open, rho_fb), (dyn_open, dyn_fb)):
        assert open_loop.result.status == "not_converged"
        assert np.min(open_loop.final_errors[[0, 2]]) > 1e-2
        assert feedback.result.status == "converged"
        assert np.max(feedback.final_errors) < 1e-4
        assert np.max(feedback.max_errors) < 0.5 * np.max(open_loop.max_errors)


# ------------------------------------------------------------------ configuration and CLI
def test_path_config_and_cli(capsys):
    config = load_scenario(data="controller: !PathFollowing {duration: 5, feedback_gain: 0}\n")
    assert config.controller == PathFollowing(duration=5, feedback_gain=0)
    for bad, needle in (
        ("controller: !PathFollowing {duration: 0}\n", "controller.duration"),
        ("controller: !PathFollowing {feedback_gain: -1}\n", "controller.feedback_gain"),
        ("controller: !PathFollowing {radius_scale: 0}\n", "controller.radius_scale"),
        ("carrier: ceiling\n", "carrier must be one of free, fixed, arm"),
    ):
        with pytest.raises(ValueError, match=needle):
            load_scenario(data=bad).validate()
    code = main(
        ["simulate", "--plant", "kinematic", "--controller", "path", "--path-duration", "4",
         "--path-feedback", "1", "--duration", "5", "--json"]
    )  # fmt: skip
    out, _ = capsys.readouterr()
    assert code == 0 and '"controller": "path"' in out and "geodesic path stays in D" in out
    code = main(["simulate", "--controller", "path", "--path-feedback=-1"])
    _, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1 and "controller.feedback_gain" in err
    # A law's flag with another law: one line naming the law it applies to.
    code = main(["simulate", "--controller", "pbvs", "--path-duration", "4"])
    _, err = capsys.readouterr()
    assert code == 2 and err.strip().splitlines() == [
        "geovs-drake: --path-duration applies to --controller path, the controller here is "
        "pbvs: add --controller path (or controller: !PathFollowing {...} in the scenario)"
    ]
