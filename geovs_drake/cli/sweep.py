"""``geovs-drake sweep``: the energy guarantee on many random starts in D, on Dask."""

from __future__ import annotations

import argparse
import copy
import json
import os
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

from geovs_drake.cli._options import (
    EXIT_INTERRUPTED,
    add_axis,
    add_command,
    add_config,
    add_duration,
    add_json,
    add_latency_frames,
    add_out,
    add_plant,
    add_workers,
    check_at_least_1,
    check_duration,
    check_out,
    load_layers,
)
from geovs_drake.progress import Progress

if TYPE_CHECKING:
    from collections.abc import Callable

#: The plots a sweep writes in its folder (:func:`~geovs_drake.analysis.sweep.plot_summary`).
PLOTS = ("t_converged.png", "starts.png")


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``sweep`` command."""
    p = add_command(
        sub,
        "sweep",
        "the energy guarantee on many random starts in D, in chunks on Dask",
        "Run the loop from N random starts in D (images uniform in D's model "
        "chart) on dask.distributed. The workers draw their own starts (start i depends "
        "on the seed and i only) and write their rows to the Parquet dataset "
        "DIR/results/part-*.parquet; this process merges their summaries into "
        "DIR/summary.json and the plots. DIR/sweep.json records the sweep, for --resume. "
        "Exit code 0 when the sweep ran, 2 for bad input, 130 after Ctrl-C (the finished "
        "parts are kept: --resume continues).",
    )
    add_config(p)
    add_plant(p)
    add_axis(
        p,
        "carrier",
        "what carries the camera",
        {
            "free": "the paper's free rig",
            "arm": "the camera on the arm shipped in the package (each start's joints by "
            "IK, its twist carried to the joints at the same E0 / k_p; the batch engine "
            "runs it with the exact sensor, a camera on it with --engine drake)",
            "quadrotor": "the quadrotor (--engine drake: level starts at rest, docs/quadrotor.md)",
        },
        names=("free", "arm", "quadrotor"),
    )
    add_axis(
        p,
        "sensor",
        "what the controller reads",
        {
            "exact": "y = c(H)",
            "pinhole": "the camera at its rate, on exact image points",
            "rendered": "the camera at its rate, its frames rendered",
        },
        after=" (the batch engine runs the pinhole on the free rig, the rendered camera "
        "with --engine drake; a "
        "scenario's sensor: !Pinhole {...} sets its rate, latency and errors)",
    )
    add_latency_frames(p)
    p.add_argument(
        "--starts", type=int, default=1000, metavar="N", help="number of starts (default: 1000)"
    )
    add_duration(p, "simulated time per start", 10.0, "10")
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="S",
        help="seed of the starts' generator (default: 0)",
    )
    p.add_argument(
        "--velocity",
        choices=["none", "bounded", "above"],
        default=None,
        help="initial twists: none (at rest), bounded (random, E0 < k_p) or above "
        "(E0 / k_p uniform in [1.5, 4): outside the guarantee) "
        "(default: bounded on the dynamic plant, none on the kinematic one and the quadrotor)",
    )
    p.add_argument(
        "--engine",
        choices=["batch", "drake"],
        default="batch",
        help="batch: the compiled batch engine; drake: Drake's Simulator start by start, "
        "slow, for cross-checks (default: batch)",
    )
    _add_where_options(p)
    p.add_argument(
        "--chunk", type=int, default=1000, metavar="C", help="starts per task (default: 1000)"
    )
    add_out(
        p,
        "results/sweep",
        "output folder: results/ (Parquet), sweep.json, summary.json, plots; a new sweep "
        "replaces the one there",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the sweep recorded in --out: run only the parts not written yet "
        "(the same config, seed, velocity, duration, starts, chunk and engine, or exit 2); "
        "a damaged part is named and run again (default: off, a new sweep)",
    )
    p.add_argument(
        "--csv",
        action="store_true",
        help="also write DIR/results.csv, sorted by start, for a sweep small enough to be "
        "useful as text (above the limit, 10^5 starts or about 56 MB, exit 2) (default: off)",
    )
    _add_speed_options(p)
    add_json(p, "the summary as one JSON line")
    p.set_defaults(func=run)


def _add_where_options(p: argparse.ArgumentParser) -> None:
    """``--workers``, ``--scheduler`` and ``--local-cluster``: where the parts run."""
    add_workers(
        p,
        2,
        "worker processes of the local Dask cluster, started for 100000 starts or more, "
        "--engine drake or --local-cluster; otherwise numba threads in this process",
        "2; ignored with --scheduler",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="address of a running Dask scheduler, e.g. tcp://host:8786 "
        "(default: none: this process or a local cluster, as --workers says)",
    )
    p.add_argument(
        "--local-cluster",
        action="store_true",
        help="run the parts on a local Dask cluster of --workers processes whatever the "
        "number of starts (default: off, the batch engine's cluster from 100000 starts up)",
    )


def _add_speed_options(p: argparse.ArgumentParser) -> None:
    """``--timings`` and ``--no-plots``."""
    p.add_argument(
        "--no-plots",
        action="store_true",
        help="write neither t_converged.png nor starts.png (and remove the ones an earlier "
        "run left in DIR): matplotlib's import and drawing, about 0.6-1 s of a sweep's fixed "
        "cost. The rows, sweep.json and summary.json are the same; --resume without "
        "--no-plots draws the plots later from the parts' summaries, running no part again "
        "(default: off, the plots drawn)",
    )
    p.add_argument(
        "--timings",
        action="store_true",
        help="also one line on stderr: where the command's wall time went (start-up and "
        "imports, set-up, first part, all parts, summary and plots), its CPU time on all "
        "threads and the load average (default: off)",
    )


def _checked_config(args: argparse.Namespace):
    """Every bad input in one line (ValueError), before anything starts."""
    check_at_least_1(args, "starts", "workers", "chunk")
    check_duration(args.duration)
    if args.config and not Path(args.config).is_file():
        raise ValueError(f"--config {args.config}: no such file")
    config = load_layers(args)
    if config.carrier.traits.hover:
        # The sweep draws its own starts and never reads the scenario's: a hovering
        # carrier's checks of its start (the default start's tilt) do not apply.
        config.initial = copy.deepcopy(config.goal)
    from geovs_drake.loop.resolver import resolve

    config = resolve(config).config
    if args.velocity in ("bounded", "above") and not config.dynamic:
        raise ValueError(
            f"--velocity {args.velocity} needs --plant dynamic (the kinematic loop is first order "
            "and starts at rest)"
        )
    check_out(args.out)
    from geovs_drake.analysis.sweep import CSV_LIMIT

    if args.csv and args.starts > CSV_LIMIT:
        raise ValueError(
            f"--csv writes at most {CSV_LIMIT} starts: --starts {args.starts} (read the "
            "Parquet dataset DIR/results instead)"
        )
    if args.resume and not (Path(args.out) / "sweep.json").is_file():
        raise ValueError(f"--resume: no sweep in {args.out} (no sweep.json)")
    return config


class _Clock:
    """The command's phases: seconds since :meth:`mark`'s previous call, by name."""

    def __init__(self) -> None:
        self.start = self.last = time.perf_counter()
        self.phases: dict[str, float] = {}
        self.first_part: float | None = None

    def mark(self, phase: str) -> None:
        now = time.perf_counter()
        self.phases[phase] = now - self.last
        self.last = now

    def part(self) -> None:
        if self.first_part is None:
            self.first_part = time.perf_counter() - self.start

    def line(self) -> str:
        """The ``--timings`` line; the start-up (interpreter, imports) where the system
        tells the process's start (Linux's /proc). It ends with the process's CPU time on
        all its threads and the load average: on a shared machine the wall time follows
        the load, the CPU time much less (numba's threads count in it, so on two free cores
        the parts' wall time is about half their CPU time)."""
        started = _process_start()
        before = "" if started is None else f"start-up {self.start - started:.2f} s, "
        phases = ", ".join(f"{k} {v:.2f} s" for k, v in self.phases.items())
        first = ""
        if self.first_part is not None:
            first = f"; the first part {self.first_part:.2f} s after the start-up"
        try:
            load = f", load average {os.getloadavg()[0]:.1f}"
        except OSError:  # no load average on this system
            load = ""
        cpu = f"; CPU {time.process_time():.2f} s on all threads{load}"
        return f"geovs-drake sweep: timings: {before}{phases}{first}{cpu}"


def _process_start() -> float | None:
    """This process's start on :func:`time.perf_counter`'s clock, from Linux's
    /proc/self/stat (its 22nd field, the start in clock ticks after boot) and /proc/uptime;
    None where there is no /proc."""
    try:
        with open("/proc/self/stat") as f:
            # The command name (field 2) may hold spaces: the fields after its ")" count.
            fields = f.read().rsplit(")", 1)[1].split()
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
    except (OSError, IndexError, ValueError):
        return None
    age = uptime - int(fields[19]) / os.sysconf("SC_CLK_TCK")
    return time.perf_counter() - age


def _plots_imported_after_a_part(no_plots: bool) -> Callable[[], None]:
    """A call for each finished part that starts matplotlib's import (about 0.4 s) once,
    on a thread of its own, after the first: the next parts integrate on numba's threads
    with the GIL released meanwhile, and the plots, drawn at the end, find it done. Not
    before the first part, whose set-up (numba's first load, the starts) holds the GIL
    and waited for the import (docs/performance.md, The sweep's start-up)."""
    started = no_plots

    def after_part() -> None:
        nonlocal started
        if not started:
            started = True
            from geovs_drake.plotting import pyplot

            threading.Thread(target=pyplot, name="import-pyplot", daemon=True).start()

    return after_part


def run(args: argparse.Namespace) -> int:
    """Run ``sweep``; the exit code."""
    clock = _Clock()
    from geovs_drake.analysis import sweep

    config = _checked_config(args)
    hover = config.carrier.traits.hover
    velocity = args.velocity or ("bounded" if config.dynamic and not hover else "none")
    out = Path(args.out)
    progress = Progress(args.starts, "starts", "geovs-drake sweep")

    import_plots = _plots_imported_after_a_part(args.no_plots)

    def on_part(count: int) -> None:
        clock.part()
        progress.update(count)
        import_plots()

    clock.mark("set-up")
    code = 0
    try:
        result = sweep.run_sweep(
            config,
            sweep.SampledStarts(args.starts, args.seed, velocity),
            args.duration,
            engine=args.engine,
            workers=args.workers,
            scheduler=args.scheduler,
            chunk=args.chunk,
            out=out,
            resume=args.resume,
            on_part=on_part,
            warn=lambda line: print(f"geovs-drake: {line}", file=sys.stderr),
            # A cluster of one process would only add its start: 1 runs here.
            local_cluster=True if args.local_cluster and args.workers > 1 else None,
        )
    except sweep.SweepInterrupted as e:
        result, code = e.result, EXIT_INTERRUPTED
    finally:
        progress.close()
    clock.mark("parts")
    summary = result.report()
    _write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    finished = result.summary.finished
    try:
        if args.no_plots:
            for name in PLOTS:  # an earlier sweep's plots would not be this one's
                (out / name).unlink(missing_ok=True)
        elif finished:
            result.plot(out)
        if args.csv and code == 0:
            sweep.write_csv(result, out / "results.csv")
    except KeyboardInterrupt:  # the parts and the summary are written already
        print("geovs-drake: interrupted while plotting: plots skipped", file=sys.stderr)
        code = EXIT_INTERRUPTED
    clock.mark("summary and plots")
    if args.timings:
        print(clock.line(), file=sys.stderr)
    if args.json:
        print(json.dumps(summary))
    else:
        counts = ", ".join(f"{k} {v}" for k, v in summary["counts"].items())
        g = summary["guarantee"]
        # The guarantee's condition: the energy below k_p (Appendix C), or for the
        # kinematic loop, which has no energy, phi below 1 (every start in D).
        covered = "E0 < k_p" if config.dynamic else "phi0 < 1"
        resumed = f", {result.resumed_parts} parts resumed" if result.resumed_parts else ""
        # The arm's joint limit, only where the arm ran (a free rig has none).
        limit = f", joint limit {g['joint_limit']}" if "joint_limit" in summary["counts"] else ""
        # How the arm's runs ended: a stall at the barrier told from a run still moving.
        ends = ""
        if "joint_limit" in summary["counts"]:
            ends = " | ends: " + ", ".join(
                f"{k.replace('_', ' ')} {v}" for k, v in summary["ends"].items() if v
            )
        if "hover" in summary:  # a hovering carrier: its fractions, its rotors
            h = summary["hover"]
            ends += (
                f" | converged {h['converged']:.1%}, left D {h['left_domain']:.1%}, "
                f"saturated {h['saturated']:.1%} (mean {h['mean_saturation_fraction']:.2%} "
                f"of the samples), peak tilt {h['max_tilt_deg']:.1f} deg"
            )
        print(
            f"{result.plant}: {finished} of {result.starts} starts x "
            f"{result.duration:g} s ({result.engine}{resumed}): {counts} | {covered}: "
            f"{g['starts']} starts, of which left D {g['left_domain']}, lost visibility "
            f"{g['lost_visibility']}, non-finite {g['non_finite']}{limit}{ends} | "
            f"{result.wall_time_s:.1f} s wall | {out}/"
        )
    if code == EXIT_INTERRUPTED:
        print(
            f"geovs-drake: interrupted: {finished} of {result.starts} starts finished, "
            f"in {out}/results (--resume continues)",
            file=sys.stderr,
        )
    return code


def _write_text(path: Path, text: str) -> None:
    """Write ``path`` whole or not at all (a temporary name, then a rename)."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(path)
