"""The arm loops' real-time factor against the free body's, in the same process.

Baseline: the free rig's loop (the paper's body), same law, same start, same horizon,
timed in this process alternately with the arm's, so the ratio holds when the
machine's speed drifts. Reported: the median real-time factor of each loop over
``--repeat`` runs of ``simulate()`` (its monitor and step recorder included), the
steps per simulated second, and arm / free.

    .venv/bin/python benchmarks/bench_arm.py [--repeat 5] [--duration 30]
"""

from __future__ import annotations

import argparse
import statistics

from _record import Figure, record

from geovs_drake.scenario import PoseConfig, ScenarioConfig
from geovs_drake.simulation import simulate

#: The issue's small move: a start every carrier reaches and converges from.
SMALL_MOVE = PoseConfig(xyz=[0.05, -0.03, -0.55], rpy=[0.1, -0.05, 0.3])


def run(carrier: str, plant: str, duration: float) -> tuple[float, float, str]:
    config = ScenarioConfig(carrier=carrier, plant=plant, duration=duration, initial=SMALL_MOVE)
    r = simulate(config)
    return r.sim_time_s / r.wall_time_s, r.steps / r.sim_time_s, r.status


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--duration", type=float, default=30.0)
    args = parser.parse_args()
    figures = []
    for plant in ("dynamic", "kinematic"):
        for carrier in ("free", "arm"):
            run(carrier, plant, 1.0)  # load the compiled kernels, build the caches
        rtf = {"free": [], "arm": []}
        steps, status = {}, {}
        for _ in range(args.repeat):
            for carrier in ("free", "arm"):  # alternately: the ratio survives drift
                factor, steps[carrier], status[carrier] = run(carrier, plant, args.duration)
                rtf[carrier].append(factor)
        free, arm = (statistics.median(rtf[c]) for c in ("free", "arm"))
        print(
            f"{plant}: free body {free:.0f}x real time ({steps['free']:.0f} steps/s, "
            f"{status['free']}), arm {arm:.0f}x ({steps['arm']:.0f} steps/s, {status['arm']}); "
            f"arm / free = {arm / free:.2f} (median of {args.repeat})"
        )
        figures.append(
            Figure(
                f"{plant} arm (UR5), real-time factor, small move, {args.duration:g} s",
                arm,
                "x real time",
                "the free body, same law and start, alternately",
                free,
                target=">= 30x" if plant == "dynamic" else "",
            )
        )
    record("bench_arm", "The arm loops against the free body", figures)


if __name__ == "__main__":
    main()
