"""A barrier on an arm's joint limits, to combine with the NF on D.

Each side of each joint gets a smooth step of its margin m (the distance to that
limit), zero at the limit and one from the width w on::

    s(m) = 1 - (1 - min(m / w, 1))^3        (C^2 at m = w: s' = s'' = 0 there)

and the joints' barrier is ``phi_q = 1 - prod_i s(q_i - lower_i) s(upper_i - q_i)``: 0
wherever every joint is at least w from its limits, 1 at a limit. The loop's potential
is then ``phi_total = 1 - (1 - phi)(1 - phi_q)``, the product construction of
navigation functions on cross-product spaces: 0 only at the goal with the joints away
from their limits, 1 on the boundary of D or at a joint limit. With the arm's torque
``tau = (1 - phi_q) J_C^T F_C - k_p (1 - phi) dphi_q/dq + g - B_q v``,
``E = 1/2 v^T M v + k_p phi_total`` has ``Edot = -(1 - phi_q) twist^T B twist - v^T
B_q v <= 0`` (:class:`~geovs_drake.systems.ArmCamera`), so a start with E0 < k_p never
reaches a joint limit, as it never leaves D.

The width is one number for every joint, or one per joint (:func:`joint_widths`): a
fraction of each joint's range, as ViSP's joint-limit task puts its activation in the
last 10 % of each range. A per-joint width is a constant of the formula, so the same
scalar-style code serves every scalar type.

Scalar style: ``min_`` is the min of the scalar type (``min`` for floats,
``pydrake.math.min`` for AutoDiffXd and Expression), so no branch reads a value.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

__all__ = ["combine", "joint_barrier", "joint_widths", "per_joint", "smooth_step"]


def smooth_step(m, width: float, min_: Callable) -> tuple:
    """(s(m), ds/dm) of the module docstring's step, for a margin m >= 0."""
    u = 1 - min_(m / width, 1.0)
    return 1 - u * u * u, 3 * u * u / width


def per_joint(width: float | Sequence[float], n: int) -> tuple[float, ...]:
    """The barrier's width for each of n joints: ``width`` repeated, or its n entries;
    ValueError unless every one is finite and > 0 (a width of 0 divides by 0)."""
    widths = (width,) * n if _is_number(width) else tuple(width)
    if len(widths) != n or not all(math.isfinite(w) and w > 0 for w in map(float, widths)):
        raise ValueError(f"the barrier needs {n} finite widths > 0 [rad], got {width!r}")
    return tuple(float(w) for w in widths)


def _is_number(value) -> bool:
    """A single width (a Python or numpy number, a 0-d array), not a sequence of them."""
    return not hasattr(value, "__len__") or getattr(value, "ndim", 1) == 0


def joint_widths(
    lower: Sequence[float], upper: Sequence[float], width: float = 0.0, fraction: float = 0.0
) -> tuple[float, ...] | None:
    """Each joint's barrier width [rad]: ``width`` for all, or ``fraction`` of each
    joint's range ``upper - lower`` (the two are exclusive: the arm's config checks it);
    None when both are 0 (no barrier)."""
    if fraction > 0:
        return per_joint(
            [fraction * (hi - lo) for lo, hi in zip(lower, upper, strict=True)], len(lower)
        )
    return per_joint(width, len(lower)) if width > 0 else None


def joint_barrier(
    q: Sequence,
    lower: Sequence[float],
    upper: Sequence[float],
    width: float | Sequence[float],
    min_: Callable,
) -> tuple:
    """(phi_q, dphi_q/dq) for joint positions q strictly inside [lower, upper]; ``width``
    one for all joints or one per joint (:func:`per_joint`)."""
    steps, slopes = [], []
    widths = per_joint(width, len(lower))
    for q_i, lo, hi, w in zip(q, lower, upper, widths, strict=True):
        s_lo, d_lo = smooth_step(q_i - lo, w, min_)
        s_hi, d_hi = smooth_step(hi - q_i, w, min_)
        steps.append(s_lo * s_hi)
        slopes.append(d_lo * s_hi - s_lo * d_hi)  # d/dq of s(q - lo) s(hi - q)
    product = 1.0
    for s in steps:
        product = product * s
    gradient = []
    for i in range(len(steps)):
        others = 1.0
        for j, s in enumerate(steps):
            if j != i:
                others = others * s
        gradient.append(-slopes[i] * others)
    return 1 - product, tuple(gradient)


def combine(phi, phi_q):
    """phi_total = 1 - (1 - phi)(1 - phi_q), written ``phi + phi_q - phi phi_q`` so that
    it keeps phi's accuracy near the goal (1 - (1 - phi) rounds phi = 1e-14 away)."""
    return phi + phi_q - phi * phi_q
