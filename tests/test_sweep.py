"""The sweep: its starts, its independence of workers and chunks, its engines, its CLI.

Truth for the starts: SafeDomain.contains on the camera map of each pose, and
E0 from Drake's MultibodyPlant (CalcKineticEnergy) plus k_p phi0 from
NavigationFunction, independent of the kernels the sweep uses.
"""

import copy
import csv
import json
import math

import numpy as np
import psutil
import pytest
from pydrake.math import RigidTransform

from geovs_drake.analysis import sweep
from geovs_drake.analysis.monte_carlo import random_initial_poses
from geovs_drake.diagrams import initial_body_states, make_dynamic_servo_diagram
from geovs_drake.geometry.camera import camera_map
from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.scenario import ScenarioConfig


def _same(a: dict, b: dict) -> bool:
    """Equal rows, NaN equal to NaN, nothing rounded."""
    if a.keys() != b.keys():
        return False
    for k in a:
        x, y = a[k], b[k]
        if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
            continue
        if x != y or type(x) is not type(y):
            return False
    return True


def _assert_same_rows(rows: list[dict], reference: list[dict]) -> None:
    assert len(rows) == len(reference)
    for r, ref in zip(rows, reference, strict=True):
        assert _same(r, ref), (r, ref)


def test_rows_do_not_depend_on_workers_or_chunks():
    """40 starts x 3 s: in this process in one chunk, in chunks of 7, and on a
    2-process LocalCluster in chunks of 7 give bit-identical rows; the cluster's
    processes are gone afterwards."""
    config = ScenarioConfig()
    X_BC, twists = sweep.sample_starts(config, 40, seed=1, velocity="bounded")
    reference = sweep.run_sweep(config, X_BC, twists, 3.0, workers=1, chunk=40)
    assert [r["start"] for r in reference.rows] == list(range(40))
    statuses = {r["status"] for r in reference.rows}
    assert "converged" in statuses and "not_converged" in statuses  # both kinds of rows

    chunks7 = sweep.run_sweep(config, X_BC, twists, 3.0, workers=1, chunk=7)
    _assert_same_rows(chunks7.rows, reference.rows)

    before = {p.pid for p in psutil.Process().children(recursive=True)}
    sizes: list[int] = []
    cluster = sweep.run_sweep(
        config, X_BC, twists, 3.0, workers=2, chunk=7, on_chunk=lambda rows: sizes.append(len(rows))
    )
    _assert_same_rows(cluster.rows, reference.rows)
    assert sorted(sizes) == [5, 7, 7, 7, 7, 7]
    left = [
        p
        for p in psutil.Process().children(recursive=True)
        if p.pid not in before and "resource_tracker" not in " ".join(p.cmdline())
    ]
    assert not left, [p.cmdline() for p in left]


def test_interrupt_keeps_the_finished_chunks():
    config = ScenarioConfig()
    X_BC, twists = sweep.sample_starts(config, 20, seed=2)
    seen: list[int] = []

    def stop_after_two(rows: list[dict]) -> None:
        seen.append(len(rows))
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(sweep.SweepInterrupted) as info:
        sweep.run_sweep(config, X_BC, twists, 1.0, workers=1, chunk=6, on_chunk=stop_after_two)
    result = info.value.result
    assert result.interrupted and [r["start"] for r in result.rows] == list(range(12))
    assert sweep.summarize(result)["finished"] == 12


def test_starts_lie_in_D_and_below_the_energy_bound():
    config = ScenarioConfig()
    config.rig.inertia_diagonal = [0.02, 0.03, 0.025]  # the unit twist's energy varies
    n = 300
    X_BC, twists = sweep.sample_starts(config, n, seed=4, velocity="bounded")
    domain = config.domain.to_domain()
    y0 = camera_map(np.stack([np.linalg.inv(X) for X in X_BC]), config.radius)
    assert np.all(domain.contains(y0))

    # E0 from Drake: the plant's kinetic energy of each start's state, plus k_p phi0.
    plant = make_dynamic_servo_diagram(config, log=False).GetSubsystemByName("plant")
    context = plant.CreateDefaultContext()
    kinetic = np.empty(n)
    for i, x in enumerate(initial_body_states(config, X_BC, twists)):
        plant.SetPositionsAndVelocities(context, x)
        kinetic[i] = plant.CalcKineticEnergy(context)
    nf = NavigationFunction(domain, config.goal_features(), config.navigation.to_gains())
    k_p = config.control.potential_gain
    phi0 = np.asarray(nf.value(y0))
    E0 = kinetic + k_p * phi0
    assert np.all(E0 < k_p), float(np.max(E0))
    # Kinetic energy uniform in [0, 0.99 k_p (1 - phi0)): its fraction of the room spans it.
    fraction = kinetic / (k_p * (1 - phi0))
    assert np.all(fraction < sweep.ENERGY_FACTOR + 1e-12)
    assert fraction.min() < 0.05 and fraction.max() > 0.9
    assert abs(np.mean(fraction) - sweep.ENERGY_FACTOR / 2) < 0.05

    # At rest: the same poses as random_initial_poses with the same seed, zero twists.
    X_rest, zero = sweep.sample_starts(config, 5, seed=4)
    poses = random_initial_poses(np.random.default_rng(4), 5, config, shrink=sweep.SHRINK)
    expected = np.stack([p.to_rigid_transform().GetAsMatrix4() for p in poses])
    assert np.allclose(X_rest, expected, atol=1e-12) and not np.any(zero)

    kinematic = copy.deepcopy(config)
    kinematic.plant = "kinematic"
    with pytest.raises(sweep.SweepError, match="velocity 'bounded' needs the dynamic plant"):
        sweep.sample_starts(kinematic, 3, velocity="bounded")


def test_drake_engine_gives_the_batch_engine_statuses():
    """3 sampled starts, and one thrown sideways at 15 m/s (E0 >> k_p) that leaves D."""
    config = ScenarioConfig()
    X_BC, twists = sweep.sample_starts(config, 4, seed=5, velocity="bounded")
    twists[3] = [0.0, 0.0, 0.0, 15.0, 0.0, 0.0]
    batch = sweep.run_sweep(config, X_BC, twists, 10.0, engine="batch", workers=1)
    drake = sweep.run_sweep(config, X_BC, twists, 10.0, engine="drake", workers=1)
    assert [r["status"] for r in drake.rows] == [r["status"] for r in batch.rows]
    assert [r["status"] for r in batch.rows] == ["converged"] * 3 + ["left_domain"]
    for b, d in zip(batch.rows, drake.rows, strict=True):
        assert abs(b["initial_energy_ratio"] - d["initial_energy_ratio"]) < 1e-9
        if b["status"] == "converged":
            assert abs(b["t_converged"] - d["t_converged"]) < 0.1
    assert batch.rows[3]["initial_energy_ratio"] > 1


def test_cli_end_to_end(tmp_path, capsys, run_cli):
    out_dir = tmp_path / "sweep"
    code, out, err = run_cli(
        "sweep",
        *("--starts", "6", "--duration", "2", "--workers", "1", "--chunk", "4"),
        *("--seed", "3", "--out", str(out_dir), "--json"),
    )
    assert code == 0, err
    summary = json.loads(out)
    assert out.count("\n") == 1
    assert summary == json.loads((out_dir / "summary.json").read_text())
    assert summary["starts"] == summary["finished"] == 6
    assert sum(summary["counts"].values()) == 6
    assert summary["plant"] == "dynamic" and summary["velocity"] == "bounded"
    assert summary["guarantee"]["starts"] == summary["starts_below_energy_bound"] == 6
    assert summary["guarantee"]["left_domain"] == 0
    assert (summary["seed"], summary["chunk"], summary["duration"]) == (3, 4, 2.0)
    assert summary["wall_time_s"] > 0
    with open(out_dir / "results.csv", newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = list(reader)
    assert tuple(header) == sweep.ROW_FIELDS
    assert [int(r[0]) for r in rows] == list(range(6))  # rewritten sorted by start
    # The CSV's starts are sample_starts' with the same seed, to the last digit.
    X_BC, _ = sweep.sample_starts(ScenarioConfig(), 6, seed=3, velocity="bounded")
    x0 = [float(v) for v in rows[0][1:4]]
    assert x0 == RigidTransform(X_BC[0]).translation().tolist()
    assert (out_dir / "t_converged.png").is_file() and (out_dir / "starts.png").is_file()
    assert len(err.strip().splitlines()) <= 2  # sparse progress lines, no bar off a TTY


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--starts", "0"], "--starts must be >= 1"),
        (["--starts=-5"], "--starts must be >= 1"),
        (["--duration", "0"], "--duration must be finite and > 0"),
        (["--duration=-1"], "--duration must be finite and > 0"),
        (["--chunk", "0"], "--chunk must be >= 1"),
        (["--workers", "0"], "--workers must be >= 1"),
        (["--plant", "kinematic", "--velocity", "bounded"], "--velocity bounded needs"),
        (["--scheduler", "tcp://127.0.0.1:1"], "cannot reach the Dask scheduler"),
        (["--out", "FILE"], "exists and is not a directory"),
        (["--starts", "many"], "invalid int value"),
    ],
)
def test_cli_bad_input_exits_2_with_one_line(argv, message, tmp_path, capsys, monkeypatch, run_cli):
    monkeypatch.setattr(sweep, "SCHEDULER_TIMEOUT_S", 1.0)
    a_file = tmp_path / "a_file"
    a_file.write_text("not a folder")
    argv = [str(a_file) if a == "FILE" else a for a in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "out")]
    code, out, err = run_cli("sweep", "--starts", "3", "--workers", "1", *argv)
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1 and message in err, err
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()  # nothing written for bad input


@pytest.mark.parametrize("plant,covered", [("dynamic", "E0 < k_p"), ("kinematic", "phi0 < 1")])
def test_cli_line_names_the_guarantee_of_its_plant_and_the_legend_counts(
    plant, covered, tmp_path, capsys, monkeypatch, run_cli
):
    """The kinematic loop has no energy: its line says phi0 < 1, not E0 < k_p. The starts
    plot's legend gives each marker's count (a marker with no points says 0)."""
    import matplotlib.pyplot as plt

    figures = []
    monkeypatch.setattr(plt, "close", figures.append)
    code, out, err = run_cli(
        "sweep",
        *("--plant", plant, "--starts", "4", "--duration", "3", "--workers", "1"),
        *("--out", str(tmp_path)),
    )
    assert code == 0, err
    assert f"| {covered}: 4 starts, of which left D 0" in out
    assert ("E0" in out) == (plant == "dynamic")
    labels = [t.get_text() for t in figures[-1].axes[0].get_legend().get_texts()]
    summary = json.loads((tmp_path / "summary.json").read_text())
    failed = sum(summary["counts"][k] for k in ("left_domain", "lost_visibility", "non_finite"))
    assert labels[0] == "start (4)"
    assert labels[1] == f"not converged ({summary['counts']['not_converged']})"
    assert labels[3] == f"left D / failed ({failed})"


def test_local_cluster_says_nothing_when_the_dashboard_port_is_taken(capfd):
    """Port 8787 busy (another sweep, any Dask session): no UserWarning on stderr."""
    import socket
    import warnings

    busy = socket.socket()
    try:
        busy.bind(("127.0.0.1", 8787))
        busy.listen()
    except OSError:
        pass  # already taken by someone else: the case under test all the same
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            client, cluster = sweep._connect(None, 1)
            client.close()
            cluster.close()
    finally:
        busy.close()
    assert not [w for w in caught if "already in use" in str(w.message)]
    assert "already in use" not in capfd.readouterr().err
