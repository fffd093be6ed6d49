"""The SOS-certified region of attraction (analysis.certified_region) and the Taylor
jets under it (geometry.taylor).

Truths: central differences of the batch engine's own flow (the loop in minimal
coordinates), Drake's ``Linearize`` (the Taylor polynomial's linear part), the
remainder's order (the polynomial's error must shrink 2^(d+1)-fold when the offset
halves), direct evaluation of the polynomial's Vdot on the certified set (the SDP's
claim), and the batch engine's nonlinear loop from starts inside.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from geovs_drake.analysis.linear.certified_region import certify_region, minimal_field, taylor_field
from geovs_drake.analysis.linear.linearization import linearize
from geovs_drake.analysis.linear.region import _minimal, check_inside, lyapunov_region, states_of
from geovs_drake.batch.engine import _rhs, loop_parameters
from geovs_drake.geometry.taylor import Jet, monomials, variables
from geovs_drake.scenario import Dynamic, Kinematic, ScenarioConfig, variant_name

PLANTS = [Kinematic(), Dynamic()]


def test_jets_are_the_taylor_polynomial_of_a_formula():
    # f(x, y) = sin(x) sqrt(1 + y) / (2 + cos(x y)) - 3 y^2: its degree-3 polynomial at
    # (0.3, 0.2) must miss f by O(h^4) along any direction.
    def f(x, y):
        return np.sin(x) * np.sqrt(1 + y) / (2 + np.cos(x * y)) - 3 * y**2

    x0 = np.array([0.3, 0.2])
    jet = f(*variables(x0, 3))
    assert isinstance(jet, Jet) and jet.value == pytest.approx(f(*x0), abs=1e-15)
    basis = np.array(monomials(2, 3))
    u = np.array([0.6, -0.8])
    errors = []
    for h in (1e-2, 5e-3, 2.5e-3):
        dx = h * u
        poly = jet.coefficients @ np.prod(dx[None] ** basis, axis=1)
        errors.append(abs(f(*(x0 + dx)) - poly))
    ratios = [errors[i] / errors[i + 1] for i in range(2)]
    assert all(14.0 < r < 18.0 for r in ratios), ratios


def test_a_jet_rejects_a_power_it_cannot_take():
    (x,) = variables(np.array([1.0]), 2)
    with pytest.raises(ValueError, match="integer powers"):
        x**0.5


def _flow(config, x):
    """Central difference of the batch engine's flow, mapped to minimal coordinates."""
    p = loop_parameters(config)
    _, s = states_of(config, x[None])
    s = s[0]
    f = np.zeros(len(s))
    _rhs(not config.dynamic, s.copy(), f, p.camera, p.navigation, p.controller, p.body)
    h = 1e-6
    return (_minimal(config, (s + h * f)[None]) - _minimal(config, (s - h * f)[None]))[0] / (2 * h)


@pytest.mark.parametrize("plant", PLANTS, ids=variant_name)
def test_the_minimal_field_is_the_engines_flow(plant):
    config = ScenarioConfig(plant=plant)
    rng = np.random.default_rng(4)
    for _ in range(3):
        x = 0.03 * rng.normal(size=12 if isinstance(plant, Dynamic) else 6)
        exact = minimal_field(config, x)
        assert np.allclose(exact.astype(float), _flow(config, x), rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("plant", PLANTS, ids=variant_name)
def test_the_taylor_field_is_exact_to_its_order(plant):
    config = ScenarioConfig(plant=plant)
    model = taylor_field(config, 3)
    n = len(model.T)
    A = linearize(config).A  # Drake's Linearize of the diagram
    assert np.allclose(model.coefficients[:, 1 : n + 1], A, rtol=1e-9, atol=1e-9 * np.abs(A).max())
    u = np.random.default_rng(5).normal(size=n)
    errors = [
        np.abs(minimal_field(config, h * u).astype(float) - model(h * u)[0]).max()
        for h in (8e-3, 4e-3, 2e-3)
    ]
    ratios = [errors[i] / errors[i + 1] for i in range(2)]
    assert all(14.0 < r < 18.0 for r in ratios), (errors, ratios)


def _polynomial_vdot(region, model, n_points, seed=2):
    """Vdot of the Taylor polynomial at points filling the certified ellipsoid."""
    rng = np.random.default_rng(seed)
    n = len(model.T)
    u = rng.normal(size=(n_points, n))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    radius = math.sqrt(region.rho / region.sampled.failing_level)  # |w| on the boundary
    w = u * radius * rng.uniform(0.05, 1.0, size=(n_points, 1)) ** (1.0 / n)
    return 2.0 * np.sum(w * model(w), axis=1)  # V = scale |w|^2, up to the positive scale


# make test's budget: notebook 02 certifies the same small case (degree 2, 40 rays) in
# make test's docs build and asserts its level and its starts; the polynomial check
# here runs with the slow studies.
@pytest.mark.slow
def test_kinematic_certificate_small():
    config = ScenarioConfig(plant=Kinematic())
    sampled = lyapunov_region(config, rays=40)
    region = certify_region(config, degree=2, sampled=sampled)
    # The SDP's claim, checked by evaluating the polynomial it certified.
    model = taylor_field(config, 2, region.T)
    assert np.all(_polynomial_vdot(region, model, 2000) < 0)
    # The certificate is for the polynomial; on the loop it must still sit in D with
    # Vdot < 0, and inside the level where sampling saw Vdot >= 0.
    assert region.nonlinear_check and region.boundary_max_vdot < 0
    assert 0 < region.rho < sampled.failing_level
    batch = check_inside(config, region.as_region(), 100)
    assert batch.counts()["converged"] == 100


def test_certify_region_rejects_bad_options():
    config = ScenarioConfig(plant=Kinematic())
    with pytest.raises(ValueError, match="SOS solver must be one of clarabel, csdp, scs"):
        certify_region(config, solver="mosek")
    with pytest.raises(ValueError, match="Taylor degree must be >= 2"):
        certify_region(config, degree=1)


@pytest.mark.slow
@pytest.mark.parametrize("plant", PLANTS, ids=variant_name)
def test_every_start_inside_the_certified_region_converges(plant):
    config = ScenarioConfig(plant=plant)
    region = certify_region(config)
    model = taylor_field(config, region.degree, region.T)
    assert np.all(_polynomial_vdot(region, model, 20000) < 0)
    assert region.nonlinear_check
    batch = check_inside(config, region.as_region(), 10_000)
    assert batch.counts()["converged"] == 10_000
