"""The canonical order of a spectrum and the multiset comparison (geovs_drake.spectrum).

The order must not change when the values are permuted and perturbed at rounding's
scale (what another BLAS kernel does to them), and the comparison must agree with a
brute force over every pairing."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from geovs_drake.spectrum import (
    assert_spectra_close,
    canonical_eigenvalues,
    canonical_order,
    canonical_spectrum,
    match_spectra,
    spectra_close,
)

#: Rounding's scale, relative to the spectral radius (what a kernel change moves).
NOISE = 1e-13


@st.composite
def spectra(draw) -> np.ndarray:
    """A real matrix's spectrum: real values and conjugate pairs, each possibly repeated
    (the case that broke np.sort_complex), with zeros and shared real parts."""
    values = []
    for _ in range(draw(st.integers(1, 6))):
        re = draw(st.sampled_from([0.0, -1.0, -2.4266186933596, -7.5]) | st.floats(-50, 5))
        im = draw(st.sampled_from([0.0, 0.7575066996181, 36.1]) | st.floats(0, 40))
        block = [complex(re, im), complex(re, -im)] if im > 0 else [complex(re, 0.0)]
        values += block * draw(st.integers(1, 3))
    values = np.array(values)
    # The order's promise holds for modes either equal or apart by more than its
    # tolerance (1e-6 of the spectral radius): keep the drawn ones so, with room.
    gap = 1e-5 * max(1e-300, float(np.max(np.abs(values))))
    for part in (values.real, np.abs(values.imag)):
        distinct = np.unique(np.append(part, 0.0))
        assume(np.all(np.diff(distinct) > gap))
    return values


def _jiggle(values: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``values`` permuted and moved at the 1e-13 level (relative to the spectral radius),
    each value on its own (stricter than LAPACK, which keeps a pair exactly conjugate);
    real values stay real."""
    scale = NOISE * float(np.max(np.abs(values)))
    out = values.astype(complex)
    for k in range(len(out)):
        out[k] += scale * complex(rng.uniform(-1, 1), rng.uniform(-1, 1) if out[k].imag else 0)
    return out[rng.permutation(len(out))]


@settings(max_examples=300, deadline=None)
@given(spectra(), st.integers(0, 2**32 - 1))
# make test's budget (4 s): the spectrum's other tests keep the order's small cases.
@pytest.mark.slow
def test_the_canonical_order_is_unchanged_by_permutation_and_rounding(values, seed):
    rng = np.random.default_rng(seed)
    reference = canonical_spectrum(values)
    scale = max(1e-300, float(np.max(np.abs(values))))
    for _ in range(5):
        other = canonical_spectrum(_jiggle(values, rng))
        # Element-wise: the same mode at each index, to within the perturbation.
        np.testing.assert_allclose(other, reference, rtol=0, atol=10 * NOISE * scale)
        # And the signs of the imaginary parts in the same places (wherever |Im| is
        # above the perturbation): no pair reordered.
        clear = np.abs(reference.imag) > 10 * NOISE * scale
        assert np.array_equal(np.sign(other.imag[clear]), np.sign(reference.imag[clear]))


@settings(max_examples=200, deadline=None)
@given(spectra())
def test_the_canonical_order_is_what_the_docstring_says(values):
    """Checked on the output alone: real parts ascending, pairs adjacent with the
    negative-imaginary member first, |Im| ascending among equal real parts."""
    lam = canonical_spectrum(values)
    tol = 1e-6 * max(1e-300, float(np.max(np.abs(lam))))
    assert sorted(lam.tolist(), key=lambda z: (z.real, z.imag)) == sorted(
        values.tolist(), key=lambda z: (z.real, z.imag)
    )  # a permutation of the input
    assert np.all(np.diff(lam.real) > -tol)
    k = 0
    while k < len(lam):
        if abs(lam[k].imag) > tol:  # a pair: its partner follows
            assert lam[k].imag < 0 and lam[k + 1] == pytest.approx(np.conj(lam[k]), abs=tol)
            k += 2
        else:
            k += 1
    same_real = np.abs(np.diff(lam.real)) <= tol
    assert np.all(np.diff(np.abs(lam.imag))[same_real] > -tol)


def test_a_repeated_pair_reads_minus_plus_minus_plus():
    """The loop's goal spectrum has -2.4266 +- 0.7575j twice: np.sort_complex gives
    (-, -, +, +) or (-, +, -, +) by the kernel; the canonical order gives the latter for
    every rounding of the real parts."""
    pair = [complex(-2.4266, 0.7575), complex(-2.4266, -0.7575)]
    for dre in (-1e-15, 0.0, 1e-15):
        values = np.array(pair + [v + dre for v in pair])
        assert np.sign(canonical_spectrum(values).imag).tolist() == [-1, 1, -1, 1]


def test_canonical_eigenvalues_of_similar_matrices_agree_element_wise():
    """The same operator in two random bases: LAPACK rounds differently in each (as another
    kernel does); the canonical spectra agree entry by entry."""
    rng = np.random.default_rng(3)
    blocks = [(-2.4266, 0.7575), (-2.4266, 0.7575), (-7.5, 5.8), (-1.0, 0.0), (0.0, 0.0)]
    n = sum(2 if im else 1 for _, im in blocks)
    J = np.zeros((n, n))
    k = 0
    for re, im in blocks:
        if im:
            J[k : k + 2, k : k + 2] = [[re, im], [-im, re]]
            k += 2
        else:
            J[k, k] = re
            k += 1
    spectra_seen = []
    for _ in range(6):
        S = rng.normal(size=(n, n))
        spectra_seen.append(canonical_eigenvalues(S @ J @ np.linalg.inv(S)))
    for lam in spectra_seen[1:]:
        np.testing.assert_allclose(lam, spectra_seen[0], atol=1e-9)
    assert np.sign(np.round(spectra_seen[0].imag, 6)).tolist() == [-1, 1, -1, 1, -1, 1, 0, 0]


def test_canonical_spectrum_orders_each_row_of_a_stack():
    rows = np.array([[1j, -1j, -3.0], [-1.0, -2.0 + 1j, -2.0 - 1j]])
    out = canonical_spectrum(rows)
    assert out.tolist() == [[-3.0, -1j, 1j], [-2.0 - 1j, -2.0 + 1j, -1.0]]
    assert canonical_order(np.array([])).shape == (0,)


def _brute_force_bottleneck(a: np.ndarray, b: np.ndarray) -> float:
    return min(float(np.max(np.abs(a - b[list(p)]))) for p in itertools.permutations(range(len(b))))


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.complex_numbers(max_magnitude=10), min_size=1, max_size=6),
    st.lists(st.complex_numbers(max_magnitude=10), min_size=6, max_size=6),
)
def test_match_spectra_is_the_best_pairing_of_a_brute_force(a, b):
    a = np.array(a)
    b = np.array(b[: len(a)])
    index, distance = match_spectra(a, b)
    assert sorted(index.tolist()) == list(range(len(a)))
    assert distance == pytest.approx(float(np.max(np.abs(a - b[index]))), abs=0)
    assert distance == pytest.approx(_brute_force_bottleneck(a, b), rel=1e-12, abs=1e-300)


def test_spectra_close_is_a_multiset_comparison():
    a = np.array([-1 + 2j, -1 - 2j, -3.0, -3.0])
    assert spectra_close(a, a[::-1])
    assert spectra_close(a, a + 1e-12, rtol=1e-9)
    assert not spectra_close(a, a + 1e-6, rtol=1e-9)
    # The same values, another multiplicity: not the same spectrum.
    assert not spectra_close(a, np.array([-1 + 2j, -1 - 2j, -1 - 2j, -3.0]), atol=1e-3)
    assert not spectra_close(a, a[:3])
    assert_spectra_close(a[::-1], a)
    with pytest.raises(AssertionError, match=r"best matching leaves a pair 1e-06 apart"):
        assert_spectra_close(a + 1e-6, a, rtol=1e-9)
    with pytest.raises(ValueError, match="different sizes"):
        match_spectra(a, a[:2])
