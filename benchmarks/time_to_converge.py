"""Time to reach 1 mm and 1 mrad from random starts in D, both loops.

Backs the default duration (30 s): it should be several times the worst
time seen. Runs on 2 processes.

    .venv/bin/python benchmarks/time_to_converge.py [--samples 50] [--seed 123]
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import numpy as np
from pydrake.common.yaml import yaml_dump_typed
from pydrake.math import RigidTransform

from geovs_drake.analysis.studies.monte_carlo import random_initial_poses, scenarios_from_starts
from geovs_drake.scenario import PLANT_VARIANTS, ScenarioConfig, load_scenario
from geovs_drake.simulation import (
    CONVERGENCE_POSITION_M,
    CONVERGENCE_ROTATION_RAD,
    pose_error,
    simulate,
)


def time_to_converge(text: str) -> tuple[float, str]:
    """The first logged time after which the pose error stays within tolerance."""
    config = load_scenario(data=text)
    r = simulate(config)
    err = np.array([pose_error(RigidTransform(X), config.X_BC_goal) for X in r.X_BC])
    outside = np.flatnonzero(
        (err[:, 0] > CONVERGENCE_POSITION_M) | (err[:, 1] > CONVERGENCE_ROTATION_RAD)
    )
    if len(outside) == 0:
        return 0.0, r.status
    if outside[-1] + 1 >= len(r.times):
        return float("inf"), r.status
    return float(r.times[outside[-1] + 1]), r.status


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--samples", type=int, default=50)
    parser.add_argument("--seed", type=int, default=123)
    args = parser.parse_args()
    for controller in ("dynamic", "kinematic"):
        config = ScenarioConfig(plant=PLANT_VARIANTS[controller]())
        starts = random_initial_poses(np.random.default_rng(args.seed), args.samples, config)
        texts = [yaml_dump_typed(c) for c in scenarios_from_starts(config, starts)]
        with ProcessPoolExecutor(2, mp_context=get_context("spawn")) as pool:
            results = list(pool.map(time_to_converge, texts))
        t = np.array([r[0] for r in results])
        statuses = sorted({r[1] for r in results})
        print(
            f"{controller}: {args.samples} starts, statuses {statuses}; time to 1 mm / 1 mrad: "
            f"median {np.median(t):.2f} s, worst {t.max():.2f} s "
            f"(default duration {config.duration:.0f} s = {config.duration / t.max():.1f}x worst)"
        )


if __name__ == "__main__":
    main()
