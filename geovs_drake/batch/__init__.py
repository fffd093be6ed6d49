"""Layer 4: N closed loops at once on the compiled kernels (see :mod:`.engine`)."""

from geovs_drake.batch.engine import (
    DEFAULT_STEP,
    STATUS_NAMES,
    BatchResult,
    LoopParameters,
    loop_parameters,
    run_batch,
)

__all__ = [
    "DEFAULT_STEP",
    "STATUS_NAMES",
    "BatchResult",
    "LoopParameters",
    "loop_parameters",
    "run_batch",
]
