"""Command line: ``geovs-drake simulate``, ``demo``, ``sweep``, ``compare``, ``robustness``,
``camera-accuracy``, ``linearize``, ``place-base``, ``station`` and ``controller`` (the Panda
over LCM, issue 34); one module per command, the shared options in ``_options``.

Examples::

    geovs-drake simulate --json
    geovs-drake simulate --plant kinematic --initial=-0.1,0.05,-0.7,0.1,0,1.2
    geovs-drake simulate --scenario-text "{plant: !Kinematic {}, control: {kinematic_gain: 2}}"
    geovs-drake simulate --initial-velocity=-0.2,0,0.3,0.05,-0.1,0
    geovs-drake simulate --sensor rendered --camera-rate 30 --resolution 320x240
    geovs-drake demo --out results
    geovs-drake sweep --starts 10000 --duration 10 --json
    geovs-drake sweep --scheduler tcp://host:8786 --starts 100000
    geovs-drake simulate --controller ibvs --ibvs-depth mean --initial=0,0,-0.5,0,0,3.1
    geovs-drake compare --plant kinematic --out results/compare
    geovs-drake robustness --starts 20 --workers 2
    geovs-drake camera-accuracy --poses 200 --resolution 320x240
    geovs-drake linearize --plant kinematic --json
    geovs-drake linearize --at=0.02,-0.01,-0.52,0.02,-0.01,0.1
    geovs-drake place-base --arm panda
    geovs-drake station --json &  geovs-drake controller --json

A scenario is read once, in layers: ``--config FILE``, then ``--scenario-text YAML``,
then each option that sets a field (``--plant kinematic`` is ``{plant: kinematic}``, the
bare name of ``!Kinematic {}``),
with :func:`~geovs_drake.scenario.load_scenario`'s ``overrides``.

Exit codes: see ``EXIT_CODES`` (shown by ``geovs-drake --help``). A command that
needs an extra that is not installed says so in one line, e.g. ``geovs-drake sweep
needs dask[distributed]: pip install "geovs-drake[sweep]"``, and exits with 2.
"""

from __future__ import annotations

import argparse
import atexit
import os
import sys
import threading

from geovs_drake import __version__
from geovs_drake._optional import MissingExtra
from geovs_drake.cli import (
    camera_accuracy,
    compare,
    controller,
    demo,
    linearize,
    place_base,
    robustness,
    simulate,
    station,
    sweep,
)
from geovs_drake.cli._options import (
    EXIT_BAD_INPUT,
    EXIT_BROKEN_PIPE,
    EXIT_CODES,
    EXIT_CONVERGED,
    EXIT_INTERRUPTED,
    EXIT_NOT_CONVERGED,
    EpilogTableFormatter,
    OneLineParser,
    exit_code_of,
    exit_codes_epilog,
)

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
    "help_text",
    "main",
    "subcommands",
]

#: ``simulate`` shows progress on stderr only once a run has taken this long [s wall]
#: (the default 30 s run takes well under a second).
SIMULATE_PROGRESS_DELAY_S = 3.0


def build_parser() -> argparse.ArgumentParser:
    """The ``geovs-drake`` argument parser: its subcommands and their options."""
    parser = OneLineParser(
        prog="geovs-drake",
        description="Geometric visual servoing (Cowan & Chang) on Drake.",
        epilog=exit_codes_epilog(),
        formatter_class=EpilogTableFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    # Read here, at build time, so that the package's constant is the one in effect.
    simulate.add_parser(sub, SIMULATE_PROGRESS_DELAY_S)
    demo.add_parser(sub)
    sweep.add_parser(sub)
    compare.add_parser(sub)
    robustness.add_parser(sub)
    camera_accuracy.add_parser(sub)
    linearize.add_parser(sub)
    place_base.add_parser(sub)
    station.add_parser(sub)
    controller.add_parser(sub)
    return parser


def subcommands(
    parser: argparse.ArgumentParser | None = None,
) -> dict[str, argparse.ArgumentParser]:
    """Each command's name and parser, in the order ``geovs-drake --help`` lists them."""
    parser = parser or build_parser()
    return next(a for a in parser._actions if a.dest == "command").choices


def help_text(command: str | None = None, columns: int = 88) -> str:
    """The ``--help`` of ``geovs-drake`` or of ``command``, wrapped at ``columns``: the
    text the manual's reference shows (``.. cli-help::`` in docs/cli.rst)."""
    # argparse wraps to $COLUMNS, read when the formatter is made: set for this call only.
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(columns)
    try:
        parser = build_parser()
        return (subcommands(parser)[command] if command else parser).format_help().rstrip()
    finally:
        if saved is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = saved


#: How long the command's exit waits for a worker thread still running [s] before it
#: leaves the exit to Python's own finalisation (:func:`entry`).
THREAD_JOIN_S = 5.0


def entry() -> None:
    """The ``geovs-drake`` console script (and ``python -m geovs_drake.cli``): :func:`main`,
    then the process's exit without CPython's finalisation.

    That finalisation frees every module and runs pydrake's and numba's C++ static
    destructors: 0.15-0.3 s of a command's wall time (a 200-start sweep, alternating
    runs: 1.15-1.49 s against 0.95-1.02 s), when every output is written, closed and
    renamed into place already. What registered for the exit still runs (the threads
    still working are joined, then the ``atexit`` handlers: a Dask cluster's shutdown,
    logging's flush), and stdout and stderr are flushed. A thread still running after
    :data:`THREAD_JOIN_S` leaves the exit to Python as usual.
    """
    code = main()
    main_thread = threading.main_thread()
    workers = [t for t in threading.enumerate() if t is not main_thread and not t.daemon]
    for thread in workers:
        thread.join(THREAD_JOIN_S)
    if any(thread.is_alive() for thread in workers):
        sys.exit(code)
    atexit._run_exitfuncs()  # CPython's own call at exit, before the modules go
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a reader gone (main() said so) or a closed stream
            pass
    os._exit(code)


def main(argv: list[str] | None = None) -> int:
    """Run ``geovs-drake`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Bad input (an argument, the ``--config`` file or ``--scenario-text``, a start
    outside D) and a missing extra are one line on stderr and exit code 2; see
    :data:`EXIT_CODES`.
    """
    args = build_parser().parse_args(argv)
    try:
        code = args.func(args)
        # A pipe's stdout is block-buffered: a reader gone shows at this flush, inside
        # the try, not at the interpreter's own flush on exit (exit code 120 there).
        sys.stdout.flush()
        return code
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
