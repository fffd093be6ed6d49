"""A sweep's parts run in this process, one after the other, on numba's threads.

Below :data:`~geovs_drake.analysis.sweep.run.LOCAL_CLUSTER_MIN_STARTS` a sweep runs here
rather than on Dask (:func:`~geovs_drake.analysis.sweep.run.run_sweep`): a part
integrates on the sweep's ``workers`` numba threads while one helper thread finishes the
part before it and prepares the part after it.
"""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from geovs_drake.analysis.sweep.parts import Part, compute_part, finish_part, prepare_part

__all__ = ["run_here"]


def run_here(todo: list[tuple[Part, str]], threads: int) -> Iterator[tuple[dict, object]]:
    """The parts run here one after the other, each on ``threads`` numba threads (at
    most numba's pool); numba's thread count is restored afterwards.

    While a part integrates (numba kernels on ``threads`` threads, the GIL released), a
    thread finishes the one before (:func:`~.parts.finish_part`: its runs' ends, its
    summary and its Parquet file, 20-30 ms a part of 1000 free-body starts) and prepares
    the next part's starts (:func:`~.parts.prepare_part`: on the arm its IK and branch,
    Python and serial kernels on one core, about half of the sweep's CPU time). Neither
    calls a parallel kernel, so never two launches into numba's pool at once. A part is
    yielded once it is finished and the next one has integrated; stopped (Ctrl-C, an
    ``on_part`` that raises), the folder holds exactly the parts yielded."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    ahead = ThreadPoolExecutor(max_workers=1, thread_name_prefix="next-part")
    finishing = None  # (the future of a part being finished, the part, its file's name)
    try:
        following = ahead.submit(prepare_part, todo[0][0]) if todo else None
        for i, (part, name) in enumerate(todo):
            starts = following.result()
            if i + 1 < len(todo):
                following = ahead.submit(prepare_part, todo[i + 1][0])
            columns = compute_part(part, starts)
            if finishing is not None:
                done, finishing = finishing, None
                yield done[0].result()
            finishing = (ahead.submit(finish_part, part, name, columns), part, name)
        if finishing is not None:
            done, finishing = finishing, None
            yield done[0].result()
    finally:
        ahead.shutdown(wait=False, cancel_futures=True)
        numba.set_num_threads(before)
        if finishing is not None:  # stopped before it was yielded: not kept
            _drop_unyielded(*finishing)


def _drop_unyielded(future, part: Part, name: str) -> None:
    """A part finished on the thread but never yielded (stopped while the next one
    integrated): its file, once written, is removed (a resume runs it again)."""
    if future.cancel() or future.exception() is not None or part.results is None:
        return
    (Path(part.results) / name).unlink(missing_ok=True)
