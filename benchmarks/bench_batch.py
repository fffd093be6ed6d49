"""The batch engine: 10^4 dynamic starts x 10 s, against the Drake loop, in one process.

Baseline, timed in the same process: the same kind of starts run one by one
through the Drake diagram (``simulate()``), on a sample, per start-second.

    .venv/bin/python benchmarks/bench_batch.py [--starts 10000] [--duration 10] [--drake 20]
"""

from __future__ import annotations

import argparse
import copy
import time

import numba
import numpy as np
from _record import Figure, record
from pydrake.math import RigidTransform

from geovs_drake.batch import loop_parameters, run_batch
from geovs_drake.geometry.camera import camera_map_inverse
from geovs_drake.sampling import random_features_in_domain
from geovs_drake.scenario import PLANT_VARIANTS, PoseConfig, ScenarioConfig
from geovs_drake.simulation import simulate


def starts(config: ScenarioConfig, n: int, seed: int) -> np.ndarray:
    """Camera poses X_BC whose images are uniform in D's model chart (at rest)."""
    y = random_features_in_domain(np.random.default_rng(seed), n, config.domain.to_domain(), 0.98)
    X_CB = camera_map_inverse(y, config.radius)
    return np.linalg.inv(X_CB)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--starts", type=int, default=10_000)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--drake", type=int, default=20, help="starts for the Drake baseline")
    args = parser.parse_args()
    figures = []
    for plant in ("dynamic", "kinematic"):
        config = ScenarioConfig(plant=PLANT_VARIANTS[plant](), duration=args.duration)
        X_BC = starts(config, args.starts, seed=1)
        p = loop_parameters(config)
        run_batch(config, X_BC[:2], duration=0.1, parameters=p)  # load the compiled code
        t = time.perf_counter()
        result = run_batch(config, X_BC, parameters=p)
        wall = time.perf_counter() - t
        t = time.perf_counter()
        for i in range(args.drake):
            c = copy.deepcopy(config)
            c.initial = PoseConfig.from_rigid_transform(RigidTransform(X_BC[i]))
            simulate(c)
        drake_per_start = (time.perf_counter() - t) / args.drake
        counts = {k: v for k, v in result.counts().items() if v}
        print(
            f"{plant}: {args.starts} starts x {args.duration:g} s in {wall:.1f} s wall "
            f"({numba.get_num_threads()} threads, {np.mean(result.steps):.0f} steps per start), "
            f"{counts}; Drake loop {drake_per_start:.2f} s per start: batch is "
            f"{drake_per_start * args.starts / wall:.0f}x faster"
        )
        figures.append(
            Figure(
                f"batch engine, {args.starts} {plant} starts x {args.duration:g} s, "
                f"{numba.get_num_threads()} threads",
                wall,
                "s",
                f"the Drake loop start by start ({args.drake} starts, scaled to {args.starts})",
                drake_per_start * args.starts,
                target="<= 10 s" if plant == "dynamic" else "",
            )
        )
    record("bench_batch", "The batch engine against the Drake loop", figures)


if __name__ == "__main__":
    main()
