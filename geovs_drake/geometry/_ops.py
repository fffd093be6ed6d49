"""Elementary functions chosen per number type, and the checks on values.

Every formula of :mod:`geovs_drake.geometry` is written once, in scalar style,
on named components (``q1x, q1y, ...``) with ``+ - * /`` and the functions of
an :class:`Ops` namespace (the array-API pattern). The namespace is picked
from the type of one component:

* ``float``: :mod:`math` (a Python float operation costs about 30 ns, against
  about 1 us for a numpy call on a 3-vector);
* ``numpy.ndarray`` of floats, shape (N,) or any batch shape: :mod:`numpy`, so
  one call evaluates N poses;
* ``AutoDiffXd`` and symbolic ``Expression``: :mod:`pydrake.math`, so the
  TemplateSystems convert and ``Linearize`` works.

No formula branches on a value (``if x > 0`` fails for Expression): where a
formula needs a case split it is written branch-free.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pydrake.math as pm
from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import Expression, Variable

__all__ = [
    "DRAKE",
    "MATH",
    "NUMPY",
    "OutOfDomainError",
    "Ops",
    "any_true",
    "components",
    "first_bad",
    "namespace",
    "pack",
    "to_float",
]


class OutOfDomainError(ValueError):
    """A value outside the set a map is defined on: an invisible pose, an image
    outside I, a non-finite entry. Distinct from malformed input (shapes,
    parameters), so that a caller can tell a point outside the maps' domain
    from a wrong call."""


class Ops(NamedTuple):
    """The elementary functions a formula may call, for one number type."""

    sqrt: object
    sin: object
    cos: object
    atan2: object
    asin: object


MATH = Ops(math.sqrt, math.sin, math.cos, math.atan2, math.asin)
NUMPY = Ops(np.sqrt, np.sin, np.cos, np.arctan2, np.arcsin)
DRAKE = Ops(pm.sqrt, pm.sin, pm.cos, pm.atan2, pm.asin)

_BY_TYPE = {float: MATH, int: MATH, np.float64: MATH, np.ndarray: NUMPY}


def namespace(x: object) -> Ops:
    """The :class:`Ops` for the number type of ``x`` (one component of a formula).

    An ndarray gets numpy, whatever its entries: on object arrays (AutoDiffXd,
    Expression) numpy's ufuncs call each entry's own method, which pydrake
    provides. Any other non-float scalar is a pydrake scalar.
    """
    return _BY_TYPE.get(type(x), DRAKE)


class _Unevaluable(Exception):
    """A symbolic entry with free variables: its value cannot be checked."""


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


def to_float(x: object) -> np.ndarray | None:
    """Float values of ``x`` (any scalar type, any shape), or None where a
    symbolic entry has free variables and the value cannot be known."""
    a = np.asarray(x)
    if a.dtype != object:
        return a.astype(float)
    try:
        return np.asarray(_vectorized_value(a), dtype=float).reshape(a.shape)
    except _Unevaluable:
        return None


def first_bad(values: object, bad: object) -> tuple[float, str]:
    """``(value, " at batch index ...")`` of the first offending entry.

    ``values`` and ``bad`` are floats/bools or arrays of one batch shape.
    """
    bad = np.asarray(bad)
    values = np.broadcast_to(np.asarray(values, dtype=float), bad.shape)
    if bad.ndim == 0:
        return float(values), ""
    idx = tuple(int(i) for i in np.argwhere(bad)[0])
    return float(values[idx]), f" at batch index {idx}"


def any_true(x: object) -> bool:
    """``bool(x)`` for a bool, ``any(x)`` for a bool array."""
    return bool(np.any(x)) if type(x) is np.ndarray else bool(x)


def components(v: object, n: int, name: str) -> tuple:
    """The ``n`` components of ``v`` (last axis), as the formulas take them.

    A float vector gives Python floats (``tolist``: the fast scalar path), a
    batch (..., n) gives ``n`` arrays of the batch shape, an object vector
    gives its entries.
    """
    a = v if type(v) is np.ndarray else np.asarray(v)
    if a.shape[-1:] != (n,):
        raise ValueError(f"{name} must have shape (..., {n}), got {a.shape}")
    if a.ndim == 1:
        return tuple(a.tolist()) if a.dtype != object else tuple(a)
    if a.dtype != object:
        a = a.astype(float, copy=False)
    return tuple(np.moveaxis(a, -1, 0))


def pack(values: Sequence[object]) -> np.ndarray:
    """Stack components into a vector (scalars) or a (..., n) batch (arrays)."""
    if any(type(v) is np.ndarray and v.ndim > 0 for v in values):
        return np.stack(np.broadcast_arrays(*values), axis=-1)
    out = np.array(values, dtype=object)
    if all(type(v) in (float, int, np.float64) for v in values):
        return out.astype(float)
    return out
