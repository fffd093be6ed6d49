"""Measurements behind docs/hardware.md, in one process on ``memq://``.

``python -m geovs_drake.hardware.profile steps [DURATION] [COMMAND_RATE]``: the wall
time each side costs per 1 ms of simulated time, the station and the controller each
in its own Simulator (as in two processes), stepped alternately 1 ms on one bus.

``python -m geovs_drake.hardware.profile drops``: the camera's distance from the goal
at fixed times, the controller and the station in lockstep (one Simulator, the issue's
small move), against :func:`~geovs_drake.simulation.simulate`, for command rates and
dropped frames.

``python -m geovs_drake.hardware.profile delays``: the same for statuses that report
the joints as they were 0 to 50 ms ago (``hardware.status_delay``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator

from geovs_drake.hardware.controller import build_controller
from geovs_drake.hardware.run import Setup, load_setup, lockstep
from geovs_drake.hardware.station import build_station
from geovs_drake.simulation import simulate
from geovs_drake.simulation.result import pose_error

__all__ = [
    "DELAY_CASES",
    "DROP_CASES",
    "DROP_TIMES",
    "SMALL_MOVE",
    "lockstep_errors",
    "main",
    "step_costs",
]

#: The issue's small move.
SMALL_MOVE = {"xyz": [0.05, -0.03, -0.55], "rpy": [0.1, -0.05, 0.3]}
#: The status period [s] the two simulators are stepped by.
STEP_S = 1e-3
#: The times [s] of the ``drops`` table, and its cases: (command rate [Hz], drop every
#: N-th frame).
DROP_TIMES = (0.5, 1.0, 2.0, 3.0, 5.0, 10.0)
DROP_CASES = ((1000.0, 0), (250.0, 0), (250.0, 10), (250.0, 3))
#: The ``delays`` table's status delays [s], at the shipped 250 Hz.
DELAY_CASES = (0.0, 0.005, 0.01, 0.02, 0.05)
#: Percentiles reported of the per-step cost.
_PERCENTILES = (50, 99)


def _setup(duration: float, **hardware) -> Setup:
    changes = {"lcm_url": "memq://", "real_time_rate": 0.0, **hardware}
    return load_setup(None, [("profile", {"initial": SMALL_MOVE, "duration": duration})], changes)


def step_costs(duration: float = 3.0, command_rate: float = 250.0) -> dict[str, np.ndarray]:
    """Wall seconds per ``STEP_S`` of simulated time, ``station`` and ``controller``
    (the controller warmed up first, as ``run_controller`` does)."""
    setup = _setup(duration, command_rate=command_rate)
    lcm = DrakeLcm("memq://")
    station = build_station(setup.resolved, setup.hardware, lcm)
    controller = build_controller(setup.resolved, setup.hardware, lcm)
    controller.warm_up()
    s_sim = Simulator(station.diagram)
    station.set_initial_state(s_sim.get_mutable_context())
    c_sim = Simulator(controller.diagram)
    s_sim.Initialize()
    c_sim.Initialize()
    steps = int(round(duration / STEP_S))
    costs = {"station": np.zeros(steps), "controller": np.zeros(steps)}
    for k in range(steps):
        for name, sim in (("station", s_sim), ("controller", c_sim)):
            start = time.perf_counter()
            sim.AdvanceTo((k + 1) * STEP_S)
            costs[name][k] = time.perf_counter() - start
    return costs


def lockstep_errors(
    command_rate: float,
    drop_every_frame: int,
    times: Sequence[float] = DROP_TIMES,
    status_delay: float = 0.0,
) -> tuple[np.ndarray, int, Setup]:
    """The camera's distance from the goal [m] at ``times`` in lockstep, the frames the
    controller counted as dropped, and the setup."""
    setup = _setup(
        times[-1],
        command_rate=command_rate,
        drop_every_frame=drop_every_frame,
        status_delay=status_delay,
    )
    both = lockstep(setup)
    station, controller, simulator, root = both.station, both.controller, both.simulator, both.root
    errors = []
    for t in times:
        simulator.AdvanceTo(t)
        errors.append(pose_error(station.X_BC(root), setup.resolved.config.X_BC_goal)[0])
    link = controller.tracker.link_output.Eval(controller.tracker.GetMyContextFromRoot(root))
    return np.array(errors), int(link[2]), setup


def _simulated(setup: Setup, times: Sequence[float]) -> np.ndarray:
    result = simulate(setup.resolved)
    goal = setup.resolved.config.X_BC_goal
    index = [int(np.argmin(np.abs(result.times - t))) for t in times]
    return np.array([pose_error(RigidTransform(result.X_BC[k]), goal)[0] for k in index])


def main(argv: Sequence[str] | None = None) -> int:
    """``steps [DURATION] [COMMAND_RATE]`` or ``drops``; prints a table."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] == ["steps"]:
        try:
            duration = float(args[1]) if len(args) > 1 else 3.0
            rate = float(args[2]) if len(args) > 2 else 250.0
        except ValueError:
            print(f"profile steps: DURATION and RATE must be numbers: {args[1:]}", file=sys.stderr)
            return 2
        if not (duration > 0 and rate > 0):
            print(f"profile steps: DURATION and RATE must be > 0: {args[1:]}", file=sys.stderr)
            return 2
        for name, cost in step_costs(duration, rate).items():
            p = np.percentile(cost, _PERCENTILES) * 1e3
            print(
                f"{name:10s} per 1 ms: mean {cost.mean() * 1e3:.3f} ms, p50 {p[0]:.3f}, "
                f"p99 {p[1]:.3f}, max {cost.max() * 1e3:.3f} ms (command rate {rate:g} Hz)"
            )
        return 0
    if args[:1] == ["delays"]:
        rows = [lockstep_errors(250.0, 0, status_delay=d) for d in DELAY_CASES]
        print("| status delay | " + " | ".join(f"{t:g} s" for t in DROP_TIMES) + " |")
        print("| --- " * (len(DROP_TIMES) + 1) + "|")
        for delay, (errors, _, _) in zip(DELAY_CASES, rows, strict=True):
            cells = " | ".join(f"{e * 1e3:.4f}" for e in errors)
            print(f"| {delay * 1e3:g} ms | {cells} |")
        return 0
    if args[:1] == ["drops"]:
        rows = [lockstep_errors(rate, drop) for rate, drop in DROP_CASES]
        reference = _simulated(rows[0][2], DROP_TIMES)
        print("| case | " + " | ".join(f"{t:g} s" for t in DROP_TIMES) + " | dropped |")
        print("| --- " * (len(DROP_TIMES) + 2) + "|")
        cells = " | ".join(f"{e * 1e3:.4f}" for e in reference)
        print(f"| simulate | {cells} | |")
        for (rate, drop), (errors, dropped, _) in zip(DROP_CASES, rows, strict=True):
            cells = " | ".join(f"{e * 1e3:.4f}" for e in errors)
            print(f"| {rate:g} Hz, drop every {drop or 'none'} | {cells} | {dropped} |")
        return 0
    print(
        f"profile: the command must be steps, drops or delays, got {args[:1]}: "
        "python -m geovs_drake.hardware.profile steps [DURATION] [RATE] | drops | delays",
        file=sys.stderr,
    )
    return 2


if __name__ == "__main__":
    sys.exit(main())
