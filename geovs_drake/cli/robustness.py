"""``geovs-drake robustness``: the loop through a camera under pixel noise, focal-length
and radius errors, latency and the camera rate (:mod:`geovs_drake.analysis.studies.robustness`)."""

from __future__ import annotations

import argparse
import math
import sys
import time

from geovs_drake.cli._options import (
    EXIT_CONVERGED,
    add_command,
    add_config,
    add_duration,
    add_out,
    add_workers,
    check_at_least_1,
    check_duration,
    check_out,
    load_config,
)
from geovs_drake.scenario import PREDICTIONS, Pinhole, camera_like


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``robustness`` command."""
    from geovs_drake.analysis.studies.robustness_levels import LEVELS, SHRINK

    p = add_command(
        sub,
        "robustness",
        "the loop through a camera under each camera error, from random starts",
        "Run the dynamic loop through a camera from random starts in D with one error "
        "at a time (pixel noise, focal-length error, radius error, latency; or the "
        "camera rate with --only rate), and latency again with soft gains; write "
        "DIR/rows.json, DIR/table.json and DIR/robustness.png once every run is done, "
        "and print a line per case. Exit code 0 when the table is finished, 2 for bad input.",
    )
    add_config(p)
    p.add_argument(
        "--starts", type=int, default=20, metavar="N", help="starts per case (default: 20)"
    )
    add_duration(p, "simulated time per run", 10.0, "10")
    p.add_argument(
        "--seed", type=int, default=0, metavar="S", help="seed of the starts (default: 0)"
    )
    p.add_argument(
        "--shrink",
        type=float,
        default=SHRINK,
        metavar="F",
        help="starts are drawn in this fraction of D's model chart, in (0, 1] "
        f"(default: {SHRINK:g})",
    )
    p.add_argument(
        "--sensor",
        choices=["pinhole", "rendered"],
        default="pinhole",
        help="pinhole: the extractor's measurement on exact image points; rendered: "
        "through Drake's rendered frames, slow (default: pinhole)",
    )
    p.add_argument(
        "--prediction",
        choices=list(PREDICTIONS),
        default=None,
        help="what the law sees between frames: none, the held frame; odometry, the held "
        "frame moved by the rig's motion since its capture (default: the config's "
        "camera's, else odometry)",
    )
    add_workers(p, 1)
    p.add_argument(
        "--only",
        choices=list(LEVELS),
        default=None,
        help="one sweep alone (default: every error, not the rate)",
    )
    p.add_argument(
        "--soft-duration",
        type=float,
        default=20.0,
        metavar="T",
        help="horizon of the latency sweep with SOFT_GAINS, which converge slower [s]; "
        "0 skips it (default: 20)",
    )
    add_out(p, "results/robustness", "output folder: rows.json, table.json, robustness.png")
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> None:
    """Every bad input in one line (ValueError), before anything runs."""
    check_at_least_1(args, "starts", "workers")
    check_duration(args.duration)
    if not (math.isfinite(args.soft_duration) and args.soft_duration >= 0):
        raise ValueError(
            f"--soft-duration must be finite and >= 0 [s]: --soft-duration {args.soft_duration}"
        )
    if not (math.isfinite(args.shrink) and 0 < args.shrink <= 1):
        raise ValueError(f"--shrink must be in (0, 1]: --shrink {args.shrink}")
    check_out(args.out)


def run(args: argparse.Namespace) -> int:
    """Run ``robustness``; the exit code."""
    from geovs_drake.analysis.studies.robustness import robustness_study

    _check(args)
    config = load_config(args)
    if args.prediction is not None:  # the camera of every case keeps the config's fields
        config.sensor = camera_like(config.sensor, Pinhole, prediction=args.prediction)
    start = time.perf_counter()
    runs = {"done": 0}

    def progress(done: int, total: int) -> None:
        runs["done"] += 1
        if done == total or done % max(1, total // 20) == 0:
            print(f"robustness: {done}/{total} runs", file=sys.stderr)

    table = robustness_study(
        config,
        args.out,
        starts=args.starts,
        duration=args.duration,
        seed=args.seed,
        shrink=args.shrink,
        sensor=args.sensor,
        only=args.only,
        soft_duration=args.soft_duration,
        workers=args.workers,
        progress=progress,
    )
    for t in table:
        predicted = t.get("predicted_position_error_m")
        print(
            f"{t['gains']:>7} {t['parameter']:>15} {t['level']:>6g}: "
            f"stayed {t['stayed']}/{t['runs']}, settled {t['settled']}/{t['runs']}, "
            f"at goal {t['converged']}/{t['runs']}, "
            "position error median "
            f"{t['position_error_median_m']:.2e} max {t['position_error_max_m']:.2e} m"
            + ("" if predicted is None else f" (predicted {predicted:.2e})")
            + f", rotation error median {t['rotation_error_median_rad']:.2e} max "
            f"{t['rotation_error_max_rad']:.2e} rad, spectral radius "
            f"{t['spectral_radius']:.3f}, {t['statuses']}"
        )
    print(f"{runs['done']} runs in {time.perf_counter() - start:.0f} s wall", file=sys.stderr)
    return EXIT_CONVERGED
