"""The quadrotor loop's cost (issue 43), against the free body measured in this process.

The NF on the quadrotor (the forward camera, the exact sensor, a level start at the
default position with its heading 0.3 rad off) and the paper's free body from the
default start, each for ``DURATION_S`` through ``simulate()``. Reported, each as a
ratio to the free body's (the machine is shared and noisy: the ratios are the figures
to compare): the real-time factor (the best of ``--repeat`` runs), and the diagram's
derivative evaluation at a new state (what the attitude cascade, the level view and the
four propellers add to every step).

    .venv/bin/python benchmarks/bench_quadrotor.py [--repeat 3] [--no-record]
"""

from __future__ import annotations

import argparse

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
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-record", action="store_true", help="print only")
    args = parser.parse_args()
    free = ScenarioConfig(duration=DURATION_S)
    quad = ScenarioConfig(carrier=Quadrotor(), initial=LEVEL_START, duration=DURATION_S)
    rtf, derivative = {}, {}
    for name, config in (("free body", free), ("quadrotor", quad)):
        evaluate, _ = derivative_timer(build_loop(config, log=False).diagram)
        derivative[name] = best(evaluate, EVALUATIONS, repeat=3)
        runs = [simulate(config) for _ in range(args.repeat)]
        assert all(r.status == "converged" for r in runs), [r.message for r in runs]
        rtf[name] = DURATION_S / min(r.wall_time_s for r in runs)
        print(
            f"{name}: {rtf[name]:.1f}x real time, derivative {1e6 * derivative[name]:.1f} us "
            f"({runs[0].steps} steps over {DURATION_S:g} s)"
        )
    ratio = rtf["quadrotor"] / rtf["free body"]
    print(
        f"quadrotor against the free body: real-time factor x{ratio:.2f}, "
        f"derivative x{derivative['quadrotor'] / derivative['free body']:.2f}"
    )
    if args.no_record:
        return
    figures = [
        Figure(
            "quadrotor simulate(), exact sensor, real-time factor",
            rtf["quadrotor"],
            "x",
            "the free body's simulate() from the default start",
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
    record("bench_quadrotor", "The quadrotor loop against the free body", figures)


if __name__ == "__main__":
    main()
