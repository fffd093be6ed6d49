"""Command line: ``geovs-drake simulate`` and ``geovs-drake demo``.

Examples::

    geovs-drake simulate --json
    geovs-drake simulate --controller kinematic --initial=-0.1,0.05,-0.7,0.1,0,1.2
    geovs-drake simulate --initial-velocity=-0.2,0,0.3,0.05,-0.1,0
    geovs-drake demo --out results
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import NoReturn

from geovs_drake.scenario import PoseConfig, ScenarioConfig, load_scenario
from geovs_drake.simulation import StartOutsideDomain, simulate

__all__ = ["main"]


class _OneLineParser(argparse.ArgumentParser):
    """Bad arguments in one line on stderr (exit code 2), without argparse's usage block."""

    def error(self, message: str) -> NoReturn:
        if message.endswith("expected one argument"):  # most often a value "-0.1,..."
            message += " (write a value that starts with '-' as --option=-0.1,...)"
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _six_numbers(text: str, names: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"expected 6 numbers {names}: {text!r}") from e
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected 6 finite numbers {names}, got {text!r}")
    return values


def _pose_arg(text: str) -> PoseConfig:
    values = _six_numbers(text, "x,y,z,roll,pitch,yaw")
    return PoseConfig(xyz=values[:3], rpy=values[3:])


def _twist_arg(text: str) -> list[float]:
    return _six_numbers(text, "wx,wy,wz,vx,vy,vz")


def _config_from_args(args: argparse.Namespace) -> ScenarioConfig:
    config = load_scenario(args.config) if args.config else ScenarioConfig()
    if args.controller:
        config.controller = args.controller
    if args.initial is not None:
        config.initial = args.initial
    if args.initial_velocity is not None:
        config.initial_velocity = args.initial_velocity
    if args.goal is not None:
        config.goal = args.goal
    if args.duration is not None:
        config.duration = args.duration
    return config


def _add_scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="scenario YAML (fields of ScenarioConfig)")
    p.add_argument("--controller", choices=["kinematic", "dynamic"])
    p.add_argument(
        "--initial",
        type=_pose_arg,
        metavar="x,y,z,roll,pitch,yaw",
        help="initial camera pose X_BC in the target frame [m, rad]; "
        "write negative first values as --initial=-0.2,...",
    )
    p.add_argument(
        "--initial-velocity",
        type=_twist_arg,
        metavar="wx,wy,wz,vx,vy,vz",
        help="initial body twist (Omega, V) of the camera in its frame C [rad/s, m/s], "
        "G^-1 dG/dt for G = X_BC (dynamic loop only; default at rest); "
        "write negative first values as --initial-velocity=-0.1,...",
    )
    p.add_argument(
        "--goal",
        type=_pose_arg,
        metavar="x,y,z,roll,pitch,yaw",
        help="goal camera pose X_BC* (default 0,0,-0.5,0,0,0)",
    )
    p.add_argument("--duration", type=float, help="simulated seconds")


def _simulate(args: argparse.Namespace) -> int:
    config = _config_from_args(args)
    try:
        result = simulate(config)
    except StartOutsideDomain as e:
        print(f"geovs-drake: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result.summary()))
    else:
        print(result.one_line())
    return 0 if result.status in ("converged", "not_converged") else 1


def _demo(args: argparse.Namespace) -> int:
    from geovs_drake.demo import run_demo

    return run_demo(args.out, args.duration, meshcat=not args.no_meshcat)


def main(argv: list[str] | None = None) -> int:
    parser = _OneLineParser(
        prog="geovs-drake",
        description="Geometric visual servoing (Cowan & Chang) on Drake.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="simulate a scenario and print a one-line result")
    _add_scenario_args(sim)
    sim.add_argument("--json", action="store_true", help="print one JSON object")
    sim.set_defaults(func=_simulate)
    demo = sub.add_parser("demo", help="the default dynamic scenario from a hard start, with plots")
    demo.add_argument("--out", default="results", help="output folder (default: results)")
    demo.add_argument("--duration", type=float, default=None)
    demo.add_argument("--no-meshcat", action="store_true", help="skip the Meshcat recording")
    demo.set_defaults(func=_demo)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as e:  # bad configuration: one clear line, no traceback
        print(f"geovs-drake: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
