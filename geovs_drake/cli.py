"""Command line: ``geovs-drake demo`` and ``geovs-drake simulate``."""

from __future__ import annotations

import argparse
import sys

import numpy as np
from pydrake.math import RigidTransform

from geovs_drake.camera import camera_map, camera_map_inverse, visibility


def _demo(args: argparse.Namespace) -> int:
    X_CB = RigidTransform([0.0, 0.0, 0.5])
    y = camera_map(X_CB, 0.1)
    np.set_printoptions(precision=6, suppress=True)
    print("default goal X_CB* = translation (0, 0, 0.5), identity rotation")
    print(f"visibility nu(H*) = {float(visibility(X_CB, 0.1)):.6f}")
    print(f"y* = c(H*) = [q1, q2, q3, lambda, s] = {y.to_vector()}")
    print(f"c^-1(y*) =\n{camera_map_inverse(y, 0.1).GetAsMatrix4()}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="geovs-drake", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run the default scenario")
    demo.set_defaults(func=_demo)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
