"""The loop linearised at any state (analysis.linearization.linearize, linearize_along).

Truths: central differences of the batch engine's right-hand side (the compiled
kernels, not Drake's AutoDiffXd), Drake's ``Linearize`` of the diagram (its A does not
depend on the state being an equilibrium once the check is off), the goal's
``linearize_at_goal`` and closed form, and, for the kinematic loop, central
differences of the vector field written in the Gibbs chart itself.
"""

from __future__ import annotations

import copy
import json
import re

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.framework import InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import Linearize

from geovs_drake.analysis.linear.linearization import (
    INPUTS,
    OUTPUTS,
    closed_form_A,
    linearize,
    linearize_along,
    linearize_at_goal,
    rig_spatial_inertia,
    state_at,
    wrench_to_generalized_force,
)
from geovs_drake.batch.engine import _rhs, loop_parameters
from geovs_drake.geometry.camera import ImageFeatures, camera_map
from geovs_drake.geometry.navigation import NavigationFunction, image_chart
from geovs_drake.goal.linear_model import chart_jacobian, navigation_hessian
from geovs_drake.loop import build_loop, exact_twin, resolve
from geovs_drake.scenario import (
    Dynamic,
    Kinematic,
    Pinhole,
    PlantConfig,
    PoseConfig,
    ScenarioConfig,
    variant_name,
)
from geovs_drake.simulation import StartOutsideDomain, check_start, simulate
from geovs_drake.spectrum import assert_spectra_close, canonical_eigenvalues

#: Random states per plant, and the spread of their poses about the goal and twists.
N_STATES = 4
ROTATION_SPREAD_RAD, POSITION_SPREAD_M, TWIST_SPREAD = 0.3, 0.08, 0.2
#: Central-difference step along the tangent, and the relative agreement asked for
#: (the truncation error is h^2 |f'''|, the rounding eps |f| / h).
FD_STEP, FD_RTOL = 1e-5, 1e-6


def _states_in_D(plant: PlantConfig, seed: int) -> list[np.ndarray]:
    """Random Drake states whose camera pose is in D (rejection), at random twists."""
    rng = np.random.default_rng(seed)
    config = ScenarioConfig(plant=plant)
    out = []
    while len(out) < N_STATES:
        rpy = rng.uniform(-ROTATION_SPREAD_RAD, ROTATION_SPREAD_RAD, 3)
        xyz = np.array(config.goal.xyz) + rng.uniform(-POSITION_SPREAD_M, POSITION_SPREAD_M, 3)
        c = copy.deepcopy(config)
        c.initial = PoseConfig(xyz=list(xyz), rpy=list(rpy))
        try:
            check_start(c)
        except StartOutsideDomain:
            continue
        twist = rng.uniform(-TWIST_SPREAD, TWIST_SPREAD, 6) if config.dynamic else None
        out.append(state_at(config, c.X_BC_initial, twist))
    return out


def _batch_rhs(config: ScenarioConfig):
    p = loop_parameters(config)
    kinematic = not config.dynamic

    def f(x: np.ndarray) -> np.ndarray:
        out = np.zeros(len(x))
        _rhs(kinematic, np.ascontiguousarray(x), out, p.camera, p.navigation, p.controller, p.body)
        return out

    return f


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_A_matches_central_differences_of_the_batch_engine_and_drakes_linearize(plant):
    config = ScenarioConfig(plant=plant)
    f = _batch_rhs(config)
    diagram = build_loop(config, log=False).diagram
    for x0 in _states_in_D(plant, seed=21):
        lin = linearize(config, x0)
        assert not lin.at_equilibrium and type(lin.system).__name__ == "AffineSystem"
        # Drake's affine model is xdot = A x + f0, f0 = xdot(x0) - A x0: at x0, the engine's f.
        xdot = lin.A_drake @ x0 + lin.system.f0()
        assert np.allclose(xdot, f(x0), rtol=1e-9, atol=1e-9 * np.abs(xdot).max())
        # Along the tangent (the quaternion's norm is Drake's business, not the loop's).
        fd = np.stack(
            [(f(x0 + FD_STEP * t) - f(x0 - FD_STEP * t)) / (2 * FD_STEP) for t in lin.T.T], axis=1
        )
        scale = np.linalg.norm(fd)
        assert np.linalg.norm(lin.A_drake @ lin.T - fd) < FD_RTOL * scale
        # Drake's Linearize of the diagram at the same (non-equilibrium) state.
        context = diagram.CreateDefaultContext()
        context.SetContinuousState(x0)
        drake = Linearize(
            diagram,
            context,
            input_port_index=InputPortSelection.kNoInput,
            output_port_index=OutputPortSelection.kNoOutput,
            equilibrium_check_tolerance=np.inf,
        )
        assert np.allclose(drake.A(), lin.A_drake, rtol=1e-12, atol=1e-9)
        assert lin.A.shape == ((12, 12) if isinstance(plant, Dynamic) else (6, 6))


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_at_the_goal_it_is_linearize_at_goal_and_the_closed_form(plant):
    config = ScenarioConfig(plant=plant)
    lin = linearize(config)
    goal = linearize_at_goal(config)
    assert lin.at_equilibrium and type(lin.system).__name__ == "LinearSystem"
    assert np.allclose(lin.A, goal.A, atol=1e-12)
    assert np.allclose(lin.A, goal.A_closed, rtol=1e-9, atol=1e-9 * np.abs(goal.A_closed).max())
    assert lin.max_real_part < 0
    stable = lin.eigenvalues.real < 0
    assert np.all(lin.damping_ratios[stable] > 0) and np.all(lin.time_constants[stable] > 0)


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The Hamilton product of (w, x, y, z) quaternions (not normalised)."""
    return np.r_[a[0] * b[0] - a[1:] @ b[1:], a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:])]


def _gibbs_chart(x0: np.ndarray, f):
    """The kinematic loop's vector field in the Gibbs chart, F(z) = DPsi(Phi(z)) f(Phi(z)):
    Phi(z) = (q0 (x) (1, dtheta / 2) normalised, p0 + R0 dp) and
    Psi(x) = (2 vec(u) / u_w, R0^T (p - p0)), u = q0^* (x) q."""
    q0 = x0[0:4] / np.linalg.norm(x0[0:4])
    R0 = RotationMatrix(Quaternion(q0)).matrix()
    conj = q0 * np.array([1.0, -1.0, -1.0, -1.0])

    def F(z: np.ndarray) -> np.ndarray:
        dq = np.r_[1.0, z[0:3] / 2]
        x = np.r_[_qmul(q0, dq / np.linalg.norm(dq)), x0[4:7] + R0 @ z[3:6]]
        xdot = f(x)
        u, du = _qmul(conj, x[0:4]), _qmul(conj, xdot[0:4])
        dtheta = 2 * (du[1:] * u[0] - u[1:] * du[0]) / u[0] ** 2
        return np.r_[dtheta, R0.T @ xdot[4:7]]

    return F


def test_the_kinematic_minimal_A_is_the_chart_jacobian():
    """Away from the goal the kinematic loop's A is exactly the Jacobian of its vector field
    in the Gibbs chart (central differences of that field, on the batch engine's f)."""
    config = ScenarioConfig(plant=Kinematic())
    f = _batch_rhs(config)
    for x0 in _states_in_D(Kinematic(), seed=5):
        lin = linearize(config, x0)
        F = _gibbs_chart(x0, f)
        fd = np.stack(
            [(F(FD_STEP * e) - F(-FD_STEP * e)) / (2 * FD_STEP) for e in np.eye(6)], axis=1
        )
        assert np.linalg.norm(lin.A - fd) < FD_RTOL * np.linalg.norm(fd), np.abs(lin.A - fd).max()


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_linearize_along_a_run_ends_at_the_goals_model(plant):
    config = ScenarioConfig(plant=plant, duration=20.0)
    config.initial = PoseConfig(xyz=[0.02, -0.01, -0.52], rpy=[0.02, -0.01, 0.1])
    result = simulate(config)
    along = linearize_along(result, [0.0, 1.0, 20.0])
    assert along.eigenvalues.shape == (3, 12 if isinstance(plant, Dynamic) else 6)
    goal = linearize_at_goal(config)
    # At 20 s the state is at the goal to rounding: the same spectrum.
    assert_spectra_close(along.eigenvalues[-1], goal.eigenvalues, rtol=0, atol=1e-6)
    # In the canonical order, entry by entry (the goal's repeated pair included).
    assert np.allclose(along.eigenvalues[-1], goal.eigenvalues, atol=1e-6)
    assert along.max_real_part[-1] == pytest.approx(goal.max_real_part, abs=1e-6)
    # At t = 0 it is linearize at the logged start.
    direct = linearize(config, result.states[0])
    assert np.allclose(along.models[0].A, direct.A)


# ---- inputs (disturbance, feature noise) and outputs (pose error, y)


def _offset_config(plant: PlantConfig) -> ScenarioConfig:
    """A rig whose camera sits off its centre of mass, turned: the disturbance's map to
    the plant's generalized force and the rig's inertia about C are not trivial."""
    config = ScenarioConfig(plant=plant)
    config.carrier.camera_offset = PoseConfig(xyz=[0.03, -0.02, 0.05], rpy=[0.2, -0.1, 0.3])
    return config


def test_the_wrench_map_is_the_force_systems_own():
    """G (F_C -> the free rig's generalized force) against ImageJacobianForce, which
    outputs both at a random rig state."""
    config = _offset_config(Dynamic())
    loop = build_loop(config, log=False)
    force = loop.diagram.GetSubsystemByName("image_jacobian_force")
    x0 = _states_in_D(Dynamic(), seed=3)[0]
    context = loop.diagram.CreateDefaultContext()
    context.SetContinuousState(x0)
    sub = force.GetMyContextFromRoot(context)
    F_C = force.wrench_C_output.Eval(sub)
    generalized = force.generalized_force_output.Eval(sub)
    X_WR = RigidTransform(Quaternion(x0[0:4] / np.linalg.norm(x0[0:4])), x0[4:7])
    G = wrench_to_generalized_force(X_WR, config.X_RC)
    assert np.allclose(G @ F_C, generalized, rtol=1e-12, atol=1e-12 * np.abs(generalized).max())


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_at_the_goal_inputs_and_outputs_are_the_closed_form(plant):
    """At the goal: the disturbance enters as M^-1 (a wrench on the rig's inertia about
    C, Appendix C.0.6) or as the twist itself; the pose error is the minimal coordinates;
    nothing feeds through."""
    config = _offset_config(plant)
    lin = linearize(config)
    assert type(lin.minimal).__name__ == "LinearSystem"
    dist, noise = INPUTS["disturbance"], INPUTS["feature_noise"]
    if isinstance(plant, Dynamic):
        expected = np.vstack([np.zeros((6, 6)), np.linalg.inv(rig_spatial_inertia(config))])
    else:
        expected = np.eye(6)
    assert np.allclose(lin.B[:, dist], expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    n = lin.A.shape[0]
    assert np.allclose(lin.C[OUTPUTS["pose_error"]], np.eye(6, n), atol=1e-12)
    assert np.all(lin.D == 0)
    # The law reads the chart coordinate xi = -C_chart eps + n (the image moves by
    # -C_chart eps, module linearization): F = -K eps + k_p C_chart^T H n (Eq. 45) and
    # nu = -k C_chart^-1 H (-C_chart eps + n) with the kinematic sign (Eqs. 17-19).
    y = config.goal_features()
    nf = NavigationFunction(config.domain.to_domain(), y, config.navigation.to_gains())
    H, Cc = navigation_hessian(nf, y), chart_jacobian(y, config.radius)
    if isinstance(plant, Dynamic):
        M = rig_spatial_inertia(config)
        gain = config.control.potential_gain * Cc.T @ H
        expected = np.vstack([np.zeros((6, 6)), np.linalg.solve(M, gain)])
    else:
        expected = config.control.kinematic_gain * np.linalg.solve(Cc, H)
    scale = np.abs(expected).max()
    assert np.allclose(lin.B[:, noise], expected, rtol=1e-8, atol=1e-9 * scale), (
        np.abs(lin.B[:, noise] - expected).max() / scale
    )


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_B_matches_central_differences_of_the_diagram_in_its_inputs(plant):
    """B at random states in D (AffineSystems) against central differences of the
    study diagram's double derivative in u, mapped as linearize documents."""
    config = _offset_config(plant)
    loop = build_loop(exact_twin(config), log=False, study_ports=True)
    diagram = loop.diagram
    for x0 in _states_in_D(plant, seed=8)[:2]:
        lin = linearize(config, x0)
        context = diagram.CreateDefaultContext()
        context.SetContinuousState(x0)

        y0 = loop.camera.image_features_output.Eval(loop.camera.GetMyContextFromRoot(context))

        def xdot(u: np.ndarray, context=context, y0=y0) -> np.ndarray:
            # The noise moves y within the image space, along the chart (exactly).
            y = image_chart(ImageFeatures.from_vector(y0), u[6:12]).to_vector()
            diagram.GetInputPort("disturbance").FixValue(context, u[0:6])
            diagram.GetInputPort("feature_noise").FixValue(context, y - y0)
            return diagram.EvalTimeDerivatives(context).CopyToVector()

        fd = np.stack(
            [(xdot(FD_STEP * e) - xdot(-FD_STEP * e)) / (2 * FD_STEP) for e in np.eye(12)], axis=1
        )
        if loop.disturbance == "generalized_force":
            X_WR = RigidTransform(Quaternion(x0[0:4] / np.linalg.norm(x0[0:4])), x0[4:7])
            fd[:, 0:6] = fd[:, 0:6] @ wrench_to_generalized_force(X_WR, config.X_RC)
        expected = np.linalg.pinv(lin.T) @ fd
        assert np.linalg.norm(lin.B - expected) < FD_RTOL * np.linalg.norm(expected)


def _gibbs(d):
    """The rotation whose Gibbs vector is d (2 vec(q) / w, q = (1, d / 2) normalised),
    for AutoDiffXd entries."""
    w, x, y, z = np.r_[1.0, d / 2] / np.sqrt(1.0 + d @ d / 4)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_C_is_the_autodiff_of_the_camera_map_and_the_pose_error(plant):
    """C's y rows against AutoDiffXd of c(H) (the geometry, not the diagram) along the
    minimal coordinates, X_WC = X_WC0 (Cay(dtheta), dp); its pose-error rows against
    the same of the goal's chart."""
    config = _offset_config(plant)
    for x0 in _states_in_D(plant, seed=13)[:2]:
        lin = linearize(config, x0)
        X_WR = RigidTransform(Quaternion(x0[0:4] / np.linalg.norm(x0[0:4])), x0[4:7])
        X_WC0 = X_WR @ (config.X_RC if isinstance(plant, Dynamic) else RigidTransform())
        eps = InitializeAutoDiff(np.zeros(6)).ravel()
        R = X_WC0.rotation().matrix() @ _gibbs(eps[0:3])
        p = X_WC0.translation() + X_WC0.rotation().matrix() @ eps[3:6]
        X_WC = np.block([[R, p[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
        X_CB = _inverse(X_WC) @ config.X_WB.GetAsMatrix4()
        y = camera_map(X_CB, config.radius).to_vector()
        J_y = ExtractGradient(y)
        n = lin.A.shape[0]
        assert np.allclose(lin.C[OUTPUTS["image_features"]][:, 0:6], J_y, atol=1e-10)
        assert np.all(lin.C[:, 6:n] == 0)  # neither output sees the twist
        X_goal = config.X_WB @ config.X_BC_goal
        R_err = X_goal.rotation().matrix().T @ R
        g = _gibbs_vector(R_err)
        dp = X_goal.rotation().matrix().T @ (p - X_goal.translation())
        J_e = ExtractGradient(np.concatenate([g, dp]))
        assert np.allclose(lin.C[OUTPUTS["pose_error"]][:, 0:6], J_e, atol=1e-10)


def _inverse(X):
    R, p = X[0:3, 0:3], X[0:3, 3]
    return np.block([[R.T, (-R.T @ p)[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])


def _gibbs_vector(R):
    """2 vec(q) / w of a rotation matrix (from its skew part and trace: w vec(q) =
    (R - R^T)^vee / 4, w^2 = (1 + tr R) / 4), for AutoDiffXd entries."""
    skew = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return 2.0 * skew / (1.0 + R[0, 0] + R[1, 1] + R[2, 2])


def test_a_state_of_the_wrong_size_is_refused():
    with pytest.raises(ValueError, match="state must have 7 entries"):
        linearize(ScenarioConfig(plant=Kinematic()), np.zeros(13))


def test_state_at_puts_the_camera_where_asked():
    config = ScenarioConfig(plant=Kinematic())
    X = RigidTransform(RollPitchYaw(0.1, -0.2, 0.3), [0.01, 0.02, -0.6])
    x = state_at(config, X)
    X_WC = RigidTransform(Quaternion(x[0:4]), x[4:7])
    assert np.allclose((config.X_WB.inverse() @ X_WC).GetAsMatrix4(), X.GetAsMatrix4())


# ---- geovs-drake linearize


def test_cli_json_at_the_goal_is_the_closed_forms_spectrum(run_cli, tmp_path):
    run = run_cli("linearize", "--plant", "kinematic", "--json", "--out", str(tmp_path))
    assert run.code == 0, run.err
    out = json.loads(run.out)
    assert out["plant"] == "kinematic" and out["stable"] and out["at_equilibrium"]
    closed = canonical_eigenvalues(closed_form_A(resolve(ScenarioConfig()), Kinematic()))
    lam = np.array([complex(re, im) for re, im in out["eigenvalues"]])
    assert_spectra_close(lam, closed, rtol=1e-9)
    assert np.allclose(lam, closed, rtol=1e-9)  # the JSON's order is the canonical one
    assert out["max_real_part"] == pytest.approx(closed.real.max(), rel=1e-9)
    assert np.allclose(out["damping_ratios"], -closed.real / np.abs(closed))
    assert np.allclose(out["time_constants"], -1 / closed.real)
    assert np.array(out["A"]).shape == (6, 6)
    assert json.loads((tmp_path / "linearize.json").read_text()) == out


def test_cli_text_at_a_pose_names_the_frozen_model(run_cli):
    run = run_cli("linearize", "--at=0.02,-0.01,-0.52,0.02,-0.01,0.1")
    assert run.code == 0, run.err
    first = run.out.splitlines()[0]
    assert first.startswith("dynamic loop linearised at X_BC = (0.02,-0.01,-0.52")
    assert "stable" in first and "frozen-time" in first
    assert len(run.out.splitlines()) == 2 + 12  # the heading, the columns, 12 modes


@pytest.mark.parametrize(
    ("at", "expected"),
    [
        ("--at=0,0,-0.5,0,2,0", "--at 0,0,-0.5,0,2,0 is outside D: fov margin = -1.333 < 0"),
        ("--at=0,0,-0.5,0,0", "expected 6 finite numbers x,y,z,roll,pitch,yaw"),
        ("--at=goal,1", "expected 6 numbers x,y,z,roll,pitch,yaw: 'goal,1'"),
    ],
)
def test_cli_bad_at_is_one_line_and_exit_2(run_cli, at, expected):
    run = run_cli("linearize", at)
    assert run.code == 2 and run.out == ""
    assert len(run.err.strip().splitlines()) == 1 and expected in run.err
    assert "Traceback" not in run.err


#: The camera's held frame (no prediction between frames): the sampled loop these studies
#: are about (the default camera predicts, and its model is the continuous loop's).
HELD = "sensor: !Pinhole {prediction: none}"


def test_cli_studies_in_the_json_and_the_root_locus_written(run_cli, tmp_path):
    run = run_cli(
        "linearize", "--settling-time", "2", "--damping-ratio", "0.6", "--latency", "1",
        "--json", "--out", str(tmp_path), "--scenario-text", HELD,
    )  # fmt: skip
    assert run.code == 0, run.err
    out = json.loads(run.out)
    design = out["design"]
    assert design["achieved_damping_ratio"] == pytest.approx(0.6, abs=1e-9)
    assert design["achieved_settling_time"] == pytest.approx(2.0, rel=1e-9)
    assert design["energy_bound"] == design["potential_gain"] > 0
    # The camera study is of the gains the command reports, the designed ones (issue 31):
    # the sampled-data model of the designed loop, the camera damping with the designed B.
    from geovs_drake.analysis.linear.gain_design import design_gains
    from geovs_drake.analysis.linear.latency import sampled_model

    designed = design_gains(ScenarioConfig(), 2.0, 0.6, run_start=False).config
    designed.sensor = Pinhole(damping=list(designed.control.damping))
    model = sampled_model(designed)
    camera = out["camera"]
    assert camera["gains"] == "designed"
    assert camera["spectral_radius"] == pytest.approx(model.spectral_radius(30.0, 1), rel=1e-9)
    # Not stable even without latency: the margin says so (-1), and the rate it needs is
    # the boundary of the model's stable rates.
    assert not camera["stable"] and camera["latency_margin_frames"] == -1
    needed = camera["slowest_stable_rate_hz"]
    assert needed > 30.0
    assert model.spectral_radius(needed * 1.001, 1) < 1 <= model.spectral_radius(needed / 1.001, 1)
    assert "warning: the designed gains are not stable with a 30 Hz camera" in run.err
    assert f"at least {needed:.3g} Hz" in run.err and run.err.count("\n") == 1
    assert (tmp_path / "root_locus.png").stat().st_size > 0


def test_cli_camera_study_of_the_scenarios_gains_at_another_rate(run_cli):
    """Without a design the camera study is of the scenario's gains, and the slowest
    stable rate is reported at any --camera-rate (it was dropped away from 30 Hz)."""
    from geovs_drake.analysis.linear.latency import sampled_model

    run = run_cli(
        "linearize", "--latency", "0", "--camera-rate", "60", "--json", "--scenario-text", HELD
    )
    assert run.code == 0 and run.err == "", run.err
    camera = json.loads(run.out)["camera"]
    model = sampled_model(ScenarioConfig())
    assert camera["gains"] == "scenario" and camera["stable"]
    slowest = camera["slowest_stable_rate_hz"]
    assert slowest is not None and slowest < 60.0
    assert (
        model.spectral_radius(slowest * 1.001, 0) < 1 <= model.spectral_radius(slowest / 1.001, 0)
    )


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--settling-time", "1", "--damping-ratio", "0"], "damping_ratio = 0.0"),
        (["--settling-time", "1", "--damping-ratio", "-0.2"], "damping_ratio = -0.2"),
        (["--settling-time", "-1"], "settling_time = -1.0"),
        (["--latency", "-1"], "latency_frames = -1"),
        (["--latency", "1", "--camera-rate", "0"], "rate = 0.0"),
        (["--at=0,0,-5,0,0,0"], "is outside D"),
        (["--certify", "--sos-solver", "mosek"], "one of clarabel, csdp, scs: .mosek."),
    ],
)
def test_cli_bad_study_input_is_one_line_and_writes_nothing(run_cli, tmp_path, args, match):
    out = tmp_path / "out"
    run = run_cli("linearize", *args, "--out", str(out))
    assert run.code == 2 and re.search(match, run.err), run.err
    assert len(run.err.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.slow
def test_cli_certify_reports_the_certified_level_inside_the_sampled_one(run_cli):
    run = run_cli("linearize", "--plant", "kinematic", "--certify", "--json")
    assert run.code == 0, run.err
    region = json.loads(run.out)["region"]
    certified = region["certified"]
    assert certified["nonlinear_check"] and certified["degree"] == 3  # the kinematic default
    assert 0 < certified["level"] < region["level"] / 0.9  # below the failing level
    assert 0 < certified["largest_distance_m"] < region["largest_distance_m"] / 0.9**0.5


def test_linearize_of_a_camera_loop_is_its_continuous_twins_whatever_the_cameras_errors():
    """A sampled camera has no A: linearize takes the exact-sensor twin, the camera's own
    errors (noise, latency) dropped with it (it raised 'pixel_noise needs a camera'),
    the believed radius kept (and B the exact loop's, control.damping, as before). Drake's
    Linearize of the exact loop is the truth."""
    camera = ScenarioConfig(sensor=Pinhole(pixel_noise=0.5, latency_frames=1, radius_error=0.05))
    exact = ScenarioConfig()
    exact.sensor.radius_error = 0.05
    np.testing.assert_allclose(linearize(camera).A, linearize(exact).A, rtol=0, atol=1e-12)
    # the caller's config untouched
    assert camera.sensor == Pinhole(pixel_noise=0.5, latency_frames=1, radius_error=0.05)


def test_cli_linearize_on_the_arm_is_drakes_model_at_the_goal_and_its_camera_study(run_cli):
    """Issue 31: linearize and the camera study run on the arm (they refused it). The
    eigenvalues are those of the closed form through J_C; the camera study is the goal's
    sampled model at the arm's own gain (auto, chosen for this camera and latency), which
    keeps the margin; the free rig's studies are refused in one line."""
    from geovs_drake.analysis.linear.arm_study import linearize_arm_at_goal
    from geovs_drake.goal.camera_fit import GAIN_MARGIN
    from geovs_drake.loop import resolve
    from geovs_drake.scenario import Arm

    held = "sensor: !Pinhole {prediction: none}"
    run = run_cli(
        "linearize", "--carrier", "arm", "--latency", "1", "--json", "--scenario-text", held
    )
    assert run.code == 0, run.err
    out = json.loads(run.out)
    assert out["carrier"] == "arm" and out["stable"]
    closed = linearize_arm_at_goal(ScenarioConfig(carrier=Arm())).A_closed
    eigenvalues = np.array([complex(re, im) for re, im in out["eigenvalues"]])
    assert_spectra_close(eigenvalues, np.linalg.eigvals(closed), rtol=0, atol=1e-8)
    sensor = Pinhole(latency_frames=1, prediction="none")
    fit = resolve(ScenarioConfig(carrier=Arm(), sensor=sensor)).camera_fit
    camera = out["camera"]
    assert camera["prediction"] == "none"
    assert camera["gain_scale"] == pytest.approx(fit.gain_value)
    assert camera["spectral_radius"] == pytest.approx(fit.spectral_radius) and camera["stable"]
    assert fit.margin == pytest.approx(GAIN_MARGIN, rel=1e-6)
    # The default camera predicts between frames: the continuous loop, sampled, at 10.
    predicted = json.loads(
        run_cli("linearize", "--carrier", "arm", "--latency", "1", "--json").out
    )["camera"]
    assert predicted["prediction"] == "odometry" and predicted["gain_scale"] == 10.0
    from geovs_drake.goal.camera_fit import goal_sampled_model

    held_model = goal_sampled_model(
        resolve(ScenarioConfig(carrier=Arm(gain_scale=10.0), sensor=sensor))
    )
    A = held_model.A_c + held_model.B_n @ held_model.C_xi  # the continuous loop's
    slowest = np.max(np.linalg.eigvals(A).real)
    assert predicted["spectral_radius"] == pytest.approx(
        np.exp(slowest / predicted["rate"]), rel=1e-9
    )
    refused = run_cli("linearize", "--carrier", "arm", "--settling-time", "2")
    assert refused.code == 2 and "--settling-time is the free rig's study" in refused.err
    assert refused.err.count("\n") == 1
