"""Compile the package's numba kernels into their on-disk cache, once.

numba compiles a kernel the first time a process calls it; ``cache=True`` then keeps the
machine code on disk, beside the source, for every later process. Processes started side
by side on a fresh checkout (``make test``: pytest's two workers and the notebooks'
kernels) would each compile the same kernels before any of them had written the cache.
``python -m geovs_drake.batch.warm`` compiles them first, once, in two halves that run
in two processes side by side (each kernel compiles in one process, on one core):

* :func:`warm_free`: the loop's generated kernels (a short
  :func:`~geovs_drake.simulation.simulate` on each plant, and one of the quadrotor for
  its cascade's and level view's) and the batch engine's for the free rig
  (:func:`~geovs_drake.batch.engine.run_batch` on each plant, with the exact sensor and
  the sampled camera), and the arm's start path
  (:func:`~geovs_drake.batch.arm_ik.warm_arm_ik`): about 32 s of CPU cold;
* :func:`warm_arm`: the sweep's compiled IK of the arm's starts
  (:func:`~geovs_drake.batch.arm_ik.warm_start_solver`), the arm's compiled loop and its
  batch integrators (:func:`~geovs_drake.batch.arm_rhs.warm_arm_loop`,
  :func:`~geovs_drake.batch.arm_engine.warm_arm_engine`): about 34 s (50 s while the
  arm's integrators were ``prange`` loops: :mod:`geovs_drake.batch._threads`).

Measured with an empty cache (``NUMBA_CACHE_DIR``), one half after the other: 32 s and
34 s of CPU, so the halves side by side take about 35 s of wall time on two free cores.
Running it changes no result: a warm cache is what every later run of the same checkout
uses anyway.
"""

from __future__ import annotations

import multiprocessing
import sys
import time

__all__ = ["HALVES", "warm", "warm_arm", "warm_free"]

#: How long each warming run simulates [s]: a few steps call every kernel.
WARM_DURATION_S = 0.05


def warm_free() -> None:
    """Call the free rig's and the quadrotor's compiled kernels once (each plant's loop and
    batch engine, the exact sensor and the sampled camera)."""
    import numpy as np

    from geovs_drake.batch.engine import run_batch
    from geovs_drake.scenario import Dynamic, Kinematic, Pinhole, Quadrotor, ScenarioConfig
    from geovs_drake.simulation import simulate

    for plant in (Dynamic(), Kinematic()):
        config = ScenarioConfig(plant=plant, duration=WARM_DURATION_S)
        simulate(config)
        run_batch(config, np.stack([config.X_BC_initial.GetAsMatrix4()] * 2))
        config.sensor = Pinhole()  # the sampled camera's integrator (batch.sampled)
        run_batch(config, np.stack([config.X_BC_initial.GetAsMatrix4()] * 2))
    # The quadrotor's cascade and level view (systems/_quadrotor_kernels.py), from its
    # default start (level).
    simulate(ScenarioConfig(carrier=Quadrotor(), duration=WARM_DURATION_S))
    # The arm's start path (its compiled branch follower): here, the lighter half.
    from geovs_drake.batch.arm_ik import warm_arm_ik

    warm_arm_ik()


def warm_arm() -> None:
    """Call the arm's compiled kernels once: the sweep's IK of its starts, its closed loop,
    its batch integrators and its Drake loop's compiled checks."""
    from geovs_drake.batch.arm_engine import warm_arm_engine
    from geovs_drake.batch.arm_ik import warm_start_solver
    from geovs_drake.batch.arm_rhs import warm_arm_loop
    from geovs_drake.scenario import Arm, Dynamic, Kinematic, ScenarioConfig
    from geovs_drake.simulation import simulate

    # The sweep's compiled IK first (a few seconds): the arm sweep's tests and notebook,
    # which run beside this half, find it in the cache early.
    warm_start_solver()
    warm_arm_loop()
    warm_arm_engine()
    # The Drake arm loop's own compiled checks (the kinematic arm's singular zone and
    # speed scale, the monitor's joint limits), which pytest's workers and the notebooks
    # would otherwise each compile.
    for plant in (Dynamic(), Kinematic()):
        simulate(ScenarioConfig(carrier=Arm(), plant=plant, duration=WARM_DURATION_S))


#: The halves by name, for ``python -m geovs_drake.batch.warm [free|arm ...]``.
HALVES = {"free": warm_free, "arm": warm_arm}


def warm(names: tuple[str, ...] = ("arm", "free")) -> float:
    """Compile the kernels of the halves ``names`` (:data:`HALVES`; default both, each in
    a process of its own, side by side); returns the seconds it took (mostly compiling
    where the cache was cold). Raises RuntimeError naming a half that failed."""
    start = time.perf_counter()
    # spawn: a fresh interpreter each, no forked copy of numba's or Drake's threads.
    context = multiprocessing.get_context("spawn")
    halves = [context.Process(target=HALVES[n], name=HALVES[n].__name__) for n in names]
    for half in halves:
        half.start()
    for half in halves:
        half.join()
    failed = [f"{h.name} (exit code {h.exitcode})" for h in halves if h.exitcode != 0]
    if failed:
        raise RuntimeError(f"the warm-up failed: {', '.join(failed)}")
    return time.perf_counter() - start


if __name__ == "__main__":
    # make test warms the free rig's half first, then builds the docs (whose notebooks
    # need only it) beside the arm's half, then runs pytest.
    chosen = tuple(sys.argv[1:]) or tuple(HALVES)
    unknown = [n for n in chosen if n not in HALVES]
    if unknown:
        print(f"warm: unknown half {unknown[0]!r} (choose from free, arm)", file=sys.stderr)
        sys.exit(2)
    seconds = warm(chosen)
    print(
        f"numba kernels ({', '.join(chosen)}) compiled or found in their cache: {seconds:.1f} s",
        file=sys.stderr,
    )
