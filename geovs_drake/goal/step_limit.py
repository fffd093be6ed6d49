"""The integrator's step limit from the loop's fastest mode at the goal.

A run that has converged sits at the goal, where the loop is its linearisation. An
explicit Runge-Kutta step h is stable there only while every ``h lambda`` (lambda an
eigenvalue of the goal's A) lies in the method's region of absolute stability,
``abs(R(h lambda)) <= 1`` with R the method's stability polynomial. Beyond it the error
control keeps rejecting and shrinking steps around the bound, and the pose error stalls
or grows (measured: the kinematic loop from a small move ended 2.9e-7 m from the goal
after 40 s with RK3's 0.05 s limit, where its fastest mode is -70.9 1/s; ``h abs(lambda)`` =
3.5 against RK3's real-axis bound 2.51; the UR5 on the dynamic plant ended 2.5e-11 m
from it after 30 s and 6.4e-10 m after 40 s with 0.05 s, beyond its bound of 0.039 s).

:func:`step_limit` finds the largest h whose ``h lambda`` stay in the region, for every
eigenvalue of the goal's A (:func:`goal_A`: the free rig's closed form,
:func:`~geovs_drake.goal.linear_model.closed_form_A`, or the dynamic arm's, :func:`arm_goal_A`),
and takes :data:`STABILITY_MARGIN` of it where that bound, not the cap, limits the step
(RK3: ``h abs(lambda)`` <= 0.8 x 2.51 = 2.0 on a real mode).
It is the one place that decides the step limit: the simulator
(:func:`~geovs_drake.simulation.monitor.make_simulator`) and the batch engine both read
:attr:`StepLimit.max_step_size`.

Who decides. ``simulator.max_step_size`` left unset (None, the default scenario's)
is automatic: the loop runs with :data:`~geovs_drake.scenario.DEFAULT_MAX_STEP` where
that is inside the stability bound, else with the bound's share (the margin buys room
below the edge where the edge sets the step; a cap already inside it keeps it: the
Panda's bound is 0.0526 s, and the share, 0.042 s, took 6% more steps than 0.05 s for
the same error, 4.5e-15 m after 30 s). Any other value is the user's and is used as
given, with one warning line (:meth:`StepLimit.warning`) where it puts the goal's
fastest mode outside the region.

Stiff loops. Where the goal's fastest mode is :data:`STIFFNESS_RATIO` or more times its
slowest and its bound is below the cap, an explicit method takes about ``duration /
stable_step`` steps, each held by a mode that has long died out, however slowly the loop
itself moves: a 6R arm with light links and no rotor inertia (``tests/data/stiff_6r.urdf``)
has a mode at -2.6e4 1/s (the law's and the joint's damping, 3.5 N m s/rad, over the
last link's 1.35e-4 kg m^2) and its slowest at -0.74 1/s; RK3 took 310,301 steps over
30 s, radau3 1,615. There the automatic limit stays the cap (the bound's share took 23%
more steps: the error control finds the edge itself) and the run gets one warning line
naming the mode and the remedy, an implicit integrator (:meth:`StepLimit.warning`):
``simulator.integration_scheme`` is the user's, which the package does not override.

Explicit methods whose stability polynomial is the truncated exponential only
(``runge_kutta2``, ``runge_kutta3``: as many stages as their order); the NF's law on the
free rig in the hand or on the dynamic arm (the closed forms are theirs). Elsewhere the
automatic limit is :data:`~geovs_drake.scenario.DEFAULT_MAX_STEP`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from geovs_drake.goal.inputs import GoalInputs
from geovs_drake.goal.linear_model import (
    chart_jacobian,
    closed_form_A,
    closed_form_refusal,
    second_order_A,
)
from geovs_drake.scenario import DEFAULT_MAX_STEP, ScenarioConfig

__all__ = [
    "IMPLICIT_REMEDY",
    "STABILITY_MARGIN",
    "STABILITY_POLYNOMIALS",
    "STIFFNESS_RATIO",
    "GoalModel",
    "StepLimit",
    "arm_goal_A",
    "goal_A",
    "step_limit",
]

#: The fraction of the stability bound the step may use: the error control wants room
#: below the bound, not a step that sits on it.
STABILITY_MARGIN = 0.8
#: Each explicit scheme's stability polynomial's coefficients (R(z) = sum c_k z^k): the
#: truncated exponential for RK2 and RK3, which have as many stages as their order;
#: Drake's RK5 is Dormand and Prince's 5(4), whose six stages that advance the step give
#: the exponential to z^5 and 1/600 z^6 (Hairer & Wanner, Solving ODEs II, Sec. IV.2).
STABILITY_POLYNOMIALS: dict[str, tuple[float, ...]] = {
    "runge_kutta2": (1.0, 1.0, 1 / 2),
    "runge_kutta3": (1.0, 1.0, 1 / 2, 1 / 6),
    "runge_kutta5": (1.0, 1.0, 1 / 2, 1 / 6, 1 / 24, 1 / 120, 1 / 600),
}
#: ``abs(fastest) / abs(slowest)`` of the goal's modes from which a loop is stiff for an
#: explicit method: its stable step is then about 1/1000 of the slowest time constant,
#: some 500 steps or more per time constant the loop needs (UR5: 70, Panda: 36, the
#: free rig: 14 dynamic and 39 kinematic; the light 6R arm of the tests: 35,000).
STIFFNESS_RATIO = 1000.0
#: The implicit scheme the stiff warning names: measured on the light 6R arm over 30 s,
#: radau3 took 1,615 steps (2.5 s), implicit_euler 11,462 (22.6 s: first order, its
#: steps are held by the accuracy), RK3 310,301 (114 s); each ended within 5e-14 m.
IMPLICIT_REMEDY = "radau3"
#: The schemes whose step a stiff loop holds to the bound's share all the same: RK5's
#: trial stages beyond its bound grow as (h lambda)^6 and reach inf before its error
#: control rejects the step (the stiff arm of the tests, at 0.05 s: MultibodyPlant then
#: refuses the state and aborts the process), where RK3's stay finite.
_HELD_WHEN_STIFF = ("runge_kutta5",)
#: Modes below this share of the fastest's modulus are a zero eigenvalue in rounding
#: (a redundant arm's self-motion has no stiffness: the Panda's is 6e-15 1/s).
_ZERO_MODE = 1e-9


@dataclass(frozen=True)
class GoalModel:
    """The loop's linear model at the goal: ``A`` and, on the arm, the joint each of its
    velocity coordinates is (``velocity_names``, the second half of A's state)."""

    A: np.ndarray
    velocity_names: tuple[str, ...] = ()


@dataclass(frozen=True)
class StepLimit:
    """The step limit the loop runs with, and the goal's modes that set it.

    ``max_step_size``: what the integrator runs with [s]; ``automatic``: True where
    ``simulator.max_step_size`` was left unset (None) (then it is
    ``DEFAULT_MAX_STEP`` where that is at most ``stable_step`` or the loop is
    :attr:`stiff`, else ``STABILITY_MARGIN * stable_step``), False where it is the user's
    value as given; ``fastest_mode`` and ``slowest_mode``: the goal's eigenvalues of
    largest and of least nonzero modulus [1/s] (of a conjugate pair, the member with
    Im >= 0); ``stable_step``: the largest h with every ``h lambda`` in the method's
    region [s]; ``explicit_steps``: ``ceil(duration / stable_step)``, the fewest steps
    the explicit method takes over the run where the bound holds it; ``fastest_joint``:
    on the arm, the joint that moves most in the fastest mode; ``third_order_step``: the
    same bound as ``stable_step`` for RK3's polynomial, whatever the scheme (the batch
    engine's third-order pair steps at the limit where this bound allows it). All None
    where the bound does not apply (see the module).
    """

    max_step_size: float
    automatic: bool
    fastest_mode: complex | None = None
    stable_step: float | None = None
    slowest_mode: complex | None = None
    explicit_steps: int | None = None
    fastest_joint: str | None = None
    third_order_step: float | None = None

    @property
    def beyond_bound(self) -> bool:
        """The step may leave the stability region at the goal (``h > stable_step``)."""
        return self.stable_step is not None and self.max_step_size > self.stable_step

    @property
    def stiffness(self) -> float | None:
        """``abs(fastest_mode) / abs(slowest_mode)``, None where the bound does not apply."""
        if self.fastest_mode is None or self.slowest_mode is None:
            return None
        return abs(self.fastest_mode) / abs(self.slowest_mode)

    @property
    def stiff(self) -> bool:
        """The explicit method's step is held far below the loop's own time scale: the
        modes' ratio is :data:`STIFFNESS_RATIO` or more and the bound, not the cap,
        limits the step."""
        ratio = self.stiffness
        return (
            ratio is not None and ratio >= STIFFNESS_RATIO and self.stable_step < DEFAULT_MAX_STEP
        )

    def warning(self, scheme: str) -> str | None:
        """The one line a user gets for a stiff loop on an explicit ``scheme`` (the mode,
        the scheme's bound, the remedy), or for their limit beyond the bound; else None."""
        lam = self.fastest_mode
        if self.stiff:
            slow = self.slowest_mode
            joint = "" if self.fastest_joint is None else f", mostly {self.fastest_joint}"
            model = (
                ""
                if self.fastest_joint is None
                else "; or give the arm's joints their reflected inertia (drake:rotor_inertia)"
            )
            return (
                f"the loop is stiff at the goal: its fastest mode ({_mode(lam)} 1/s{joint}) "
                f"is {self.stiffness:.2g} times its slowest ({_mode(slow)} 1/s), and "
                f"{scheme} is stable there only for steps below {self.stable_step:.3g} s, "
                f"about {self.explicit_steps:,} steps for the run; an implicit integrator "
                f"is not held to it: --scenario-text "
                f'"{{simulator: {{integration_scheme: {IMPLICIT_REMEDY}}}}}"{model}'
            )
        if self.automatic or not self.beyond_bound:
            return None
        return (
            f"simulator.max_step_size {self.max_step_size:g} s puts the goal's fastest mode "
            f"({lam.real:.4g}{lam.imag:+.4g}j 1/s) outside {scheme}'s stability region "
            f"(h |lambda| = {self.max_step_size * abs(lam):.3g}, bound at h = "
            f"{self.stable_step:.3g} s): the pose error may stall near the goal; leave it "
            f"unset for the automatic {STABILITY_MARGIN * self.stable_step:.3g} s"
        )


def _mode(lam: complex) -> str:
    """A mode as the warnings write it: its real part, and its imaginary one if any."""
    return f"{lam.real:.4g}" if lam.imag == 0 else f"{lam.real:.4g}{lam.imag:+.4g}j"


def _stable(coefficients: tuple[float, ...], z: np.ndarray) -> bool:
    R = np.polyval(coefficients[::-1], z)
    return bool(np.all(np.abs(R) <= 1.0 + 1e-12))


def step_limit(config: ScenarioConfig, model: GoalModel | None) -> StepLimit:
    """The :class:`StepLimit` the loop runs with (the one place it is decided), from the
    goal's linear ``model`` (:func:`goal_A`; None: no model covers the loop). The resolver
    calls it once; a run reads ``resolved.step_limit``."""
    configured = config.simulator.max_step_size
    automatic = configured is None
    chosen = DEFAULT_MAX_STEP if automatic else float(configured)
    coefficients = STABILITY_POLYNOMIALS.get(config.simulator.integration_scheme)
    if coefficients is None or model is None:
        return StepLimit(max_step_size=chosen, automatic=automatic)
    eigenvalues, vectors = np.linalg.eig(model.A)
    modulus = np.abs(eigenvalues)
    nonzero = modulus > _ZERO_MODE * modulus.max()
    if not np.any(nonzero):
        return StepLimit(max_step_size=chosen, automatic=automatic)
    fastest, stable = _bound(coefficients, eigenvalues[nonzero])
    limit = StepLimit(
        max_step_size=chosen,
        automatic=automatic,
        fastest_mode=fastest,
        stable_step=stable,
        slowest_mode=_upper(eigenvalues[nonzero][np.argmin(modulus[nonzero])]),
        explicit_steps=math.ceil(config.duration / stable),
        fastest_joint=_fastest_joint(model, vectors[:, np.argmax(modulus)]),
        third_order_step=(
            stable
            if coefficients == STABILITY_POLYNOMIALS["runge_kutta3"]
            else _bound(STABILITY_POLYNOMIALS["runge_kutta3"], eigenvalues[nonzero])[1]
        ),
    )
    held = not limit.stiff or config.simulator.integration_scheme in _HELD_WHEN_STIFF
    if automatic and held and DEFAULT_MAX_STEP > stable:
        # The bound, not the cap, sets the step: take its share. A stiff loop keeps the
        # cap (its error control finds the edge itself, with fewer steps) and is warned,
        # except on RK5 (below).
        limit = replace(limit, max_step_size=STABILITY_MARGIN * stable)
    return limit


def _upper(lam: complex) -> complex:
    """Of a conjugate pair, the member with Im >= 0, whichever rounding gave."""
    return complex(lam.real, abs(lam.imag))


def _fastest_joint(model: GoalModel, vector: np.ndarray) -> str | None:
    """The joint whose velocity moves most in the mode ``vector`` (None off the arm)."""
    if not model.velocity_names:
        return None
    nv = len(model.velocity_names)
    return model.velocity_names[int(np.argmax(np.abs(vector[nv:])))]


def _bound(coefficients: tuple[float, ...], eigenvalues: np.ndarray) -> tuple[complex, float]:
    """The fastest of ``eigenvalues`` (nonzero) and the largest stable step for them."""
    # Of a conjugate pair (equal moduli: argmax's tie), the member with Im >= 0.
    fastest = _upper(complex(eigenvalues[np.argmax(np.abs(eigenvalues))]))
    # Bisection on h: the region is star-shaped from 0 along each ray for these
    # polynomials, so stability is monotone in h along the eigenvalues' rays.
    lo, hi = 0.0, 10.0 / abs(fastest)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _stable(coefficients, mid * eigenvalues) else (lo, mid)
    return fastest, lo


def goal_A(resolved: GoalInputs) -> GoalModel | None:
    """The NF loop's A at the goal where the package has it in closed form: the free rig
    in the hand (:func:`~geovs_drake.goal.linear_model.closed_form_A`, minimal coordinates),
    the dynamic arm (:func:`arm_goal_A`, on (q, v)); None for another law or loop, and
    for an arm that cannot reach the goal (the run says so itself)."""
    config = resolved.config
    if not resolved.law.traits.navigation:
        return None
    if config.carrier.traits.joints:
        # Imported here: the batch engine's workers read the free rig's limit and never
        # load the arm's MultibodyPlant.
        from geovs_drake.goal.arm import Unreachable

        if not config.dynamic:
            return None
        try:
            return arm_goal_A(resolved)
        except Unreachable:
            return None
    if closed_form_refusal(config, "the step limit") is not None:
        return None
    return GoalModel(closed_form_A(resolved))


def arm_goal_A(resolved: GoalInputs) -> GoalModel:
    """The dynamic arm's A at the goal on (q, v) (:mod:`geovs_drake.analysis.linear.arm_study`
    writes the same and checks it against Drake's ``Linearize``):
    ``M(q*) ddq = -J_C^T K J_C dq - (J_C^T B J_C + D_joint) dq_dot``, K the NF's stiffness
    ``k_p C_chart^T H C_chart`` and B the loop's damping (the arm's gain scale applied),
    D_joint the joints' own (:class:`~geovs_drake.goal.arm.ArmGoalModel`)."""
    from geovs_drake.goal.arm import arm_goal_model, arm_model, joint_names
    from geovs_drake.systems.arm_model import arm_plant

    config = resolved.config
    goal = arm_goal_model(config)
    H, Cc = resolved.hessian, chart_jacobian(resolved.y_goal, resolved.believed_radius)
    K = config.control.potential_gain * Cc.T @ H @ Cc
    J = goal.J
    A = second_order_A(goal.M, J.T @ K @ J, J.T @ np.diag(resolved.damping) @ J + goal.D_joint)
    return GoalModel(A, joint_names(arm_plant(arm_model(config))))
