"""The sweep on Dask the way clusters run: separate scheduler and worker processes, a
worker killed mid-sweep, a client killed mid-sweep and resumed.

Slow (about a minute together): ``make test-slow`` runs them. The suite keeps their
small cases in tests/test_sweep.py (interrupt and resume in one process, a damaged
part, rows independent of workers and chunks on a LocalCluster).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest

from geovs_drake.analysis import sweep
from geovs_drake.scenario import ScenarioConfig

pytestmark = pytest.mark.slow

BIN = Path(sys.executable).parent
CLI = [sys.executable, "-m", "geovs_drake.cli", "sweep"]


def _wait_for(condition, timeout: float, what: str) -> None:
    deadline = time.time() + timeout
    while not condition():
        if time.time() > deadline:
            raise TimeoutError(what)
        time.sleep(0.2)


def _parts(out: Path) -> int:
    return len(list((out / "results").glob("part-*.parquet")))


@pytest.fixture
def cluster(tmp_path):
    """``dask scheduler`` and two ``dask worker --no-nanny`` processes (one process
    each, so that killing one kills that worker); yields (address, workers)."""
    file = tmp_path / "scheduler.json"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    procs = [
        subprocess.Popen(
            [BIN / "dask", "scheduler", "--scheduler-file", file, "--port", "0"]
            + ["--dashboard-address", ":0"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
        )
    ]
    try:
        _wait_for(file.exists, 30, "the scheduler's file")
        workers = [
            subprocess.Popen(
                [BIN / "dask", "worker", "--scheduler-file", file, "--nthreads", "1"]
                + ["--no-nanny", "--no-dashboard"],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                env=env,
            )
            for _ in range(2)
        ]
        procs += workers
        address = json.loads(file.read_text())["address"]
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
        yield address, workers
    finally:
        for p in procs:
            p.kill()
            p.wait()


def test_a_worker_killed_mid_sweep_costs_no_row(tmp_path, cluster):
    """SIGKILL one of two workers while the sweep runs on the scheduler: the scheduler
    gives its parts to the other, and every start's row is there exactly once."""
    address, workers = cluster
    out = tmp_path / "sweep"
    n = 6000
    client = subprocess.Popen(
        [*CLI, "--scheduler", address, "--starts", str(n), "--chunk", "100", "--duration", "5"]
        + ["--out", str(out), "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait_for(lambda: _parts(out) >= 10, 120, "ten parts")
    workers[0].send_signal(signal.SIGKILL)
    stdout, stderr = client.communicate(timeout=300)
    assert client.returncode == 0, stderr
    assert json.loads(stdout)["finished"] == n
    rows = pd.read_parquet(out / "results")
    assert sorted(rows["start"]) == list(range(n))  # each start once: none lost, none twice
    assert _parts(out) == n // 100


def test_a_client_killed_mid_sweep_resumes_to_the_uninterrupted_result(tmp_path):
    """SIGKILL the client of a LocalCluster sweep: its workers exit on their own, and
    --resume gives the rows and the summary of a sweep that was never interrupted."""
    n, common = 8000, ["--starts", "8000", "--chunk", "200", "--duration", "5", "--json"]
    out = tmp_path / "cut"
    client = subprocess.Popen(
        [*CLI, *common, "--workers", "2", "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    _wait_for(lambda: _parts(out) >= 10, 120, "ten parts")
    family = [p.pid for p in psutil.Process(client.pid).children(recursive=True)]
    client.send_signal(signal.SIGKILL)
    client.wait()
    assert 10 <= _parts(out) < n // 200
    _wait_for(lambda: not any(psutil.pid_exists(p) for p in family), 60, "the workers' exit")

    resumed = subprocess.run(
        [*CLI, *common, "--workers", "2", "--out", str(out), "--resume"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert resumed.returncode == 0, resumed.stderr
    report = json.loads(resumed.stdout)
    assert report["resumed_parts"] >= 10

    whole = sweep.run_sweep(
        ScenarioConfig(), sweep.SampledStarts(n, 0, "bounded"), 5.0, workers=1, chunk=200
    )
    rows = pd.read_parquet(out / "results").sort_values("start").reset_index(drop=True)
    pd.testing.assert_frame_equal(rows, whole.table)
    ignore = {"wall_time_s": 0, "resumed_parts": 0, "workers": 0}
    assert report | ignore == whole.report() | ignore
