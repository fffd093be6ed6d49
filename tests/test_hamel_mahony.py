"""Hamel & Mahony's law on the quadrotor (issue 43, item 3): its spherical feature against
the geometry of the sphere's image, its loop at hover against the closed form of its depth
mode, a short run, the refusal on the other carriers, and compare's two laws."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.framework import InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import Linearize

from geovs_drake.analysis.studies.compare import (
    compared_laws,
    default_suite,
    law_label,
    run_compare,
    suite_cases,
)
from geovs_drake.geometry.camera import camera_map
from geovs_drake.loop import resolve
from geovs_drake.loop.assembly import assemble_loop
from geovs_drake.scenario import (
    Dynamic,
    HamelMahony,
    PoseConfig,
    Quadrotor,
    ScenarioConfig,
    load_suite,
)
from geovs_drake.simulation import simulate
from geovs_drake.systems.hamel_mahony_controller import (
    depth_weight,
    spherical_centroid,
    target_rotation,
)

RHO = 0.1
#: A pose of the target in C away from every symmetry: 0.62 m off, 14 deg off the axis.
X_CB = RigidTransform(RollPitchYaw(0.4, -0.7, 1.9), [0.09, -0.12, 0.6])
SMALL_START = PoseConfig(xyz=[0.03, 0.02, -0.55], rpy=[0.0, 0.05, 0.0])


def _quad(law: HamelMahony | None = None, **fields) -> ScenarioConfig:
    config = ScenarioConfig(carrier=Quadrotor(), plant=Dynamic(), **fields)
    config.controller = law or HamelMahony()
    config.initial = fields.get("initial", SMALL_START)
    return config


def _cap_directions(p_CB: np.ndarray, n: int = 400) -> np.ndarray:
    """The unit directions of a fine grid on the image sphere whose rays hit the sphere of
    radius RHO at p_CB: the cap the sphere covers, from the ray-sphere test alone."""
    u = (np.arange(n) + 0.5) / n
    z, phi = 1 - 2 * u[:, None], 2 * math.pi * u[None, :] * 37.0  # a spiral-like grid
    z, phi = np.broadcast_arrays(z, phi)
    r = np.sqrt(1 - z**2)
    p = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1).reshape(-1, 3)
    # A ray t p (t > 0) meets the sphere where |t p - c|^2 = rho^2 has a real root.
    along = p @ p_CB
    hits = (along > 0) & (along**2 - p_CB @ p_CB + RHO**2 >= 0)
    return p[hits]


def test_the_spherical_centroid_is_the_mean_direction_over_the_cap_the_sphere_covers():
    y = camera_map(X_CB.GetAsMatrix4(), RHO).to_vector()
    p_CB = X_CB.translation()
    d = np.linalg.norm(p_CB)
    # The cap's half-angle is asin(rho / d); y's lambda is its sine.
    assert math.asin(y[9]) == pytest.approx(math.asin(RHO / d), rel=1e-12)
    q = spherical_centroid(y)
    # The centroid points at the centre, and is the mean of the cap's directions (the
    # grid's mean: uniform in area on the sphere), within the grid's resolution.
    assert np.allclose(q / np.linalg.norm(q), p_CB / d, atol=1e-12)
    cap = _cap_directions(p_CB, 1200)
    assert len(cap) > 500
    assert np.allclose(q, cap.mean(axis=0), atol=2e-4)


def test_the_feature_kinematics_matrix_q_is_symmetric_positive_definite():
    """q_W = -Q v with Q > 0 (Hamel & Mahony's property): Q by central differences of the
    centroid of the exact image as the camera moves, the camera's attitude held."""
    p_CB = X_CB.translation()

    def q_of(p):
        X = RigidTransform(X_CB.rotation(), p)
        return spherical_centroid(camera_map(X.GetAsMatrix4(), RHO).to_vector())

    h = 1e-6
    # The camera moving by v moves the centre by -v in C: dq/dv = -dq/dp_CB = -Q.
    Q = np.column_stack([(q_of(p_CB + h * e) - q_of(p_CB - h * e)) / (2 * h) for e in np.eye(3)])
    assert np.allclose(Q, Q.T, atol=1e-6)
    eigenvalues = np.linalg.eigvalsh((Q + Q.T) / 2)
    assert eigenvalues.min() > 0
    # Its depth eigenvalue is f'(d) = rho^2 / (2 d^3 cos theta), the weak one.
    d = np.linalg.norm(p_CB)
    cos_theta = math.sqrt(1 - (RHO / d) ** 2)
    assert eigenvalues.min() == pytest.approx(RHO**2 / (2 * d**3 * cos_theta), rel=1e-5)


def test_the_target_rotation_from_the_image_is_the_pose_s():
    y = camera_map(X_CB.GetAsMatrix4(), RHO).to_vector()
    assert np.allclose(target_rotation(y), X_CB.rotation().matrix(), atol=1e-10)


@pytest.mark.parametrize("depth_balance", [0.0, 1.0])
def test_the_loop_at_hover_is_stable_and_its_depth_mode_is_the_closed_forms(depth_balance):
    """The loop's Jacobian at hover by central differences: every mode but the
    quaternion's norm decays, and the depth mode is the root of m s^2 + m k2 s + k1 k2 w f'
    (f' = rho^2 / (2 d*^3 cos theta*), w = depth_weight): with the paper's W = I about 50
    times slower than with the depth balanced."""
    law = HamelMahony(depth_balance=depth_balance)
    config = _quad(law, initial=ScenarioConfig().goal)
    loop = assemble_loop(resolve(config), log=False)
    diagram, context = loop.diagram, loop.diagram.CreateDefaultContext()
    loop.carrier.set_initial_state(context)
    x0 = context.get_continuous_state_vector().CopyToVector()

    def f(x):
        context.SetContinuousState(x)
        return diagram.EvalTimeDerivatives(context).CopyToVector()

    assert np.abs(f(x0)).max() < 1e-9  # hover at the goal is an equilibrium
    h = 1e-6
    A = np.column_stack([(f(x0 + h * e) - f(x0 - h * e)) / (2 * h) for e in np.eye(len(x0))])
    # Drake's Linearize (AutoDiffXd through the law; `geovs-drake linearize` uses it) agrees.
    context.SetContinuousState(x0)
    A_drake = Linearize(
        diagram,
        context,
        input_port_index=InputPortSelection.kNoInput,
        output_port_index=OutputPortSelection.kNoOutput,
    ).A()
    assert np.allclose(A_drake, A, atol=1e-4 * np.abs(A).max())
    eigenvalues = np.linalg.eigvals(A)
    near_zero = np.abs(eigenvalues) < 1e-6
    assert near_zero.sum() == 1
    assert np.max(eigenvalues[~near_zero].real) < 0
    d = 0.5  # the goal's distance to the centre
    lam = RHO / d
    f_prime = RHO**2 / (2 * d**3 * math.sqrt(1 - lam**2))
    m, k1, k2 = config.carrier.mass, law.image_gain, law.velocity_gain
    K = k1 * k2 * depth_weight(lam, depth_balance) * f_prime
    # The depth mode's slower root (the one W is for; the faster one meets the attitude
    # loop's lag) is among the loop's eigenvalues (a set, with a tolerance).
    slow = max(np.roots([m, m * k2, K]), key=lambda r: r.real)
    assert np.min(np.abs(eigenvalues - slow)) < 0.02 * abs(slow), (slow, eigenvalues)


def test_a_short_run_from_a_small_move_closes_in_and_reports_the_rotors():
    result = simulate(_quad(duration=1.5))
    s = result.summary()
    assert not result.left_domain and s["min_fov_margin"] > 0
    errors = result.position_errors
    assert errors[-1] < 0.6 * errors[0]
    assert 0.0 <= s["rotor_saturation_fraction"] <= 1.0 and s["max_tilt_deg"] <= 10.5


@pytest.mark.slow
def test_the_small_move_converges_to_1_mm():
    result = simulate(_quad(duration=8.0))
    assert result.converged and result.convergence_time < 8.0


@pytest.mark.parametrize("carrier", ["free", "arm", "fixed"])
def test_the_other_carriers_refuse_it_in_one_line(carrier, run_cli):
    code, out, err = run_cli("simulate", "--carrier", carrier, "--controller", "hamel_mahony")
    lines = err.strip().splitlines()
    assert code == 2 and out == "" and len(lines) == 1 and "Traceback" not in err, err
    assert "needs carrier quadrotor" in lines[0] and f"got carrier {carrier}" in lines[0]


def test_bad_gains_are_refused_in_one_line(run_cli):
    code, out, err = run_cli(
        "simulate",
        "--carrier",
        "quadrotor",
        "--initial=0.03,0.02,-0.55,0,0.05,0",
        "--scenario-text",
        "controller: !HamelMahony {velocity_gain: -1}",
    )
    assert code == 2 and out == "" and "controller.velocity_gain" in err and "-1" in err, err


def test_compare_on_the_quadrotor_runs_the_nf_and_hamel_mahony_on_the_quadrotor_starts():
    base = _quad()
    base.controller = ScenarioConfig().controller
    assert [law_label(law) for law in compared_laws(base)] == ["nf", "hamel_mahony"]
    assert [law_label(law) for law in compared_laws(ScenarioConfig())][0] == "nf"
    assert "hamel_mahony" not in [law_label(law) for law in compared_laws(ScenarioConfig())]
    suite = load_suite(default_suite(base))
    cases = suite_cases(suite, base=base)  # each validated: every start a level one
    assert [(s, law) for s, law, _ in cases] == [
        (name, law) for name in ("level", "small", "far") for law in ("nf", "hamel_mahony")
    ]


@pytest.mark.slow
def test_compare_on_the_quadrotor_tables_both_laws_with_tilt_and_saturation():
    base = _quad()
    suite = load_suite(default_suite(base))
    suite.scenarios = [s for s in suite.scenarios if s.name == "small"]
    suite.conundrum = "small"
    result = run_compare(suite, workers=1, duration=6.0, base=base)
    assert [r["law"] for r in result.rows] == ["nf", "hamel_mahony"]
    for row in result.rows:
        assert row["status"] == "converged"
        assert row["max_tilt_deg"] <= 10.5 and 0 <= row["rotor_saturation_fraction"] <= 1
