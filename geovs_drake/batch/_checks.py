"""The batch engine's check of one state, shared by the exact and the sampled sensor's
integrators (:mod:`.engine`, :mod:`.sampled`, the arm's :mod:`.arm_engine` and
:mod:`.arm_sampled`)."""

import math

import numpy as np
from numba import njit

#: The arm's status code for a joint outside its range (after the free rig's five).
JOINT_LIMIT = 5


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


@njit(cache=True, nogil=True, error_model="numpy")
def joint_margin(x, joint):
    """The least distance of a joint of x from its limits (< 0: outside; ``joint``: the
    arm tree's rows, lower and upper limits in columns 3 and 4)."""
    m = np.inf
    for c in range(joint.shape[0]):
        m = min(m, x[c] - joint[c, 3], joint[c, 4] - x[c])
    return m
