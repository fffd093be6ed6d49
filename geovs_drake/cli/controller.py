"""``geovs-drake controller``: the NF law on PANDA_STATUS and the camera's frames,
commanding PANDA_COMMAND; what it saw as one line (or one JSON object) at the end."""

from __future__ import annotations

import argparse
import json

from geovs_drake.cli._options import (
    EXIT_CONVERGED,
    EXIT_NOT_CONVERGED,
    add_command,
    add_field,
    add_json,
)
from geovs_drake.cli.station import add_hardware_options, setup_of
from geovs_drake.hardware.config import MODES


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``controller`` command."""
    p = add_command(
        sub,
        "controller",
        "run the NF law on a Panda's LCM channels (a station's or a real robot's)",
        "Run the NF law on what a real Panda gives: joint state from PANDA_STATUS, frames "
        "from the camera channel (predicted between frames from the joints' motion), and "
        "command PANDA_COMMAND. With no status or no frame within its timeout it stops "
        "commanding and says so; it refuses to start from an image it cannot invert (exit "
        "2). At the end: frames received and dropped, its own estimate of the image error. "
        "Exit 0 when it ran its duration, or when the statuses stopped after its own "
        "estimate had converged (status station_stopped: the station ended its run); 3 "
        "when it stopped otherwise (statuses lost mid-servo, no frame, the target lost).",
    )
    add_hardware_options(p)
    add_field(
        p,
        "--sensor",
        ("sensor",),
        "the station's camera: pinhole (y from lcmt_scope on the camera channel) or "
        "rendered (images from lcmt_image_array on the image channel: y extracted, the "
        "arm's own pixels masked by a self-filter drawn at the capture's joints)",
        choices=("pinhole", "rendered"),
    )
    p.add_argument(
        "--mode",
        choices=tuple(MODES),
        help="what PANDA_COMMAND carries: "
        + "; ".join(f"{name}: {text}" for name, text in MODES.items())
        + " (default: the config's, else torque)",
    )
    p.add_argument(
        "--command-rate",
        type=float,
        metavar="HZ",
        help="PANDA_COMMAND's rate [Hz], at most the status rate (default: the config's, "
        "else 250; the robot holds the last command between)",
    )
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the controller; the exit code (0 when it ran its duration or the station
    stopped after it had converged, 3 when it stopped otherwise)."""
    if args.command_rate is not None and not args.command_rate > 0:
        raise ValueError(f"--command-rate must be > 0 [Hz]: {args.command_rate}")
    setup = setup_of(args, mode=args.mode, command_rate=args.command_rate)
    from geovs_drake.hardware.controller import build_controller
    from geovs_drake.hardware.run import CONTROLLER_SUCCESS, open_lcm, run_controller

    controller = build_controller(setup.resolved, setup.hardware, open_lcm(setup.hardware.lcm_url))
    summary = run_controller(controller, setup.resolved.config.duration)
    if args.json:
        print(json.dumps(summary, allow_nan=False))
    else:
        why = f" ({summary['stop_reason']})" if summary["stop_reason"] else ""
        print(
            f"{summary['status']}{why}: {summary['frames_received']} frames "
            f"({summary['frames_dropped']} dropped), {summary['commands_sent']} commands, "
            f"image error {summary['final_image_error']:.3g} (real-time rate "
            f"{summary['realtime_rate']:.3g})"
        )
    return EXIT_CONVERGED if summary["status"] in CONTROLLER_SUCCESS else EXIT_NOT_CONVERGED
