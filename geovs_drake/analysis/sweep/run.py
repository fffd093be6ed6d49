"""The sweep's client: cut the starts into parts, run them (here or on Dask), merge the summaries.

Where the parts run: on the Dask scheduler given (``scheduler``), or on a LocalCluster
of ``workers`` processes for a sweep of :data:`LOCAL_CLUSTER_MIN_STARTS` starts or more
or an engine not in :data:`THREADED_ENGINES` (Drake's), or else in this process, on
``workers`` numba threads (the batch engine's ``prange``). Below
that size a LocalCluster does not pay on one machine: its start (about 3 s: processes,
imports, numba's cache loaded in each) and its transfers cost more than they save
(measured on 2 cores, free body, 10 s per start: 10^4 starts 16.1 s on the cluster
against 7.2 s in process, 3 x 10^4 starts 36.5 s against 25.6 s; docs/performance.md).

The client holds no rows. It submits at most a window of parts at a time
(:data:`WINDOW_PER_WORKER` per worker thread), so the scheduler's queue does
not grow with N either, merges each finished part's summary, and forgets the
part. With ``out``, the rows are in ``out/results/part-*.parquet``, written
by the workers, and ``out/sweep.json`` records what the sweep is (config,
seed, velocity, duration, N, chunk, engine) before anything runs.
``resume=True`` reads that record, refuses a different sweep in one line,
reads the finished parts' summaries from their metadata, and runs the parts
that are missing: the dataset and the summary are then those of an
uninterrupted run. A part whose file is damaged is named and run again.
"""

from __future__ import annotations

import copy
import itertools
import json
import logging
import math
import signal
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_dump_typed

from geovs_drake import __version__
from geovs_drake._optional import require
from geovs_drake.analysis.sweep.here import run_here
from geovs_drake.analysis.sweep.parts import (
    HOVER_FIELDS,
    ROW_FIELDS,
    Part,
    part_name,
    read_part_summary,
    run_part,
)
from geovs_drake.analysis.sweep.starts import SampledStarts, SweepError
from geovs_drake.analysis.sweep.summary import SweepSummary, plot_summary
from geovs_drake.batch import loop_parameters
from geovs_drake.loop.resolved import exact_twin, free_twin
from geovs_drake.scenario import ScenarioConfig, variant_name

__all__ = [
    "CSV_LIMIT",
    "ENGINES",
    "LOCAL_CLUSTER_CONFIG",
    "LOCAL_CLUSTER_MIN_STARTS",
    "SCHEDULER_TIMEOUT_S",
    "THREADED_ENGINES",
    "WINDOW_PER_WORKER",
    "SweepInterrupted",
    "SweepResult",
    "read_results",
    "run_sweep",
    "write_csv",
]

ENGINES = ("batch", "drake")
#: How long to try to reach an existing scheduler before giving up [s].
SCHEDULER_TIMEOUT_S = 10.0
#: Parts in flight per worker thread: enough to keep every worker busy while the
#: client merges, few enough that the scheduler's queue does not grow with N.
WINDOW_PER_WORKER = 4
#: ``--csv`` writes ``results.csv`` up to this many starts: at about 560 bytes a row,
#: 56 MB of text; beyond it the Parquet dataset is the only sensible form.
CSV_LIMIT = 100_000
#: Dask settings of the LocalCluster the sweep starts (its workers receive them): no
#: statistical profiler sampling every worker's stack every 10 ms, which costs the
#: compiled engine CPU for a dashboard nobody watches here.
LOCAL_CLUSTER_CONFIG = {"distributed.worker.profile.enabled": False}
#: Without ``scheduler``, a sweep of this many starts or more runs on a LocalCluster of
#: ``workers`` processes; a smaller one in this process on ``workers`` numba threads (the
#: module docstring's measurements: in process it was faster at every size measured, up
#: to 3 x 10^4; at 10^5 the cluster's overhead over the engine alone was 16 %, recorded
#: in benchmarks/results/bench_sweep_overhead.json, and its processes keep a crash in
#: one part to that worker).
LOCAL_CLUSTER_MIN_STARTS = 100_000
#: The engines whose parts run on numba's threads (``prange``), the only ones that run
#: in this process below :data:`LOCAL_CLUSTER_MIN_STARTS`: the Drake engine simulates one
#: start at a time on one core, so its ``workers`` stay processes of a LocalCluster.
THREADED_ENGINES = ("batch",)
#: The record of what a sweep in a folder is, for ``resume``.
MANIFEST = "sweep.json"
#: The fields of the record that must match for ``resume``.
_SAME_SWEEP = ("config", "seed", "velocity", "duration", "starts", "chunk", "engine")


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`run_sweep`; ``result`` holds the parts that had finished
    (the cluster is closed already, the parts are on disk). A KeyboardInterrupt, so
    code that does not care sees the usual one."""

    def __init__(self, result: SweepResult) -> None:
        super().__init__(f"sweep interrupted after {result.summary.finished} starts")
        self.result = result


@dataclass
class SweepResult:
    """A sweep: its merged summary, how it ran, and its rows as a table.

    ``table``: the rows as a pandas DataFrame sorted by start, read from ``out`` on
    first use (or held, when the sweep ran without a folder). A big sweep's client
    never needs it: the summary holds the figures.
    """

    summary: SweepSummary
    plant: str
    engine: str
    workers: int
    chunk: int
    duration: float
    starts: int  # requested; ``summary.finished`` is smaller only after an interruption
    wall_time_s: float
    seed: int | None = None
    velocity: str | None = None
    interrupted: bool = False
    scheduler: str | None = None
    out: Path | None = None
    potential_gain: float = 1.0  # k_p (1 for the kinematic loop's phi)
    resumed_parts: int = 0
    _table: object = field(default=None, repr=False)

    @property
    def table(self):
        """The rows (pandas DataFrame, :data:`~.parts.ROW_FIELDS` columns) sorted by start."""
        if self._table is None:
            if self.out is None:
                raise SweepError("this sweep kept no rows (it ran with neither out nor tables)")
            self._table = read_results(self.out)
        return self._table

    def report(self) -> dict:
        """The sweep in JSON-ready numbers (non-finite values as None): how it ran and
        :meth:`~.summary.SweepSummary.report`.

        ``guarantee`` counts, among the starts with E0 < k_p (``initial_energy_ratio``
        < 1; for the kinematic loop phi0 < 1, every start in D), those that left D,
        lost sight of the marked point or went non-finite: Appendix C says these
        counts are zero for the dynamic loop, up to the integrator's error.
        """
        return {
            "plant": self.plant,
            "engine": self.engine,
            "starts": self.starts,
            "interrupted": self.interrupted,
            "duration": self.duration,
            "seed": self.seed,
            "velocity": self.velocity,
            "workers": self.workers,
            "scheduler": self.scheduler,
            "chunk": self.chunk,
            "wall_time_s": self.wall_time_s,
            "resumed_parts": self.resumed_parts,
            "energy_bound": self.potential_gain,
            **self.summary.report(),
        }

    def plot(self, out_dir: str | Path) -> list[str]:
        """The summary's plots (:func:`~.summary.plot_summary`) in ``out_dir``."""
        return plot_summary(self.summary, self.plant, out_dir)


def read_results(out: str | Path):
    """The rows of the sweep in ``out`` (``out/results``), as a pandas DataFrame sorted
    by start. The same folder reads with ``dask.dataframe.read_parquet`` for sweeps
    bigger than memory."""
    pandas = require("pandas", "sweep", "reading a sweep's rows")
    table = pandas.read_parquet(Path(out) / "results")
    return table.sort_values("start", kind="stable").reset_index(drop=True)


def _frame(tables: list):
    """The parts' tables as one DataFrame sorted by start (none: the empty table)."""
    pa = require("pyarrow", "sweep", "run_sweep")
    require("pandas", "sweep", "run_sweep's table")
    table = pa.concat_tables(tables) if tables else pa.table({k: [] for k in ROW_FIELDS})
    frame = table.to_pandas()
    return frame.sort_values("start", kind="stable").reset_index(drop=True)


def write_csv(result: SweepResult, path: str | Path) -> Path:
    """``results.csv`` of a sweep of at most :data:`CSV_LIMIT` starts, sorted by start."""
    if result.summary.finished > CSV_LIMIT:
        raise SweepError(
            f"a CSV is written for at most {CSV_LIMIT} starts: this sweep has "
            f"{result.summary.finished} (read its Parquet dataset instead)"
        )
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    table = result.table
    table[[*ROW_FIELDS, *(k for k in HOVER_FIELDS if k in table)]].to_csv(tmp, index=False)
    tmp.replace(path)
    return path


# --------------------------------------------------------------------------------- settings
def _check_settings(starts, duration, engine, workers, chunk) -> tuple[int, object]:
    """(N, the starts' source) after the checks that need no config."""
    if not (isinstance(duration, int | float) and math.isfinite(duration) and duration > 0):
        raise SweepError(f"duration must be finite and > 0 [s]: duration = {duration!r}")
    if engine not in ENGINES:
        raise SweepError(f"engine must be one of {ENGINES}: engine = {engine!r}")
    for name, value in (("workers", workers), ("chunk", chunk)):
        if not (isinstance(value, int | np.integer) and value >= 1):
            raise SweepError(f"{name} must be an integer >= 1: {name} = {value!r}")
    if isinstance(starts, SampledStarts):
        return int(starts.n), starts
    X_BC, twists = starts
    X_BC = np.asarray(X_BC, dtype=float)
    if X_BC.ndim != 3 or X_BC.shape[1:] != (4, 4) or len(X_BC) == 0:
        raise SweepError(f"X_BC must be (N >= 1, 4, 4): shape = {X_BC.shape}")
    n = len(X_BC)
    twists = np.zeros((n, 6)) if twists is None else np.asarray(twists, dtype=float)
    if twists.shape != (n, 6):
        raise SweepError(f"twists must be (N, 6) = ({n}, 6): shape = {twists.shape}")
    return n, (X_BC, twists)


def _manifest(text: str, n: int, source, duration, chunk, engine, plant) -> dict:
    sampled = isinstance(source, SampledStarts)
    return {
        "format": 1,
        "geovs_drake": __version__,
        "config": text,
        "plant": plant,
        "seed": int(source.seed) if sampled else None,
        "velocity": source.velocity if sampled else None,
        "duration": float(duration),
        "starts": n,
        "chunk": int(chunk),
        "engine": engine,
        "parts": math.ceil(n / chunk),
        "columns": list(ROW_FIELDS),
    }


def _check_record(out: Path, manifest: dict) -> None:
    """For ``resume``: SweepError unless ``out/sweep.json`` records this very sweep."""
    record = out / MANIFEST
    if manifest["seed"] is None:
        raise SweepError("resume needs sampled starts (SampledStarts), not given arrays")
    if not record.is_file():
        raise SweepError(f"--resume: no sweep in {out} (no {MANIFEST})")
    try:
        old = json.loads(record.read_text())
    except (OSError, ValueError) as e:
        raise SweepError(f"--resume: {record} is unreadable: {e}") from e
    for key in _SAME_SWEEP:
        if old.get(key) != manifest[key]:
            what = "the scenario" if key == "config" else f"{key} {old.get(key)!r}"
            now = "" if key == "config" else f", this run {manifest[key]!r}"
            raise SweepError(f"--resume: {out} holds another sweep: {what}{now}")


def _start_folder(out: Path, manifest: dict) -> None:
    """Record a new sweep in ``out/sweep.json``, replacing an earlier sweep's record and
    part files in ``out``."""
    results = out / "results"
    results.mkdir(parents=True, exist_ok=True)
    for stale in results.glob("part-*.parquet"):
        stale.unlink()
    tmp = out / f".{MANIFEST}.tmp"
    tmp.write_text(json.dumps(manifest, indent=2) + "\n")
    tmp.replace(out / MANIFEST)


def _finished_parts(out: Path, parts: list[Part], names: list[str], warn) -> dict[int, dict]:
    """The summaries of the parts already written in ``out/results``; a damaged part
    is named (``warn``), removed and left to run again."""
    done = {}
    for part, name in zip(parts, names, strict=True):
        path = out / "results" / name
        if not path.exists():
            continue
        try:
            done[part.index] = read_part_summary(path, part.last - part.first)
        except ValueError as e:
            warn(f"{e}; it runs again")
            path.unlink(missing_ok=True)
    return done


# ------------------------------------------------------------------------------- execution
def _connect(scheduler: str | None, workers: int):
    """(client, cluster or None): a Client on ``scheduler``, or on a LocalCluster of
    ``workers`` single-threaded processes started here."""
    from distributed import Client, LocalCluster

    dask = require("dask", "sweep", "run_sweep on Dask", package="dask[distributed]")

    if scheduler is not None:
        try:
            return Client(scheduler, timeout=SCHEDULER_TIMEOUT_S), None
        except (OSError, TimeoutError, ValueError, TypeError) as e:
            raise SweepError(f"cannot reach the Dask scheduler at {scheduler!r}: {e}") from e
    # The workers ignore SIGINT (a terminal's Ctrl-C goes to the whole process group):
    # this process catches it and closes them, instead of K tracebacks and orphans.
    previous = signal.getsignal(signal.SIGINT)
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        with warnings.catch_warnings(), dask.config.set(LOCAL_CLUSTER_CONFIG):
            # The scheduler's HTTP server falls back to a free port when 8787 is taken
            # (another sweep, any Dask session): nothing the user must act on.
            warnings.filterwarnings("ignore", "Port .* is already in use", UserWarning)
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                # Not a warning per task cancelled by Ctrl-C, nor the ERROR with two
                # tracebacks that a worker logs when its heartbeat is in flight as the
                # scheduler closes (seen on a loaded machine, every row in): a task's
                # own error still reaches this process, raised by its future.
                silence_logs=logging.CRITICAL,
            )
    finally:
        signal.signal(signal.SIGINT, previous)
    try:
        return Client(cluster), cluster
    except BaseException:
        cluster.close()
        raise


def _on_dask(client, todo: list[tuple[Part, str]]) -> Iterator[tuple[dict, object]]:
    """The parts' results as they finish, with at most a window of parts in flight."""
    distributed = require("distributed", "sweep", "run_sweep on Dask", package="dask[distributed]")
    threads = max(1, sum(client.nthreads().values()))
    pending = iter(todo)

    def submit(item):
        return client.submit(run_part, *item, pure=False)

    first = [submit(item) for item in itertools.islice(pending, WINDOW_PER_WORKER * threads)]
    flow = distributed.as_completed(first)
    for future in flow:
        result = future.result()
        future.release()
        following = next(pending, None)
        if following is not None:
            flow.add(submit(following))
        yield result


def _check_starts_and_extras(
    config: ScenarioConfig,
    source,
    n: int,
    engine: str,
    workers: int,
    scheduler: str | None,
    local_cluster: bool | None,
) -> bool:
    """SweepError for starts the loop cannot take; MissingExtra for a package the sweep
    needs and lacks. Whether it runs on Dask (module docstring)."""
    if isinstance(source, SampledStarts):
        source.check(config)
    elif not config.dynamic and np.any(source[1] != 0):
        raise SweepError("initial twists apply to the dynamic plant only (kinematic: at rest)")
    if local_cluster is None:
        # Drake's Simulator runs one start at a time on one core: its workers are processes.
        threaded = engine in THREADED_ENGINES
        local_cluster = workers > 1 and (not threaded or n >= LOCAL_CLUSTER_MIN_STARTS)
    use_dask = scheduler is not None or bool(local_cluster)
    if use_dask:
        require("distributed", "sweep", "run_sweep on Dask", package="dask[distributed]")
    require("pyarrow", "sweep", "run_sweep")  # the parts' Parquet files, with or without Dask
    return use_dask


def _shipped_parameters(config: ScenarioConfig, engine: str):
    """The kernels' parameters, read once here from the built diagram and shipped with
    every part. The Drake engine runs any carrier and sensor; its starts are drawn with
    the free rig's kernels on the exact y (the same domain, goal and NF), which the batch
    engine also runs. SweepError for a loop the batch engine does not run."""
    try:
        arm = engine == "batch" and config.carrier.traits.joints
        if arm:
            _check_arm_batch(config)
        drawn_by = config if engine == "batch" and not arm else exact_twin(free_twin(config))
        return loop_parameters(drawn_by)
    except ValueError as e:
        raise SweepError(str(e)) from e


def _check_arm_batch(config: ScenarioConfig) -> None:
    """ValueError, with the remedy, for an arm's loop the batch engine does not run (the
    rendered camera on the arm, a pinhole whose frames arrive after their capture, a
    moving target, the joint barrier): refused before any part. The pinhole runs
    (:mod:`geovs_drake.batch.arm_sampled`)."""
    from geovs_drake.batch.arm_rhs import arm_loop_parameters

    try:
        arm_loop_parameters(config)
    except ValueError as e:
        raise ValueError(f"{e} (run it with --engine drake)") from e


def _parts(
    text: str, n: int, chunk: int, source, out: Path | None, use_dask: bool, common: dict
) -> tuple[list[Part], list[str]]:
    """The sweep's parts of at most ``chunk`` starts each, and their file names: sampled
    starts are drawn in each part (its seed and index), given ones sliced into it."""
    parts, names = [], []
    count = math.ceil(n / chunk)
    for index in range(count):
        a, b = index * chunk, min((index + 1) * chunk, n)
        given = {}
        if not isinstance(source, SampledStarts):
            given = {"X_BC": source[0][a:b], "twists": source[1][a:b]}
        parts.append(
            Part(
                config_yaml=text,
                index=index,
                first=a,
                last=b,
                seed=getattr(source, "seed", 0),
                velocity=getattr(source, "velocity", "none"),
                results=None if out is None else str(out / "results"),
                single_thread=use_dask,
                **common,
                **given,
            )
        )
        names.append(part_name(index, count))
    return parts, names


def _resumed(out: Path, parts: list[Part], names: list[str], warn, summary, on_part) -> dict:
    """For ``resume``: the finished parts' summaries (:func:`_finished_parts`), merged
    into ``summary`` and counted by ``on_part``."""
    done = _finished_parts(out, parts, names, warn or warnings.warn)
    for data in done.values():
        summary.merge(SweepSummary.from_json(data))
        if on_part is not None:
            on_part(int(data["finished"]))
    return done


def _run_parts(
    todo: list,
    summary: SweepSummary,
    on_part: Callable[[int], None] | None,
    use_dask: bool,
    scheduler: str | None,
    workers: int,
    out: Path | None,
    manifest: dict,
    resume: bool,
) -> tuple[list, bool]:
    """Run the parts still to do (on Dask, or in this process), merging each one's summary
    as it finishes; the tables kept (without ``out``) and whether Ctrl-C stopped it. The
    client and the cluster are closed whatever happens."""
    tables = []
    interrupted = False
    client = cluster = None
    try:
        # Connect before writing anything: an unreachable scheduler leaves no folder.
        if use_dask and todo:
            client, cluster = _connect(scheduler, workers)
        if out is not None and not resume:
            _start_folder(out, manifest)
        results = _on_dask(client, todo) if client is not None else run_here(todo, workers)
        for data, table in results:
            summary.merge(SweepSummary.from_json(data))
            if table is not None:
                tables.append(table)
            if on_part is not None:
                on_part(int(data["finished"]))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    return tables, interrupted


def _started_at_goal(config: ScenarioConfig) -> ScenarioConfig:
    """``config`` as the sweep resolves it: each start replaces the scenario's, which no
    run reads, so a hovering carrier's checks of a start (its tilt) are asked of the goal."""
    if not config.carrier.traits.hover:
        return config
    config = copy.deepcopy(config)
    config.initial = copy.deepcopy(config.goal)
    return config


def run_sweep(
    config: ScenarioConfig,
    starts: SampledStarts | tuple[np.ndarray, np.ndarray | None],
    duration: float,
    engine: str = "batch",
    workers: int = 2,
    scheduler: str | None = None,
    chunk: int = 1000,
    out: str | Path | None = None,
    resume: bool = False,
    on_part: Callable[[int], None] | None = None,
    warn: Callable[[str], None] | None = None,
    local_cluster: bool | None = None,
) -> SweepResult:
    """Run ``config``'s loop (``config.plant``) from each start, in parts, here or on Dask.

    Args:
        config: the scenario; its ``initial``, ``initial_velocity`` and ``duration``
            are replaced by each start's and ``duration``.
        starts: :class:`~.starts.SampledStarts` (N, seed, velocity: each part draws
            its own), or ``(X_BC, twists)``: camera poses in the target frame
            (N, 4, 4) and body twists (Omega, V) in C (N, 6) or None at rest.
        duration: simulated time per start [s].
        engine: ``"batch"`` (:func:`~geovs_drake.batch.run_batch` per part) or
            ``"drake"`` (:func:`~geovs_drake.simulation.simulate` per start; slow,
            for cross-checks).
        workers: processes of the LocalCluster, or numba threads when the parts run
            in this process (ignored with ``scheduler``).
        scheduler: the address of a running Dask scheduler, e.g. ``"tcp://host:8786"``;
            its workers need this package installed, and ``out`` must be a folder
            they can all write (a shared filesystem).
        chunk: starts per part.
        out: the folder for ``results/part-*.parquet`` and ``sweep.json``; None keeps
            the rows in memory instead (small sweeps).
        resume: continue the sweep recorded in ``out`` (module docstring).
        on_part: called with each finished part's number of starts (on ``resume``,
            first for each part found finished).
        warn: called with one line for each damaged part that runs again (default:
            :mod:`warnings`).
        local_cluster: without ``scheduler``: True, a LocalCluster of ``workers``
            processes; False, this process; None (default), the module docstring's rule.

    Raises :class:`~.starts.SweepError` for bad settings, a folder that holds another
    sweep or an unreachable scheduler; :class:`SweepInterrupted` (with the finished
    parts) on Ctrl-C, after closing the client and the cluster; and
    :class:`~geovs_drake._optional.MissingExtra` when pyarrow or Dask is needed but
    not installed (the ``sweep`` extra), before anything runs.
    """
    # Here, not at the top: a sweep's workers import this module without the loop's.
    from geovs_drake.loop.resolver import resolve

    # The arm's gain_scale: auto, chosen once for every start (resolve validates).
    resolved = resolve(_started_at_goal(config))
    config = resolved.fitted_config
    n, source = _check_settings(starts, duration, engine, workers, chunk)
    dynamic = config.dynamic
    use_dask = _check_starts_and_extras(
        config, source, n, engine, workers, scheduler, local_cluster
    )
    text = yaml_dump_typed(config)
    out = None if out is None else Path(out)
    if resume and out is None:
        raise SweepError("resume needs the sweep's folder (out)")
    manifest = _manifest(text, n, source, duration, chunk, engine, variant_name(config.plant))
    if resume:  # before anything else: a different sweep in the folder is the first thing to say
        _check_record(out, manifest)
    parameters = _shipped_parameters(config, engine)
    common = dict(duration=float(duration), engine=engine, parameters=parameters)
    parts, names = _parts(text, n, chunk, source, out, use_dask, common)
    summary = SweepSummary.empty(config, duration)
    done = _resumed(out, parts, names, warn, summary, on_part) if resume else {}
    todo = [(p, name) for p, name in zip(parts, names, strict=True) if p.index not in done]
    start = time.perf_counter()
    tables, interrupted = _run_parts(
        todo, summary, on_part, use_dask, scheduler, workers, out, manifest, resume
    )
    result = SweepResult(
        summary=summary,
        plant=variant_name(config.plant),
        engine=engine,
        workers=int(workers),
        chunk=int(chunk),
        duration=float(duration),
        starts=n,
        wall_time_s=time.perf_counter() - start,
        seed=getattr(source, "seed", None),
        velocity=getattr(source, "velocity", None),
        interrupted=interrupted,
        scheduler=scheduler,
        out=out,
        # The loop's own k_p (resolve() scales the arm's), 1 for the kinematic loop's phi.
        potential_gain=float(resolved.config.control.potential_gain) if dynamic else 1.0,
        resumed_parts=len(done),
    )
    if out is None:
        result._table = _frame(tables)
    if interrupted:
        raise SweepInterrupted(result)
    return result
