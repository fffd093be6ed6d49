"""The guarantee study on many starts: the closed loop from N random starts in D, on Dask.

Appendix C's claim: with E0 = 1/2 nu^T M nu + k_p phi(y0) < k_p, the energy E
never rises and k_p phi <= E, so phi stays below 1 and the dynamic loop never
leaves D. A sweep runs the loop from N starts that the claim covers (or, with
``velocity="above"``, starts it does not) and counts how many left D anyway.

Built to run at cluster scale (10^8 starts) with a client whose memory does not
grow with N:

* :mod:`.starts`: each part draws its own starts from a counter-based stream,
  so start i depends on (seed, i) only, not on N, the workers or the chunk.
* :mod:`.parts`: each part runs on a worker and writes its rows to one Parquet
  file, ``out/results/part-XXXXX.parquet``, atomically, with its summary in the
  file's metadata.
* :mod:`.summary`: the summaries merge (counts, extrema, a fine histogram of
  the convergence times, a coarse map of the starts), and the report and the
  plots are drawn from the merged summary.
* :mod:`.run`: :func:`run_sweep`, the client: a bounded window of parts on a
  ``LocalCluster`` or an existing scheduler, and ``resume`` from ``out``.
* :mod:`.here`: a smaller sweep's parts in this process, on numba's threads, each part
  finished on a helper thread while the next one integrates.

Why chunks of the batch engine: one :func:`~geovs_drake.batch.run_batch` call
integrates a part in one compiled loop, so a task costs a few bytes of
arguments, not one diagram per start. Why Dask rather than a process pool: the
same code runs on this machine's cores or on a cluster somebody already runs
(``scheduler="tcp://host:8786"``). ``engine="drake"`` runs each start through
:func:`~geovs_drake.simulation.simulate` (Drake's Simulator on the diagram):
much slower, for cross-checks on a few starts.
"""

from geovs_drake.analysis.sweep.parts import ROW_FIELDS
from geovs_drake.analysis.sweep.run import (
    CSV_LIMIT,
    ENGINES,
    LOCAL_CLUSTER_MIN_STARTS,
    SCHEDULER_TIMEOUT_S,
    SweepInterrupted,
    SweepResult,
    read_results,
    run_sweep,
    write_csv,
)
from geovs_drake.analysis.sweep.starts import (
    ABOVE_RANGE,
    ENERGY_FACTOR,
    SHRINK,
    START_BLOCK,
    VELOCITIES,
    SampledStarts,
    SweepError,
    sample_starts,
)
from geovs_drake.analysis.sweep.summary import (
    ARM_STATUSES,
    TIME_BINS,
    SweepSummary,
    plot_summary,
)

__all__ = [
    "ABOVE_RANGE",
    "ARM_STATUSES",
    "CSV_LIMIT",
    "LOCAL_CLUSTER_MIN_STARTS",
    "ENERGY_FACTOR",
    "ENGINES",
    "ROW_FIELDS",
    "SCHEDULER_TIMEOUT_S",
    "SHRINK",
    "START_BLOCK",
    "TIME_BINS",
    "VELOCITIES",
    "SampledStarts",
    "SweepError",
    "SweepInterrupted",
    "SweepResult",
    "SweepSummary",
    "plot_summary",
    "read_results",
    "run_sweep",
    "sample_starts",
    "write_csv",
]
