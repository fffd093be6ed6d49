"""The integrator's step limit from the loop's fastest mode at the goal.

A run that has converged sits at the goal, where the loop is its linearisation. An
explicit Runge-Kutta step h is stable there only while every ``h lambda`` (lambda an
eigenvalue of the goal's A) lies in the method's region of absolute stability,
``abs(R(h lambda)) <= 1`` with R the method's stability polynomial. Beyond it the error
control keeps rejecting and shrinking steps around the bound, and the pose error stalls
or grows (measured: the kinematic loop from a small move ended 2.9e-7 m from the goal
after 40 s with RK3's 0.05 s limit, where its fastest mode is -70.9 1/s; ``h abs(lambda)`` =
3.5 against RK3's real-axis bound 2.51).

:func:`step_limit` finds the largest h whose ``h lambda`` stay in the region, for every
eigenvalue of the closed form (:func:`~geovs_drake.linear_model.closed_form_A`), and takes
:data:`STABILITY_MARGIN` of it (RK3: ``h abs(lambda)`` <= 0.8 x 2.51 = 2.0 on a real mode).
It is the one place that decides the step limit: the simulator
(:func:`~geovs_drake.simulation.monitor.make_simulator`) and the batch engine both read
:attr:`StepLimit.max_step_size`.

Who decides. ``simulator.max_step_size`` left unset (None, the default scenario's)
is automatic: the loop runs with the smaller of
:data:`~geovs_drake.scenario.DEFAULT_MAX_STEP` and the stability bound's share. Any
other value is the user's and is used as given, with one warning line
(:meth:`StepLimit.warning`) where it puts the goal's fastest mode outside the region.
Explicit methods whose stability polynomial is the truncated exponential only
(``runge_kutta2``, ``runge_kutta3``: as many stages as their order); the NF's law on the
free rig in the hand only (the closed form is the free body's). Elsewhere the automatic
limit is :data:`~geovs_drake.scenario.DEFAULT_MAX_STEP`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geovs_drake.linear_model import closed_form_A, closed_form_refusal
from geovs_drake.scenario import (
    DEFAULT_MAX_STEP,
    Nf,
    ResolvedScenario,
)

__all__ = [
    "STABILITY_MARGIN",
    "STABILITY_POLYNOMIALS",
    "StepLimit",
    "stable_step",
    "step_limit",
]

#: The fraction of the stability bound the step may use: the error control wants room
#: below the bound, not a step that sits on it.
STABILITY_MARGIN = 0.8
#: Each explicit scheme's stability polynomial's coefficients (R(z) = sum c_k z^k): the
#: truncated exponential, since each has as many stages as its order.
STABILITY_POLYNOMIALS: dict[str, tuple[float, ...]] = {
    "runge_kutta2": (1.0, 1.0, 1 / 2),
    "runge_kutta3": (1.0, 1.0, 1 / 2, 1 / 6),
}


@dataclass(frozen=True)
class StepLimit:
    """The step limit the loop runs with, and the goal's fastest mode that sets it.

    ``max_step_size``: what the integrator runs with [s]; ``automatic``: True where
    ``simulator.max_step_size`` was left unset (None)
    (then it is ``min(DEFAULT_MAX_STEP, STABILITY_MARGIN * stable_step)``), False where
    it is the user's value as given; ``fastest_mode``: the goal's eigenvalue of largest
    modulus [1/s] (of a conjugate pair, the member with Im >= 0) and ``stable_step``:
    the largest h with every ``h lambda`` in the method's region [s], both None where
    the bound does not apply (see the module).
    """

    max_step_size: float
    automatic: bool
    fastest_mode: complex | None = None
    stable_step: float | None = None

    @property
    def beyond_bound(self) -> bool:
        """The step may leave the stability region at the goal (``h > stable_step``)."""
        return self.stable_step is not None and self.max_step_size > self.stable_step

    def warning(self, scheme: str) -> str | None:
        """The one line a user gets when their limit is beyond the bound, else None."""
        if self.automatic or not self.beyond_bound:
            return None
        lam = self.fastest_mode
        return (
            f"simulator.max_step_size {self.max_step_size:g} s puts the goal's fastest mode "
            f"({lam.real:.4g}{lam.imag:+.4g}j 1/s) outside {scheme}'s stability region "
            f"(h |lambda| = {self.max_step_size * abs(lam):.3g}, bound at h = "
            f"{self.stable_step:.3g} s): the pose error may stall near the goal; leave it "
            f"unset for the automatic {STABILITY_MARGIN * self.stable_step:.3g} s"
        )


def _stable(coefficients: tuple[float, ...], z: np.ndarray) -> bool:
    R = np.polyval(coefficients[::-1], z)
    return bool(np.all(np.abs(R) <= 1.0 + 1e-12))


def step_limit(resolved: ResolvedScenario) -> StepLimit:
    """The :class:`StepLimit` the loop runs with (the one place it is decided)."""
    config = resolved.config
    configured = config.simulator.max_step_size
    automatic = configured is None
    chosen = DEFAULT_MAX_STEP if automatic else float(configured)
    bound = stable_step(resolved)
    if bound is None:
        return StepLimit(max_step_size=chosen, automatic=automatic)
    fastest, stable = bound
    if automatic:
        chosen = min(chosen, STABILITY_MARGIN * stable)
    return StepLimit(
        max_step_size=chosen, automatic=automatic, fastest_mode=fastest, stable_step=stable
    )


def stable_step(resolved: ResolvedScenario) -> tuple[complex, float] | None:
    """The goal's fastest mode and the largest stable step h for the configured scheme,
    or None where they do not apply (a scheme without a stability polynomial here, a law
    other than the NF, a carrier other than the free rig in the hand:
    :func:`~geovs_drake.linear_model.closed_form_A`
    is theirs only)."""
    config = resolved.config
    coefficients = STABILITY_POLYNOMIALS.get(config.simulator.integration_scheme)
    if coefficients is None or not isinstance(resolved.law, Nf):
        return None
    if closed_form_refusal(config, "the step limit") is not None:
        return None
    eigenvalues = np.linalg.eigvals(closed_form_A(config, damping=resolved.damping))
    eigenvalues = eigenvalues[np.abs(eigenvalues) > 0]
    if len(eigenvalues) == 0:
        return None
    # Of a conjugate pair (equal moduli: argmax's tie), the member with Im >= 0, whichever
    # of the two rounding made the larger.
    fastest = complex(eigenvalues[np.argmax(np.abs(eigenvalues))])
    fastest = complex(fastest.real, abs(fastest.imag))
    # Bisection on h: the region is star-shaped from 0 along each ray for these
    # polynomials, so stability is monotone in h along the eigenvalues' rays.
    lo, hi = 0.0, 10.0 / abs(fastest)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _stable(coefficients, mid * eigenvalues) else (lo, mid)
    return fastest, lo
