"""The sweep: its starts, its independence of workers and chunks, its parts and their
summaries, resume, its engines, its CLI.

Truth for the starts: SafeDomain.contains on the camera map of each pose, and E0 from
Drake's MultibodyPlant (CalcKineticEnergy) plus k_p phi0 from NavigationFunction,
independent of the kernels the sweep uses. Truth for the summaries: numpy on the rows
themselves, read back from the Parquet files with pandas.
"""

import copy
import json
import os
import re
import time

import numpy as np
import pandas as pd
import psutil
import pyarrow.parquet as pq
import pytest
from pydrake.common.yaml import yaml_dump_typed

from geovs_drake.analysis import sweep
from geovs_drake.geometry.camera import camera_map
from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.loop import build_loop
from geovs_drake.loop.state import initial_body_states
from geovs_drake.scenario import Arm, Kinematic, ScenarioConfig

FAILED = ("left_domain", "lost_visibility", "non_finite")


def _children() -> set[int]:
    return {
        p.pid
        for p in psutil.Process().children(recursive=True)
        if "resource_tracker" not in " ".join(p.cmdline())
    }


# ------------------------------------------------------------------------------ starts
def test_start_i_depends_on_the_seed_and_i_only():
    """Any N, any first index: start i is the same bits (blocks drawn whole)."""
    config = ScenarioConfig()
    X_all, tw_all = sweep.sample_starts(config, 250, seed=7, velocity="bounded")
    for n, first in ((1, 0), (7, 93), (130, 60), (3, 247)):
        X, tw = sweep.sample_starts(config, n, seed=7, velocity="bounded", first=first)
        assert np.array_equal(X, X_all[first : first + n])
        assert np.array_equal(tw, tw_all[first : first + n])
    X_other, _ = sweep.sample_starts(config, 250, seed=8, velocity="bounded")
    assert not np.any(np.all(np.isclose(X_other, X_all), axis=(1, 2)))  # another seed
    # The blocks are independent streams: no two blocks repeat each other.
    b = sweep.START_BLOCK
    assert not np.allclose(X_all[:b], X_all[b : 2 * b])


def test_starts_lie_in_D_and_below_the_energy_bound():
    config = ScenarioConfig()
    config.carrier.inertia_diagonal = [0.02, 0.03, 0.025]  # the unit twist's energy varies
    n = 300
    X_BC, twists = sweep.sample_starts(config, n, seed=4, velocity="bounded")
    domain = config.domain.to_domain()
    y0 = camera_map(np.stack([np.linalg.inv(X) for X in X_BC]), config.radius)
    assert np.all(domain.contains(y0))
    assert np.allclose(X_BC[:, 3], [0, 0, 0, 1]) and np.allclose(
        np.einsum("nij,nkj->nik", X_BC[:, :3, :3], X_BC[:, :3, :3]), np.eye(3)
    )

    # E0 from Drake: the plant's kinetic energy of each start's state, plus k_p phi0.
    plant = build_loop(config, log=False).diagram.GetSubsystemByName("plant")
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

    X_rest, zero = sweep.sample_starts(config, 5, seed=4)
    assert np.array_equal(X_rest, X_BC[:5]) and not np.any(zero)  # the same images at rest

    kinematic = copy.deepcopy(config)
    kinematic.plant = Kinematic()
    with pytest.raises(sweep.SweepError, match="velocity 'bounded' needs the dynamic plant"):
        sweep.sample_starts(kinematic, 3, velocity="bounded")


# ------------------------------------------------------------------- rows and summaries
# dask's own Parquet reader uses a keyword that pandas 3.1 deprecates: not ours to fix.
@pytest.mark.filterwarnings("ignore:The inplace keyword")
@pytest.mark.slow  # 9 s: make test's budget; the sweep's other row tests stay in it
def test_rows_do_not_depend_on_workers_or_chunks(tmp_path):
    """40 starts x 3 s: in this process in one part, in parts of 7 written to Parquet,
    and on a 2-process LocalCluster in parts of 7 give bit-identical rows and the same
    summary; the cluster's processes are gone afterwards."""
    config = ScenarioConfig()
    starts = sweep.SampledStarts(40, seed=1, velocity="bounded")
    reference = sweep.run_sweep(config, starts, 3.0, workers=1, chunk=40)
    assert reference.table["start"].tolist() == list(range(40))
    assert list(reference.table.columns) == list(sweep.ROW_FIELDS)
    statuses = set(reference.table["status"])
    assert "converged" in statuses and "not_converged" in statuses  # both kinds of rows

    chunks7 = sweep.run_sweep(config, starts, 3.0, workers=1, chunk=7, out=tmp_path / "a")
    pd.testing.assert_frame_equal(chunks7.table, reference.table)
    assert sorted(p.name for p in (tmp_path / "a" / "results").iterdir()) == [
        f"part-{i:05d}.parquet" for i in range(6)
    ]

    before = _children()
    sizes: list[int] = []
    cluster = sweep.run_sweep(
        config,
        starts,
        3.0,
        workers=2,
        chunk=7,
        out=tmp_path / "b",
        on_part=sizes.append,
        local_cluster=True,  # 40 starts run in this process by default
    )
    pd.testing.assert_frame_equal(cluster.table, reference.table)
    assert sorted(sizes) == [5, 7, 7, 7, 7, 7]
    assert cluster.report() | {"wall_time_s": 0, "chunk": 0, "workers": 0} == (
        reference.report() | {"wall_time_s": 0, "chunk": 0, "workers": 0}
    )
    assert not _children() - before
    # The dataset reads with dask.dataframe too, as a cluster's user would.
    import dask.dataframe as dd

    frame = dd.read_parquet(str(tmp_path / "b" / "results")).compute()
    frame = frame.sort_values("start").reset_index(drop=True)
    # (dask's string columns carry NaN, pandas' NA, for a missing value: none here.)
    pd.testing.assert_frame_equal(frame, reference.table, check_dtype=False)


def test_a_sweep_below_the_cluster_size_runs_here_on_workers_threads(monkeypatch):
    """Below LOCAL_CLUSTER_MIN_STARTS the batch engine starts no Dask cluster (its start
    costs more than it saves, docs/performance.md): the parts run in this process on
    --workers numba threads, rows identical to one thread's; numba's own count is
    restored. The Drake engine still starts one."""
    import numba

    class Started(Exception):
        pass

    def no_cluster(*args):
        raise Started

    monkeypatch.setattr(sweep.run, "_connect", no_cluster)
    threads: list[int] = []
    compute_part = sweep.here.compute_part

    def counting(*args):
        threads.append(numba.get_num_threads())
        return compute_part(*args)

    monkeypatch.setattr(sweep.here, "compute_part", counting)
    before = numba.get_num_threads()
    config = ScenarioConfig()
    starts = sweep.SampledStarts(6, seed=2, velocity="bounded")
    two = sweep.run_sweep(config, starts, 1.0, workers=2, chunk=3)
    one = sweep.run_sweep(config, starts, 1.0, workers=1, chunk=3)
    assert threads == [min(2, numba.config.NUMBA_NUM_THREADS)] * 2 + [1] * 2
    assert numba.get_num_threads() == before
    pd.testing.assert_frame_equal(two.table, one.table)
    assert 6 < sweep.LOCAL_CLUSTER_MIN_STARTS
    # Drake's engine runs a start on one core: its workers stay processes.
    with pytest.raises(Started):
        sweep.run_sweep(config, starts, 1.0, engine="drake", workers=2)


def test_in_process_the_next_parts_starts_are_prepared_while_a_part_runs(monkeypatch):
    """Each part's starts are drawn once, on the helper thread (the arm's IK beside the
    integration), and the rows are those of the parts run start to end one by one."""
    import threading

    prepare = sweep.here.prepare_part
    threads: list[str] = []

    def recording(part):
        threads.append(threading.current_thread().name)
        return prepare(part)

    monkeypatch.setattr(sweep.here, "prepare_part", recording)
    config = ScenarioConfig()
    starts = sweep.SampledStarts(6, seed=2, velocity="bounded")
    ahead = sweep.run_sweep(config, starts, 0.5, workers=1, chunk=2)
    assert len(threads) == 3 and all(name.startswith("next-part") for name in threads)
    from geovs_drake.analysis.sweep.parts import Part, run_part

    text = yaml_dump_typed(config)
    one_by_one = [
        run_part(Part(text, i, 2 * i, 2 * i + 2, 0.5, "batch", seed=2, velocity="bounded"))[1]
        for i in range(3)
    ]
    rows = pd.concat([t.to_pandas() for t in one_by_one], ignore_index=True)
    pd.testing.assert_frame_equal(ahead.table.reset_index(drop=True), rows, check_like=True)


def test_the_merged_summary_is_the_summary_of_the_rows():
    """Counts, extrema and the guarantee's counts exactly; the convergence-time
    quantiles within the histogram's stated bound of numpy's inverted-CDF quantiles."""
    config = ScenarioConfig()
    X_BC, twists = sweep.sample_starts(config, 120, seed=9, velocity="above")
    result = sweep.run_sweep(config, (X_BC, twists), 4.0, workers=1, chunk=17)
    rows, report = result.table, result.report()
    status = rows["status"].to_numpy()
    assert report["counts"] == {k: int(np.sum(status == k)) for k in report["counts"]}
    assert sum(report["counts"][k] for k in FAILED) > 0  # above the bound: some leave D
    covered = rows["initial_energy_ratio"].to_numpy() < 1
    assert report["guarantee"] == {
        "starts": int(covered.sum()),
        **{k: int(np.sum(covered & (status == k))) for k in FAILED},
    }
    fov = rows["min_fov_margin"].to_numpy()
    assert report["worst_margins"]["fov"] == float(np.min(fov[np.isfinite(fov)]))
    ratio = rows["max_energy_ratio"].to_numpy()
    assert report["max_energy_ratio"] == float(np.max(ratio[np.isfinite(ratio)]))
    assert report["monotone"] == int(rows["monotone"].sum())
    # The free rig has no joints: each run's end is its status, counted as the statuses.
    end = rows["end"].to_numpy()
    assert (end == status).all() and rows["final_joint_speed"].isna().all()
    assert report["ends"] == {k: int(np.sum(end == k)) for k in report["ends"]}
    assert sum(report["ends"].values()) == len(rows)
    t = rows["t_converged"].to_numpy()[status == "converged"]
    bound = report["t_converged_resolution_s"]
    assert bound == 4.0 / (2 * sweep.TIME_BINS)
    for key, q in (("median", 0.5), ("p90", 0.9), ("p99", 0.99)):
        exact = float(np.quantile(t, q, method="inverted_cdf"))
        assert abs(report["t_converged_s"][key] - exact) <= bound * (1 + 1e-12), key
    assert report["t_converged_s"]["max"] == float(np.max(t))
    slowest = [s[0] for s in result.summary.slowest]
    assert slowest == sorted(t, reverse=True)[: len(slowest)]
    assert int(result.summary.grid[0].sum()) == len(rows)
    assert int(result.summary.grid[2].sum()) == sum(report["counts"][k] for k in FAILED)


def test_interrupt_keeps_the_finished_parts_and_resume_finishes_identically(tmp_path):
    """Ctrl-C after two parts keeps them on disk; resume runs the other parts only, and
    the dataset and the summary are those of an uninterrupted run."""
    config = ScenarioConfig()
    starts = sweep.SampledStarts(20, seed=2)
    whole = sweep.run_sweep(config, starts, 1.0, workers=1, chunk=6, out=tmp_path / "whole")
    seen: list[int] = []

    def stop_after_two(n: int) -> None:
        seen.append(n)
        if len(seen) == 2:
            raise KeyboardInterrupt

    out = tmp_path / "cut"
    with pytest.raises(sweep.SweepInterrupted) as info:
        sweep.run_sweep(config, starts, 1.0, workers=1, chunk=6, out=out, on_part=stop_after_two)
    cut = info.value.result
    assert cut.interrupted and cut.summary.finished == 12
    assert cut.table["start"].tolist() == list(range(12))
    # A damaged part is named, removed and run again.
    (out / "results" / "part-00001.parquet").write_bytes(b"not parquet")
    warned: list[str] = []
    resumed = sweep.run_sweep(
        config, starts, 1.0, workers=1, chunk=6, out=out, resume=True, warn=warned.append
    )
    assert len(warned) == 1 and "part-00001.parquet: unreadable part" in warned[0]
    assert resumed.resumed_parts == 1
    pd.testing.assert_frame_equal(resumed.table, whole.table)
    ignore = {"wall_time_s": 0, "resumed_parts": 0}
    assert resumed.report() | ignore == whole.report() | ignore
    # A different sweep in the same folder is refused, naming what differs.
    for change, needle in (
        ({"starts": sweep.SampledStarts(21, seed=2)}, "starts 20, this run 21"),
        ({"starts": sweep.SampledStarts(20, seed=3)}, "seed 2, this run 3"),
        ({"duration": 2.0}, "duration 1.0, this run 2.0"),
        ({"config": ScenarioConfig(radius=0.12)}, "holds another sweep: the scenario"),
    ):
        settings = {"config": config, "starts": starts, "duration": 1.0} | change
        with pytest.raises(sweep.SweepError, match=needle):
            sweep.run_sweep(**settings, workers=1, chunk=6, out=out, resume=True)
    with pytest.raises(sweep.SweepError, match="no sweep in"):
        sweep.run_sweep(config, starts, 1.0, workers=1, out=tmp_path / "none", resume=True)


def test_ctrl_c_while_a_part_finishes_keeps_exactly_the_merged_parts(tmp_path, monkeypatch):
    """In one process a part is finished (its file written) on a thread while the next
    integrates: Ctrl-C in that integration leaves the folder with exactly the parts the
    interrupted result counts (the one being finished is removed, not half-kept), and
    resume completes it to the uninterrupted sweep."""
    config = ScenarioConfig()
    starts = sweep.SampledStarts(20, seed=2)
    whole = sweep.run_sweep(config, starts, 1.0, workers=1, chunk=6, out=tmp_path / "whole")
    compute_part = sweep.here.compute_part
    calls: list[int] = []

    def ctrl_c_at_the_third(*args):
        calls.append(1)
        if len(calls) == 3:  # part 1 is being finished on the thread: Ctrl-C once written
            written = tmp_path / "cut" / "results" / "part-00001.parquet"
            deadline = time.monotonic() + 60
            while not written.exists() and time.monotonic() < deadline:
                time.sleep(0.01)
            assert written.exists()
            raise KeyboardInterrupt
        return compute_part(*args)

    monkeypatch.setattr(sweep.here, "compute_part", ctrl_c_at_the_third)
    out = tmp_path / "cut"
    with pytest.raises(sweep.SweepInterrupted) as info:
        sweep.run_sweep(config, starts, 1.0, workers=1, chunk=6, out=out)
    cut = info.value.result
    files = sorted(p.name for p in (out / "results").iterdir())
    assert files == ["part-00000.parquet"] and cut.summary.finished == 6
    assert cut.table["start"].tolist() == list(range(6))
    monkeypatch.setattr(sweep.here, "compute_part", compute_part)
    resumed = sweep.run_sweep(config, starts, 1.0, workers=1, chunk=6, out=out, resume=True)
    assert resumed.resumed_parts == 1
    pd.testing.assert_frame_equal(resumed.table, whole.table)


def test_drake_engine_gives_the_batch_engine_statuses():
    """3 sampled starts, and one thrown sideways at 15 m/s (E0 >> k_p) that leaves D."""
    config = ScenarioConfig()
    X_BC, twists = sweep.sample_starts(config, 4, seed=5, velocity="bounded")
    twists[3] = [0.0, 0.0, 0.0, 15.0, 0.0, 0.0]
    batch = sweep.run_sweep(config, (X_BC, twists), 10.0, engine="batch", workers=1).table
    drake = sweep.run_sweep(config, (X_BC, twists), 10.0, engine="drake", workers=1).table
    assert drake["status"].tolist() == batch["status"].tolist()
    assert batch["status"].tolist() == ["converged"] * 3 + ["left_domain"]
    assert np.allclose(batch["initial_energy_ratio"], drake["initial_energy_ratio"], atol=1e-9)
    converged = batch["status"] == "converged"
    assert np.all(np.abs(batch["t_converged"] - drake["t_converged"])[converged] < 0.1)
    assert batch["initial_energy_ratio"][3] > 1


# ----------------------------------------------------------------------------------- CLI
def test_cli_end_to_end(tmp_path, run_cli):
    import time

    out_dir = tmp_path / "sweep"
    cpu_before = time.process_time()
    code, out, err = run_cli(
        "sweep",
        *("--starts", "6", "--duration", "2", "--workers", "1", "--chunk", "4"),
        *("--seed", "3", "--out", str(out_dir), "--json", "--csv", "--timings"),
    )
    cpu_after = time.process_time()
    assert code == 0, err
    # --timings: one line of the phases; the parts' phase holds the sweep's own wall
    # time (summary.json), the first part came before the parts ended; then the process's
    # CPU time (this process: read between the clock's two readings here).
    *progress, timings = err.strip().splitlines()
    timings, cpu = timings.split("; CPU ")
    cpu = float(cpu.split(" s on all threads")[0])
    assert cpu_before - 0.01 <= cpu <= cpu_after + 0.01
    line, first = timings.split("timings: ")[1].split("; the first part ")
    phases = {k.strip(): float(v) for k, v in re.findall(r"([a-z -]+) ([0-9.]+) s", line)}
    assert list(phases)[-3:] == ["set-up", "parts", "summary and plots"]
    phases["first part"] = float(first.split(" s after")[0])
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
    assert phases["parts"] >= summary["wall_time_s"]
    assert phases["first part"] <= phases["set-up"] + phases["parts"]
    rows = pd.read_parquet(out_dir / "results").sort_values("start")
    assert rows["start"].tolist() == list(range(6))
    # The rows' starts are sample_starts' with the same seed, to the last digit.
    X_BC, _ = sweep.sample_starts(ScenarioConfig(), 6, seed=3, velocity="bounded")
    assert rows[["x", "y", "z"]].to_numpy().tolist() == X_BC[:, :3, 3].tolist()
    text = pd.read_csv(out_dir / "results.csv")
    assert list(text.columns) == list(sweep.ROW_FIELDS)
    assert np.allclose(text["t_converged"], rows["t_converged"], equal_nan=True)
    record = json.loads((out_dir / "sweep.json").read_text())
    assert (record["seed"], record["starts"], record["chunk"], record["parts"]) == (3, 6, 4, 2)
    assert (out_dir / "t_converged.png").is_file() and (out_dir / "starts.png").is_file()
    assert not [p for p in out_dir.rglob(".*")]  # no temporary file left
    assert len(progress) <= 2  # sparse progress lines, no bar off a TTY

    # --resume of a finished sweep runs nothing and reports the same figures; with
    # --no-plots it draws none and removes the earlier run's, which the next --resume
    # draws again from the parts' summaries, pixel for pixel.
    drawn = {name: (out_dir / name).read_bytes() for name in ("t_converged.png", "starts.png")}
    ignore = {"wall_time_s": 0, "resumed_parts": 0}
    for plots in (["--no-plots"], []):
        code, out, err = run_cli(
            "sweep",
            *("--starts", "6", "--duration", "2", "--workers", "1", "--chunk", "4"),
            *("--seed", "3", "--out", str(out_dir), "--json", "--resume", *plots),
        )
        assert code == 0, err
        again = json.loads(out)
        assert again["resumed_parts"] == 2
        assert again | ignore == summary | ignore
        for name, image in drawn.items():
            assert (out_dir / name).is_file() != bool(plots), (name, plots)
            if not plots:
                assert (out_dir / name).read_bytes() == image


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
        (["--resume"], "--resume: no sweep in"),
        (["--starts", "100001", "--csv"], "--csv writes at most 100000 starts"),
        (["--seed=-1"], "the seed must be an integer >= 0"),
        # The batch engine runs the arm with the exact sensor and the pinhole; the rendered
        # camera is refused with the remedy named.
        (["--carrier", "arm", "--sensor", "rendered"], "(run it with --engine drake)"),
    ],
)
def test_cli_bad_input_exits_2_with_one_line(argv, message, tmp_path, monkeypatch, run_cli):
    monkeypatch.setattr(sweep.run, "SCHEDULER_TIMEOUT_S", 1.0)
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


def test_the_nf_given_as_its_variant_sweeps_as_the_nf(tmp_path, run_cli):
    """``controller: !Nf {}`` is the NF: the batch engine asks what the law is, not how it
    was spelled (it refused "controller = Nf()"), and gives the rows of the default."""
    common = ("--starts", "3", "--duration", "1", "--workers", "1", "--json")
    tagged = run_cli(
        "sweep", *common, "--out", str(tmp_path / "a"), "--scenario-text", "controller: !Nf {}"
    )
    assert tagged.code == 0, tagged.err
    plain = run_cli("sweep", *common, "--out", str(tmp_path / "b"))
    assert plain.code == 0, plain.err
    rows = [pq.read_table(tmp_path / d / "results").to_pandas() for d in ("a", "b")]
    assert len(rows[0]) == 3 and rows[0].equals(rows[1])


def test_the_csv_limit_the_help_names_is_the_one_enforced(run_cli):
    """The help says 10^5 without importing the sweep (the command line starts light)."""
    run = run_cli("sweep", "--help")
    assert run.code == 0 and "10^5 starts" in " ".join(run.out.split())
    assert sweep.CSV_LIMIT == 10**5
    # So is the size from which a local Dask cluster starts.
    assert "cluster, started for 100000 starts" in " ".join(run.out.split())
    assert sweep.LOCAL_CLUSTER_MIN_STARTS == 100_000


def test_cli_resume_of_another_sweep_exits_2_and_leaves_the_folder_as_it_was(tmp_path, run_cli):
    out_dir = tmp_path / "sweep"
    common = ("--duration", "1", "--workers", "1", "--out", str(out_dir))
    assert run_cli("sweep", "--starts", "3", *common).code == 0
    before = {p: p.stat().st_mtime_ns for p in out_dir.rglob("*")}
    code, out, err = run_cli("sweep", "--starts", "4", "--resume", *common)
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        f"geovs-drake: --resume: {out_dir} holds another sweep: starts 3, this run 4"
    ]
    assert {p: p.stat().st_mtime_ns for p in out_dir.rglob("*")} == before


@pytest.mark.parametrize("plant,covered", [("dynamic", "E0 < k_p"), ("kinematic", "phi0 < 1")])
def test_cli_line_names_the_guarantee_of_its_plant_and_the_legend_counts(
    plant, covered, tmp_path, monkeypatch, run_cli
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
    failed = sum(summary["counts"][k] for k in FAILED)
    assert labels[0] == "start (4)"
    assert labels[1] == f"not converged ({summary['counts']['not_converged']})"
    assert labels[3] == f"left D / failed ({failed})"


@pytest.mark.slow  # 3 s (a Dask cluster of its own): make test's budget
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
            client, cluster = sweep.run._connect(None, 1)
            client.close()
            cluster.close()
    finally:
        busy.close()
    assert not [w for w in caught if "already in use" in str(w.message)]
    assert "already in use" not in capfd.readouterr().err


def test_part_files_are_written_whole_or_not_at_all(tmp_path, monkeypatch):
    """A writer that dies mid-file leaves no part under its final name."""
    from geovs_drake.analysis.sweep import parts

    def broken(table, where):
        with open(where, "wb") as f:
            f.write(b"PAR1 half a file")
        raise OSError("disk full")

    monkeypatch.setattr(pq, "write_table", broken)
    part = parts.Part(
        config_yaml=yaml_dump_typed(ScenarioConfig()),
        index=0,
        first=0,
        last=2,
        duration=0.5,
        engine="batch",
        results=str(tmp_path),
    )
    with pytest.raises(OSError, match="disk full"):
        parts.run_part(part, "part-00000.parquet")
    assert os.listdir(tmp_path) == []


def test_pose_columns_are_drakes_roll_pitch_yaw():
    """The parts' batched RollPitchYaw against Drake's, pose by pose (within 1e-9: the
    closed form loses digits only near pitch = +-90 deg, where roll and yaw trade)."""
    from pydrake.math import RigidTransform, RollPitchYaw

    from geovs_drake.analysis.sweep.parts import _pose_columns

    rng = np.random.default_rng(0)
    X = np.stack(
        [
            RigidTransform(
                RollPitchYaw(rng.uniform(-3, 3, 3)), rng.uniform(-1, 1, 3)
            ).GetAsMatrix4()
            for _ in range(500)
        ]
    )
    X[7] = np.nan  # a non-finite pose gives NaN columns
    columns = _pose_columns(X)
    for i in (i for i in range(len(X)) if i != 7):
        rpy = RollPitchYaw(RigidTransform(X[i]).rotation()).vector()
        got = [columns[k][i] for k in ("roll", "pitch", "yaw")]
        assert np.allclose(got, rpy, atol=1e-9), i
        assert [columns[k][i] for k in ("x", "y", "z")] == X[i, :3, 3].tolist()
    assert all(np.isnan(columns[k][7]) for k in ("x", "roll", "yaw"))


_WORKER = """
import pickle, sys
from geovs_drake.analysis.sweep.parts import Part, run_part
text, parameters = pickle.loads(sys.stdin.buffer.read())
part = Part(text, 0, 0, 3, 1.0, "batch", parameters, seed=4, velocity="bounded")
summary, table = run_part(part)
heavy = [m for m in ("geovs_drake.loop.build", "pydrake.multibody.plant", "pandas")
         if m in sys.modules]
sys.stdout.buffer.write(pickle.dumps((heavy, table.to_pandas())))
"""


def test_a_worker_runs_its_part_without_building_or_importing_a_diagram():
    """The client ships loop_parameters; a worker then needs the engine only (start-up),
    and its part's table no pandas (pyarrow's own conversion imports it: 0.3-0.9 s)."""
    import pickle
    import subprocess
    import sys

    from geovs_drake.analysis.sweep.parts import Part, run_part
    from geovs_drake.batch import loop_parameters

    config = ScenarioConfig()
    shipped = pickle.dumps((yaml_dump_typed(config), loop_parameters(config)))
    done = subprocess.run(
        [sys.executable, "-c", _WORKER], input=shipped, capture_output=True, check=True
    )
    heavy, table = pickle.loads(done.stdout)
    assert heavy == []
    # The same rows as a part run here, where the diagram is built (parameters=None).
    text = yaml_dump_typed(config)
    _, here = run_part(Part(text, 0, 0, 3, 1.0, "batch", None, seed=4, velocity="bounded"))
    pd.testing.assert_frame_equal(table, here.to_pandas())


def test_a_parts_file_is_byte_for_byte_pyarrows_own_conversion(tmp_path):
    """The part's arrays, built from their buffers, write the same Parquet bytes as
    pyarrow's own conversion of the same columns (pa.array): NaN, inf, strings, bools."""
    import pyarrow as pa

    from geovs_drake.analysis.sweep.parts import HOVER_FIELDS, ROW_FIELDS, _table

    rng = np.random.default_rng(3)
    n = 37
    columns = {}
    for k in (*ROW_FIELDS, *HOVER_FIELDS):
        if k in ("status", "end"):
            columns[k] = rng.choice(["converged", "left_domain", "not_converged", ""], n)
        elif k in ("monotone", "torque_clamped"):
            columns[k] = rng.random(n) > 0.5
        elif k == "start":
            columns[k] = np.arange(100, 100 + n)
        else:
            v = rng.normal(size=(n, 2))[:, 1]  # a strided column, as min_margins[:, j]
            v[[2, 5]] = np.nan, np.inf
            columns[k] = v
    summary = {"finished": n}
    ours = _table(columns, summary)
    arrays = [
        pa.array([str(s) for s in v], pa.string())
        if k in ("status", "end")
        else pa.array(np.asarray(v, bool if k in ("monotone", "torque_clamped") else None))
        for k, v in columns.items()
    ]
    theirs = pa.Table.from_arrays(arrays, names=list(columns))
    theirs = theirs.replace_schema_metadata(ours.schema.metadata)
    assert ours.schema == theirs.schema
    pq.write_table(ours, tmp_path / "ours.parquet")
    pq.write_table(theirs, tmp_path / "theirs.parquet")
    assert (tmp_path / "ours.parquet").read_bytes() == (tmp_path / "theirs.parquet").read_bytes()


@pytest.mark.slow  # 4 s: make test's budget; the arm's camera sweep below keeps the engine in it
def test_the_drake_engine_runs_the_arm_keeping_each_starts_energy_ratio():
    """`sweep --engine drake` on the arm: IK for each start (``unreachable`` where there
    is none), the sampled twist carried to the joints at the kinetic energy that keeps
    E0 / k_p. The truth: the batch engine's E0 / k_p of the same starts on the free rig
    (the arm's k_p is ten times the rig's, its kinetic energy scaled alike)."""
    arm = ScenarioConfig(carrier=Arm())
    starts = sweep.SampledStarts(5, seed=3, velocity="bounded")
    on_arm = sweep.run_sweep(arm, starts, 2.0, engine="drake", workers=1)
    free = sweep.run_sweep(ScenarioConfig(), starts, 2.0, workers=1)
    rows, reference = on_arm.table, free.table
    counts = on_arm.summary.counts
    assert set(sweep.ARM_STATUSES) <= set(counts) and sum(counts.values()) == 5
    reached = (rows["status"] != "unreachable").to_numpy()
    assert reached.any() and on_arm.potential_gain == 10 * free.potential_gain
    ratio = rows["initial_energy_ratio"].to_numpy()[reached]
    assert np.allclose(ratio, reference["initial_energy_ratio"].to_numpy()[reached], rtol=1e-6)
    assert np.all(ratio < 1) and rows["monotone"].all()
    assert counts["joint_limit"] == 0 and counts["left_domain"] == 0
    # The arm's end: no barrier (phi_q 0), the nearest joint inside its range; none where
    # IK found no joints.
    arm = rows[reached]
    assert (arm["final_joint_barrier"] == 0).all() and (arm["final_joint_margin"] > 0).all()
    assert np.isfinite(arm["final_joint_speed"]).all()
    assert rows[~reached][["final_joint_speed", "final_joint_margin"]].isna().all().all()
    assert set(arm["end"]) <= {"converged", "moving", "stalled"}


def test_the_cli_line_counts_how_the_arm_s_runs_ended(tmp_path, run_cli):
    """On the arm the line adds the runs' ends (a stall at the barrier told from a run
    still moving), the counts of summary.json's ends."""
    run = run_cli(
        "sweep",
        *("--carrier", "arm", "--engine", "drake", "--starts", "2", "--duration", "0.5"),
        *("--workers", "1", "--out", str(tmp_path)),
    )
    assert run.code == 0, run.err
    ends = json.loads((tmp_path / "summary.json").read_text())["ends"]
    listed = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in ends.items() if v)
    assert sum(ends.values()) == 2 and f"| ends: {listed} |" in run.out, run.out


def test_the_drake_engine_sweeps_the_arm_through_its_camera(run_cli):
    """`sweep --carrier arm --engine drake --sensor pinhole` (issue 31): the starts are the
    exact sweep's (drawn on the exact y with the free rig's kernels), each run through the
    30 Hz camera, so the rows' final errors are the camera loop's, not the exact one's;
    the batch engine, which runs the arm with the exact y and the pinhole, refuses the
    rendered camera on the arm in one line."""
    from geovs_drake.scenario import Pinhole

    starts = sweep.SampledStarts(1, seed=2, velocity="bounded")  # a start the arm reaches
    camera = sweep.run_sweep(
        ScenarioConfig(carrier=Arm(), sensor=Pinhole()), starts, 1.0, engine="drake", workers=1
    )
    exact = sweep.run_sweep(ScenarioConfig(carrier=Arm()), starts, 1.0, engine="drake", workers=1)
    for column in ("initial_energy_ratio",):  # the same starts, at the same E0 / k_p
        np.testing.assert_allclose(camera.table[column], exact.table[column], rtol=1e-9)
    assert (camera.table["status"] != "unreachable").all()  # the arm ran this start
    errors = [run.table["final_position_error_m"].to_numpy() for run in (camera, exact)]
    assert np.isfinite(errors).all()
    assert not np.allclose(errors[0], errors[1], rtol=1e-6, atol=0)
    run = run_cli(
        "sweep", "--carrier", "arm", "--sensor", "rendered", "--starts", "2", "--duration", "1"
    )
    assert run.code == 2 and "--engine drake" in run.err
    assert run.err.count("\n") == 1
