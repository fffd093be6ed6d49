"""The batch integrators' Runge-Kutta pairs and their step control.

Truths: the order conditions of Runge-Kutta methods (Butcher's rooted trees up to order
five), which the advancing and the embedded solutions must meet at their orders and
the embedded one must miss at the next; the step control's rule as stated.
"""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from geovs_drake.batch._pairs import (
    ACCEPT,
    BOGACKI_SHAMPINE,
    DORMAND_PRINCE,
    MIN_STEP,
    RETRY,
    UNDERFLOW,
    pair_for,
    step_control,
)


def _order_conditions(A: np.ndarray, b: np.ndarray, order: int) -> list[float]:
    """The residuals of the order conditions up to ``order`` for weights b (Butcher)."""
    c = A.sum(axis=1)
    conditions = [b.sum() - 1]
    if order >= 2:
        conditions.append(b @ c - 1 / 2)
    if order >= 3:
        conditions += [b @ c**2 - 1 / 3, b @ A @ c - 1 / 6]
    if order >= 4:
        conditions += [
            b @ c**3 - 1 / 4,
            b @ (c * (A @ c)) - 1 / 8,
            b @ A @ c**2 - 1 / 12,
            b @ A @ A @ c - 1 / 24,
        ]
    if order >= 5:
        Ac, Ac2 = A @ c, A @ c**2
        conditions += [
            b @ c**4 - 1 / 5,
            b @ (c**2 * Ac) - 1 / 10,
            b @ (c * Ac2) - 1 / 15,
            b @ (c * (A @ Ac)) - 1 / 30,
            b @ Ac**2 - 1 / 20,
            b @ A @ c**3 - 1 / 20,
            b @ A @ (c * Ac) - 1 / 40,
            b @ A @ A @ c**2 - 1 / 60,
            b @ A @ A @ A @ c - 1 / 120,
        ]
    return conditions


@pytest.mark.parametrize("pair,order", [(BOGACKI_SHAMPINE, 3), (DORMAND_PRINCE, 5)])
def test_each_pair_meets_its_orders_and_its_estimate_is_one_lower(pair, order):
    # The embedded solution's weights B - E: E's last entry weighs the new state's
    # derivative, the stage after the advancing solution (first same as last), so the
    # extended tableau has the advancing weights as its last row.
    s = pair.stages
    A_ext = np.zeros((s + 1, s + 1))
    A_ext[:s, :s] = pair.A
    A_ext[s, :s] = pair.B
    b_ext = np.append(pair.B, 0.0)
    embedded = b_ext - pair.E
    assert np.max(np.abs(_order_conditions(A_ext, b_ext, order))) < 1e-14
    assert np.max(np.abs(_order_conditions(A_ext, embedded, order - 1))) < 1e-14
    assert np.max(np.abs(_order_conditions(A_ext, embedded, order))) > 1e-6
    assert pair.exponent == pytest.approx(1 / order)


def test_the_pair_is_the_schemes_order():
    assert pair_for("runge_kutta5") is DORMAND_PRINCE
    for scheme in ("runge_kutta3", "runge_kutta2", "radau3", None):
        assert pair_for(scheme) is BOGACKI_SHAMPINE


@given(
    err=st.floats(0, 1e3, allow_nan=False),
    outside=st.booleans(),
    h=st.floats(1e-12, 0.1),
)
def test_step_control_accepts_only_an_accurate_step_inside_D_or_a_last_one_at_its_edge(
    err, outside, h
):
    accuracy, exponent = 1e-6, 1 / 5
    verdict, factor = step_control(err, accuracy, outside, h, exponent)
    if err <= accuracy and not outside:  # accepted, and the next step grows, at most 5x
        assert verdict == ACCEPT and 0.9 <= factor <= 5.0
        return
    # Rejected: shorter by the error's ratio (a half where only D refused it), at least 0.2.
    shrink = 0.5 if err <= accuracy else 0.9 * (accuracy / err) ** exponent
    assert factor == pytest.approx(max(0.2, shrink)) and factor <= 0.9
    if h * factor >= MIN_STEP:
        assert verdict == RETRY
    else:  # underflowed: at D's edge the step stands (the check stops it), else none does
        assert verdict == (ACCEPT if outside else UNDERFLOW)


def test_a_non_finite_error_shrinks_the_step_as_far_as_it_goes():
    assert step_control(float("nan"), 1e-6, False, 0.01, 1 / 3) == (RETRY, 0.2)
    assert step_control(float("inf"), 1e-6, False, 1e-10, 1 / 3) == (UNDERFLOW, 0.2)
