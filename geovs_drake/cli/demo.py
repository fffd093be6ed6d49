"""``geovs-drake demo``: the default dynamic scenario from a hard start, with plots."""

from __future__ import annotations

import argparse

from geovs_drake.cli._options import (
    add_command,
    add_duration,
    add_out,
    exit_code_of,
    field_default,
)
from geovs_drake.scenario import CARRIER_VARIANTS


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``demo`` command."""
    p = add_command(
        sub,
        "demo",
        "the default dynamic scenario from a hard start, with plots",
        "Run the dynamic loop from a hard start (rolled 160 deg about the optical "
        "axis, offset sideways and 0.35 m further out than the goal) and write to DIR: "
        "servo.html (the Meshcat recording, standalone), image_view.png, run.png, "
        "nf_slices.png, block_diagram.svg|png and summary.json. Prints progress on stderr, "
        "the run's line and where the recording is on stdout.",
    )
    add_out(p, "results", "output folder, created if missing")
    add_duration(p, "simulated time", None, f"{field_default(('duration',)):g}")
    p.add_argument(
        "--carrier",
        choices=("free", "arm"),
        default="free",
        help="free: the paper's free rig; arm: the camera on the arm shipped in the "
        "package, IK from the same start (default: free)",
    )
    p.add_argument(
        "--no-meshcat",
        action="store_true",
        help="skip the Meshcat recording servo.html (default: record it)",
    )
    p.add_argument(
        "--no-rendered",
        action="store_true",
        help="skip the run through rendered camera images (default: run it, the first "
        "6 s at 320x240 and 30 Hz; it needs OpenCV and EGL)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``demo``; the exit code."""
    from geovs_drake.demo import check_demo_args, run_demo

    check_demo_args(args.out, args.duration)  # before any side effect
    result = run_demo(
        args.out,
        args.duration,
        meshcat=not args.no_meshcat,
        rendered=not args.no_rendered,
        carrier=CARRIER_VARIANTS[args.carrier](),
    )
    return exit_code_of(result.status)
