"""The arm loops' real-time factor against the free body's, in the same process.

Baseline: the free rig's loop (the paper's body), same law, same start, same horizon,
timed in this process alternately with the arm's, so the ratio holds when the
machine's speed drifts. Reported: the median real-time factor of each loop over
``--repeat`` runs of ``simulate()`` (its monitor and step recorder included), the
steps per simulated second, and arm / free; on the dynamic plant also the arm with
the joint-limit barrier (width :data:`BARRIER_WIDTH`); on both plants the 7-axis
Panda (``--arm panda``, when example-robot-data is installed).

Then the cameras (issue 31): the UR5 with the 30 Hz pinhole camera and with the rendered
one (RenderEngineVtk, EGL), each with the odometry predictor (the default), against the
UR5 with the exact sensor as the baseline, alternately in the same process, over
``--camera-duration`` simulated seconds; and that exact-sensor loop itself against the
free body over the same seconds, alternately with them. Issue 44's targets are on these
rows: the exact sensor at 100x real time or more, the 30 Hz pinhole at 20x or more.
``--cameras pinhole`` leaves the rendered camera out (its runs take most of the time:
about 1.2x real time, bound by the renderer).

    .venv/bin/python benchmarks/bench_arm.py [--repeat 5] [--duration 30] [--camera-duration 10]
        [--cameras pinhole rendered]
"""

from __future__ import annotations

import argparse
import importlib.metadata
import statistics

from _record import Figure, record

from geovs_drake.scenario import (
    PLANT_VARIANTS,
    SENSOR_VARIANTS,
    Arm,
    FreeRig,
    PoseConfig,
    ScenarioConfig,
)
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
#: The camera loops on the UR5, by the sensor they name, against the exact sensor's.
CAMERAS = {
    "pinhole": "UR5 with the 30 Hz pinhole camera",
    "rendered": "UR5 with the 30 Hz rendered camera",
}


def run(
    carrier: str, plant: str, duration: float, sensor: str = "exact"
) -> tuple[float, float, str]:
    """One run of ``carrier``: free, arm (the UR5), arm+barrier or panda, with ``sensor``."""
    arm = Arm(
        model="panda" if carrier == "panda" else "default",
        joint_barrier_width=BARRIER_WIDTH if carrier == "arm+barrier" else 0.0,
    )
    config = ScenarioConfig(
        carrier=FreeRig() if carrier == "free" else arm,
        plant=PLANT_VARIANTS[plant](),
        sensor=SENSOR_VARIANTS[sensor](),
        duration=duration,
        initial=SMALL_MOVE,
    )
    r = simulate(config)
    return r.sim_time_s / r.wall_time_s, r.steps / r.sim_time_s, r.status


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--camera-duration", type=float, default=10.0)
    parser.add_argument("--cameras", nargs="+", choices=list(CAMERAS), default=list(CAMERAS))
    parser.add_argument("--note", default="", help="a line for the record (the machine's state)")
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
    figures += camera_figures(args.repeat, args.camera_duration, args.cameras)
    record("bench_arm", "The arm loops against the free body, and with cameras", figures, args.note)


#: Issue 44's targets on the camera section's rows, by the sensor (all plants).
TARGETS = {"exact": ">= 100x", "pinhole": ">= 20x"}


def camera_figures(repeat: int, duration: float, cameras: list[str]) -> list[Figure]:
    """The UR5's camera loops against its exact-sensor loop, and that loop against the
    free body's (module docstring)."""
    figures = []
    for plant in ("dynamic", "kinematic"):
        loops = (("free", "exact"), ("arm", "exact"), *(("arm", c) for c in cameras))
        for carrier, sensor in loops:
            run(carrier, plant, 1.0, sensor)  # the renderer's first frame, the caches
        rtf = {loop: [] for loop in loops}
        status = {}
        for _ in range(repeat):
            for loop in loops:  # alternately: the ratios survive drift
                factor, _, status[loop] = run(loop[0], plant, duration, loop[1])
                rtf[loop].append(factor)
        free = statistics.median(rtf["free", "exact"])
        exact = statistics.median(rtf["arm", "exact"])
        print(
            f"{plant}: UR5, exact sensor {exact:.1f}x real time ({status['arm', 'exact']}); "
            f"free body {free:.1f}x; / free = {exact / free:.2f} (median of {repeat})"
        )
        figures.append(
            Figure(
                f"{plant} UR5 with the exact sensor, real-time factor, small move, {duration:g} s",
                exact,
                "x real time",
                "the free body, same law and start, alternately",
                free,
                target=TARGETS["exact"],
            )
        )
        for sensor in cameras:
            factor = statistics.median(rtf["arm", sensor])
            print(
                f"{plant}: {CAMERAS[sensor]} {factor:.1f}x ({status['arm', sensor]}); / exact = "
                f"{factor / exact:.2f} (median of {repeat})"
            )
            figures.append(
                Figure(
                    f"{plant} {CAMERAS[sensor]}, real-time factor, small move, {duration:g} s",
                    factor,
                    "x real time",
                    "the UR5 with the exact sensor, same law and start, alternately",
                    exact,
                    target=TARGETS.get(sensor, ""),
                )
            )
    return figures


if __name__ == "__main__":
    main()
