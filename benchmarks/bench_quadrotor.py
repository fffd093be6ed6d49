"""The quadrotor loop's cost (issue 43), against the free body measured in this process.

The NF on the quadrotor (the forward camera, the exact sensor, a level start at the
default position with its heading 0.3 rad off) and the paper's free body from the
default start, each for ``DURATION_S`` through ``simulate()``. Reported, each as a
ratio to the free body's (the machine is shared and noisy: the ratios are the figures
to compare): the real-time factor (the median of ``--repeat`` rounds, the runs
alternating free body, quadrotor, quadrotor on RK5), the same with
``simulator.integration_scheme: runge_kutta5`` (the quadrotor's default; docs/quadrotor.md:
the same results in a third of the steps), and the diagram's derivative evaluation at a
new state (what the attitude cascade, the level view and the four propellers add to every
step).

    .venv/bin/python benchmarks/bench_quadrotor.py [--repeat 5] [--no-record] [--note TEXT]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics

from _record import Figure, record
from bench_closed_loop import best, derivative_timer

from geovs_drake.loop import build_loop
from geovs_drake.scenario import PoseConfig, Quadrotor, ScenarioConfig
from geovs_drake.simulation import simulate

#: The runs' length [s] and the quadrotor's level start (docs/quadrotor.md).
DURATION_S = 10.0
LEVEL_START = PoseConfig(xyz=[0.12, -0.08, -0.8], rpy=[0.0, 0.3, 0.0])
#: Derivative evaluations per timing.
EVALUATIONS = 2000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--no-record", action="store_true", help="print only")
    parser.add_argument("--note", default="", help="a word on the run for the record")
    args = parser.parse_args()
    free = ScenarioConfig(duration=DURATION_S)
    # Each scheme by name: the quadrotor's unset scheme is RK5 (its carrier's, as every
    # dynamic plant's since 2026-11-28), RK3 the one it ran before.
    quad = ScenarioConfig(carrier=Quadrotor(), initial=LEVEL_START, duration=DURATION_S)
    quad.simulator.integration_scheme = "runge_kutta3"
    rk5 = dataclasses.replace(
        quad, simulator=dataclasses.replace(quad.simulator, integration_scheme="runge_kutta5")
    )
    configs = {"free body": free, "quadrotor": quad, "quadrotor RK5": rk5}
    derivative = {}
    for name in ("free body", "quadrotor"):
        evaluate, _ = derivative_timer(build_loop(configs[name], log=False).diagram)
        derivative[name] = best(evaluate, EVALUATIONS, repeat=3)
    for config in configs.values():  # each loop's kernels loaded before any timing
        simulate(dataclasses.replace(config, duration=0.05))
    walls: dict[str, list[float]] = {name: [] for name in configs}
    steps = {}
    for _ in range(args.repeat):
        for name, config in configs.items():
            result = simulate(config)
            assert result.status == "converged", result.message
            walls[name].append(result.wall_time_s)
            steps[name] = result.steps
    rtf = {name: DURATION_S / statistics.median(w) for name, w in walls.items()}
    for name in configs:
        extra = f", derivative {1e6 * derivative[name]:.1f} us" if name in derivative else ""
        print(
            f"{name}: {rtf[name]:.1f}x real time{extra} ({steps[name]} steps over {DURATION_S:g} s)"
        )
    ratio = {name: rtf[name] / rtf["free body"] for name in configs}
    print(
        f"quadrotor against the free body: real-time factor x{ratio['quadrotor']:.2f}"
        f" (RK5 x{ratio['quadrotor RK5']:.2f}), "
        f"derivative x{derivative['quadrotor'] / derivative['free body']:.2f}"
    )
    if args.no_record:
        return
    baseline = "the free body's simulate() from the default start"
    figures = [
        Figure(
            "quadrotor simulate(), exact sensor, real-time factor",
            rtf["quadrotor"],
            "x",
            baseline,
            rtf["free body"],
            target=">= 100x",
        ),
        Figure(
            "quadrotor simulate(), exact sensor, runge_kutta5, real-time factor",
            rtf["quadrotor RK5"],
            "x",
            baseline,
            rtf["free body"],
            target=">= 100x",
        ),
        Figure(
            "quadrotor diagram derivative evaluation",
            1e6 * derivative["quadrotor"],
            "us",
            "the free body's diagram derivative evaluation",
            1e6 * derivative["free body"],
        ),
    ]
    note = (
        f"steps over {DURATION_S:g} s: free body {steps['free body']}, quadrotor "
        f"{steps['quadrotor']} (runge_kutta3), {steps['quadrotor RK5']} (runge_kutta5); "
        f"median of {args.repeat} alternating rounds"
    ) + (f"; {args.note}" if args.note else "")
    record("bench_quadrotor", "The quadrotor loop against the free body", figures, note)


if __name__ == "__main__":
    main()
