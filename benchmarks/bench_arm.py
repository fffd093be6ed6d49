"""The arm loops' real-time factor against the free body's, in the same process.

Baseline: the free rig's loop (the paper's body), same law, same start, same horizon,
timed in this process alternately with the arm's, so the ratio holds when the
machine's speed drifts. Reported: the median real-time factor of each loop over
``--repeat`` runs of ``simulate()`` (its monitor and step recorder included), the
steps per simulated second, and arm / free; on the dynamic plant also the arm with
the joint-limit barrier (width :data:`BARRIER_WIDTH`); on both plants the 7-axis
Panda (``--arm panda``, when example-robot-data is installed).

    .venv/bin/python benchmarks/bench_arm.py [--repeat 5] [--duration 30]
"""

from __future__ import annotations

import argparse
import importlib.metadata
import statistics

from _record import Figure, record

from geovs_drake.scenario import PLANT_VARIANTS, Arm, FreeRig, PoseConfig, ScenarioConfig
from geovs_drake.simulation import simulate

#: The issue's small move: a start every carrier reaches and converges from.
SMALL_MOVE = PoseConfig(xyz=[0.05, -0.03, -0.55], rpy=[0.1, -0.05, 0.3])
#: The barrier's width in the "arm+barrier" loop [rad]: active only near a limit, so the
#: row measures the barrier's cost, not a different path.
BARRIER_WIDTH = 1.0
#: The timed loops besides the free body, as the figures name them.
LOOPS = {
    "arm": "arm (UR5)",
    "arm+barrier": f"arm (UR5) with the joint-limit barrier (width {BARRIER_WIDTH:g} rad)",
    "panda": "arm (7-axis Panda)",
}


def run(carrier: str, plant: str, duration: float) -> tuple[float, float, str]:
    """One run of ``carrier``: free, arm (the UR5), arm+barrier or panda."""
    arm = Arm(
        model="panda" if carrier == "panda" else "default",
        joint_barrier_width=BARRIER_WIDTH if carrier == "arm+barrier" else 0.0,
    )
    config = ScenarioConfig(
        carrier=FreeRig() if carrier == "free" else arm,
        plant=PLANT_VARIANTS[plant](),
        duration=duration,
        initial=SMALL_MOVE,
    )
    r = simulate(config)
    return r.sim_time_s / r.wall_time_s, r.steps / r.sim_time_s, r.status


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--duration", type=float, default=30.0)
    args = parser.parse_args()
    figures = []
    try:
        importlib.metadata.distribution("example-robot-data")
        panda = ("panda",)
    except importlib.metadata.PackageNotFoundError:
        print('skipping the Panda: pip install "geovs-drake[panda]"')
        panda = ()
    for plant in ("dynamic", "kinematic"):
        barrier = ("arm+barrier",) if plant == "dynamic" else ()
        carriers = ("free", "arm", *barrier, *panda)
        for carrier in carriers:
            run(carrier, plant, 1.0)  # load the compiled kernels, build the caches
        rtf = {c: [] for c in carriers}
        steps, status = {}, {}
        for _ in range(args.repeat):
            for carrier in carriers:  # alternately: the ratio survives drift
                factor, steps[carrier], status[carrier] = run(carrier, plant, args.duration)
                rtf[carrier].append(factor)
        free = statistics.median(rtf["free"])
        print(f"{plant}: free body {free:.0f}x real time ({steps['free']:.0f} steps/s)")
        for carrier in carriers[1:]:
            factor = statistics.median(rtf[carrier])
            print(
                f"{plant}: {LOOPS[carrier]} {factor:.0f}x ({steps[carrier]:.0f} steps/s, "
                f"{status[carrier]}); / free = {factor / free:.2f} (median of {args.repeat})"
            )
            figures.append(
                Figure(
                    f"{plant} {LOOPS[carrier]}, real-time factor, small move, {args.duration:g} s",
                    factor,
                    "x real time",
                    "the free body, same law and start, alternately",
                    free,
                    # The target is the 6-axis dynamic arm's.
                    target=">= 30x" if plant == "dynamic" and carrier != "panda" else "",
                )
            )
    record("bench_arm", "The arm loops against the free body", figures)


if __name__ == "__main__":
    main()
