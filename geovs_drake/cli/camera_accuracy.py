"""``geovs-drake camera-accuracy``: the rendered camera's y against the exact c(H)
(:mod:`geovs_drake.analysis.studies.camera_accuracy`)."""

from __future__ import annotations

import argparse
import json

from geovs_drake.cli._options import (
    EXIT_CONVERGED,
    add_command,
    add_config,
    check_at_least_1,
    load_config,
    resolution_arg,
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``camera-accuracy`` command."""
    p = add_command(
        sub,
        "camera-accuracy",
        "how well the rendered camera measures y, against the exact c(H)",
        "Render the target from poses in D (images uniform in D's model chart), extract y "
        "from each frame and compare it with the exact y = c(H); print the errors' median "
        "and worst, and the failures by reason, as JSON. Exit code 0 when it ran, 2 for "
        "bad input.",
    )
    add_config(p)
    p.add_argument(
        "--poses", type=int, default=200, metavar="N", help="poses rendered (default: 200)"
    )
    p.add_argument(
        "--resolution",
        type=resolution_arg,
        default=[640, 480],
        metavar="WxH",
        help="image size [px] (default: 640x480)",
    )
    p.add_argument(
        "--seed", type=int, default=0, metavar="S", help="seed of the poses (default: 0)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``camera-accuracy``; the exit code."""
    check_at_least_1(args, "poses")
    config = load_config(args)
    from geovs_drake.analysis.studies.camera_accuracy import feature_accuracy

    result = feature_accuracy(
        config, n=args.poses, resolution=tuple(args.resolution), seed=args.seed
    )
    print(json.dumps(result.summary(), indent=2))
    return EXIT_CONVERGED
