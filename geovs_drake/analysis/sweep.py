"""The guarantee study on many starts: the closed loop from N random starts in D, on Dask.

Appendix C's claim: with E0 = 1/2 nu^T M nu + k_p phi(y0) < k_p, the energy
E never rises and k_p phi <= E, so phi stays below 1 and the dynamic loop never
leaves D. :func:`sample_starts` draws starts that the claim covers (images
uniform in D's model chart, optionally with a random twist below the energy
bound); :func:`run_sweep` runs them in chunks on ``dask.distributed`` and
returns one row per start (:data:`ROW_FIELDS`); :func:`summarize` counts what
happened, and in particular how many covered starts left D anyway (the
``guarantee`` entry: it should read zeros).

Why chunks of the batch engine: one :func:`~geovs_drake.batch.run_batch` call
integrates a chunk in one compiled loop, so a task costs one pickle of a few
arrays, not one diagram per start. Why Dask rather than a process pool: the
same code runs on this machine's cores (a ``LocalCluster`` the sweep starts
and closes) or on a cluster somebody already runs (``scheduler=
"tcp://host:8786"``), and ``as_completed`` streams rows as chunks finish.
Every start is drawn in the calling process from one seeded generator and
every start is integrated on its own, so the rows do not depend on the number
of workers or the chunk size (a test checks they are bit-identical).

``engine="drake"`` runs each start through :func:`~geovs_drake.simulation.simulate`
(Drake's Simulator on the diagram): much slower, for cross-checks on a few starts.
"""

from __future__ import annotations

import copy
import csv
import functools
import logging
import math
import signal
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_dump_typed
from pydrake.math import RigidTransform

from geovs_drake._optional import require
from geovs_drake.analysis.nf_study import random_features_in_domain
from geovs_drake.batch import STATUS_NAMES, LoopParameters, loop_parameters, run_batch
from geovs_drake.diagrams import initial_body_states
from geovs_drake.geometry import kernels
from geovs_drake.geometry.camera import camera_map_inverse
from geovs_drake.scenario import PoseConfig, ScenarioConfig, load_scenario
from geovs_drake.simulation import (
    StartOutsideDomain,
    camera_pose_in_target,
    simulate,
)

__all__ = [
    "ABOVE_RANGE",
    "ENERGY_FACTOR",
    "ROW_FIELDS",
    "SCHEDULER_TIMEOUT_S",
    "SHRINK",
    "SweepError",
    "SweepInterrupted",
    "SweepResult",
    "run_sweep",
    "run_sweep_to_csv",
    "sample_starts",
    "summarize",
]

#: Per-start columns, in the CSV's order. Poses are X_BC (metres, Drake RollPitchYaw
#: in radians); the twist is the camera's body twist (Omega, V) in C [rad/s, m/s].
ROW_FIELDS = (
    "start",
    "x",
    "y",
    "z",
    "roll",
    "pitch",
    "yaw",
    "wx",
    "wy",
    "wz",
    "vx",
    "vy",
    "vz",
    "status",
    "t_converged",
    "final_position_error_m",
    "final_rotation_error_rad",
    "min_fov_margin",
    "min_lambda_margin",
    "min_occlusion_margin",
    "initial_energy_ratio",
    "max_energy_ratio",
    "monotone",
    "final_x",
    "final_y",
    "final_z",
    "final_roll",
    "final_pitch",
    "final_yaw",
)
#: The model chart is sampled in a ball of this radius (1 is the boundary of D): a
#: start on the boundary itself has phi0 = 1 and no room below the energy bound.
SHRINK = 0.95
#: The kinetic energy of a bounded start is this fraction, at most, of the room
#: k_p (1 - phi0) below the bound: strictly below 1, so E0 < k_p holds with a margin
#: that rounding cannot eat.
ENERGY_FACTOR = 0.99
#: How long to try to reach an existing scheduler before giving up [s].
SCHEDULER_TIMEOUT_S = 10.0
ENGINES = ("batch", "drake")
VELOCITIES = ("none", "bounded", "above")
#: With ``velocity="above"``: E0 / k_p is drawn uniformly in this interval, outside
#: the guarantee, to show how often the loop then leaves D.
ABOVE_RANGE = (1.5, 4.0)


class SweepError(ValueError):
    """A sweep's settings are wrong, or its scheduler cannot be reached."""


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`run_sweep`; ``result`` holds the chunks that had finished
    (the cluster is closed already). A KeyboardInterrupt, so code that does not care
    sees the usual one."""

    def __init__(self, result: SweepResult) -> None:
        super().__init__(f"sweep interrupted after {len(result.rows)} starts")
        self.result = result


@dataclass
class SweepResult:
    """The rows of :func:`run_sweep`, sorted by start index, and how they were run."""

    rows: list[dict]
    plant: str
    engine: str
    workers: int
    chunk: int
    duration: float
    starts: int  # requested; ``len(rows)`` is smaller only after an interruption
    wall_time_s: float
    interrupted: bool = False
    scheduler: str | None = None
    potential_gain: float = field(default=1.0)  # k_p (1 for the kinematic loop's phi)


# --------------------------------------------------------------------------
# Starts
# --------------------------------------------------------------------------
def sample_starts(
    config: ScenarioConfig, n: int, seed: int = 0, velocity: str = "none"
) -> tuple[np.ndarray, np.ndarray]:
    """N starts: camera poses X_BC (n, 4, 4) and body twists (Omega, V) in C (n, 6).

    This samples the *image space*, not poses: images uniform in D's model chart
    (:func:`~geovs_drake.analysis.nf_study.random_features_in_domain` at
    :data:`SHRINK`), mapped back by ``c^-1`` (Eq. 23). So every start is in D by
    construction, and the poses are spread the way D is parametrised, not
    uniformly in SE(3). At rest (``velocity="none"``) the poses are those of
    :func:`~geovs_drake.analysis.monte_carlo.random_initial_poses` with the
    same seed.

    ``velocity="bounded"`` (dynamic loop only) gives each start a twist whose
    direction is uniform on the unit sphere of R^6 and whose kinetic energy KE is
    uniform in [0, k_p (1 - phi0)) times :data:`ENERGY_FACTOR`, so that
    E0 = k_p phi0 + KE < k_p: every start is one Appendix C's guarantee covers.
    ``velocity="above"`` draws E0 / k_p uniformly in :data:`ABOVE_RANGE` instead:
    starts the guarantee does not cover.
    KE is quadratic in the twist's scale, so the scale is sqrt(KE / KE1) with KE1
    the kinetic energy of the unit twist, from the rig's state
    (:func:`~geovs_drake.diagrams.initial_body_states`) and the ``free_body`` kernel,
    the loop's own formulas.

    One ``np.random.default_rng(seed)`` draws everything, in this process, so the
    starts do not depend on how the sweep is later split.
    """
    if not (isinstance(n, int | np.integer) and n >= 1):
        raise SweepError(f"the number of starts must be an integer >= 1: n = {n!r}")
    if velocity not in VELOCITIES:
        raise SweepError(f"velocity must be one of {VELOCITIES}: velocity = {velocity!r}")
    dynamic = config.plant == "dynamic"
    if velocity != "none" and not dynamic:
        raise SweepError(
            f"velocity {velocity!r} needs the dynamic plant (the kinematic loop is first order "
            f"and starts at rest): controller = {config.plant!r}"
        )
    rng = np.random.default_rng(seed)
    y = random_features_in_domain(rng, int(n), config.domain.to_domain(), shrink=SHRINK)
    X_CB = camera_map_inverse(y, config.radius)
    X_BC = np.stack([RigidTransform(X).inverse().GetAsMatrix4() for X in X_CB])
    twists = np.zeros((int(n), 6))
    if velocity == "none":
        return X_BC, twists
    p = loop_parameters(config)
    phi0 = np.asarray(kernels.navigation(tuple(y.to_vector().T), p.navigation)[8])
    direction = rng.normal(size=(int(n), 6))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    kinetic_unit = _kinetic_energy(config, p, X_BC, direction)
    if velocity == "above":
        target = p.potential_gain * rng.uniform(*ABOVE_RANGE, size=int(n))
        kinetic = target - p.potential_gain * phi0
    else:
        room = p.potential_gain * (1.0 - phi0)
        kinetic = ENERGY_FACTOR * rng.uniform(0.0, 1.0, size=int(n)) * room
    twists = direction * np.sqrt(kinetic / kinetic_unit)[:, None]
    return X_BC, twists


def _kinetic_energy(
    config: ScenarioConfig, p: LoopParameters, X_BC: np.ndarray, twists: np.ndarray
) -> np.ndarray:
    """1/2 nu^T M nu of the rig for camera poses and twists (the ``free_body`` kernel)."""
    states = initial_body_states(config, X_BC, twists)
    zero_force = tuple(np.zeros(6))
    return np.asarray(kernels.free_body(tuple(states.T), zero_force, tuple(p.body))[13])


# --------------------------------------------------------------------------
# Chunks (these run in the workers)
# --------------------------------------------------------------------------
@functools.lru_cache(maxsize=4)
def _worker_setup(config_yaml: str) -> tuple[ScenarioConfig, LoopParameters]:
    """The config and its loop parameters, once per worker process (configs cross the
    process boundary as YAML: Drake's SimulatorConfig does not pickle)."""
    config = load_scenario(data=config_yaml)
    return config, loop_parameters(config)


def _pose_columns(X: RigidTransform | None, prefix: str = "") -> dict[str, float]:
    names = [prefix + k for k in ("x", "y", "z", "roll", "pitch", "yaw")]
    if X is None:
        return dict.fromkeys(names, math.nan)
    pose = PoseConfig.from_rigid_transform(X)
    return dict(zip(names, [*pose.xyz, *pose.rpy], strict=True))


def _start_columns(index: int, X_BC: np.ndarray, twist: np.ndarray) -> dict:
    X = RigidTransform(X_BC) if np.all(np.isfinite(X_BC)) else None
    row = {"start": int(index), **_pose_columns(X)}
    row.update(zip(("wx", "wy", "wz", "vx", "vy", "vz"), map(float, twist), strict=True))
    return row


def _batch_chunk(
    config_yaml: str,
    first: int,
    X_BC: np.ndarray,
    twists: np.ndarray,
    duration: float,
    single_thread: bool,
) -> list[dict]:
    """One chunk through the batch engine: its rows."""
    if single_thread:
        import numba

        # K worker processes on the cores, not K x cores threads. (Not NUMBA_NUM_THREADS
        # in the workers' environment: numba rereads it when it compiles, and refuses a
        # value that differs from the one its thread pool started with.)
        numba.set_num_threads(1)
    config, p = _worker_setup(config_yaml)
    dynamic = p.plant == "dynamic"
    r = run_batch(config, X_BC, twists if dynamic else None, duration=duration, parameters=p)
    monotone = r.monotone
    rows = []
    for i in range(len(X_BC)):
        x = r.final_states[i]
        final = camera_pose_in_target(config, x, dynamic) if np.all(np.isfinite(x)) else None
        row = _start_columns(first + i, X_BC[i], twists[i])
        row.update(
            status=STATUS_NAMES[int(r.status_code[i])],
            t_converged=float(r.t_converged[i]),
            final_position_error_m=float(r.final_position_error_m[i]),
            final_rotation_error_rad=float(r.final_rotation_error_rad[i]),
            min_fov_margin=float(r.min_margins[i, 0]),
            min_lambda_margin=float(min(r.min_margins[i, 1], r.min_margins[i, 2])),
            min_occlusion_margin=float(r.min_margins[i, 3]),
            initial_energy_ratio=float(r.initial_lyapunov[i] / p.potential_gain),
            max_energy_ratio=float(r.max_lyapunov_ratio[i]),
            monotone=bool(monotone[i]),
            **_pose_columns(final, "final_"),
        )
        rows.append(row)
    return rows


def _drake_row(config: ScenarioConfig, k_p: float, index: int, X_BC, twist) -> dict:
    """One start through simulate(): the same columns as the batch engine's."""
    dynamic = config.plant == "dynamic"
    c = copy.deepcopy(config)
    c.initial = PoseConfig.from_rigid_transform(RigidTransform(X_BC))
    c.initial_velocity = [float(v) for v in twist] if dynamic else [0.0] * 6
    row = _start_columns(index, X_BC, twist)
    try:
        r = simulate(c)
    except StartOutsideDomain as e:  # stopped at t = 0, as the batch engine would
        status = "lost_visibility" if "not visible" in str(e) else "left_domain"
        nan = math.nan
        row.update(dict.fromkeys(ROW_FIELDS[14:], nan), status=status, monotone=True)
        return row
    dp, dr = r.final_errors
    L = r.lyapunov
    row.update(
        status=r.status,
        t_converged=r.convergence_time,
        final_position_error_m=dp,
        final_rotation_error_rad=dr,
        min_fov_margin=float(np.min(r.margins[:, 0])),
        min_lambda_margin=float(np.min(r.margins[:, 1:3])),
        min_occlusion_margin=float(np.min(r.margins[:, 3])),
        initial_energy_ratio=float(L[0] / k_p),
        max_energy_ratio=float(np.max(L) / k_p),
        monotone=bool(r.lyapunov_monotone),
        **_pose_columns(r.final_X_BC, "final_"),
    )
    return row


def _drake_chunk(
    config_yaml: str,
    first: int,
    X_BC: np.ndarray,
    twists: np.ndarray,
    duration: float,
    single_thread: bool,
) -> list[dict]:
    """One chunk, a start at a time, through Drake's Simulator (``single_thread`` is
    unused: simulate() starts no numba threads). Margins and energies are those of
    simulate()'s logs (``config.log_rate``), not of every step as in the batch engine."""
    config, p = _worker_setup(config_yaml)
    config = copy.deepcopy(config)
    config.duration = duration
    return [
        _drake_row(config, p.potential_gain, first + i, X_BC[i], twists[i])
        for i in range(len(X_BC))
    ]


# --------------------------------------------------------------------------
# The sweep
# --------------------------------------------------------------------------
def _check_settings(X_BC, twists, duration, engine, workers, chunk) -> tuple:
    X_BC = np.asarray(X_BC, dtype=float)
    if X_BC.ndim != 3 or X_BC.shape[1:] != (4, 4) or len(X_BC) == 0:
        raise SweepError(f"X_BC must be (N >= 1, 4, 4): shape = {X_BC.shape}")
    n = len(X_BC)
    twists = np.zeros((n, 6)) if twists is None else np.asarray(twists, dtype=float)
    if twists.shape != (n, 6):
        raise SweepError(f"twists must be (N, 6) = ({n}, 6): shape = {twists.shape}")
    if not (isinstance(duration, int | float) and math.isfinite(duration) and duration > 0):
        raise SweepError(f"duration must be finite and > 0 [s]: duration = {duration!r}")
    if engine not in ENGINES:
        raise SweepError(f"engine must be one of {ENGINES}: engine = {engine!r}")
    for name, value in (("workers", workers), ("chunk", chunk)):
        if not (isinstance(value, int | np.integer) and value >= 1):
            raise SweepError(f"{name} must be an integer >= 1: {name} = {value!r}")
    return X_BC, twists


def _connect(scheduler: str | None, workers: int):
    """(client, cluster or None): a Client on ``scheduler``, or on a LocalCluster of
    ``workers`` single-threaded processes started here."""
    from distributed import Client, LocalCluster

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
        with warnings.catch_warnings():
            # The scheduler's HTTP server falls back to a free port when 8787 is taken
            # (another sweep, any Dask session): nothing the user must act on.
            warnings.filterwarnings("ignore", "Port .* is already in use", UserWarning)
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,  # not a warning per task cancelled by Ctrl-C
            )
    finally:
        signal.signal(signal.SIGINT, previous)
    try:
        return Client(cluster), cluster
    except BaseException:
        cluster.close()
        raise


def run_sweep(
    config: ScenarioConfig,
    X_BC: np.ndarray,
    twists: np.ndarray | None,
    duration: float,
    engine: str = "batch",
    workers: int = 2,
    scheduler: str | None = None,
    chunk: int = 1000,
    on_chunk: Callable[[list[dict]], None] | None = None,
) -> SweepResult:
    """Run ``config``'s loop (``config.plant``) from each start, in chunks on Dask.

    Args:
        config: the scenario; its ``initial``, ``initial_velocity`` and ``duration``
            are replaced by each start's and ``duration``.
        X_BC: initial camera poses in the target frame, (N, 4, 4).
        twists: initial body twists (Omega, V) in C, (N, 6); None or zeros at rest.
        duration: simulated time per start [s].
        engine: ``"batch"`` (:func:`~geovs_drake.batch.run_batch` per chunk) or
            ``"drake"`` (:func:`~geovs_drake.simulation.simulate` per start; slow,
            for cross-checks).
        workers: processes of the LocalCluster (ignored with ``scheduler``). With
            1 and no scheduler the chunks run in this process, without Dask.
        scheduler: the address of a running Dask scheduler, e.g. ``"tcp://host:8786"``;
            its workers need this package installed.
        chunk: starts per task.
        on_chunk: called with each finished chunk's rows, in the order chunks finish.

    Returns the rows sorted by start index. Raises :class:`SweepError` for bad
    settings or an unreachable scheduler, :class:`SweepInterrupted` (with the
    finished rows) on Ctrl-C, after closing the client and the cluster, and
    :class:`~geovs_drake._optional.MissingExtra` when Dask is needed (``workers`` > 1
    or a ``scheduler``) but not installed (the ``sweep`` extra), before anything runs.
    """
    config.validate()
    X_BC, twists = _check_settings(X_BC, twists, duration, engine, workers, chunk)
    dynamic = config.plant == "dynamic"
    if not dynamic and np.any(twists != 0):
        raise SweepError("initial twists apply to the dynamic plant only (kinematic: at rest)")
    text = yaml_dump_typed(config)
    task = _batch_chunk if engine == "batch" else _drake_chunk
    n = len(X_BC)
    bounds = [(i, min(i + chunk, n)) for i in range(0, n, chunk)]
    rows: list[dict] = []

    def finished(chunk_rows: list[dict]) -> None:
        rows.extend(chunk_rows)
        if on_chunk is not None:
            on_chunk(chunk_rows)

    start = time.perf_counter()
    interrupted = False
    if workers == 1 and scheduler is None:
        try:
            for a, b in bounds:
                finished(task(text, a, X_BC[a:b], twists[a:b], float(duration), False))
        except KeyboardInterrupt:
            interrupted = True
    else:
        distributed = require(
            "distributed", "sweep", "run_sweep on Dask", package="dask[distributed]"
        )
        client, cluster = _connect(scheduler, workers)
        try:
            futures = [
                client.submit(
                    task, text, a, X_BC[a:b], twists[a:b], float(duration), True, pure=False
                )
                for a, b in bounds
            ]
            for future in distributed.as_completed(futures):
                finished(future.result())
        except KeyboardInterrupt:
            interrupted = True
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    rows.sort(key=lambda r: r["start"])
    result = SweepResult(
        rows=rows,
        plant=config.plant,
        engine=engine,
        workers=int(workers),
        chunk=int(chunk),
        duration=float(duration),
        starts=n,
        wall_time_s=time.perf_counter() - start,
        interrupted=interrupted,
        scheduler=scheduler,
        potential_gain=float(config.control.potential_gain) if dynamic else 1.0,
    )
    if interrupted:
        raise SweepInterrupted(result)
    return result


def run_sweep_to_csv(
    config: ScenarioConfig,
    X_BC: np.ndarray,
    twists: np.ndarray | None,
    out_dir: str | Path,
    on_chunk: Callable[[list[dict]], None] | None = None,
    **settings,
) -> SweepResult:
    """:func:`run_sweep` (``settings``: its keywords) writing ``out_dir/results.csv``.

    Rows are written as chunks finish, so a crash leaves what finished; at the end the
    file is rewritten sorted by start, also after Ctrl-C, before
    :class:`SweepInterrupted` goes on up. ``out_dir`` is created with the first rows.
    """
    out = Path(out_dir)
    path = out / "results.csv"
    stream = {}

    def streamed(rows: list[dict]) -> None:
        if not stream:
            out.mkdir(parents=True, exist_ok=True)
            stream["file"] = open(path, "w", newline="")
            stream["writer"] = csv.DictWriter(stream["file"], fieldnames=ROW_FIELDS)
            stream["writer"].writeheader()
        stream["writer"].writerows(rows)
        stream["file"].flush()
        if on_chunk is not None:
            on_chunk(rows)

    interrupted = None
    try:
        result = run_sweep(config, X_BC, twists, on_chunk=streamed, **settings)
    except SweepInterrupted as e:
        result, interrupted = e.result, e
    finally:
        if stream:
            stream["file"].close()
    _write_csv(path, result.rows)
    if interrupted is not None:
        raise interrupted
    return result


def _write_csv(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=ROW_FIELDS)
        writer.writeheader()
        writer.writerows(rows)


# --------------------------------------------------------------------------
# Summary
# --------------------------------------------------------------------------
def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _column(rows: Sequence[dict], name: str) -> np.ndarray:
    return np.array([r[name] for r in rows], dtype=float)


def summarize(result: SweepResult, seed: int | None = None, velocity: str | None = None) -> dict:
    """The sweep in JSON-ready numbers (non-finite values as None).

    ``guarantee`` counts, among the starts with E0 < k_p (``initial_energy_ratio``
    < 1; for the kinematic loop phi0 < 1, every start in D), those that left D,
    lost sight of the marked point or went non-finite: Appendix C says these
    counts are zero for the dynamic loop, up to the integrator's error.
    """
    rows = result.rows
    status = np.array([r["status"] for r in rows], dtype=object)
    counts = {name: int(np.sum(status == name)) for name in STATUS_NAMES}
    t = _column(rows, "t_converged")[status == "converged"]
    quantiles = dict.fromkeys(("median", "p90", "p99", "max"))
    if len(t):
        values = np.quantile(t, [0.5, 0.9, 0.99]).tolist() + [float(np.max(t))]
        quantiles = dict(zip(quantiles, values, strict=True))

    def worst(name: str) -> float | None:
        v = _column(rows, name)
        v = v[np.isfinite(v)]
        return float(np.min(v)) if len(v) else None

    ratio0 = _column(rows, "initial_energy_ratio")
    covered = ratio0 < 1
    max_ratio = _column(rows, "max_energy_ratio")
    max_ratio = max_ratio[np.isfinite(max_ratio)]
    return {
        "plant": result.plant,
        "engine": result.engine,
        "starts": result.starts,
        "finished": len(rows),
        "interrupted": result.interrupted,
        "duration": result.duration,
        "seed": seed,
        "velocity": velocity,
        "workers": result.workers,
        "scheduler": result.scheduler,
        "chunk": result.chunk,
        "wall_time_s": result.wall_time_s,
        "counts": counts,
        "t_converged_s": quantiles,
        "worst_margins": {
            name: worst(f"min_{name}_margin") for name in ("fov", "lambda", "occlusion")
        },
        "max_energy_ratio": float(np.max(max_ratio)) if len(max_ratio) else None,
        "monotone": int(sum(bool(r["monotone"]) for r in rows)),
        "energy_bound": result.potential_gain,
        "starts_below_energy_bound": int(np.sum(covered)),
        "guarantee": {
            "starts": int(np.sum(covered)),
            **{
                name: int(np.sum(covered & (status == name)))
                for name in ("left_domain", "lost_visibility", "non_finite")
            },
        },
    }


def plot_sweep(result: SweepResult, out_dir) -> list[str]:
    """``t_converged.png`` and ``starts.png`` in ``out_dir``; the file names written.

    ``starts.png`` shows the starts on a slice of D: distance |p_BC| against the yaw of
    X_BC, which at the goal's orientation is the roll about the optical axis (the hard
    direction: near pi the arrow points the wrong way, the NF's saddle). Failed starts
    (neither converged nor still on the way) and the 20 slowest are marked.
    """
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    rows = result.rows
    status = np.array([r["status"] for r in rows], dtype=object)
    t = _column(rows, "t_converged")
    converged = status == "converged"

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.hist(t[converged], bins=50)
    ax.set_xlabel("convergence time [s]")
    ax.set_ylabel("starts")
    ax.set_title(f"{int(converged.sum())} of {len(rows)} starts converged ({result.plant})")
    fig.tight_layout()
    fig.savefig(out / "t_converged.png", dpi=120)
    plt.close(fig)

    distance = np.sqrt(_column(rows, "x") ** 2 + _column(rows, "y") ** 2 + _column(rows, "z") ** 2)
    yaw = _column(rows, "yaw")
    failed = ~np.isin(status, ["converged", "not_converged"])
    slowest = np.argsort(np.where(converged, t, -np.inf))[::-1][: min(20, int(converged.sum()))]
    # Each label counts its points: a marker listed with none on the plot says "(0)".
    not_converged = status == "not_converged"
    fig, ax = plt.subplots(figsize=(6.5, 5))
    ax.scatter(distance, yaw, s=4, c="0.6", label=f"start ({len(rows)})")
    ax.scatter(
        distance[not_converged],
        yaw[not_converged],
        s=10,
        c="tab:orange",
        label=f"not converged ({int(not_converged.sum())})",
    )
    ax.scatter(
        distance[slowest],
        yaw[slowest],
        s=30,
        facecolors="none",
        edgecolors="b",
        label=f"{len(slowest)} slowest",
    )
    ax.scatter(
        distance[failed],
        yaw[failed],
        s=30,
        c="r",
        marker="x",
        label=f"left D / failed ({int(failed.sum())})",
    )
    ax.set_xlabel("distance |p_BC| [m]")
    ax.set_ylabel("yaw of X_BC (roll about the optical axis) [rad]")
    ax.set_title(f"{len(rows)} starts ({result.plant}): failed and slowest marked")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=4, fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "starts.png", dpi=120)
    plt.close(fig)
    return ["t_converged.png", "starts.png"]
