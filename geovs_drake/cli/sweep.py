"""``geovs-drake sweep``: the energy guarantee on many random starts in D, on Dask."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from geovs_drake.cli._options import (
    EXIT_INTERRUPTED,
    add_command,
    add_config,
    add_duration,
    add_json,
    add_out,
    add_plant,
    add_workers,
    check_at_least_1,
    check_duration,
    check_out,
    load_config,
)
from geovs_drake.progress import Progress


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``sweep`` command."""
    p = add_command(
        sub,
        "sweep",
        "the energy guarantee on many random starts in D, in chunks on Dask",
        "Run the loop from N random starts in D (images uniform in D's model "
        "chart) on dask.distributed; write DIR/results.csv (a row per start), "
        "DIR/summary.json and plots. Exit code 0 when the sweep ran, 2 for bad input, "
        "130 after Ctrl-C (the finished rows are written).",
    )
    add_config(p)
    add_plant(p)
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
        "(default: bounded on the dynamic plant, none on the kinematic one)",
    )
    p.add_argument(
        "--engine",
        choices=["batch", "drake"],
        default="batch",
        help="batch: the compiled batch engine; drake: Drake's Simulator start by start, "
        "slow, for cross-checks (default: batch)",
    )
    add_workers(p, 2, "worker processes of the local Dask cluster", "2; ignored with --scheduler")
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="address of a running Dask scheduler, e.g. tcp://host:8786 "
        "(default: none, a local cluster of --workers processes)",
    )
    p.add_argument(
        "--chunk", type=int, default=1000, metavar="C", help="starts per task (default: 1000)"
    )
    add_out(p, "results/sweep", "output folder: results.csv, summary.json, plots")
    add_json(p, "the summary as one JSON line")
    p.set_defaults(func=run)


def _checked_config(args: argparse.Namespace):
    """Every bad input in one line (ValueError), before anything starts."""
    check_at_least_1(args, "starts", "workers", "chunk")
    check_duration(args.duration)
    if args.config and not Path(args.config).is_file():
        raise ValueError(f"--config {args.config}: no such file")
    config = load_config(args)
    if args.velocity in ("bounded", "above") and config.plant == "kinematic":
        raise ValueError(
            f"--velocity {args.velocity} needs --plant dynamic (the kinematic loop is first order "
            "and starts at rest)"
        )
    check_out(args.out)
    return config


def run(args: argparse.Namespace) -> int:
    """Run ``sweep``; the exit code."""
    from geovs_drake.analysis import sweep

    config = _checked_config(args)
    velocity = args.velocity or ("bounded" if config.plant == "dynamic" else "none")
    X_BC, twists = sweep.sample_starts(config, args.starts, args.seed, velocity)
    out = Path(args.out)
    progress = Progress(args.starts, "starts", "geovs-drake sweep")
    code = 0
    try:
        result = sweep.run_sweep_to_csv(
            config,
            X_BC,
            twists,
            out,
            on_chunk=lambda rows: progress.update(len(rows)),
            duration=args.duration,
            engine=args.engine,
            workers=args.workers,
            scheduler=args.scheduler,
            chunk=args.chunk,
        )
    except sweep.SweepInterrupted as e:
        result, code = e.result, EXIT_INTERRUPTED
    finally:
        progress.close()
    summary = sweep.summarize(result, seed=args.seed, velocity=velocity)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    if result.rows:
        try:
            sweep.plot_sweep(result, out)
        except KeyboardInterrupt:  # the rows and the summary are written already
            print("geovs-drake: interrupted while plotting: plots skipped", file=sys.stderr)
            code = EXIT_INTERRUPTED
    if args.json:
        print(json.dumps(summary))
    else:
        counts = ", ".join(f"{k} {v}" for k, v in summary["counts"].items())
        g = summary["guarantee"]
        # The guarantee's condition: the energy below k_p (Appendix C), or for the
        # kinematic loop, which has no energy, phi below 1 (every start in D).
        covered = "E0 < k_p" if result.plant == "dynamic" else "phi0 < 1"
        print(
            f"{result.plant}: {len(result.rows)} of {result.starts} starts x "
            f"{result.duration:g} s ({result.engine}): {counts} | {covered}: {g['starts']} "
            f"starts, of which left D {g['left_domain']}, lost visibility "
            f"{g['lost_visibility']}, non-finite {g['non_finite']} | "
            f"{result.wall_time_s:.1f} s wall | {out}/"
        )
    if code == EXIT_INTERRUPTED:
        print(
            f"geovs-drake: interrupted: {len(result.rows)} of {result.starts} starts "
            f"finished, written to {out}/",
            file=sys.stderr,
        )
    return code
