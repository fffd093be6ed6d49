"""The linearisation studies' cost, against the loop they linearise, in the same process.

Figures (medians of ``--repeat``): one ``linearize`` call at an arbitrary state in D
(the dynamic loop, its inputs and outputs included) against one ``build_loop`` of the
same loop (each call builds its study diagram); the LTV model of a 10-s run at 100
samples (``linearize_along``), the sampled Lyapunov region (200 rays) and the SOS
certificate of the kinematic loop's region (``certify_region``: degree-3 Taylor
polynomial, Drake's ``RegionOfAttraction`` with SCS, the nonlinear boundary check)
against the 10-s run itself (``simulate``). The dynamic loop's certificate (degree 2,
about 4 to 9 minutes) stays out of the benchmark; docs/linearization.md quotes it.

    .venv/bin/python benchmarks/bench_linearize.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from _record import Figure, record

from geovs_drake.analysis.linear.certified_region import certify_region
from geovs_drake.analysis.linear.linearization import linearize, linearize_along, state_at
from geovs_drake.analysis.linear.region import lyapunov_region
from geovs_drake.loop import build_loop
from geovs_drake.scenario import Kinematic, PoseConfig, ScenarioConfig
from geovs_drake.simulation import simulate

#: An arbitrary state in D: a small move off the goal, moving.
START = PoseConfig(xyz=[0.02, -0.01, -0.52], rpy=[0.02, -0.01, 0.1])
TWIST = np.array([0.05, -0.02, 0.03, 0.01, 0.02, -0.01])


def _median_s(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    config = ScenarioConfig(duration=10.0)
    config.initial = START
    x0 = state_at(config, config.X_BC_initial, TWIST)
    linearize(config, x0)  # compile and cache
    one = _median_s(lambda: linearize(config, x0), args.repeat)
    build = _median_s(lambda: build_loop(config, log=False), args.repeat)
    run = simulate(config)
    sim = _median_s(lambda: simulate(config), args.repeat)
    times = np.linspace(0.0, run.times[-1], 100)
    ltv = _median_s(lambda: linearize_along(run, times), max(1, args.repeat // 2))
    region = _median_s(lambda: lyapunov_region(config, rays=200), 1)
    kinematic = ScenarioConfig(plant=Kinematic(), duration=10.0)
    kinematic.initial = START
    sampled = lyapunov_region(kinematic, rays=200)
    certify = _median_s(lambda: certify_region(kinematic, sampled=sampled), 1)
    sim_kinematic = _median_s(lambda: simulate(kinematic), args.repeat)
    print(f"linearize at a state: {1e3 * one:.1f} ms (build_loop {1e3 * build:.1f} ms)")
    print(f"LTV of a 10-s run, 100 samples: {ltv:.2f} s (the run: {sim:.3f} s)")
    print(f"Lyapunov region, 200 rays: {region:.2f} s")
    print(f"SOS certificate (kinematic, degree 3): {certify:.2f} s (run {sim_kinematic:.3f} s)")
    figures = [
        Figure("one linearize call at a state in D (dynamic, inputs and outputs)", 1e3 * one,
               "ms", "one build_loop of the same loop", 1e3 * build),
        Figure("LTV model of a 10-s run at 100 samples", ltv, "s",
               "simulate() of that 10-s run", sim),
        Figure("sampled Lyapunov region, 200 rays (dynamic)", region, "s",
               "simulate() of a 10-s run", sim),
        Figure("SOS-certified region (kinematic, degree 3, SCS)", certify, "s",
               "simulate() of a 10-s kinematic run", sim_kinematic),
    ]  # fmt: skip
    record("bench_linearize", "The linearisation studies against the loop", figures)


if __name__ == "__main__":
    main()
