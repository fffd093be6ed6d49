"""Spectra in an order that rounding cannot change, and compared as multisets.

LAPACK returns eigenvalues in an order of its own, and the last bits of each value
depend on the BLAS kernel that numpy runs (OpenBLAS picks one per processor, and
``OPENBLAS_CORETYPE`` can pin another). ``np.sort_complex`` does not repair that: it
orders by the real part first, so the two members of a repeated complex pair, whose
real parts differ only by rounding, come out as (-, -, +, +) on one machine and
(-, +, -, +) on another. Every spectrum this package returns goes through
:func:`canonical_spectrum`, and every comparison of two spectra through
:func:`match_spectra` (or :func:`assert_spectra_close` in tests and notebooks).

**The canonical order**, for a spectrum of spectral radius r:

1. by the real part, ascending (the fastest-decaying modes first, the slowest last),
   where real parts closer than ``rtol * r`` (chained) count as equal;
2. then by ``|Im|``, ascending, with the same clustering;
3. then, among values of that real part and ``|Im|``, the real ones first, then the
   conjugate pairs kept together, each ``a - bj`` before ``a + bj``: a repeated pair
   reads ``(-, +, -, +)``;
4. values still tied are equal to within ``rtol * r``; among them the raw value decides,
   which is harmless: any order of them agrees element-wise to that tolerance.

Clustering instead of rounding to a grid: a grid puts a boundary somewhere, and a value
that rounding moves across it changes the order; a cluster only splits at a gap wider
than ``rtol * r``. The default ``rtol`` of 1e-6 is far above rounding (1e-15 for a
semisimple eigenvalue, about ``sqrt(eps) = 1.5e-8`` for a defective double one, as at a
critically damped mode) and far below what a study distinguishes.

``spectrum[k]`` is therefore the same mode on every machine, within ``rtol * r``, as
long as no two modes are closer than that (then they are interchangeable anyway).

**A continuum of equilibria.** Where the equilibria are not isolated (a redundant arm's
goal is a curve of joint configurations: its self-motion), the linear model has an
eigenvalue 0 per direction along them, which rounding puts a hair either side of 0.
Its sign is noise, not a verdict: :func:`continuum_modes` names those modes by their
eigenvectors (in the continuum's directions, which the caller knows from the geometry),
and :class:`EigenvalueFacts` leaves them out of the verdict, the damping ratios and the
time constants.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "SPECTRUM_RTOL",
    "EigenvalueFacts",
    "assert_spectra_close",
    "canonical_eigenvalues",
    "canonical_order",
    "canonical_spectrum",
    "continuum_modes",
    "damping_ratios",
    "match_spectra",
    "spectra_close",
    "time_constants",
]

#: Values closer than this times the spectral radius count as one in the canonical order.
SPECTRUM_RTOL = 1e-6


def _clusters(keys: np.ndarray, tol: float) -> np.ndarray:
    """A cluster number per entry of ``keys`` (1-D, real): sorted, a new cluster at each
    gap wider than ``tol``; numbered in ascending order of the keys."""
    order = np.argsort(keys, kind="stable")
    gaps = np.diff(keys[order]) > tol
    labels = np.empty(len(keys), dtype=int)
    labels[order] = np.concatenate([[0], np.cumsum(gaps)])
    return labels


def canonical_order(values: np.ndarray, rtol: float = SPECTRUM_RTOL) -> np.ndarray:
    """The permutation that puts the 1-D complex array ``values`` in the canonical order
    (module docstring): ``values[canonical_order(values)]``."""
    lam = np.asarray(values, dtype=complex).ravel()
    if lam.size == 0:
        return np.zeros(0, dtype=int)
    radius = float(np.max(np.abs(lam)))
    tol = rtol * radius if radius > 0 else 0.0
    real = _clusters(lam.real, tol)
    # |Im| is clustered within each real-part cluster: a pair's members differ there by
    # rounding only.
    modulus = np.empty(len(lam), dtype=int)
    for c in np.unique(real):
        members = real == c
        modulus[members] = _clusters(np.abs(lam.imag[members]), tol)
    # Within a group of equal real part and |Im|, the rank: the real values (Im = 0) first,
    # by value; then the pairs interleaved (-, +, -, +), the k-th negative member beside
    # the k-th positive one (each side in its own raw order, so exact conjugates stand
    # together, and a pair whose |Im| is below the tolerance still reads (-, +)).
    rank = np.empty(len(lam), dtype=int)
    for key in set(zip(real.tolist(), modulus.tolist(), strict=True)):
        group = np.flatnonzero((real == key[0]) & (modulus == key[1]))
        imag = lam.imag[group]
        start = int(np.count_nonzero(imag == 0))
        for side, offset, step in (
            (imag == 0, 0, 1),
            (imag < 0, start, 2),
            (imag > 0, start + 1, 2),
        ):
            members = group[side]
            raw = np.lexsort((np.abs(lam.imag[members]), lam.real[members]))
            rank[members[raw]] = offset + step * np.arange(len(members))
    # np.lexsort sorts by the last key first.
    return np.lexsort((rank, modulus, real))


def canonical_spectrum(values: np.ndarray, rtol: float = SPECTRUM_RTOL) -> np.ndarray:
    """``values`` (a 1-D spectrum, or a 2-D stack of them, one per row) in the canonical
    order, as complex arrays."""
    lam = np.asarray(values, dtype=complex)
    if lam.ndim == 2:
        return np.array([row[canonical_order(row, rtol)] for row in lam]).reshape(lam.shape)
    return lam.ravel()[canonical_order(lam, rtol)]


def canonical_eigenvalues(A: np.ndarray, rtol: float = SPECTRUM_RTOL) -> np.ndarray:
    """The eigenvalues of the square matrix ``A`` in the canonical order."""
    return canonical_spectrum(np.linalg.eigvals(np.asarray(A, dtype=float)), rtol)


def _perfect_matching(allowed: np.ndarray) -> np.ndarray | None:
    """A perfect matching of the bipartite graph ``allowed[i, j]`` (n x n booleans) as
    ``match[i] = j``, or None (Kuhn's augmenting paths: n is a spectrum's size)."""
    n = len(allowed)
    owner = np.full(n, -1)  # owner[j] = the row matched to column j

    def augment(i: int, seen: np.ndarray) -> bool:
        for j in np.flatnonzero(allowed[i] & ~seen):
            seen[j] = True
            if owner[j] < 0 or augment(int(owner[j]), seen):
                owner[j] = i
                return True
        return False

    for i in range(n):
        if not augment(i, np.zeros(n, dtype=bool)):
            return None
    match = np.empty(n, dtype=int)
    match[owner] = np.arange(n)
    return match


def match_spectra(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """Pair each value of ``a`` with one of ``b`` so that the largest distance is the
    least possible (the bottleneck assignment), whatever either's order.

    Returns ``(index, distance)``: ``b[index]`` lines up with ``a``, and ``distance`` is
    ``max |a - b[index]|``. Raises ValueError where the sizes differ."""
    a = np.asarray(a, dtype=complex).ravel()
    b = np.asarray(b, dtype=complex).ravel()
    if a.shape != b.shape:
        raise ValueError(f"spectra of different sizes cannot match: {a.size} and {b.size}")
    if a.size == 0:
        return np.zeros(0, dtype=int), 0.0
    cost = np.abs(a[:, None] - b[None, :])
    levels = np.unique(cost)
    # The smallest level at which a perfect matching exists: bisection over the
    # distinct distances (a matching exists at the largest, where every pair is allowed).
    lo, hi = 0, len(levels) - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if _perfect_matching(cost <= levels[mid]) is None:
            lo = mid + 1
        else:
            hi = mid
    index = _perfect_matching(cost <= levels[lo])
    return index, float(levels[lo])


def spectra_close(a: np.ndarray, b: np.ndarray, rtol: float = 1e-9, atol: float = 0.0) -> bool:
    """Whether ``a`` and ``b`` are the same multiset of values, each within
    ``atol + rtol * r`` of its partner (r the larger spectral radius)."""
    a = np.asarray(a, dtype=complex).ravel()
    b = np.asarray(b, dtype=complex).ravel()
    if a.shape != b.shape:
        return False
    if a.size == 0:
        return True
    radius = max(float(np.max(np.abs(a))), float(np.max(np.abs(b))))
    return match_spectra(a, b)[1] <= atol + rtol * radius


def assert_spectra_close(
    actual: np.ndarray, desired: np.ndarray, rtol: float = 1e-9, atol: float = 0.0
) -> None:
    """Raise AssertionError unless :func:`spectra_close` (for tests and notebooks): the
    message gives both spectra in the canonical order and the worst pair's distance."""
    if spectra_close(actual, desired, rtol, atol):
        return
    actual = np.asarray(actual, dtype=complex).ravel()
    desired = np.asarray(desired, dtype=complex).ravel()
    if actual.shape != desired.shape:
        raise AssertionError(f"spectra of different sizes: {actual.size} and {desired.size}")
    _, distance = match_spectra(actual, desired)
    radius = max(float(np.max(np.abs(actual))), float(np.max(np.abs(desired))))
    raise AssertionError(
        f"spectra differ: the best matching leaves a pair {distance:.3g} apart, tolerance "
        f"{atol + rtol * radius:.3g} (atol {atol:g} + rtol {rtol:g} * radius {radius:.4g})\n"
        f" actual: {canonical_spectrum(actual)}\ndesired: {canonical_spectrum(desired)}"
    )


def damping_ratios(eigenvalues: np.ndarray) -> np.ndarray:
    """``-Re(lambda) / |lambda|`` per eigenvalue (1 for a real stable mode; NaN at 0)."""
    lam = np.asarray(eigenvalues)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(np.abs(lam) > 0, -lam.real / np.abs(lam), np.nan)


def time_constants(eigenvalues: np.ndarray) -> np.ndarray:
    """``-1 / Re(lambda)`` [s] per eigenvalue (inf where Re(lambda) = 0, negative where
    the mode grows)."""
    with np.errstate(divide="ignore"):
        return -1.0 / np.asarray(eigenvalues).real


def continuum_modes(
    A: np.ndarray, directions: np.ndarray, rtol: float = SPECTRUM_RTOL
) -> tuple[np.ndarray, tuple[int, ...]]:
    """The eigenvalues of ``A`` in the canonical order, and the indices among them of the
    modes on a known continuum of equilibria: those within ``rtol`` times the spectral
    radius of 0 whose eigenvector lies, to ``rtol``, in the span of ``directions`` (n x m,
    orthonormal columns: the states along which the equilibrium continues, which the
    caller knows from the geometry).

    None where ``A`` does not vanish on ``directions`` (to ``rtol |A|``: they are then no
    equilibria), nor where more than m modes qualify: the 0 is then defective, a drift
    along the continuum rather than a rest on it, and its modes count."""
    A = np.asarray(A, dtype=float)
    directions = np.asarray(directions, dtype=float).reshape(len(A), -1)
    values, vectors = np.linalg.eig(A)
    order = canonical_order(values, rtol)
    values, vectors = values[order], vectors[:, order]
    m = directions.shape[1]
    scale = float(np.linalg.norm(A, 2))
    if m == 0 or np.linalg.norm(A @ directions, 2) > rtol * scale:
        return values, ()
    tol = rtol * float(np.max(np.abs(values)))
    unit = vectors / np.linalg.norm(vectors, axis=0)
    outside = np.linalg.norm(unit - directions @ (directions.T @ unit), axis=0)
    found = tuple(int(k) for k in np.flatnonzero((np.abs(values) <= tol) & (outside <= rtol)))
    return values, (found if len(found) <= m else ())


class EigenvalueFacts:
    """What a linear model's ``eigenvalues`` say, for the result classes that hold them
    (the linearisations at the goal, along a run, of the arm): written once here.

    ``continuum``: the indices of the modes on a known continuum of equilibria
    (:func:`continuum_modes`), and ``continuum_name`` what it is, in words; none by
    default. Those modes are named, and left out of :attr:`max_real_part` (so of
    ``stable``), the damping ratios and the time constants (NaN there): their eigenvalue
    is 0 to rounding, and its sign says nothing about the loop."""

    eigenvalues: np.ndarray
    continuum: tuple[int, ...] = ()
    continuum_name: str | None = None

    @property
    def _on_continuum(self) -> np.ndarray:
        """Per eigenvalue: it is one of :attr:`continuum`'s modes."""
        mask = np.zeros(len(np.asarray(self.eigenvalues)), dtype=bool)
        mask[list(self.continuum)] = True
        return mask

    @property
    def max_real_part(self) -> float:
        """The largest real part of the eigenvalues off the continuum: < 0 for a stable
        model (-inf where every mode is on it)."""
        lam = np.asarray(self.eigenvalues)[~self._on_continuum]
        return float(np.max(lam.real, initial=-np.inf))

    @property
    def damping_ratios(self) -> np.ndarray:
        """:func:`damping_ratios` of the eigenvalues (NaN on the continuum)."""
        return np.where(self._on_continuum, np.nan, damping_ratios(self.eigenvalues))

    @property
    def time_constants(self) -> np.ndarray:
        """:func:`time_constants` of the eigenvalues [s] (NaN on the continuum)."""
        return np.where(self._on_continuum, np.nan, time_constants(self.eigenvalues))

    def eigenvalue_summary(self) -> dict:
        """``eigenvalues``, ``max_real_part``, ``damping_ratios``, ``time_constants`` and
        ``stable`` (every real part off the continuum < 0), as a result's summary reports
        them, with ``continuum_modes`` (the continuum's indices into ``eigenvalues``,
        empty where none) and ``continuum`` (what it is, or None)."""
        return {
            "eigenvalues": self.eigenvalues,
            "max_real_part": self.max_real_part,
            "damping_ratios": self.damping_ratios,
            "time_constants": self.time_constants,
            "stable": self.max_real_part < 0,
            "continuum_modes": list(self.continuum),
            "continuum": self.continuum_name,
        }
