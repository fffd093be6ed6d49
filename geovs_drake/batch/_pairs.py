"""The embedded Runge-Kutta pairs of the batch engine's integrators, as tableaux.

Every batch integrator (the free rig's and the arm's, with the exact sensor and the
sampled camera) steps with the pair of the order of the loop's Drake scheme, first same
as last: Dormand and Prince's 5(4), the tableau of Drake's RK5, where that scheme is
fifth-order (:data:`FIFTH_ORDER_SCHEMES`), else Bogacki and Shampine's 3(2). So the
batch's step limit, read from the Drake loop's, is the stability bound of a method of
its own order (:mod:`geovs_drake.goal.step_limit`). The free rig's exact-sensor engine
also takes the third-order pair's step where the step limit holds the step and RK3's
bound allows it (variable order: ``LoopParameters.third_order_at_limit``).

A pair is data, not code: each integrator calls its own right-hand side at the points
:func:`stage_point` builds and takes :func:`solution` and :func:`error_norm`, so one
step's arithmetic is written once for every integrator and both pairs. ``K`` holds the
step's stages, one row each, ``K[0]`` the derivative at the step's start (the last
step's last stage: first same as last).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = [
    "ACCEPT",
    "BOGACKI_SHAMPINE",
    "DORMAND_PRINCE",
    "FIFTH_ORDER_SCHEMES",
    "MIN_STEP",
    "RETRY",
    "UNDERFLOW",
    "Pair",
    "error_norm",
    "pair_for",
    "solution",
    "stage_point",
    "step_control",
    "step_to_frame",
]

#: Drake's schemes whose order the engine meets with Dormand and Prince's pair.
FIFTH_ORDER_SCHEMES = ("runge_kutta5",)


@dataclass(frozen=True)
class Pair:
    """An embedded pair with the first-same-as-last property.

    ``A``: the stages' coefficients (row s: stage s's point from stages 0..s-1);
    ``B``: the advancing solution's weights; ``E``: the error estimate's weights (the
    advancing solution's less the embedded one's), one more than the stages, the last
    for the derivative at the new state; ``exponent``: the step-size rule's, 1 / (the
    embedded solution's order + 1)."""

    name: str
    A: np.ndarray
    B: np.ndarray
    E: np.ndarray
    exponent: float

    def kernel_args(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """What the integrators take: ``(A, B, E, exponent)``."""
        return self.A, self.B, self.E, self.exponent

    @property
    def stages(self) -> int:
        """The derivative evaluations a step takes anew (the first is the last step's)."""
        return len(self.B)


BOGACKI_SHAMPINE = Pair(
    "Bogacki-Shampine 3(2)",
    A=np.array([[0.0, 0.0, 0.0], [1 / 2, 0.0, 0.0], [0.0, 3 / 4, 0.0]]),
    B=np.array([2 / 9, 1 / 3, 4 / 9]),
    E=np.array([-5 / 72, 1 / 12, 1 / 9, -1 / 8]),
    exponent=1 / 3,
)
DORMAND_PRINCE = Pair(
    "Dormand-Prince 5(4)",
    A=np.array(
        [
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [1 / 5, 0.0, 0.0, 0.0, 0.0, 0.0],
            [3 / 40, 9 / 40, 0.0, 0.0, 0.0, 0.0],
            [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0, 0.0],
            [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0, 0.0],
            [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0.0],
        ]
    ),
    B=np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]),
    E=np.array([71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40]),
    exponent=1 / 5,
)


def pair_for(scheme: str | None) -> Pair:
    """The pair of ``scheme``'s order (a Drake integrator's name, as resolved)."""
    return DORMAND_PRINCE if scheme in FIFTH_ORDER_SCHEMES else BOGACKI_SHAMPINE


@njit(cache=True, nogil=True, error_model="numpy")
def stage_point(A, s, x, h, K, out):
    """Stage s's point ``x + h sum_m A[s, m] K[m]`` into ``out``."""
    for j in range(x.shape[0]):
        acc = 0.0
        for m in range(s):
            acc += A[s, m] * K[m, j]
        out[j] = x[j] + h * acc


@njit(cache=True, nogil=True, error_model="numpy")
def solution(B, x, h, K, out):
    """The advancing solution ``x + h sum_m B[m] K[m]`` into ``out``."""
    for j in range(x.shape[0]):
        acc = 0.0
        for m in range(B.shape[0]):
            acc += B[m] * K[m, j]
        out[j] = x[j] + h * acc


@njit(cache=True, nogil=True, error_model="numpy")
def error_norm(E, x, h, K, d):
    """The local error estimate (``d``: the derivative at the new state, the last
    stage), each component relative to max(1, abs(x_j)), the largest: the engine's
    error control, like Drake's, compares it with the accuracy."""
    last = E.shape[0] - 1
    err = 0.0
    for j in range(x.shape[0]):
        acc = E[last] * d[j]
        for m in range(last):
            acc += E[m] * K[m, j]
        err = max(err, abs(h * acc) / max(1.0, abs(x[j])))
    return err


#: :func:`step_control`'s verdicts on a tried step: accepted; rejected, to be tried again
#: shorter; no accurate step at all (the step size underflowed away from D's boundary).
ACCEPT, RETRY, UNDERFLOW = 0, 1, 2
#: The shortest step tried [s]: a shorter one has underflowed.
MIN_STEP = 1e-10


@njit(cache=True, nogil=True, error_model="numpy")
def step_control(err, accuracy, outside, h, exponent):
    """The error control's verdict on a step of ``h`` whose local error is ``err`` and
    whose new state is ``outside`` D or not, and the factor on h for the next try.

    Rejected where the error exceeds the accuracy (a non-finite error, a stage outside
    the maps' domain, counts as huge) or the state left D: the exact flow of a start
    with E0 < k_p never leaves D, so a start leaves D only where the step size
    underflows at the boundary, and that last step is accepted for the state check to
    stop the start. Growth and shrinkage as Drake's error control: 0.9 (accuracy /
    err)^exponent, within [0.2, 5]."""
    if not math.isfinite(err):
        err = 1e300
    if err > accuracy or outside:
        shrink = max(0.2, 0.5 if err <= accuracy else 0.9 * (accuracy / err) ** exponent)
        if h * shrink >= MIN_STEP:
            return RETRY, shrink
        return (ACCEPT if outside else UNDERFLOW), shrink
    return ACCEPT, 5.0 if err == 0.0 else min(5.0, 0.9 * (accuracy / err) ** exponent)


@njit(cache=True, nogil=True, error_model="numpy")
def step_to_frame(t, t1, hh, h_try, grow, last):
    """The clock and the next step after an accepted step ``hh`` of a sampled camera's
    integrator, whose steps end at the frame ``t1``: a step clipped there (``last``) says
    nothing of the next one, which keeps at least the step it would have tried."""
    if last:
        return t1, max(hh * grow, h_try)
    return t + hh, hh * grow
