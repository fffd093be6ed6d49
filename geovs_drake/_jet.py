"""Forward-mode tangent propagation ("jets") over numpy arrays of any dtype.

A :class:`Jet` carries a value ``v`` (shape S) and ``n`` directional
derivatives ``d`` (shape (n,) + S). Arithmetic, ``sqrt``, indexing, sums and
stacking propagate both. The entries may be floats, AutoDiffXd or symbolic
Expressions, so one formula written on jets yields a function *and* its
differential for every scalar type, without a second hand-derived formula to
keep in sync. Only negative axes are used, so the leading tangent axis never
shifts the data axes.
"""

from __future__ import annotations

import numpy as np

from geovs_drake._scalar import cross as _scalar_cross


def _expand(d: np.ndarray, v_ndim: int, ndim: int) -> np.ndarray:
    """Insert axes after the tangent axis so ``d`` broadcasts like a value of ``ndim``."""
    if v_ndim == ndim:
        return d
    return d.reshape((d.shape[0],) + (1,) * (ndim - v_ndim) + d.shape[1:])


class Jet:
    __slots__ = ("d", "v")
    __array_ufunc__ = None  # make numpy defer to our reflected operators

    def __init__(self, v: object, d: np.ndarray) -> None:
        self.v = np.asarray(v)
        self.d = np.asarray(d)

    @staticmethod
    def constant(v: object, n: int) -> Jet:
        v = np.asarray(v)
        return Jet(v, np.zeros((n,) + v.shape))

    @property
    def n(self) -> int:
        return self.d.shape[0]

    @property
    def shape(self) -> tuple[int, ...]:
        return self.v.shape

    def _pair(self, other: object) -> tuple[Jet, Jet, int]:
        o = other if isinstance(other, Jet) else Jet.constant(other, self.n)
        ndim = max(self.v.ndim, o.v.ndim)
        return self, o, ndim

    def __add__(self, other: object) -> Jet:
        a, b, nd = self._pair(other)
        return Jet(a.v + b.v, _expand(a.d, a.v.ndim, nd) + _expand(b.d, b.v.ndim, nd))

    __radd__ = __add__

    def __neg__(self) -> Jet:
        return Jet(-self.v, -self.d)

    def __sub__(self, other: object) -> Jet:
        return self + (-other if isinstance(other, Jet) else -np.asarray(other))

    def __rsub__(self, other: object) -> Jet:
        return (-self) + other

    def __mul__(self, other: object) -> Jet:
        a, b, nd = self._pair(other)
        return Jet(
            a.v * b.v,
            _expand(a.d, a.v.ndim, nd) * b.v + a.v * _expand(b.d, b.v.ndim, nd),
        )

    __rmul__ = __mul__

    def __truediv__(self, other: object) -> Jet:
        a, b, nd = self._pair(other)
        q = a.v / b.v
        return Jet(q, (_expand(a.d, a.v.ndim, nd) - q * _expand(b.d, b.v.ndim, nd)) / b.v)

    def __rtruediv__(self, other: object) -> Jet:
        return Jet.constant(other, self.n) / self

    def __pow__(self, k: int) -> Jet:
        if k != 2:
            raise NotImplementedError("Jet supports only squaring")
        return self * self

    def __getitem__(self, index: object) -> Jet:
        idx = index if isinstance(index, tuple) else (index,)
        return Jet(self.v[idx], self.d[(slice(None),) + idx])


def sqrt(x: Jet) -> Jet:
    r = np.sqrt(x.v)
    return Jet(r, x.d / (2 * r))


def jsum(x: Jet) -> Jet:
    """Sum over the last axis."""
    return Jet(np.sum(x.v, axis=-1), np.sum(x.d, axis=-1))


def stack(items: list[Jet], axis: int = -1) -> Jet:
    if axis >= 0:
        raise ValueError("use a negative axis")
    shapes = {i.v.shape for i in items}
    if len(shapes) != 1:  # broadcast first (rare: a constant beside a batch)
        shape = np.broadcast_shapes(*shapes)
        items = [
            Jet(
                np.broadcast_to(i.v, shape),
                np.broadcast_to(_expand(i.d, i.v.ndim, len(shape)), (i.n,) + shape),
            )
            for i in items
        ]
    return Jet(np.stack([i.v for i in items], axis=axis), np.stack([i.d for i in items], axis=axis))


def dot(a: Jet, b: Jet) -> Jet:
    return jsum(a * b)


def cross(a: Jet, b: Jet) -> Jet:
    """a x b over the last axis; the product rule on whole arrays, not components."""
    nd = max(a.v.ndim, b.v.ndim)
    return Jet(
        _scalar_cross(a.v, b.v),
        _scalar_cross(_expand(a.d, a.v.ndim, nd), b.v)
        + _scalar_cross(a.v, _expand(b.d, b.v.ndim, nd)),
    )
