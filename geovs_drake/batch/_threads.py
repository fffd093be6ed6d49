"""The batch integrators' starts on threads: serial numba kernels that release the GIL.

Three batch integrators (:mod:`~geovs_drake.batch.sampled`,
:mod:`~geovs_drake.batch.arm_engine`, :mod:`~geovs_drake.batch.arm_sampled`) are each
one loop over independent starts. They were ``prange`` loops (``@njit(parallel=True)``),
whose parfor passes cost some 8 s of compiling a kernel. Now each is a serial kernel
(:data:`batch_kernel`, ``nogil``) and :func:`over_starts` runs it on slices of the
starts side by side, one slice per numba thread (``numba.get_num_threads()``, which a
sweep sets per part), the same static split as the ``prange`` loop's OpenMP schedule. A
start's arithmetic is the same, so the results are the same bit for bit (eight sweeps,
both carriers, plants and sensors: identical rows). The warm-up's two halves went from
36 s and 50 s of CPU on a cold cache to 32 s and 34 s. The price is the arm's exact
integrator's speed: 10^4 UR5 starts x 10 s through the CLI took 50.8-52.6 s on threads
against 42.4-47.4 s as a ``prange`` loop (alternating runs, load about 2). The
``prange`` loop was tried back: its 18 s of compiling reached ``make test``'s critical
path (pytest's workers compiled it again before the warm-up had), 233 s on a fresh
clone against 201-214 s. The pinhole integrators' runs are bound by their frames'
Python measurement, not by the kernel.

The free rig's exact integrator (:func:`geovs_drake.batch.engine._integrate`) stays a
``prange`` loop: there the parfor's compiled loop ran 1.37 times faster than the same
function serial (2000 starts x 10 s on one thread: 1.86 s against 2.55 s), and its
10^4 starts' 5-s target (docs/performance.md) has no room to give.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from numba import njit

__all__ = ["batch_kernel", "over_starts"]

#: The batch integrators' decorator: a serial kernel over a slice of the starts, kept
#: whole (its step, checks and records inline: as a kernel of its own the step ran the
#: kinematic 10^4 starts 1.6 times slower), releasing the GIL so that threads run it.
batch_kernel = njit(cache=True, error_model="numpy", nogil=True)

_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _pool() -> ThreadPoolExecutor:
    """The threads the slices run on, made once: as many as numba's own pool."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(numba.config.NUMBA_NUM_THREADS, "batch-starts")
        return _POOL


def _sliced(args: Sequence, per_start: frozenset[int], first: int, last: int) -> list:
    """``args`` with each per-start argument (an array, or a tuple of arrays, along its
    first axis) cut to the starts [first, last): views, so in-place writes reach them."""
    out = []
    for k, a in enumerate(args):
        if k not in per_start:
            out.append(a)
        elif isinstance(a, tuple):  # a record of per-start arrays, not a scenario variant
            out.append(tuple(x[first:last] for x in a))
        else:
            out.append(a[first:last])
    return out


def over_starts(kernel: Callable, args: Sequence, per_start: Sequence[int]) -> tuple | None:
    """``kernel(*args)`` over the starts, split along the first axis of the arguments at
    ``per_start`` into one slice per numba thread, the slices run side by side (the last
    on this thread). Returns the slices' outputs joined start by start (each output an
    array over the starts), or None for a kernel that writes its per-start arguments in
    place and returns nothing."""
    per = frozenset(per_start)
    first = args[per_start[0]]
    n = len(first[0] if isinstance(first, tuple) else first)
    threads = min(numba.get_num_threads(), n)
    if threads <= 1:
        return kernel(*args)
    edges = np.linspace(0, n, threads + 1).astype(np.int64)
    spans = list(zip(edges[:-1], edges[1:], strict=True))
    futures = [_pool().submit(kernel, *_sliced(args, per, a, b)) for a, b in spans[:-1]]
    last = kernel(*_sliced(args, per, *spans[-1]))
    parts = [f.result() for f in futures] + [last]
    if last is None:
        return None
    return tuple(np.concatenate(column) for column in zip(*parts, strict=True))
