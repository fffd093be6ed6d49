"""`sweep --carrier arm` on the batch engine against the Drake engine's per-start time.

N UR5 starts x 10 s with the exact sensor through the CLI (`geovs-drake sweep --carrier
arm --starts N --workers 2`, the batch engine, the default), against the same command
with `--engine drake` on the first M of the same starts, its wall time scaled to N.
Both walls include each start's IK (the same code: the sweep's _ArmStarts). With
``--sensor pinhole`` both run the 30 Hz pinhole camera (its own record,
``results/bench_arm_sweep_pinhole.json``).

    .venv/bin/python benchmarks/bench_arm_sweep.py [--starts 10000] [--drake 40]
        [--sensor exact|pinhole]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time

from _record import Figure, record


def _sweep(starts: int, engine: str, out: str, sensor: str = "exact") -> float:
    """The CLI's wall time [s] for ``starts`` UR5 starts x 10 s on ``engine``."""
    argv = [sys.executable, "-m", "geovs_drake.cli", "sweep", "--carrier", "arm"]
    argv += ["--starts", str(starts), "--workers", "2", "--engine", engine, "--out", out]
    argv += ["--sensor", sensor]
    t = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - t
    print(done.stdout.strip().splitlines()[-1])
    return wall


def main() -> None:
    """Run both sweeps and record the figure."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--starts", type=int, default=10_000)
    parser.add_argument("--drake", type=int, default=40, help="starts for the Drake baseline")
    parser.add_argument("--sensor", choices=("exact", "pinhole"), default="exact")
    args = parser.parse_args()
    sensor = args.sensor
    with tempfile.TemporaryDirectory() as tmp:
        _sweep(4, "batch", f"{tmp}/warm", sensor)  # load the compiled code once
        batch = _sweep(args.starts, "batch", f"{tmp}/batch", sensor)
        drake = _sweep(args.drake, "drake", f"{tmp}/drake", sensor) * args.starts / args.drake
    print(f"batch {batch:.1f} s, Drake engine scaled {drake:.1f} s: {drake / batch:.1f}x")
    exact = sensor == "exact"
    record(
        "bench_arm_sweep" if exact else "bench_arm_sweep_pinhole",
        "The arm sweep: the batch engine against the Drake engine"
        + ("" if exact else ", the 30 Hz pinhole"),
        [
            Figure(
                f"geovs-drake sweep --carrier arm --sensor {sensor} --workers 2, "
                f"{args.starts} UR5 starts x 10 s",
                batch,
                "s",
                f"the Drake engine start by start ({args.drake} starts, scaled to {args.starts})",
                drake,
                target="<= 60 s for 10000 starts",
            )
        ],
    )


if __name__ == "__main__":
    main()
