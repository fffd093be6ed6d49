"""A stiff user arm (``tests/data/stiff_6r.urdf``): the step limit from the arm's goal
model (simulation.step_limit), and the one warning line that names the goal's fastest
mode and the remedy.

Truths: the eigenvalues of Drake's own ``Linearize`` of the whole arm loop at the goal
(``linearize_arm_at_goal``), the fixture's own numbers (the last link's inertia about its
axis and the damping on that joint), the explicit schemes' stability polynomials (Drake's
own steps on a linear mode: test_step_limit.py), and the runs themselves: their step
counts, with the explicit scheme and with the remedy. The dynamic arm's default scheme is
RK5 (its traits), so the warning and the bound are RK5's; the slow runs pin RK3.
"""

from __future__ import annotations

import importlib.metadata
import math
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from geovs_drake.analysis.linear.arm_study import linearize_arm_at_goal
from geovs_drake.goal.step_limit import (
    IMPLICIT_REMEDY,
    STABILITY_MARGIN,
    STABILITY_POLYNOMIALS,
    STIFFNESS_RATIO,
)
from geovs_drake.loop import resolve
from geovs_drake.scenario import DEFAULT_MAX_STEP, Arm, PoseConfig, ScenarioConfig, load_scenario
from geovs_drake.simulation import simulate

DATA = Path(__file__).parent / "data"
STIFF_URDF = DATA / "stiff_6r.urdf"
#: The UR5's scene (its base and camera, ARMS["default"]): the fixture has its kinematics.
BASE = PoseConfig(xyz=[-0.85, 0.65, 1.0], rpy=[0.0, 0.0, -math.pi / 2])
CAMERA = PoseConfig(xyz=[0.0, 0.0, 0.03])
#: A small move to the goal (test_step_limit's), whose transient is short.
NEAR = PoseConfig(xyz=[0.02, -0.01, -0.52], rpy=[0.02, -0.01, 0.1])
#: The fixture's last link about its axis, m r^2 / 2 [kg m^2], and the damping on that
#: joint: the arm's joint_damping and the law's rotational B times the dynamic arm's
#: gain scale (10), through J_C, whose last column is that axis [N m s/rad].
LAST_LINK_INERTIA = 0.3 * 0.03**2 / 2
LAST_JOINT_DAMPING = Arm().joint_damping + 10 * ScenarioConfig().control.damping[0]
RK3 = "runge_kutta3"


def _stiff(**fields) -> ScenarioConfig:
    carrier = Arm(
        model=str(STIFF_URDF), end_effector_frame="tool0", base_pose=BASE, camera_offset=CAMERA
    )
    return ScenarioConfig(carrier=carrier, **fields)


def _drake_modes(config: ScenarioConfig) -> np.ndarray:
    """The nonzero eigenvalues of Drake's Linearize of the arm loop at the goal."""
    eigenvalues = np.linalg.eigvals(linearize_arm_at_goal(config).A_drake)
    return eigenvalues[np.abs(eigenvalues) > 1e-9 * np.abs(eigenvalues).max()]


def _inside(scheme: str, h: float, modes: np.ndarray) -> bool:
    R = STABILITY_POLYNOMIALS[scheme][::-1]
    return bool(np.all(np.abs(np.polyval(R, h * modes)) <= 1 + 1e-12))


def _real_edge(scheme: str) -> float:
    """Where the scheme's real stability interval ends: the negative real root of
    R(z) = +-1 nearest 0 (numpy's roots; RK3's is R = -1 at z = -2.5127)."""
    R = np.array(STABILITY_POLYNOMIALS[scheme][::-1])
    roots = np.concatenate([np.roots(R - np.eye(len(R))[-1] * s) for s in (1, -1)])
    real = roots[(np.abs(roots.imag) < 1e-9) & (roots.real < -1e-9)].real
    return float(real.max())


def test_the_stiff_arms_fastest_mode_is_drakes_its_last_joints_damping_over_its_inertia():
    config = _stiff()
    resolved = resolve(config)
    limit, scheme = resolved.step_limit, resolved.config.simulator.integration_scheme
    assert scheme == Arm.traits.dynamic_integration_scheme
    modes = _drake_modes(config)
    fastest, slowest = modes[np.argmax(np.abs(modes))], modes[np.argmin(np.abs(modes))]
    assert limit.fastest_mode == pytest.approx(complex(fastest), rel=1e-6)
    assert limit.slowest_mode == pytest.approx(complex(slowest.real, abs(slowest.imag)), rel=1e-6)
    # Why it is stiff: the last joint alone, its damping over the last link's inertia.
    assert limit.fastest_mode.real == pytest.approx(
        -LAST_JOINT_DAMPING / LAST_LINK_INERTIA, rel=0.01
    )
    assert limit.fastest_joint == "wrist_3_joint"
    assert limit.stiffness > STIFFNESS_RATIO and limit.stiff
    # The scheme's step is held at its real-axis edge over that mode. On RK3 the automatic
    # limit stays the cap (the bound's share took more steps); on RK5 it is the bound's
    # share (its trial stages beyond the bound overflow before its error control rejects).
    assert limit.stable_step == pytest.approx(_real_edge(scheme) / fastest.real, rel=1e-6)
    assert _inside(scheme, limit.stable_step, modes)
    assert not _inside(scheme, 1.01 * limit.stable_step, modes)
    assert limit.automatic
    assert limit.max_step_size == pytest.approx(STABILITY_MARGIN * limit.stable_step)
    config.simulator.integration_scheme = RK3
    assert resolve(config).step_limit.max_step_size == DEFAULT_MAX_STEP


@pytest.mark.parametrize("scheme", [None, RK3])
@pytest.mark.parametrize("model", ["default", "panda"])
def test_the_named_arms_step_keeps_drakes_goal_modes_in_the_region_and_no_warning(model, scheme):
    """The UR5's cap (0.05 s) is beyond RK3's region at its goal: its step comes down to
    the bound's share; inside RK5's (the default's), kept. The Panda's cap is inside
    both: kept. Neither is stiff or warned."""
    if model == "panda":
        try:
            importlib.metadata.distribution("example-robot-data")
        except importlib.metadata.PackageNotFoundError:
            pytest.skip('the Panda needs example-robot-data: pip install "geovs-drake[panda]"')
    config = ScenarioConfig(carrier=Arm(model=model))
    config.simulator.integration_scheme = scheme
    resolved = resolve(config)
    limit, scheme = resolved.step_limit, resolved.config.simulator.integration_scheme
    modes = _drake_modes(config)
    assert _inside(scheme, limit.max_step_size, modes)
    assert not limit.stiff and limit.stiffness < 100
    assert limit.warning(scheme) is None
    if model == "default" and scheme == RK3:
        assert not _inside(scheme, DEFAULT_MAX_STEP, modes)
        assert limit.max_step_size == pytest.approx(STABILITY_MARGIN * limit.stable_step)
        assert limit.max_step_size < DEFAULT_MAX_STEP
    else:
        assert _inside(scheme, DEFAULT_MAX_STEP, modes)
        assert limit.max_step_size == DEFAULT_MAX_STEP


def test_the_ur5_reaches_the_goal_to_rounding_and_stays():
    """From the small move the dynamic UR5's pose error is below 1e-12 m from 30 s on, to
    45 s (its slowest mode is -0.91 1/s). With the 0.05 s cap, beyond its goal's bound,
    it stalled near 1e-10 m from 20 s on and drifted up to 2.9e-9 m."""
    config = ScenarioConfig(carrier=Arm(), duration=45.0, initial=NEAR)
    result = simulate(config)
    error = np.linalg.norm(result.X_BC[:, :3, 3] - config.X_BC_goal.translation(), axis=1)
    after = error[np.searchsorted(result.times, 30.0) :]
    assert np.max(after) < 1e-12, np.max(after)
    assert result.step_warning is None


def _scenario_text(extra: str = "") -> list[str]:
    """``--scenario-text`` of the stiff arm in the UR5's scene, and ``extra`` fields."""
    text = f"{{carrier: !Arm {{model: {STIFF_URDF}, end_effector_frame: tool0, "
    text += "base_pose: {xyz: [-0.85, 0.65, 1.0], rpy: [0, 0, -1.5707963267948966]}, "
    text += "camera_offset: {xyz: [0, 0, 0.03]}}"
    return ["--scenario-text", text + extra + "}"]


def test_the_stiff_arm_gets_one_warning_line_naming_the_mode_and_the_remedy(run_cli):
    run = run_cli("simulate", "--duration", "0.02", *_scenario_text())
    # The step limit's line among the run's warnings (others, e.g. the torques', may join).
    warnings = [line for line in run.err.splitlines() if "warning: the loop is stiff" in line]
    assert run.code == 3 and len(warnings) == 1, run.err
    line = warnings[0]
    resolved = resolve(_stiff(duration=0.02))
    limit, scheme = resolved.step_limit, resolved.config.simulator.integration_scheme
    assert f"fastest mode ({limit.fastest_mode.real:.4g} 1/s, mostly wrist_3_joint)" in line
    assert f"{scheme} is stable there only for steps below {limit.stable_step:.3g} s" in line
    # The remedy as the line writes it: a layer that loads, and names the implicit scheme.
    remedy = shlex.split(re.search(r'--scenario-text ("[^"]*")', line).group(1))[0]
    assert load_scenario(data=remedy).simulator.integration_scheme == IMPLICIT_REMEDY
    # With the remedy the line is gone (an implicit scheme is not held to the bound).
    fixed = _scenario_text(", simulator: {integration_scheme: radau3}")
    run = run_cli("simulate", "--duration", "0.02", *fixed)
    assert run.code == 3 and "stiff" not in run.err and "radau3" not in run.err, run.err


@pytest.mark.slow  # 5 s; the warning's test above keeps the stiff arm in make test
def test_rk3s_steps_on_the_stiff_arm_are_held_by_the_bound_and_the_remedys_are_not():
    """0.4 s from the small move: RK3 takes at least duration / stable_step steps (the
    bound holds them, whatever the accuracy asks) and at most 15% more; radau3 (the
    warning's remedy) takes five times fewer or less."""
    config = _stiff(duration=0.4, initial=NEAR)
    config.simulator.integration_scheme = RK3
    explicit = simulate(config)
    limit = explicit.step_limit
    assert limit.explicit_steps == math.ceil(0.4 / limit.stable_step)
    assert limit.explicit_steps <= explicit.steps <= 1.15 * limit.explicit_steps
    config.simulator.integration_scheme = IMPLICIT_REMEDY
    implicit = simulate(config)
    assert implicit.step_warning is None and implicit.step_limit.stable_step is None
    assert implicit.steps * 5 <= explicit.steps, (implicit.steps, explicit.steps)
    # The same trajectory: both at the accuracy 1e-6 of the same loop.
    assert np.allclose(implicit.X_BC[-1], explicit.X_BC[-1], atol=1e-5)


@pytest.mark.slow
def test_thirty_seconds_of_the_stiff_arm_on_rk3_and_on_the_remedy():
    """The user's report, reproduced: 30 s of the stiff arm from the docs' small start.
    RK3 takes about duration / stable_step steps (measured 310,301 against 309,823; about
    3 min of wall), radau3 a hundred times fewer or less (measured 1,615); both converge."""
    config = _stiff(initial=PoseConfig(xyz=[0.05, -0.03, -0.55], rpy=[0.1, -0.05, 0.3]))
    config.simulator.integration_scheme = RK3
    explicit = simulate(config)
    assert explicit.status == "converged", explicit.message
    assert explicit.steps == pytest.approx(explicit.step_limit.explicit_steps, rel=0.02)
    assert IMPLICIT_REMEDY in explicit.step_warning
    config.simulator.integration_scheme = IMPLICIT_REMEDY
    implicit = simulate(config)
    assert implicit.status == "converged", implicit.message
    assert implicit.steps * 100 <= explicit.steps, (implicit.steps, explicit.steps)
    assert implicit.wall_time_s * 10 <= explicit.wall_time_s
