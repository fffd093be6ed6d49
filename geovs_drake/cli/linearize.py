"""``geovs-drake linearize``: the loop's linear model at the goal or at a pose
(:func:`geovs_drake.analysis.linearization.linearize`): its eigenvalues, damping ratios
and time constants, and whether it is stable."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from geovs_drake.cli._options import (
    EXIT_BAD_INPUT,
    EXIT_CONVERGED,
    add_command,
    add_config,
    add_json,
    add_plant,
    check_out,
    load_config,
    pose_arg,
)

#: The file ``--out DIR`` writes: the JSON object ``--json`` prints.
OUT_FILE = "linearize.json"


def at_arg(text: str) -> str | dict[str, list[float]]:
    """``goal`` or a camera pose ``x,y,z,roll,pitch,yaw`` (X_BC, the target frame)."""
    return "goal" if text.strip().lower() == "goal" else pose_arg(text)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``linearize`` command."""
    p = add_command(
        sub,
        "linearize",
        "the loop's linear model at the goal or a pose: eigenvalues, damping, stability",
        "Linearise the closed loop (Drake's Linearize at the goal, "
        "FirstOrderTaylorApproximation at another pose, the camera at rest there) in "
        "minimal coordinates (the camera's displacement, then its twist for the dynamic "
        "loop) and print its eigenvalues, damping ratios and time constants and whether "
        "it is stable (every real part < 0). Away from the goal the model is the "
        "frozen-time one: an indication, not a proof. Exit code 0 when it ran, 2 for bad "
        "input (a pose outside D included).",
    )
    add_config(p)
    add_plant(p)
    p.add_argument(
        "--at",
        type=at_arg,
        default="goal",
        metavar="goal|x,y,z,roll,pitch,yaw",
        help="where: the goal, or a camera pose X_BC in the target frame [m, rad], at "
        "rest; write negative first values as --at=-0.1,... (default: goal)",
    )
    add_json(p)
    p.add_argument(
        "--out",
        metavar="DIR",
        help=f"also write the JSON object to DIR/{OUT_FILE} (default: none)",
    )
    p.set_defaults(func=run)


def summary(lin) -> dict:
    """The JSON object of a :class:`~geovs_drake.analysis.linearization.LoopLinearization`."""
    lam = lin.eigenvalues

    def finite_or_none(values: np.ndarray) -> list[float | None]:
        return [float(v) if np.isfinite(v) else None for v in values]

    return {
        "plant": lin.plant,
        "at_equilibrium": lin.at_equilibrium,
        "A": lin.A.tolist(),
        "eigenvalues": [[float(v.real), float(v.imag)] for v in lam],
        "max_real_part": lin.max_real_part,
        "damping_ratios": finite_or_none(lin.damping_ratios),
        "time_constants": finite_or_none(lin.time_constants),
        "stable": bool(lin.max_real_part < 0),
    }


def _table(lin, where: str) -> str:
    verdict = "stable" if lin.max_real_part < 0 else "not stable"
    lines = [
        f"{lin.plant} loop linearised at {where}: {verdict} "
        f"(largest real part {lin.max_real_part:.4g} 1/s)"
        + ("" if lin.at_equilibrium else "; not an equilibrium: the frozen-time model"),
        f"  {'eigenvalue [1/s]':>26}  {'damping ratio':>13}  {'time constant [s]':>17}",
    ]
    for lam, zeta, tau in zip(lin.eigenvalues, lin.damping_ratios, lin.time_constants, strict=True):
        lines.append(f"  {lam.real:>12.5g} {lam.imag:+12.5g}j  {zeta:>13.4g}  {tau:>17.4g}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Run ``linearize``; the exit code."""
    if args.out is not None:
        check_out(args.out)
    config = load_config(args)
    from geovs_drake.analysis.linearization import linearize, state_at
    from geovs_drake.scenario import PoseConfig
    from geovs_drake.simulation import StartOutsideDomain, check_start

    if args.at == "goal":
        where, state = "the goal", None
    else:
        text = ",".join(f"{v:g}" for v in args.at["xyz"] + args.at["rpy"])
        where = f"X_BC = ({text})"
        config.initial = PoseConfig(**args.at)
        try:
            check_start(config)  # D's margins at the pose, and the goal's
        except StartOutsideDomain as e:
            reason = str(e).removeprefix("start outside D: ")
            print(f"geovs-drake: --at {text} is outside D: {reason}", file=sys.stderr)
            return EXIT_BAD_INPUT
        state = state_at(config, config.X_BC_initial)
    lin = linearize(config, state)
    out = summary(lin)
    if args.out is not None:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / OUT_FILE).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out) if args.json else _table(lin, where))
    return EXIT_CONVERGED
