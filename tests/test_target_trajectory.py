"""A target moving along a trajectory of poses (``target_motion: !Trajectory``): the config
and its checks, the body twist of Drake's spatial velocity, the TargetMotion system along
a PiecewisePose, and the command line's ``--target-trajectory``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.framework import SystemScalarConverter
from pydrake.trajectories import PiecewisePose

from geovs_drake.geometry.target_motion import (
    body_twist_of_spatial,
    body_twist_rate_of_spatial,
    se3_exp,
    se3_log,
)
from geovs_drake.scenario import ScenarioConfig, Twist, load_scenario
from geovs_drake.scenario.targets import (
    TARGET_VARIANTS,
    Trajectory,
    check_target_motion,
    target_motion_arguments,
    target_trajectory,
    trajectory_of,
)
from geovs_drake.systems.target_motion import TargetMotion, matrix_of_pose

#: The moving-target tests' twist: a circle of radius 0.25 m in the target's x-y plane.
XI_B = np.array([0.0, 0.0, 0.2, 0.05, 0.0, 0.0])
#: A start pose X_WB0 with a rotation (which must not change the body twist).
X_WB0 = RigidTransform(RollPitchYaw(0.3, -0.2, 0.7), [0.1, -0.4, 1.5])
#: Rows of a small trajectory of X_B0B: t, qw, qx, qy, qz, x, y, z.
ROWS = [
    [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [1.0, 0.9, 0.1, -0.2, 0.3, 0.1, 0.05, -0.02],
    [2.5, 0.8, -0.3, 0.1, 0.4, 0.3, -0.1, 0.1],
    [4.0, 0.7, 0.2, 0.3, -0.1, 0.2, 0.2, 0.3],
]
#: The central differences' step [s].
H = 1e-5


def _csv(path: Path, rows: list[list[float]]) -> Path:
    lines = ["# a trajectory of poses", "t, qw, qx, qy, qz, x, y, z"]
    lines += [", ".join(repr(v) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _pose_matrix(row: list[float]) -> np.ndarray:
    q = np.asarray(row[1:5]) / np.linalg.norm(row[1:5])
    return RigidTransform(Quaternion(q), row[5:]).GetAsMatrix4()


def _system(rows: list[list[float]]):
    trajectory = target_trajectory(Trajectory(poses=rows))
    system = TargetMotion(X_WB0=X_WB0, trajectory=trajectory)
    return system, system.CreateDefaultContext(), trajectory


def _at(port, context, t: float) -> np.ndarray:
    context.SetTime(t)
    return np.array(port.Eval(context))


def _body_twist_by_differences(system, context, t: float) -> np.ndarray:
    """xi_B(t) of the system's target_pose: se3_log(X_WB(t-h)^-1 X_WB(t+h)) / 2h."""
    before = matrix_of_pose(_at(system.target_pose_output, context, t - H))
    after = matrix_of_pose(_at(system.target_pose_output, context, t + H))
    return se3_log(np.linalg.solve(before, after)) / (2 * H)


# ------------------------------------------------------------------ the config
def test_csv_and_inline_rows_load_to_the_same_trajectory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the file is relative to the current directory
    _csv(tmp_path / "path.csv", ROWS)
    from_file = load_scenario(data="target_motion: !Trajectory {file: path.csv}").target_motion
    inline = load_scenario(
        data=f"target_motion: !Trajectory {{poses: {ROWS}, feedforward: known}}"
    ).target_motion
    assert isinstance(from_file, Trajectory) and inline.poses == ROWS
    assert (from_file.feedforward, inline.feedforward) == ("estimated", "known")
    check_target_motion(from_file)
    check_target_motion(inline)
    for t in (0.0, 0.7, 2.5, 3.9):
        a, b = target_trajectory(from_file), target_trajectory(inline)
        np.testing.assert_array_equal(a.GetPose(t).GetAsMatrix4(), b.GetPose(t).GetAsMatrix4())
    assert TARGET_VARIANTS["trajectory"] is Trajectory
    ScenarioConfig(target_motion=inline).validate()


def test_shipped_circle_is_the_constant_twist_at_its_knots():
    path = Path(__file__).resolve().parents[1] / "geovs_drake/scenarios/target_circle.csv"
    trajectory = target_trajectory(Trajectory(file=str(path)))
    xi = np.array([0.0, 0.0, 0.1, 0.02, 0.0, 0.0])
    assert (trajectory.start_time(), trajectory.end_time()) == (0.0, 20.0)
    for t in (0.25, 7.5, 20.0):
        np.testing.assert_allclose(
            trajectory.GetPose(t).GetAsMatrix4(), se3_exp(t * xi), atol=1e-10
        )


def _bad_rows(k: int, value: list) -> list:
    return [*ROWS[:k], value, *ROWS[k + 1 :]]


@pytest.mark.parametrize(
    "motion, needles",
    [
        (Trajectory(), ["exactly one of file", "file = ''", "poses = none"]),
        (Trajectory(file="x.csv", poses=ROWS), ["exactly one of file", "4 rows"]),
        (Trajectory(poses=_bad_rows(1, [1.0, 1.0, 0.0])), ["poses[1]", "8 finite", "[1.0, 1.0"]),
        (Trajectory(poses=_bad_rows(2, [2.5, 1, 0, 0, 0, np.nan, 0, 0])), ["poses[2]", "nan"]),
        (Trajectory(poses=_bad_rows(2, [2.5, 0, 0, 0, 0, 0, 0, 0])), ["poses[2]", "zero"]),
        (Trajectory(poses=ROWS[:1]), ["target_motion.poses", "at least 2", "got 1"]),
        (Trajectory(poses=_bad_rows(2, [1.0, *ROWS[2][1:]])), ["poses[2]", "increase", "1 after"]),
        (Trajectory(poses=[[0.5, *ROWS[0][1:]], *ROWS[1:]]), ["poses[0]", "first time", "0.5"]),
        (Trajectory(poses=[ROWS[0][:5] + [0.0, 1e-6, 0.0], *ROWS[1:]]), ["identity", "1e-06"]),
        (Trajectory(poses=[[0.0, 0.9, 0.1, 0, 0, 0, 0, 0], *ROWS[1:]]), ["poses[0]", "identity"]),
        (Trajectory(poses=ROWS, feedforward="psychic"), ["target_motion.feedforward", "psychic"]),
        (Trajectory(poses=ROWS, twist_noise=0.0), ["target_motion.twist_noise", "0.0"]),
    ],
)
def test_a_bad_trajectory_is_one_line_naming_the_field_and_the_value(motion, needles):
    with pytest.raises(ValueError) as error:
        ScenarioConfig(target_motion=motion).validate()
    message = str(error.value)
    assert "\n" not in message
    for needle in needles:
        assert needle in message, message


@pytest.mark.parametrize(
    "text, needles",
    [
        ("t,qw,qx,qy,qz,x,y,z\n0,1,0,0,0,0,0,0\n1,1,0,0,abc,0,0,0\n", ["line 3", "'abc'"]),
        ("0,1,0,0,0,0,0,0\n\n# a comment\n1,1,0,0\n", ["line 4", "8 finite"]),
        ("0,1,0,0,0,0,0,0 # the start\n", ["at least 2 poses", "got 1"]),
        ("", ["at least 2 poses", "got 0"]),
    ],
)
def test_a_bad_file_names_the_file_and_the_line(tmp_path, text, needles):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError) as error:
        check_target_motion(Trajectory(file=str(path)))
    message = str(error.value)
    assert "\n" not in message and f"target_motion.file {str(path)!r}" in message
    for needle in needles:
        assert needle in message, message


def test_a_missing_file_names_it(tmp_path):
    with pytest.raises(ValueError, match=r"target_motion.file '.*nope.csv': cannot read it"):
        check_target_motion(Trajectory(file=str(tmp_path / "nope.csv")))


def test_quaternions_are_normalised_and_either_sign_is_the_identity():
    rows = [[0.0, -2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0, 3.0, 0.1, 0.0, 0.0]]
    trajectory = target_trajectory(Trajectory(poses=rows))
    np.testing.assert_allclose(trajectory.GetPose(0.0).GetAsMatrix4(), np.eye(4), atol=1e-15)
    np.testing.assert_allclose(
        trajectory.GetPose(1.0).GetAsMatrix4(), _pose_matrix(rows[1]), atol=1e-15
    )


def test_target_motion_arguments_give_the_twist_or_the_trajectory():
    twist = target_motion_arguments(Twist(twist=list(XI_B)))
    np.testing.assert_array_equal(twist["twist"], XI_B)
    assert isinstance(target_motion_arguments(Trajectory(poses=ROWS))["trajectory"], PiecewisePose)


def test_trajectory_of_a_piecewise_pose_round_trips():
    times = [0.0, 0.4, 1.0, 1.3]
    poses = [RigidTransform()] + [RigidTransform(_pose_matrix(row)) for row in ROWS[1:]]
    pose = PiecewisePose.MakeCubicLinearWithEndLinearVelocity(times, poses)
    motion = trajectory_of(pose, rate=50.0)
    samples = [row[0] for row in motion.poses]
    assert set(times) <= set(samples) and len(samples) == 1.3 * 50 + 1
    assert np.all(np.diff(samples) > 0)
    again = target_trajectory(motion)
    for t in (*samples, 0.111, 0.95):
        np.testing.assert_allclose(
            again.GetPose(t).GetAsMatrix4(), pose.GetPose(t).GetAsMatrix4(), atol=2e-5
        )
    with pytest.raises(ValueError, match="first time must be 0"):
        trajectory_of(PiecewisePose.MakeLinear([1.0, 2.0], [RigidTransform()] * 2))


# ------------------------------------------------------------------ the geometry
def test_body_twist_and_its_rate_of_a_spatial_velocity_are_central_differences():
    trajectory = target_trajectory(Trajectory(poses=ROWS))
    for t in (0.5, 1.7, 3.2):  # inside segments: the slerp's rate jumps at the knots
        X = trajectory.GetPose(t).GetAsMatrix4()
        before, after = (trajectory.GetPose(t + s).GetAsMatrix4() for s in (-H, H))
        xi = body_twist_of_spatial(X[:3, :3], trajectory.GetVelocity(t))
        np.testing.assert_allclose(xi, se3_log(np.linalg.solve(before, after)) / (2 * H), atol=1e-6)
        rate = body_twist_rate_of_spatial(
            X[:3, :3], trajectory.GetVelocity(t), trajectory.GetAcceleration(t)
        )
        xi_before, xi_after = (
            body_twist_of_spatial(
                trajectory.GetPose(t + s).rotation().matrix(), trajectory.GetVelocity(t + s)
            )
            for s in (-H, H)
        )
        np.testing.assert_allclose(rate, (xi_after - xi_before) / (2 * H), atol=1e-5)


# ------------------------------------------------------------------ the system
def test_target_motion_follows_the_trajectory_from_its_start_pose():
    system, context, trajectory = _system(ROWS)
    for t in (0.0, 0.5, 1.0, 2.2, 4.0):
        X_WB = X_WB0.GetAsMatrix4() @ trajectory.GetPose(t).GetAsMatrix4()
        np.testing.assert_allclose(
            matrix_of_pose(_at(system.target_pose_output, context, t)), X_WB, atol=1e-12
        )
    np.testing.assert_allclose(
        matrix_of_pose(_at(system.target_pose_output, context, 0.0)),
        X_WB0.GetAsMatrix4(),
        atol=1e-12,
    )


def test_target_twist_and_acceleration_are_the_poses_central_differences():
    system, context, _ = _system(ROWS)
    for t in (0.5, 1.7, 3.2):
        np.testing.assert_allclose(
            _at(system.target_twist_output, context, t),
            _body_twist_by_differences(system, context, t),
            atol=1e-5,
        )
        twists = [_at(system.target_twist_output, context, t + s) for s in (-H, H)]
        np.testing.assert_allclose(
            _at(system.target_acceleration_output, context, t),
            (twists[1] - twists[0]) / (2 * H),
            atol=1e-5,
        )


def test_past_its_end_the_target_holds_its_last_pose_at_rest():
    system, context, trajectory = _system(ROWS)
    last = X_WB0.GetAsMatrix4() @ _pose_matrix(ROWS[-1])
    for t in (4.0, 4.5, 100.0):
        np.testing.assert_allclose(
            matrix_of_pose(_at(system.target_pose_output, context, t)), last, atol=1e-12
        )
        assert not np.any(_at(system.target_twist_output, context, t))
        assert not np.any(_at(system.target_acceleration_output, context, t))
    assert np.any(_at(system.target_twist_output, context, 3.9))


def test_a_trajectory_sampled_from_the_constant_twist_moves_with_that_twist():
    rows = []
    for t in np.arange(0.0, 10.0 + 1e-9, 0.05):
        X = se3_exp(t * XI_B)
        q = RotationMatrix(X[:3, :3]).ToQuaternion()
        rows.append([t, q.w(), q.x(), q.y(), q.z(), *X[:3, 3]])
    system, context, _ = _system(rows)
    for t in (2.0, 4.96, 5.0, 7.33):
        np.testing.assert_allclose(_at(system.target_twist_output, context, t), XI_B, atol=1e-3)
        np.testing.assert_allclose(
            matrix_of_pose(_at(system.target_pose_output, context, t)),
            X_WB0.GetAsMatrix4() @ se3_exp(t * XI_B),
            atol=1e-6,
        )


def test_a_trajectorys_twist_follows_the_time_in_one_context():
    """Its twist and acceleration depend on the time (a cached value from an earlier time
    would be stale); the constant twist's stay as they were."""
    system, context, _ = _system(ROWS)
    first = [_at(port, context, 0.5) for port in _rates(system)]
    later = [_at(port, context, 3.2) for port in _rates(system)]
    for a, b in zip(first, later, strict=True):
        assert not np.allclose(a, b)
    constant = TargetMotion(X_WB0=X_WB0, twist=XI_B)
    other = constant.CreateDefaultContext()
    np.testing.assert_array_equal(_at(constant.target_twist_output, other, 3.0), XI_B)
    assert not np.any(_at(constant.target_acceleration_output, other, 3.0))
    with pytest.raises(ValueError, match="not both"):
        TargetMotion(X_WB0=X_WB0, twist=XI_B, trajectory=target_trajectory(Trajectory(poses=ROWS)))


def _rates(system) -> tuple:
    return system.target_twist_output, system.target_acceleration_output


def test_the_copy_constructor_keeps_the_trajectory():
    system, context, _ = _system(ROWS)
    copy = type(system).__new__(type(system))
    type(system)._construct_copy(copy, system, converter=SystemScalarConverter())
    assert copy._trajectory is system._trajectory
    other = copy.CreateDefaultContext()
    for port in ("target_pose", "target_twist", "target_acceleration"):
        np.testing.assert_array_equal(
            _at(copy.GetOutputPort(port), other, 1.7), _at(system.GetOutputPort(port), context, 1.7)
        )


# ------------------------------------------------------------------ the command line
def test_cli_bad_trajectory_file_is_one_line_exit_2(run_cli, tmp_path, monkeypatch):
    (tmp_path / "bad.csv").write_text("t,qw,qx,qy,qz,x,y,z\n0,1,0,0,0,0,0,0\n1,1,0,0,abc,0,0,0\n")
    monkeypatch.chdir(tmp_path)  # the file named as a user would, from where it lies
    run = run_cli("simulate", "--target-trajectory", "bad.csv", "--duration", "1", "--json")
    assert run.code == 2, run.err
    assert run.err.count("\n") == 1 and "Traceback" not in run.err
    assert "'bad.csv', line 3" in run.err and run.out == ""
    assert [p.name for p in tmp_path.iterdir()] == ["bad.csv"]


def test_cli_target_twist_and_trajectory_together_are_one_line(run_cli, tmp_path):
    path = _csv(tmp_path / "path.csv", ROWS)
    run = run_cli(
        "simulate", "--target-twist", "0,0,0.2,0.05,0,0", "--target-trajectory", str(path)
    )
    assert run.code == 2 and run.err.count("\n") == 1
    assert "--target-twist and --target-trajectory" in run.err


def test_cli_target_trajectory_is_the_trajectory_layer(tmp_path):
    from geovs_drake.cli.simulate import _target_trajectory

    path = _csv(tmp_path / "path.csv", ROWS)
    config = load_scenario(
        data=f"target_motion: !Trajectory {{poses: {ROWS}, feedforward: known}}",
        overrides=[("--target-trajectory", {"target_motion": _target_trajectory(str(path))})],
    )
    assert config.target_motion == Trajectory(file=str(path), feedforward="known")
    check_target_motion(config.target_motion)


# ------------------------------------------------------------------ the closed loop
def test_a_trajectory_with_known_feedforward_is_tracked_to_rounding_on_both_plants():
    """The free rig behind a trajectory target (the shipped circle, knots every 0.25 s):
    the known feed-forward (the trajectory's twist and its rate, Coriolis included) makes
    the relative loop a still target's, on the kinematic and the dynamic plant alike;
    read before the trajectory's end, where the target slows to a stop."""
    from geovs_drake.scenario import Dynamic, Kinematic, ScenarioConfig
    from geovs_drake.simulation import simulate

    circle = str(Path(__file__).resolve().parents[1] / "geovs_drake/scenarios/target_circle.csv")
    for plant in (Kinematic(), Dynamic()):
        config = ScenarioConfig(
            plant=plant,
            target_motion=Trajectory(file=circle, feedforward="known"),
            duration=12.0,
        )
        result = simulate(config)
        assert result.status == "converged" and not result.left_domain, result.message
        assert result.steady_tracking_error <= 1e-6, result.message
        # The file's last knot (the shipped circle's 20 s), as the run's motion had it.
        assert result.summary()["target_motion"] == pytest.approx(
            {"kind": "Trajectory", "feedforward": "known", "end_time_s": 20.0}
        )
