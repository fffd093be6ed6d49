"""``geovs-drake compare``: every control law on every scenario of a suite."""

from __future__ import annotations

import argparse
import copy
import json

from geovs_drake.cli._options import (
    EXIT_CONVERGED,
    add_command,
    add_config,
    add_duration,
    add_field,
    add_json,
    add_out,
    add_plant,
    add_workers,
    check_at_least_1,
    load_layers,
)
from geovs_drake.progress import Progress
from geovs_drake.scenario import load_suite


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``compare`` command."""
    p = add_command(
        sub,
        "compare",
        "every control law (NF, IBVS, PBVS, sphere features) on every scenario of a suite",
        "Run the navigation function and the baselines (point IBVS with each "
        "depth estimate, PBVS, sphere features) from every start of a suite, in the same "
        "plant with the same monitors; write DIR/table.md, DIR/table.csv and figures. Exit "
        "code 0 when the table is finished, whatever the laws did; 2 for bad input.",
    )
    add_config(p)
    add_plant(p, ", the baselines through the velocity-tracking wrench")
    add_field(
        p,
        "--carrier",
        ("carrier",),
        "free: the paper's free rig; arm: the camera on the arm shipped in the package, "
        "each start's joints by IK (the baselines' twists through the arm's velocity-"
        "tracking torques, or the kinematic arm's J_C^+); quadrotor: the NF (through its "
        "attitude cascade) and Hamel & Mahony's law side by side, the quadrotor's starts "
        "(quadrotor_suite.yaml) by default",
        choices=("free", "arm", "quadrotor"),
    )
    p.add_argument(
        "--suite",
        metavar="FILE",
        default=None,
        help="suite YAML (SuiteConfig: duration, conundrum, scenarios with name, xyz, "
        "rpy_deg) (default: the package's geovs_drake/scenarios/suite.yaml; with "
        "--carrier quadrotor, quadrotor_suite.yaml)",
    )
    add_duration(p, "simulated time per run", None, "the suite's")
    add_workers(p, 2)
    add_out(
        p,
        "results/compare",
        "output folder: table.md, table.csv, image_sphere_<conundrum>.png, camera_paths.png",
    )
    add_json(p, "the summary and rows as one JSON line")
    p.set_defaults(func=run)


def _base(args: argparse.Namespace):
    """The scenario of ``args``, resolved, with the goal for its start: the base's own start
    is never run (each entry of the suite gives one), and one the carrier refuses (the
    quadrotor's by default, tilted 115 deg) must not refuse the whole comparison."""
    from geovs_drake.loop.resolver import resolve

    config = load_layers(args)
    config.initial = copy.deepcopy(config.goal)
    config.initial_velocity = [0.0] * 6
    return resolve(config).config


def run(args: argparse.Namespace) -> int:
    """Run ``compare``; the exit code."""
    from geovs_drake.analysis.studies import compare

    check_at_least_1(args, "workers")
    base = _base(args)  # the scenario every start of the suite is put into
    suite_path = args.suite if args.suite is not None else compare.default_suite(base)
    suite = load_suite(suite_path)  # bad input before anything runs
    laws = compare.compared_laws(base)
    runs = len(suite.scenarios) * len(laws)
    progress = Progress(runs, "runs", "geovs-drake compare")
    try:
        result, files = compare.compare(
            suite_path,
            plant=None,  # the scenario's own
            out_dir=args.out,
            workers=args.workers,
            duration=args.duration,
            base=base,
            on_run=lambda run: progress.update(1),
        )
    finally:
        progress.close()
    summary = compare.summarize(result, files)
    if args.json:
        print(json.dumps(summary))
    else:
        counts = ", ".join(f"{k} {v}" for k, v in summary["counts"].items())
        print(
            f"{result.plant}: {runs} runs ({len(suite.scenarios)} scenarios x "
            f"{len(laws)} laws): {counts} | {result.wall_time_s:.1f} s wall | "
            f"{args.out}/table.md"
        )
    return EXIT_CONVERGED
