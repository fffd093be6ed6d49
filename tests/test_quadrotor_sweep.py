"""The sweep on the quadrotor (``sweep --carrier quadrotor``): level starts in D, the rows'
rotor columns against simulate() from the same start, the summary's fractions against the
rows, and the batch engine and a moving start refused in one line."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from geovs_drake.analysis import sweep
from geovs_drake.analysis.sweep.parts import HOVER_FIELDS, ROW_FIELDS
from geovs_drake.analysis.sweep.starts import level_poses, sample_starts
from geovs_drake.geometry.camera import camera_map
from geovs_drake.scenario import PoseConfig, Quadrotor, ScenarioConfig
from geovs_drake.scenario.carriers import goal_tilt
from geovs_drake.simulation import simulate

#: A start the suite's quadrotor tests use: level, heading 0.3 rad off the goal's.
LEVEL_START = PoseConfig(xyz=[0.12, -0.08, -0.8], rpy=[0.0, 0.3, 0.0])


def _quadrotor(**fields) -> ScenarioConfig:
    return ScenarioConfig(carrier=Quadrotor(**fields), initial=copy.deepcopy(LEVEL_START))


@pytest.mark.parametrize("mount", ["forward", "down"])
def test_levelled_poses_keep_the_camera_s_position_and_heading_with_the_body_level(mount):
    """level_poses against the geometry: the body X_WB X_BC X_RC^-1 of each levelled pose
    has its z axis up (tilt 0), the camera its original position, and the body's x axis
    in the vertical plane of the original body's x axis (the same heading)."""
    config = _quadrotor(mount=mount)
    rng = np.random.default_rng(3)
    rpy, xyz = rng.uniform(-1, 1, (5, 3)), rng.normal(size=(5, 3))
    X_BC = np.stack(
        [RigidTransform(RollPitchYaw(a), p).GetAsMatrix4() for a, p in zip(rpy, xyz, strict=True)]
    )
    level = level_poses(config, X_BC)
    X_RC_inv = config.X_RC.inverse()
    for before, after in zip(X_BC, level, strict=True):
        X_WC = config.X_WB @ RigidTransform(after)
        assert goal_tilt(X_WC, config.X_RC) < 1e-12
        body_before = config.X_WB @ RigidTransform(before) @ X_RC_inv
        body_after = X_WC @ X_RC_inv
        X_WC_before = config.X_WB @ RigidTransform(before)
        np.testing.assert_allclose(X_WC.translation(), X_WC_before.translation(), atol=1e-12)
        x_before = body_before.rotation().matrix()[:, 0]
        x_after = body_after.rotation().matrix()[:, 0]
        assert x_after @ x_before > 0
        assert abs(x_before[0] * x_after[1] - x_before[1] * x_after[0]) < 1e-12


def test_sampled_starts_of_the_quadrotor_are_level_in_d_and_depend_on_the_seed_only():
    """The sweep's starts on a hovering carrier: each body level (tilt 0), each image in
    D, at rest; start i the same drawn alone (first = i) or among others, across the
    sampler's blocks."""
    config = _quadrotor()
    X_BC, twists = sample_starts(config, 120, seed=2)
    domain = config.domain.to_domain()
    for X in X_BC:
        assert goal_tilt(config.X_WB @ RigidTransform(X), config.X_RC) < 1e-12
        assert domain.contains(camera_map(RigidTransform(X).inverse(), config.radius))
    assert not np.any(twists)
    again, _ = sample_starts(config, 3, seed=2, first=98)
    np.testing.assert_array_equal(again, X_BC[98:101])


#: The doc's small move (docs/quadrotor.md), level: the second start of the slow case.
SMALL_MOVE = PoseConfig(xyz=[0.03, 0.02, -0.55], rpy=[0.0, 0.05, 0.0])


@pytest.mark.parametrize(
    "count", [1, pytest.param(2, marks=pytest.mark.slow, id="two_starts")], ids=str
)
def test_sweep_rows_of_the_quadrotor_match_simulate_and_the_summary_adds_up(count):
    """Short starts on the Drake engine (the doc's level start, and the small move in the
    slow case): each row's status and rotor columns are simulate()'s from the same start,
    and the summary's fractions (converged, left D, not converged; saturated) are those of
    the rows."""
    config = _quadrotor()
    starts = [LEVEL_START, SMALL_MOVE][:count]
    X_BC = np.stack([RigidTransform(RollPitchYaw(p.rpy), p.xyz).GetAsMatrix4() for p in starts])
    duration = 0.1
    result = sweep.run_sweep(config, (X_BC, None), duration, engine="drake", workers=1)
    table = result.table
    assert list(table.columns) == [*ROW_FIELDS, *HOVER_FIELDS]
    for start, (_, row) in zip(starts, table.iterrows(), strict=True):
        c = copy.deepcopy(config)
        c.initial, c.duration = start, duration
        r = simulate(c)
        assert row.status == r.status
        for key in HOVER_FIELDS:
            assert row[key] == pytest.approx(r.carrier_entries[key], rel=1e-9, abs=1e-12)
    hover = result.report()["hover"]
    n = len(table)
    for status in ("converged", "left_domain", "not_converged"):
        assert hover[status] == pytest.approx(np.mean(table.status == status))
    assert hover["converged"] + hover["left_domain"] + hover["not_converged"] == pytest.approx(1)
    assert hover["saturated"] == pytest.approx(np.sum(table.rotor_saturation_fraction > 0) / n)
    mean = float(np.mean(table.rotor_saturation_fraction))
    assert hover["mean_saturation_fraction"] == pytest.approx(mean)
    assert hover["max_tilt_deg"] == pytest.approx(float(table.max_tilt_deg.max()))
    assert not math.isnan(hover["max_tilt_deg"])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        # The batch engine integrates the free rig only: the remedy is named.
        (
            [],
            "the batch engine runs the eye-in-hand free rig only: carrier = Quadrotor "
            "(use the Drake engine, sweep --engine drake",
        ),
        (
            ["--engine", "drake", "--velocity", "bounded"],
            "velocity 'bounded': a Quadrotor starts at rest in a level hover",
        ),
    ],
)
def test_cli_refuses_the_batch_engine_and_a_moving_start_in_one_line(
    argv, message, tmp_path, run_cli
):
    code, out, err = run_cli(
        "sweep", "--carrier", "quadrotor", "--starts", "2", "--workers", "1",
        "--out", str(tmp_path / "out"), *argv,
    )  # fmt: skip
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1 and message in err
    assert not (tmp_path / "out").exists()
