"""The baselines in closed loop, and ``geovs-drake compare`` on a mini suite.

What the literature says, checked in our plant: every law converges from a
small move; on a roll of exactly 180 deg about the optical axis (Chaumette's
conundrum) point IBVS with the true depths retreats straight along the optical
axis until it leaves D, and the NF, started on its saddle, stays there, while
179 deg converges.
"""

import csv
import json
import math

import numpy as np
import pytest

from geovs_drake.analysis.studies import compare
from geovs_drake.cli import main
from geovs_drake.scenario import (
    LAW_VARIANTS,
    Dynamic,
    FixedCamera,
    FreeRig,
    Ibvs,
    Kinematic,
    Nf,
    PoseConfig,
    ScenarioConfig,
    SuiteConfig,
    SuiteScenario,
    load_suite,
    variant_name,
)
from geovs_drake.simulation import simulate

SMALL_MOVE = PoseConfig([0.03, -0.02, -0.58], [math.radians(v) for v in (3.0, -2.0, 15.0)])
ROLL_180 = PoseConfig([0.0, 0.0, -0.5], [0.0, 0.0, math.pi])

MINI_SUITE = """\
duration: 8.0
conundrum: roll_180
scenarios:
  - name: small_move
    xyz: [0.03, -0.02, -0.58]
    rpy_deg: [3.0, -2.0, 15.0]
  - name: roll_180
    xyz: [0.0, 0.0, -0.5]
    rpy_deg: [0.0, 0.0, 180.0]
"""


@pytest.mark.parametrize("law", ["ibvs-true", "ibvs-desired", "ibvs-mean", "pbvs", "spherical"])
def test_each_baseline_converges_from_a_small_move_on_the_dynamic_plant(law):
    """(The kinematic plant: the mini suite below.) Through the velocity-tracking wrench."""
    name, _, depth = law.partition("-")
    controller = Ibvs(depth) if depth else LAW_VARIANTS[name]()
    config = ScenarioConfig(plant=Dynamic(), controller=controller, initial=SMALL_MOVE)
    config.duration = 9.0
    result = simulate(config)
    assert result.status == "converged", result.message
    assert result.summary()["min_fov_margin"] > 0 and result.energy is None
    assert result.convergence_time < 7.0


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_ibvs_true_depth_retreats_along_the_optical_axis_on_the_conundrum(plant):
    """The camera backs away along its optical axis without turning, and the run
    stops where it leaves D through lambda_min (2 m from the centre), not at 1e9 m."""
    config = ScenarioConfig(plant=plant, controller=Ibvs(), initial=ROLL_180, duration=20.0)
    result = simulate(config)
    assert result.status == "left_domain", result.message
    assert "lam_min margin" in result.message
    assert result.sim_time_s < 1.0
    p = result.X_BC[:, :3, 3]
    np.testing.assert_allclose(p[:, :2], 0.0, atol=1e-9)  # on the optical axis
    assert np.all(np.diff(p[:, 2]) <= 1e-12)  # always backwards (z_B decreasing)
    distance = -p[-1, 2]
    lam_min = config.domain.lam_min
    assert config.radius / lam_min <= distance < 1.01 * config.radius / lam_min
    # The rotation did not change: still the start's roll of pi.
    np.testing.assert_allclose(result.X_BC[-1, :3, :3], result.X_BC[0, :3, :3], atol=1e-9)
    assert result.summary()["ibvs_depth"] == "true"


@pytest.mark.parametrize("carrier", [FreeRig(), FixedCamera()], ids=variant_name)
def test_an_ibvs_point_out_of_view_stops_the_run_naming_it(monkeypatch, carrier):
    """A square too large for the field of view: the monitor stops the run at once,
    with the status lost_visibility and the point's name; the NF ignores the points.
    The fixed camera (the target is the moving body) checks the same points."""
    import geovs_drake.systems.ibvs_controller as ibvs_module

    monkeypatch.setattr(ibvs_module, "DEFAULT_SQUARE_SIDE", 5.0)  # 0.5 m: corners at 51 deg
    config = ScenarioConfig(
        plant=Kinematic(), controller=Ibvs(), initial=SMALL_MOVE, carrier=carrier
    )
    result = simulate(config)
    assert result.status == "lost_visibility"
    assert "feature b + side (a + n) outside the field of view" in result.message
    assert result.sim_time_s == 0.0
    config.controller = Nf()
    config.duration = 0.5
    assert simulate(config).status != "lost_visibility"


# make test's budget: test_cli_compare_and_simulate_baselines keeps compare's small case.
@pytest.mark.slow
def test_compare_mini_suite_writes_the_table(tmp_path):
    """The kinematic plant, 2 scenarios x 6 laws in this process: every law converges
    from the small move; on 180 deg IBVS (true) leaves D and the NF does not move off
    its saddle. The files hold what the rows say."""
    suite_file = tmp_path / "mini.yaml"
    suite_file.write_text(MINI_SUITE)
    result, files = compare.compare(suite_file, Kinematic(), tmp_path / "out", workers=1)
    rows = {(r["scenario"], r["law"]): r for r in result.rows}
    assert len(rows) == 2 * len(compare.COMPARED_LAWS)
    for variant in compare.COMPARED_LAWS:
        law = compare.law_label(variant)
        row = rows["small_move", law]
        assert row["status"] == "converged", (law, row["message"])
        assert 0 < row["t_converged_s"] < 8 and row["features_in_view"]
    assert rows["roll_180", "ibvs-true"]["status"] == "left_domain"
    assert rows["roll_180", "ibvs-true"]["path_length_m"] == pytest.approx(1.5, abs=0.02)
    nf_180 = rows["roll_180", "nf"]
    assert nf_180["status"] == "not_converged" and "saddle" in nf_180["message"]
    assert nf_180["path_length_m"] < 1e-9
    names = {f.name for f in files}
    assert {"table.md", "table.csv"} <= names
    with open(tmp_path / "out" / "table.csv") as f:
        table = list(csv.DictReader(f))
    assert [(r["scenario"], r["law"], r["status"]) for r in table] == [
        (r["scenario"], r["law"], r["status"]) for r in result.rows
    ]
    md = (tmp_path / "out" / "table.md").read_text()
    assert "| roll_180 | ibvs-true | left_domain |" in md
    matrix = md.split("Every run:")[0]
    assert "| roll_180 | not converged | left D (lam_min, 0.50 s) | left D (lam_max" in matrix
    pytest.importorskip("matplotlib")
    assert {"image_sphere_roll_180.png", "camera_paths.png"} <= names


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_nf_on_its_saddle_at_180_deg_and_converging_at_179(plant):
    """y* and the start rolled by pi are a critical pair: the NF's gradient vanishes
    there, so the loop stays (a note says why); one degree less converges."""
    config = ScenarioConfig(plant=plant, initial=ROLL_180, duration=3.0)
    on_saddle = simulate(config)
    assert on_saddle.status == "not_converged" and on_saddle.saddle_note is not None
    assert np.max(np.abs(on_saddle.X_BC - on_saddle.X_BC[0])) < 1e-9
    config.initial = PoseConfig([0.0, 0.0, -0.5], [0.0, 0.0, math.radians(179.0)])
    config.duration = 10.0 if isinstance(plant, Kinematic) else 4.0
    assert simulate(config).status == "converged"


def test_cli_compare_and_simulate_baselines(tmp_path, capsys):
    """compare exits 0 when its table is finished, whatever the laws did; simulate with
    a baseline that leaves D exits 3 with the status in its JSON; bad input exits 2."""
    suite_file = tmp_path / "one.yaml"
    suite_file.write_text(
        "duration: 1.0\nconundrum: roll_180\nscenarios:\n"
        "  - {name: roll_180, xyz: [0, 0, -0.5], rpy_deg: [0, 0, 180]}\n"
    )
    out = tmp_path / "out"
    argv = ["compare", "--plant", "kinematic", "--suite", str(suite_file), "--out", str(out)]
    assert main([*argv, "--workers", "1", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["counts"]["left_domain"] == 2  # ibvs-true and ibvs-desired
    assert (out / "table.md").exists()
    code = main(
        ["simulate", "--plant", "kinematic", "--controller", "ibvs", "--ibvs-depth", "true",
         "--initial=0,0,-0.5,0,0,3.141592653589793", "--json"]
    )  # fmt: skip
    assert code == 3
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "left_domain" and result["controller"] == "ibvs"
    with pytest.raises(SystemExit) as exit_info:
        main(["simulate", "--controller", "ibvs", "--ibvs-depth", "guess"])
    assert exit_info.value.code == 2 and "invalid choice" in capsys.readouterr().err
    assert main(["compare", "--suite", str(tmp_path / "missing.yaml")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_the_shipped_suite_loads_and_every_start_is_in_D():
    """The package's suite: the scenarios the issue asks for, each start inside D."""
    from geovs_drake.simulation import check_start

    suite = load_suite()
    names = {s.name for s in suite.scenarios}
    assert {
        "small_move",
        "far_off_axis",
        "near_target",
        "roll_170",
        "roll_179",
        "roll_180",
    } <= names
    assert "translation_and_roll" in names and suite.conundrum == "roll_180"
    for _, _, config in compare.suite_cases(suite, Dynamic())[:: len(compare.COMPARED_LAWS)]:
        check_start(config)


@pytest.mark.parametrize(
    "suite, match",
    [
        (SuiteConfig(scenarios=[]), "the suite has none"),
        (SuiteConfig(scenarios=[SuiteScenario("a"), SuiteScenario("a")]), "not unique"),
        (SuiteConfig(scenarios=[SuiteScenario("a", xyz=[0, 0])]), r"scenarios\[0\]\.xyz"),
        (SuiteConfig(conundrum="b", scenarios=[SuiteScenario("a")]), "conundrum 'b'"),
        (SuiteConfig(duration=0.0, scenarios=[SuiteScenario("a")]), "duration must be"),
    ],
)
def test_bad_suites_are_one_line_errors(suite, match):
    with pytest.raises(ValueError, match=match):
        suite.validate()


@pytest.mark.slow  # 7 s: make test's budget; the mini suite's test keeps compare in it
def test_compare_on_the_arm_shows_how_ibvs_fails_at_180_deg(tmp_path, run_cli):
    """`compare --carrier arm` on the conundrum: both point-IBVS baselines take the
    camera out of the field of view (left D), neither reaches a joint limit first;
    the NF sits on its saddle (not converged, in D)."""
    suite = tmp_path / "suite.yaml"
    suite.write_text(
        "duration: 1.0\nconundrum: roll_180\nscenarios:\n"
        "  - {name: roll_180, description: rolled 180 deg, xyz: [0.0, 0.0, -0.5], "
        "rpy_deg: [0.0, 0.0, 180.0]}\n"
    )
    run = run_cli(
        "compare", "--carrier", "arm", "--suite", str(suite), "--out", str(tmp_path / "o"),
        "--workers", "1", "--json",
    )  # fmt: skip
    assert run.code == 0, run.err
    status = {r["law"]: r["status"] for r in json.loads(run.out)["rows"]}
    assert status["ibvs-true"] == status["ibvs-desired"] == "left_domain", status
    assert status["nf"] == "not_converged" and "joint_limit" not in status.values(), status
