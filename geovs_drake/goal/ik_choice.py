"""IK's choice among an arm's solutions: the seeds it starts from, the score that ranks
its solutions and the rule that breaks a tie.

One definition for both of the package's inverse kinematics: Drake's
``InverseKinematics`` (:func:`geovs_drake.goal.arm.solve_joints`, the single runs, the
goal and the studies) and the sweep's compiled one
(:class:`geovs_drake.batch.arm_ik.StartSolver`), so that both try the same seeds and
keep a solution by the same rule.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "IK_SCORE_TIE",
    "IK_SEEDS",
    "SINGULARITY_WEIGHT",
    "better_solution",
    "ik_score",
    "ik_seeds",
]

#: Random seeds tried besides the middle of the joint range: the solution kept is the
#: one farthest from the joint limits (an arm has several inverse kinematics).
IK_SEEDS = 12

#: How IK weighs distance from a singularity (sigma_min of J_C) against distance from a
#: joint limit [rad] when it picks among its solutions.
SINGULARITY_WEIGHT = 10.0

#: Scores closer than this [rad] tie. Two solutions that differ by 2 pi in a joint away
#: from its limits have the same J_C and the same margin: their scores differ by rounding
#: alone, which the BLAS kernel decides (the UR5's goal: wrist 1 at -2.54 or +3.74 rad).
#: A tie goes to the solution nearer q = 0 (the smaller ``|q|``), whatever the seeds' order.
IK_SCORE_TIE = 1e-9


def ik_seeds(lower: np.ndarray, upper: np.ndarray, count: int = IK_SEEDS) -> np.ndarray:
    """The joints IK starts from (count + 1, nq): the middle of the range, then ``count``
    uniform draws (``default_rng(0)``) within the limits clipped to [-pi, pi]."""
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    rng = np.random.default_rng(0)
    low, high = np.maximum(lower, -np.pi), np.minimum(upper, np.pi)
    return np.array([0.5 * (lower + upper)] + [rng.uniform(low, high) for _ in range(count)])


def ik_score(
    joint_margin: float | np.ndarray, singular_value: float | np.ndarray
) -> float | np.ndarray:
    """How far a solution is from trouble: the smaller of its nearest joint limit's
    margin [rad] and :data:`SINGULARITY_WEIGHT` sigma_min(J_C) (scalars or arrays)."""
    return np.minimum(joint_margin, SINGULARITY_WEIGHT * np.asarray(singular_value))


def better_solution(
    q: np.ndarray, score: float, best: np.ndarray | None, best_score: float
) -> bool:
    """Whether IK's solution q (its score) replaces the best so far: a higher score, or a
    tied one (:data:`IK_SCORE_TIE`) nearer q = 0."""
    if best is None:
        return True
    if abs(score - best_score) <= IK_SCORE_TIE:
        return bool(np.linalg.norm(q) < np.linalg.norm(best) - IK_SCORE_TIE)
    return score > best_score
