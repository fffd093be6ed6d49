"""Compile the package's numba kernels into their on-disk cache, once.

numba compiles a kernel the first time a process calls it; ``cache=True`` then keeps the
machine code on disk, beside the source, for every later process. Processes started side
by side on a fresh checkout (``make test``: pytest's two workers and the notebooks'
kernels) would each compile the same kernels before any of them had written the cache:
the batch engine alone takes about 20 s of CPU to compile (measured: 18.5 s dynamic and
2.2 s kinematic cold, 6 ms warm). ``python -m geovs_drake.batch.warm`` compiles them
first, once: the loop's generated kernels (a short :func:`~geovs_drake.simulation.simulate`
on each plant, and one of the quadrotor for its cascade's and level view's), the batch
engine's (:func:`~geovs_drake.batch.engine.run_batch` on each plant), and the arm's
(:func:`~geovs_drake.batch.arm_rhs.warm_arm_loop`). Running it changes no result: a warm
cache is what every later run of the same checkout uses anyway.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from geovs_drake.batch.arm_engine import warm_arm_engine
from geovs_drake.batch.arm_ik import warm_arm_ik
from geovs_drake.batch.arm_rhs import warm_arm_loop
from geovs_drake.batch.engine import run_batch
from geovs_drake.scenario import Dynamic, Kinematic, Pinhole, Quadrotor, ScenarioConfig
from geovs_drake.simulation import simulate

__all__ = ["warm"]

#: How long each warming run simulates [s]: a few steps call every kernel.
WARM_DURATION_S = 0.05


def warm() -> float:
    """Call every compiled kernel once (each plant's loop and batch engine); returns the
    seconds it took (mostly compiling where the cache was cold)."""
    start = time.perf_counter()
    for plant in (Dynamic(), Kinematic()):
        config = ScenarioConfig(plant=plant, duration=WARM_DURATION_S)
        simulate(config)
        run_batch(config, np.stack([config.X_BC_initial.GetAsMatrix4()] * 2))
        config.sensor = Pinhole()  # the sampled camera's integrator (batch.sampled)
        run_batch(config, np.stack([config.X_BC_initial.GetAsMatrix4()] * 2))
    # The quadrotor's cascade and level view (systems/_quadrotor_kernels.py), from its
    # default start (level).
    simulate(ScenarioConfig(carrier=Quadrotor(), duration=WARM_DURATION_S))
    warm_arm_loop()
    warm_arm_engine()
    warm_arm_ik()
    return time.perf_counter() - start


if __name__ == "__main__":
    seconds = warm()
    print(f"numba kernels compiled or found in their cache: {seconds:.1f} s", file=sys.stderr)
