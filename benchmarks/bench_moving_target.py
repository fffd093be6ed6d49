"""The moving target's cost (issue 32), against the still target measured in this process.

The same default scenario on each plant, the target still (the baseline) and moving with
the issue's twist (0, 0, 0.2, 0.05, 0, 0) under the ``known`` and the ``estimated``
feed-forward (:mod:`geovs_drake.loop.targets`); then the UR5 arm on each plant, still
against the slow circle (0, 0, 0.1, 0.02, 0, 0) with the estimated feed-forward, for
``ARM_DURATION_S`` (the arm stays in the world: the target's frame view, its drawing,
and on the torque-driven arm the feed-forward's inverse dynamics). Reported, each as a
ratio to the still target's (the machine is shared and noisy: the ratios are the figures
to compare):

* the diagram's derivative evaluation (``CalcTimeDerivatives`` at a new state, no cache
  hits): what the target's motion and its adapter add to every step;
* ``simulate()``'s wall time over the scenario's duration (the best of ``--repeat``): the
  above, plus the estimator's 50 Hz discrete updates (which the integrator must step to)
  and its loggers.

    .venv/bin/python benchmarks/bench_moving_target.py [--repeat 3] [--no-record]
"""

from __future__ import annotations

import argparse

from _record import Figure, record
from bench_closed_loop import best, derivative_timer

from geovs_drake.loop import build_loop
from geovs_drake.scenario import PLANT_VARIANTS, Arm, ScenarioConfig, Twist
from geovs_drake.simulation import simulate

#: The issue's target: a circle of radius v / omega = 0.25 m at 0.05 m/s.
XI_B = [0.0, 0.0, 0.2, 0.05, 0.0, 0.0]
#: The moving variants, by their feed-forward mode.
MODES = ("known", "estimated")
#: Derivative evaluations per timing.
EVALUATIONS = 2000
#: The arms' slow circle (radius 0.2 m) and their runs' length [s].
ARM_XI_B = [0.0, 0.0, 0.1, 0.02, 0.0, 0.0]
ARM_DURATION_S = 10.0
#: The baselines, as the figures name them.
STILL_DERIVATIVES = "the still target's diagram derivative evaluation"
STILL_SIMULATE = "the still target's simulate(), same plant and duration"


def _config(plant: str, mode: str | None) -> ScenarioConfig:
    config = ScenarioConfig(plant=PLANT_VARIANTS[plant]())
    if mode is not None:
        config.target_motion = Twist(twist=list(XI_B), feedforward=mode)
    return config


def _arm_config(plant: str, moving: bool) -> ScenarioConfig:
    config = ScenarioConfig(carrier=Arm(), plant=PLANT_VARIANTS[plant](), duration=ARM_DURATION_S)
    if moving:
        config.target_motion = Twist(twist=list(ARM_XI_B), feedforward="estimated")
    return config


def _derivative_time(config: ScenarioConfig) -> float:
    """Seconds per CalcTimeDerivatives of the loop's diagram (no loggers)."""
    evaluate, _ = derivative_timer(build_loop(config, log=False).diagram)
    return best(evaluate, EVALUATIONS)


def _simulate_time(config: ScenarioConfig, repeat: int) -> float:
    """The best wall time [s] of ``repeat`` runs of simulate()."""
    return min(simulate(config).wall_time_s for _ in range(repeat))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per simulate() timing")
    parser.add_argument(
        "--no-record", action="store_true", help="print only (no results/bench_moving_target.json)"
    )
    args = parser.parse_args()
    figures = []
    for plant in ("dynamic", "kinematic"):
        still = _config(plant, None)
        t_still = _derivative_time(still)
        w_still = _simulate_time(still, args.repeat)
        print(
            f"{plant}, still target: derivatives {t_still * 1e6:.1f} us, "
            f"simulate() {w_still:.2f} s for {still.duration:g} s"
        )
        for mode in MODES:
            moving = _config(plant, mode)
            t = _derivative_time(moving)
            w = _simulate_time(moving, args.repeat)
            print(
                f"{plant}, moving target ({mode}): derivatives {t * 1e6:.1f} us "
                f"= {t / t_still:.2f}x still, simulate() {w:.2f} s = {w / w_still:.2f}x still"
            )
            figures += [
                Figure(f"{plant} loop, moving target ({mode}), diagram derivative evaluation",
                       t * 1e6, "us", STILL_DERIVATIVES, t_still * 1e6),
                Figure(f"{plant} loop, moving target ({mode}), simulate() of the default "
                       f"scenario ({moving.duration:g} s)", w, "s", STILL_SIMULATE, w_still),
            ]  # fmt: skip
    for plant in ("dynamic", "kinematic"):
        still, moving = _arm_config(plant, False), _arm_config(plant, True)
        t_still, t = _derivative_time(still), _derivative_time(moving)
        w_still, w = _simulate_time(still, args.repeat), _simulate_time(moving, args.repeat)
        print(
            f"UR5 {plant}, slow circle (estimated): derivatives {t * 1e6:.1f} us = "
            f"{t / t_still:.2f}x still, simulate() {w:.2f} s = {w / w_still:.2f}x still "
            f"({w_still:.2f} s for {ARM_DURATION_S:g} s)"
        )
        figures += [
            Figure(f"UR5 arm, {plant}, moving target (estimated), diagram derivative "
                   "evaluation", t * 1e6, "us", STILL_DERIVATIVES, t_still * 1e6),
            Figure(f"UR5 arm, {plant}, moving target (estimated), simulate() of "
                   f"{ARM_DURATION_S:g} s", w, "s", STILL_SIMULATE, w_still),
        ]  # fmt: skip
    if not args.no_record:
        record("bench_moving_target", "The moving target against the still one", figures)


if __name__ == "__main__":
    main()
