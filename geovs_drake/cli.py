"""Command line: ``geovs-drake simulate``, ``demo``, ``sweep`` and ``compare``.

Examples::

    geovs-drake simulate --json
    geovs-drake simulate --plant kinematic --initial=-0.1,0.05,-0.7,0.1,0,1.2
    geovs-drake simulate --initial-velocity=-0.2,0,0.3,0.05,-0.1,0
    geovs-drake simulate --sensor rendered --camera-rate 30 --resolution 320x240
    geovs-drake demo --out results
    geovs-drake sweep --starts 10000 --duration 10 --json
    geovs-drake sweep --scheduler tcp://host:8786 --starts 100000
    geovs-drake simulate --controller ibvs --ibvs-depth mean --initial=0,0,-0.5,0,0,3.1
    geovs-drake compare --plant kinematic --out results/compare

Exit codes: see ``EXIT_CODES`` (shown by ``geovs-drake --help``). A command that
needs an extra that is not installed says so in one line, e.g. ``geovs-drake sweep
needs dask[distributed]: pip install "geovs-drake[sweep]"``, and exits with 2.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
import textwrap
from pathlib import Path
from typing import NoReturn

from geovs_drake import __version__
from geovs_drake._optional import MissingExtra
from geovs_drake.progress import HorizonProgress, Progress
from geovs_drake.scenario import (
    CONTROLLERS,
    IBVS_DEPTHS,
    MOUNTS,
    PLANTS,
    SENSORS,
    PoseConfig,
    ScenarioConfig,
    load_scenario,
    load_suite,
)
from geovs_drake.simulation import StartOutsideDomain, simulate

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_BROKEN_PIPE",
    "EXIT_CODES",
    "EXIT_CONVERGED",
    "EXIT_INTERRUPTED",
    "EXIT_NOT_CONVERGED",
    "SIMULATE_PROGRESS_DELAY_S",
    "build_parser",
    "exit_code_of",
    "main",
]

EXIT_CONVERGED = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141

#: The exit codes of every command, in one place (``--help`` and the README show them).
EXIT_CODES: dict[int, str] = {
    EXIT_CONVERGED: "ran and converged (simulate, demo); the table finished (sweep, compare)",
    EXIT_BAD_INPUT: "bad input: an argument, the --config file, a start outside D,\n"
    "or a missing extra (one line on stderr, nothing run)",
    EXIT_NOT_CONVERGED: "ran and did not converge (simulate, demo): status not_converged,\n"
    "left_domain, lost_visibility, feature_lost or non_finite",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C)",
    EXIT_BROKEN_PIPE: "the reader of stdout went away (e.g. | head), as a shell reports SIGPIPE",
}


def _exit_codes_epilog() -> str:
    lines = ["exit codes:"]
    for code, text in EXIT_CODES.items():
        first, *rest = text.splitlines()
        lines.append(f"  {code:<4} {first}")
        lines += [f"       {line}" for line in rest]
    return "\n".join(lines)


def exit_code_of(status: str) -> int:
    """The exit code of a run that finished with ``status``: 0 converged, else 3."""
    return EXIT_CONVERGED if status == "converged" else EXIT_NOT_CONVERGED


class _OneLineParser(argparse.ArgumentParser):
    """Bad arguments in one line on stderr (exit code 2), without argparse's usage block."""

    def error(self, message: str) -> NoReturn:
        if message.endswith("expected one argument"):  # most often a value "-0.1,..."
            message += " (write a value that starts with '-' as --option=-0.1,...)"
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _EpilogTableFormatter(argparse.HelpFormatter):
    """Keeps the exit-code table's lines, and never breaks a word at its hyphen (an
    option such as ``--initial-velocity=-0.1,...`` stays whole, ready to copy)."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if text.startswith("exit codes:"):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        text = " ".join(text.split())
        return "\n".join(
            textwrap.wrap(
                text,
                width,
                initial_indent=indent,
                subsequent_indent=indent,
                break_on_hyphens=False,
            )
        )

    def _split_lines(self, text: str, width: int) -> list[str]:
        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)


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
    if args.plant:
        config.plant = args.plant
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
    _apply_path_and_mount_args(args, config)
    if args.ibvs_depth is not None:
        config.control.ibvs_depth = args.ibvs_depth
    _apply_camera_args(config, args)
    config.validate()
    return config


def _numbers(values: list[float]) -> str:
    return ",".join(f"{v:g}" for v in values)


def _add_scenario_args(p: argparse.ArgumentParser) -> None:
    d = ScenarioConfig()
    p.add_argument(
        "--config",
        metavar="FILE",
        help="scenario YAML (fields of ScenarioConfig; the options below override it) "
        "(default: none, the built-in scenario)",
    )
    p.add_argument(
        "--plant",
        choices=PLANTS,
        help="dynamic: the MultibodyPlant free body driven by a wrench; kinematic: the "
        f"camera's twist is commanded (default: the config's, else {d.plant})",
    )
    p.add_argument(
        "--controller",
        choices=CONTROLLERS,
        help="the control law: nf (the navigation function), or a baseline commanding the "
        "camera's twist: ibvs (four points), pbvs (pose from c^-1(y)), spherical (sphere "
        f"features) (default: the config's, else {d.controller})",
    )
    p.add_argument(
        "--ibvs-depth",
        choices=IBVS_DEPTHS,
        help="depth estimate of --controller ibvs: true (the current interaction matrix with "
        "the true depths, from c^-1(y)), desired (the matrix at the goal) or mean (their "
        f"mean) (default: the config's, else {d.control.ibvs_depth})",
    )
    p.add_argument(
        "--initial",
        type=_pose_arg,
        metavar="x,y,z,roll,pitch,yaw",
        help="initial camera pose X_BC in the target frame [m, rad]; "
        "write negative first values as --initial=-0.2,... "
        f"(default: the config's, else {_numbers(d.initial.xyz + d.initial.rpy)})",
    )
    p.add_argument(
        "--initial-velocity",
        type=_twist_arg,
        metavar="wx,wy,wz,vx,vy,vz",
        help="initial body twist (Omega, V) of the camera in its frame C [rad/s, m/s], "
        "G^-1 dG/dt for G = X_BC (dynamic loop only); "
        "write negative first values as --initial-velocity=-0.1,... "
        f"(default: the config's, else at rest {_numbers(d.initial_velocity)})",
    )
    p.add_argument(
        "--goal",
        type=_pose_arg,
        metavar="x,y,z,roll,pitch,yaw",
        help="goal camera pose X_BC* in the target frame [m, rad] "
        f"(default: the config's, else {_numbers(d.goal.xyz + d.goal.rpy)})",
    )
    p.add_argument(
        "--duration",
        type=float,
        metavar="T",
        help=f"simulated time [s] (default: the config's, else {d.duration:g})",
    )


#: ``simulate`` shows progress on stderr only once a run has taken this long [s wall]
#: (the default 30 s run takes well under a second).
SIMULATE_PROGRESS_DELAY_S = 3.0


# ---- path following (--controller path) and the fixed camera (--mount): issue 12
def _add_path_and_mount_args(p: argparse.ArgumentParser) -> None:
    d = ScenarioConfig()
    p.add_argument(
        "--mount",
        choices=MOUNTS,
        help="hand: the camera rides on the driven body (eye-in-hand); fixed: the camera is "
        "fixed in the world and the target sphere is driven (eye-to-hand, G = H^-1 of Eq. 16) "
        f"(default: the config's, else {d.mount})",
    )
    p.add_argument(
        "--path-duration",
        type=float,
        metavar="T",
        help="with --controller path: the planned image path's duration [s] "
        f"(default: the config's, else {d.path.duration:g})",
    )
    p.add_argument(
        "--path-feedback",
        type=float,
        metavar="GAIN",
        help="with --controller path: the gain k [1/s] of the log-map feedback added to the "
        "feed-forward of Eq. (18); 0 is Eq. (18) as written, open loop "
        f"(default: the config's, else {d.path.feedback_gain:g})",
    )


def _apply_path_and_mount_args(args: argparse.Namespace, config: ScenarioConfig) -> None:
    if args.mount is not None:
        config.mount = args.mount
    if args.path_duration is not None:
        config.path.duration = args.path_duration
    if args.path_feedback is not None:
        config.path.feedback_gain = args.path_feedback


# --- The camera options of `simulate` (issue 13): --sensor, --camera-rate, --resolution.
def _resolution_arg(text: str) -> list[int]:
    parts = text.lower().split("x")
    try:
        size = [int(v) for v in parts]
    except ValueError:
        size = []
    if len(size) != 2 or min(size) < 16:
        raise argparse.ArgumentTypeError(
            f"expected WxH, two integers >= 16 such as 320x240, got {text!r}"
        )
    return size


def _add_camera_args(p: argparse.ArgumentParser) -> None:
    d = ScenarioConfig().camera
    p.add_argument(
        "--sensor",
        choices=SENSORS,
        help="exact: the controller reads y = c(H); rendered: Drake renders the target "
        "(RgbdSensor, VTK) and y is extracted from each frame; pinhole: that measurement "
        "on exact image points, without rendering (dynamic plant only for the last two) "
        f"(default: the config's, else {d.sensor})",
    )
    p.add_argument(
        "--camera-rate",
        type=float,
        metavar="HZ",
        help=f"frames per second of the camera (default: the config's, else {d.rate:g})",
    )
    p.add_argument(
        "--resolution",
        type=_resolution_arg,
        metavar="WxH",
        help="image size [px]; the focal length makes the inscribed cone the field of view "
        f"(default: the config's, else {d.resolution[0]}x{d.resolution[1]})",
    )


def _apply_camera_args(config: ScenarioConfig, args: argparse.Namespace) -> None:
    if getattr(args, "sensor", None):
        config.camera.sensor = args.sensor
    if getattr(args, "camera_rate", None) is not None:
        if not (math.isfinite(args.camera_rate) and args.camera_rate > 0):
            raise ValueError(f"--camera-rate must be finite and > 0 [Hz]: {args.camera_rate}")
        config.camera.rate = args.camera_rate
    if getattr(args, "resolution", None) is not None:
        config.camera.resolution = args.resolution


# --- end of the camera options.


def _simulate(args: argparse.Namespace) -> int:
    config = _config_from_args(args)
    progress = HorizonProgress(
        config.duration, "geovs-drake simulate", delay_s=SIMULATE_PROGRESS_DELAY_S
    )
    try:
        result = simulate(config, progress=progress)
    except StartOutsideDomain as e:
        print(f"geovs-drake: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    finally:
        progress.close()
    if args.json:
        print(json.dumps(result.summary()))
    else:
        print(result.one_line())
    return exit_code_of(result.status)


def _demo(args: argparse.Namespace) -> int:
    from geovs_drake.demo import check_demo_args, run_demo

    check_demo_args(args.out, args.duration)  # before any side effect
    result = run_demo(
        args.out, args.duration, meshcat=not args.no_meshcat, rendered=not args.no_rendered
    )
    return exit_code_of(result.status)


class _SweepInputError(ValueError):
    """A bad ``sweep`` argument, found before anything runs."""


def _sweep_checks(args: argparse.Namespace) -> None:
    """Every bad input in one line, before anything starts (exit code 2)."""
    for name in ("starts", "workers", "chunk"):
        value = getattr(args, name)
        if value < 1:
            raise _SweepInputError(f"--{name} must be >= 1: --{name} {value}")
    if not (math.isfinite(args.duration) and args.duration > 0):
        raise _SweepInputError(f"--duration must be finite and > 0 [s]: --duration {args.duration}")
    if args.velocity in ("bounded", "above") and args.plant == "kinematic":
        raise _SweepInputError(
            f"--velocity {args.velocity} needs --plant dynamic (the kinematic loop is first order "
            "and starts at rest)"
        )
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise _SweepInputError(f"--out {out} exists and is not a directory")
    if args.config and not Path(args.config).is_file():
        raise _SweepInputError(f"--config {args.config}: no such file")


def _write_rows(path: Path, rows: list[dict], fields: tuple[str, ...]) -> None:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)


def _sweep(args: argparse.Namespace) -> int:
    from geovs_drake.analysis import sweep

    _sweep_checks(args)
    config = load_scenario(args.config) if args.config else ScenarioConfig()
    config.plant = args.plant
    config.validate()
    velocity = args.velocity or ("bounded" if args.plant == "dynamic" else "none")
    X_BC, twists = sweep.sample_starts(config, args.starts, args.seed, velocity)
    out = Path(args.out)
    csv_path = out / "results.csv"
    progress = Progress(args.starts, "starts", "geovs-drake sweep")
    stream = {}

    def on_chunk(rows: list[dict]) -> None:
        # Rows as they arrive (a crash leaves what finished); sorted at the end.
        if not stream:
            out.mkdir(parents=True, exist_ok=True)
            stream["file"] = open(csv_path, "w", newline="")
            stream["writer"] = csv.DictWriter(stream["file"], fieldnames=sweep.ROW_FIELDS)
            stream["writer"].writeheader()
        stream["writer"].writerows(rows)
        stream["file"].flush()
        progress.update(len(rows))

    code = 0
    try:
        result = sweep.run_sweep(
            config,
            X_BC,
            twists,
            duration=args.duration,
            engine=args.engine,
            workers=args.workers,
            scheduler=args.scheduler,
            chunk=args.chunk,
            on_chunk=on_chunk,
        )
    except sweep.SweepInterrupted as e:
        result, code = e.result, EXIT_INTERRUPTED
    finally:
        progress.close()
        if stream:
            stream["file"].close()
    out.mkdir(parents=True, exist_ok=True)
    _write_rows(csv_path, result.rows, sweep.ROW_FIELDS)
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


def _add_sweep_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--config",
        metavar="FILE",
        help="scenario YAML (fields of ScenarioConfig) (default: none, the built-in scenario)",
    )
    p.add_argument(
        "--plant",
        choices=PLANTS,
        default="dynamic",
        help="dynamic: the MultibodyPlant free body; kinematic: commanded twist (default: dynamic)",
    )
    p.add_argument(
        "--starts", type=int, default=1000, metavar="N", help="number of starts (default: 1000)"
    )
    p.add_argument(
        "--duration",
        type=float,
        default=10.0,
        metavar="T",
        help="simulated time per start [s] (default: 10)",
    )
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
    p.add_argument(
        "--workers",
        type=int,
        default=2,
        metavar="K",
        help="worker processes of the local Dask cluster; 1 runs in this process "
        "(default: 2; ignored with --scheduler)",
    )
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
    p.add_argument(
        "--out",
        default="results/sweep",
        metavar="DIR",
        help="output folder: results.csv, summary.json, plots (default: results/sweep)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print the summary as one JSON line (default: one line of text)",
    )


def _compare(args: argparse.Namespace) -> int:
    from geovs_drake.analysis import compare

    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1: --workers {args.workers}")
    suite = load_suite(args.suite)  # bad input before anything runs
    runs = len(suite.scenarios) * len(compare.LAWS)
    progress = Progress(runs, "runs", "geovs-drake compare")
    try:
        result, files = compare.compare(
            args.suite,
            plant=args.plant,
            out_dir=args.out,
            workers=args.workers,
            duration=args.duration,
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
            f"{len(compare.LAWS)} laws): {counts} | {result.wall_time_s:.1f} s wall | "
            f"{args.out}/table.md"
        )
    return EXIT_CONVERGED


def _add_compare_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--plant",
        choices=PLANTS,
        default="dynamic",
        help="dynamic: the MultibodyPlant free body, the baselines through the velocity-"
        "tracking wrench; kinematic: commanded twist (default: dynamic)",
    )
    p.add_argument(
        "--suite",
        metavar="FILE",
        default=None,
        help="suite YAML (SuiteConfig: duration, conundrum, scenarios with name, xyz, "
        "rpy_deg) (default: the package's geovs_drake/scenarios/suite.yaml)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="T",
        help="simulated time per run [s] (default: the suite's)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=2,
        metavar="K",
        help="worker processes; 1 runs in this process (default: 2)",
    )
    p.add_argument(
        "--out",
        default="results/compare",
        metavar="DIR",
        help="output folder: table.md, table.csv, image_sphere_<conundrum>.png, "
        "camera_paths.png (default: results/compare)",
    )
    p.add_argument(
        "--json", action="store_true", help="print the summary and rows as one JSON line"
    )


def build_parser() -> argparse.ArgumentParser:
    """The ``geovs-drake`` argument parser: its subcommands and their options."""
    epilog = _exit_codes_epilog()
    formatter = _EpilogTableFormatter
    parser = _OneLineParser(
        prog="geovs-drake",
        description="Geometric visual servoing (Cowan & Chang) on Drake.",
        epilog=epilog,
        formatter_class=formatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser(
        "simulate",
        help="simulate a scenario and print a one-line result",
        description="Simulate a scenario and print its result on stdout: one line, or one "
        f"JSON object with --json. A run that takes longer than {SIMULATE_PROGRESS_DELAY_S:g} s "
        "of wall time shows its progress on stderr.",
        epilog=epilog,
        formatter_class=formatter,
    )
    _add_scenario_args(sim)
    _add_path_and_mount_args(sim)
    _add_camera_args(sim)
    sim.add_argument(
        "--json", action="store_true", help="print one JSON object (default: one line of text)"
    )
    sim.set_defaults(func=_simulate)
    demo = sub.add_parser(
        "demo",
        help="the default dynamic scenario from a hard start, with plots",
        description="Run the dynamic loop from a hard start (rolled 160 deg about the optical "
        "axis, offset sideways and 0.35 m further out than the goal) and write to DIR: "
        "servo.html (the Meshcat recording, standalone), image_view.png, run.png, "
        "nf_slices.png, block_diagram.svg|png and summary.json. Prints progress on stderr, "
        "the run's line and where the recording is on stdout.",
        epilog=epilog,
        formatter_class=formatter,
    )
    demo.add_argument(
        "--out",
        default="results",
        metavar="DIR",
        help="output folder, created if missing (default: results)",
    )
    demo.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="T",
        help=f"simulated time [s] (default: {ScenarioConfig().duration:g})",
    )
    demo.add_argument(
        "--no-meshcat",
        action="store_true",
        help="skip the Meshcat recording servo.html (default: record it)",
    )
    demo.add_argument(
        "--no-rendered",
        action="store_true",
        help="skip the run through rendered camera images (default: run it, the first "
        "6 s at 320x240 and 30 Hz; it needs OpenCV and EGL)",
    )
    demo.set_defaults(func=_demo)
    sw = sub.add_parser(
        "sweep",
        help="the energy guarantee on many random starts in D, in chunks on Dask",
        description="Run the loop from N random starts in D (images uniform in D's model "
        "chart) on dask.distributed; write DIR/results.csv (a row per start), "
        "DIR/summary.json and plots. Exit code 0 when the sweep ran, 2 for bad input, "
        "130 after Ctrl-C (the finished rows are written).",
        epilog=epilog,
        formatter_class=formatter,
    )
    _add_sweep_args(sw)
    sw.set_defaults(func=_sweep)
    cmp = sub.add_parser(
        "compare",
        help="every control law (NF, IBVS, PBVS, sphere features) on every scenario of a suite",
        description="Run the navigation function and the baselines (point IBVS with each "
        "depth estimate, PBVS, sphere features) from every start of a suite, in the same "
        "plant with the same monitors; write DIR/table.md, DIR/table.csv and figures. Exit "
        "code 0 when the table is finished, whatever the laws did; 2 for bad input.",
        epilog=epilog,
        formatter_class=formatter,
    )
    _add_compare_args(cmp)
    cmp.set_defaults(func=_compare)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``geovs-drake`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Bad input (an argument, the ``--config`` file, a start outside D) and a missing
    extra are one line on stderr and exit code 2; see :data:`EXIT_CODES`.
    """
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ValueError as e:  # bad configuration: one clear line, no traceback
        print(f"geovs-drake: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MissingExtra as e:  # e.g. geovs-drake demo needs matplotlib: pip install ...
        print(e.message(f"geovs-drake {args.command}"), file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("geovs-drake: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader closed the pipe: stop quietly, and point stdout at devnull so
        # that the interpreter's final flush does not raise again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE


if __name__ == "__main__":
    sys.exit(main())
