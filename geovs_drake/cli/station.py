"""``geovs-drake station``: the simulated Panda, its camera and the target behind LCM;
its ground truth as one line (or one JSON object) at the end."""

from __future__ import annotations

import argparse
import json

from geovs_drake.cli._options import (
    EXIT_CONVERGED,
    EXIT_NOT_CONVERGED,
    _apply_variant_fields,
    _set_variant_field,
    add_command,
    add_config,
    add_field,
    add_json,
    add_latency_frames,
    add_variant_flag,
    pose_arg,
)
from geovs_drake.hardware.config import DEFAULT_LCM_URL, HARDWARE_ARM, MODES, check_lcm_url


def add_hardware_options(p: argparse.ArgumentParser) -> None:
    """What ``station`` and ``controller`` share: the station file, the arm, the bus and
    the duration."""
    add_config(p)
    # Its own flag, not the simulator's --arm: one arm only, and no --carrier here.
    add_variant_flag(
        p,
        "--arm",
        _set_variant_field("carrier", ("arm",), "model"),
        f"the arm: {HARDWARE_ARM} only (drake-franka-driver's channels, 7 joints; "
        "the default, and the station file's)",
        choices=(HARDWARE_ARM,),
    )
    p.add_argument(
        "--lcm",
        metavar="URL",
        help="the LCM bus: udpm://ADDRESS:PORT?ttl=N between processes, memq:// in one "
        f"(default: the config's hardware.lcm_url, else {DEFAULT_LCM_URL})",
    )
    add_field(p, "--duration", ("duration",), "run time [s]", type=float, metavar="T")
    add_latency_frames(p)


def hardware_changes(args: argparse.Namespace, **extra) -> dict:
    """The hardware fields the flags set (``--lcm`` checked here: one line, exit 2)."""
    changes = {k: v for k, v in extra.items() if v is not None}
    if args.lcm is not None:
        check_lcm_url(args.lcm)
        changes["lcm_url"] = args.lcm
    return changes


def setup_of(args: argparse.Namespace, **extra):
    """The resolved scenario and hardware config of ``args``: the station file
    (``--config``, default the shipped panda_lcm.yaml), ``--scenario-text``, the flags."""
    from geovs_drake.hardware.run import load_setup

    layers = []
    if args.scenario_text is not None:
        layers.append(("--scenario-text", args.scenario_text))
    layers += args.layers or []
    return load_setup(
        args.config,
        layers,
        hardware_changes(args, **extra),
        adjust=lambda config: _apply_variant_fields(config, args.variant_fields or []),
    )


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``station`` command."""
    p = add_command(
        sub,
        "station",
        "simulate the Panda, its camera and the target behind LCM",
        "Simulate the Panda, its camera and the target, publishing PANDA_STATUS at 1 kHz "
        "and the camera's frames on the camera channel, and applying PANDA_COMMAND "
        "(drake-franka-driver's channels). The arm is held at rest until the first "
        "command; after it, no command for --command-timeout seconds holds the arm "
        "(joint damping, gravity compensated) and ends the run with status command_lost. "
        "At the end, the ground truth: one line, or one JSON object with --json.",
    )
    add_hardware_options(p)
    add_field(
        p,
        "--initial",
        ("initial",),
        "initial camera pose X_BC in the target frame [m, rad]; write negative first "
        "values as --initial=-0.2,...",
        type=pose_arg,
        metavar="x,y,z,roll,pitch,yaw",
    )
    add_field(
        p,
        "--sensor",
        ("sensor",),
        "the camera: pinhole (y on exact image points, sent as lcmt_scope on the camera "
        "channel) or rendered (the scene drawn by RenderEngineVtk, its colour image sent "
        "as lcmt_image_array on the image channel, stamped with its capture time; the "
        "controller, given the same --sensor, extracts y with the arm's own pixels masked "
        "by a self-filter)",
        choices=("pinhole", "rendered"),
    )
    p.add_argument(
        "--command-timeout",
        type=float,
        metavar="S",
        help="after the first command, none for this long holds the arm [s] (default: "
        "the config's, else 0.1, drake-franka-driver's expire_sec)",
    )
    p.add_argument(
        "--mode",
        choices=tuple(MODES),
        help="what the station takes from PANDA_COMMAND (drake-franka-driver's "
        "--control_mode; a command of the other mode holds the arm and is counted as "
        "refused): "
        + "; ".join(f"{name}: {text}" for name, text in MODES.items())
        + " (default: the config's, else torque)",
    )
    p.add_argument(
        "--drop-every-frame",
        type=int,
        metavar="N",
        help="do not publish every N-th camera frame, to see what a lost frame does "
        "(default: the config's, else 0: publish all)",
    )
    p.add_argument(
        "--status-delay",
        type=float,
        metavar="S",
        help="report the joints as they were S seconds ago in PANDA_STATUS, to see what a "
        "late status does (default: the config's, else 0)",
    )
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the station; the exit code (0 converged, 3 otherwise)."""
    if args.command_timeout is not None and not args.command_timeout > 0:
        raise ValueError(f"--command-timeout must be > 0 [s]: {args.command_timeout}")
    if args.drop_every_frame is not None and args.drop_every_frame < 0:
        raise ValueError(f"--drop-every-frame must be >= 0: {args.drop_every_frame}")
    if args.status_delay is not None and not args.status_delay >= 0:
        raise ValueError(f"--status-delay must be >= 0 [s]: {args.status_delay}")
    setup = setup_of(
        args,
        command_timeout=args.command_timeout,
        drop_every_frame=args.drop_every_frame,
        mode=args.mode,
        status_delay=args.status_delay,
    )
    from geovs_drake.hardware.run import open_lcm, run_station
    from geovs_drake.hardware.station import build_station

    station = build_station(setup.resolved, setup.hardware, open_lcm(setup.hardware.lcm_url))
    summary = run_station(station, setup.resolved.config.duration)
    if args.json:
        print(json.dumps(summary, allow_nan=False))
    else:
        print(
            f"{summary['status']}: position error {summary['final_position_error_m']:.3g} m, "
            f"{summary['commands_received']} commands ({summary['commands_refused']} refused), "
            f"joint speed "
            f"{summary['final_joint_speed']:.3g} rad/s after {summary['sim_time_s']:.3g} s "
            f"(real-time rate {summary['realtime_rate']:.3g})"
        )
    return EXIT_CONVERGED if summary["status"] == "converged" else EXIT_NOT_CONVERGED
