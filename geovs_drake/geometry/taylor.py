"""Truncated multivariate Taylor arithmetic: the exact Taylor polynomial of a kernel.

A :class:`Jet` is a polynomial in n variables truncated at a degree d, stored as its
coefficients over the monomials of degree <= d. Arithmetic on jets is arithmetic on
Taylor series with every term above d dropped, so a formula evaluated on the jets
``x_i = x0_i + e_i`` returns the coefficients of its degree-d Taylor expansion at x0,
exact to rounding (forward-mode differentiation to order d).

Why not Drake's ``symbolic.TaylorExpand``: the generated kernels are straight-line code
whose temporaries are shared many times, and a symbolic Expression of them is a DAG
that Drake's ``Evaluate`` and ``Differentiate`` walk as a tree; the servo's closed loop
did not finish one evaluation in ten minutes. A jet materialises each temporary once.
No maintained library for this runs on Python 3.11 wheels here (pyaudi has none).

The generated kernels need ``+ - * /``, integer powers, ``sqrt``, ``sin`` and ``cos``
(numpy's ufuncs call the methods of the same name on object entries), so that is what a
jet implements: the elementary functions by their univariate series about the constant
term, ``f(a0 + h) = sum_k f^(k)(a0) h^k / k!`` with h nilpotent at degree d + 1.
"""

from __future__ import annotations

import itertools
import math
from functools import cache

import numpy as np

__all__ = ["Jet", "monomials", "variables"]


@cache
def monomials(n: int, degree: int) -> tuple[tuple[int, ...], ...]:
    """The exponent tuples of the monomials of degree <= ``degree`` in n variables,
    by degree, then lexicographically (the jets' coefficient order; the first is 1)."""
    out = []
    for d in range(degree + 1):
        for combo in itertools.combinations_with_replacement(range(n), d):
            e = [0] * n
            for i in combo:
                e[i] += 1
            out.append(tuple(e))
    return tuple(sorted(out, key=lambda e: (sum(e), [-v for v in e])))


@cache
def _product_table(n: int, degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, j, k): monomial i times monomial j is monomial k, for every pair whose
    degree stays <= ``degree``."""
    basis = monomials(n, degree)
    index = {e: k for k, e in enumerate(basis)}
    rows = [
        (i, j, index[tuple(a + b for a, b in zip(ei, ej, strict=True))])
        for i, ei in enumerate(basis)
        for j, ej in enumerate(basis)
        if sum(ei) + sum(ej) <= degree
    ]
    i, j, k = (np.array(c, dtype=np.intp) for c in zip(*rows, strict=True))
    return i, j, k


class Jet:
    """A truncated Taylor polynomial (module docstring). ``coefficients[k]`` multiplies
    ``monomials(n, degree)[k]``; ``coefficients[0]`` is the value at the expansion point."""

    __slots__ = ("n", "degree", "coefficients")
    __array_priority__ = 100  # float * Jet -> Jet.__rmul__, not an object array

    def __init__(self, n: int, degree: int, coefficients: np.ndarray) -> None:
        self.n, self.degree, self.coefficients = n, degree, coefficients

    # Construction ------------------------------------------------------------------
    def _constant(self, value: float) -> Jet:
        c = np.zeros_like(self.coefficients)
        c[0] = value
        return Jet(self.n, self.degree, c)

    def _lift(self, other: object) -> Jet:
        return other if isinstance(other, Jet) else self._constant(float(other))

    @property
    def value(self) -> float:
        """The constant term: the formula's value at the expansion point."""
        return float(self.coefficients[0])

    # Arithmetic --------------------------------------------------------------------
    def __add__(self, other: object) -> Jet:
        if isinstance(other, Jet):
            return Jet(self.n, self.degree, self.coefficients + other.coefficients)
        c = self.coefficients.copy()
        c[0] += float(other)
        return Jet(self.n, self.degree, c)

    __radd__ = __add__

    def __neg__(self) -> Jet:
        return Jet(self.n, self.degree, -self.coefficients)

    def __pos__(self) -> Jet:
        return self

    def __sub__(self, other: object) -> Jet:
        return self + (-other)

    def __rsub__(self, other: object) -> Jet:
        return (-self) + other

    def __mul__(self, other: object) -> Jet:
        if not isinstance(other, Jet):
            return Jet(self.n, self.degree, self.coefficients * float(other))
        i, j, k = _product_table(self.n, self.degree)
        products = self.coefficients[i] * other.coefficients[j]
        c = np.bincount(k, weights=products, minlength=len(self.coefficients))
        return Jet(self.n, self.degree, c)

    __rmul__ = __mul__

    def __truediv__(self, other: object) -> Jet:
        if not isinstance(other, Jet):
            return Jet(self.n, self.degree, self.coefficients / float(other))
        return self * other._reciprocal()

    def __rtruediv__(self, other: object) -> Jet:
        return self._reciprocal() * float(other)

    def __pow__(self, exponent: int) -> Jet:
        if not isinstance(exponent, int) or exponent < 0:
            raise ValueError(f"a jet takes non-negative integer powers only: {exponent!r}")
        out = self._constant(1.0)
        for _ in range(exponent):
            out = out * self
        return out

    # Elementary functions: sum_k f^(k)(a0) h^k / k! -----------------------------------
    def _series(self, derivatives: list[float]) -> Jet:
        """f(self) from f's derivatives at the constant term, f^(0) .. f^(degree)."""
        h = Jet(self.n, self.degree, self.coefficients.copy())
        h.coefficients[0] = 0.0
        out = self._constant(derivatives[0])
        power = self._constant(1.0)
        for k in range(1, self.degree + 1):
            power = power * h
            out = out + power * (derivatives[k] / math.factorial(k))
        return out

    def _reciprocal(self) -> Jet:
        a = self.value
        # d^k/da^k 1/a = (-1)^k k! / a^(k+1)
        return self._series(
            [(-1.0) ** k * math.factorial(k) / a ** (k + 1) for k in range(self.degree + 1)]
        )

    def sqrt(self) -> Jet:
        """The square root (``numpy.sqrt`` of a jet calls it)."""
        a = self.value
        derivatives, c = [], 1.0  # d^k/da^k a^(1/2) = (1/2)(1/2 - 1)...(1/2 - k + 1) a^(1/2 - k)
        for k in range(self.degree + 1):
            derivatives.append(c * a ** (0.5 - k))
            c *= 0.5 - k
        return self._series(derivatives)

    def sin(self) -> Jet:
        """The sine (``numpy.sin`` of a jet calls it)."""
        s, c = math.sin(self.value), math.cos(self.value)
        return self._series([(s, c, -s, -c)[k % 4] for k in range(self.degree + 1)])

    def cos(self) -> Jet:
        """The cosine (``numpy.cos`` of a jet calls it)."""
        s, c = math.sin(self.value), math.cos(self.value)
        return self._series([(c, -s, -c, s)[k % 4] for k in range(self.degree + 1)])

    def __repr__(self) -> str:
        return f"Jet(n={self.n}, degree={self.degree}, value={self.value:g})"


def variables(x0: np.ndarray, degree: int) -> np.ndarray:
    """Jets of the variables ``x_i = x0_i + e_i`` at the point x0 (an object array)."""
    x0 = np.asarray(x0, dtype=float)
    n = len(x0)
    size = len(monomials(n, degree))
    out = np.empty(n, dtype=object)
    for i, v in enumerate(x0):
        c = np.zeros(size)
        c[0], c[1 + i] = v, 1.0  # monomials: 1, then x_0 .. x_{n-1}
        out[i] = Jet(n, degree, c)
    return out
