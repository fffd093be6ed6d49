"""Scalar-type plumbing shared by the pure-math modules.

Every public math function accepts float arrays (optionally with leading batch
dimensions), or object arrays of ``AutoDiffXd`` or symbolic ``Expression``.
Input checks run on the *values*: for AutoDiffXd the value part, for
Expression only when the expression has no free variables (otherwise the
check cannot be evaluated and is skipped, as the contract says).
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import Expression, Variable


def sqrt(x: object) -> object:
    """Square root for arrays of any scalar type and for jets."""
    from geovs_drake._jet import Jet
    from geovs_drake._jet import sqrt as jet_sqrt

    if isinstance(x, Jet):
        return jet_sqrt(x)
    return np.sqrt(x)


class OutOfDomainError(ValueError):
    """A value outside the set a map is defined on: an invisible pose, an image
    outside I, a non-finite entry. Distinct from malformed input (shapes,
    parameters), so that Drake systems can turn it into NaN outputs for an
    integrator's rejected trial stage while every other error still raises."""


class _Unevaluable(Exception):
    """Raised internally when a symbolic entry has free variables."""


def _element_value(e: object) -> float:
    if isinstance(e, AutoDiffXd):
        return e.value()
    if isinstance(e, Variable):
        raise _Unevaluable
    if isinstance(e, Expression):
        if not e.GetVariables().empty():
            raise _Unevaluable
        return e.Evaluate()
    return float(e)


_vectorized_value = np.frompyfunc(_element_value, 1, 1)


def values_or_none(x: object) -> np.ndarray | None:
    """Float values of ``x``, or None where a symbolic entry has free variables."""
    a = np.asarray(x)
    if a.dtype != object:
        return a.astype(float)
    try:
        return np.asarray(_vectorized_value(a), dtype=float).reshape(a.shape)
    except _Unevaluable:
        return None


def is_float_array(x: np.ndarray) -> bool:
    return np.asarray(x).dtype != object


def as_array(x: object) -> np.ndarray:
    """``x`` as an ndarray: float dtype where possible, object otherwise."""
    a = np.asarray(x)
    if a.dtype == object:
        return a
    return a.astype(float)


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Inner product over the last axis, broadcasting over leading axes.

    Always an ndarray (0-d for single vectors), so ``[..., None]`` works for
    object dtypes too.
    """
    return np.asarray(np.sum(a * b, axis=-1))


def col(x: object) -> np.ndarray:
    """``x[..., None]``: a batch of scalars broadcast against (..., n) vectors."""
    return np.asarray(x)[..., None]


def mat(x: object) -> np.ndarray:
    """``x[..., None, None]``: a batch of scalars against (..., n, m) matrices."""
    return np.asarray(x)[..., None, None]


def norm(a: np.ndarray) -> np.ndarray:
    return np.sqrt(dot(a, a))


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (works for float and object arrays)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., :, None] * b[..., None, :]


def check_finite(name: str, x: object) -> None:
    """Raise ValueError if any evaluable entry of ``x`` is NaN or infinite."""
    v = values_or_none(x)
    if v is not None and not np.all(np.isfinite(v)):
        bad = np.argwhere(~np.isfinite(v))[0]
        raise OutOfDomainError(
            f"{name} has a non-finite entry: {name}[{', '.join(map(str, bad))}] = {v[tuple(bad)]}"
        )


def worst(values: np.ndarray, mask: np.ndarray) -> tuple[float, tuple[int, ...]]:
    """The first offending value and its batch index, for error messages."""
    idx = tuple(int(i) for i in np.argwhere(mask)[0])
    return float(values[idx]), idx


def index_note(idx: tuple[int, ...]) -> str:
    return f" at batch index {idx}" if idx else ""
