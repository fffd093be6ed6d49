"""`sweep --carrier arm` on the batch engine against the Drake engine's per-start time.

N UR5 starts x 10 s with the exact sensor through the CLI (`geovs-drake sweep --carrier
arm --starts N --workers 2`, the batch engine, the default), against the same command
with `--engine drake` on the first M of the same starts, its wall time scaled to N.
Both walls include each start's IK (the same code: the sweep's _ArmStarts). With
``--sensor pinhole`` both run the 30 Hz pinhole camera (its own record,
``results/bench_arm_sweep_pinhole.json``). ``--model panda`` runs the Panda (a config
``carrier: !Arm {model: panda}``, its record ``bench_arm_sweep_panda``);
``--local-cluster`` passes the sweep's own flag (its parts on two worker processes, the
starts' Python work in both, rather than one process's numba threads).

    .venv/bin/python benchmarks/bench_arm_sweep.py [--starts 10000] [--drake 40]
        [--sensor exact|pinhole] [--model default|panda] [--local-cluster]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _record import Figure, record


def _sweep(starts: int, engine: str, out: str, sensor: str = "exact", extra=()) -> float:
    """The CLI's wall time [s] for ``starts`` arm starts x 10 s on ``engine``; ``extra``:
    more of the CLI's arguments (the arm's config, --local-cluster)."""
    argv = [sys.executable, "-m", "geovs_drake.cli", "sweep", *extra]
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
    parser.add_argument("--model", choices=("default", "panda"), default="default")
    parser.add_argument("--local-cluster", action="store_true")
    args = parser.parse_args()
    sensor = args.sensor
    with tempfile.TemporaryDirectory() as tmp:
        extra = ["--carrier", "arm"]
        if args.model != "default":
            Path(f"{tmp}/arm.yaml").write_text(f"carrier: !Arm {{model: {args.model}}}\n")
            extra = ["--config", f"{tmp}/arm.yaml"]
        cluster = ["--local-cluster"] if args.local_cluster else []
        _sweep(4, "batch", f"{tmp}/warm", sensor, extra)  # load the compiled code once
        batch = _sweep(args.starts, "batch", f"{tmp}/batch", sensor, extra + cluster)
        drake = _sweep(args.drake, "drake", f"{tmp}/drake", sensor, extra)
        drake *= args.starts / args.drake
    print(f"batch {batch:.1f} s, Drake engine scaled {drake:.1f} s: {drake / batch:.1f}x")
    exact = sensor == "exact"
    arm = "UR5" if args.model == "default" else "Panda"
    flags = " --local-cluster" if args.local_cluster else ""
    record(
        "bench_arm_sweep"
        + ("" if exact else "_pinhole")
        + ("" if args.model == "default" else f"_{args.model}"),
        f"The arm sweep ({arm}): the batch engine against the Drake engine"
        + ("" if exact else ", the 30 Hz pinhole"),
        [
            Figure(
                f"geovs-drake sweep (the {arm}) --sensor {sensor} --workers 2{flags}, "
                f"{args.starts} {arm} starts x 10 s",
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
