"""The batch engine's check of one state, shared by the exact and the sampled sensor's
integrators (:mod:`.engine`, :mod:`.sampled`)."""

import math

from numba import njit


@njit(cache=True, error_model="numpy", nogil=True)
def state_status(x, nu, margins, phi):
    """1 if x lies in D (with finite values), else 2 left_domain, 3 lost_visibility,
    4 non_finite: the checks of the safe-domain monitor, on one state."""
    for j in range(x.shape[0]):
        if not math.isfinite(x[j]):
            return 4
    if not nu > 0:
        return 3
    worst = min(margins[0], margins[1], margins[2], margins[3])
    if not (math.isfinite(worst) and math.isfinite(phi)):
        return 4
    if worst < 0:
        return 2
    return 1
