"""The sampled Lyapunov region of attraction (analysis.region).

Truths: Drake's Lyapunov equation (near the goal the nonlinear Vdot must be
-x^T x), the map to minimal coordinates and back, and the batch engine's nonlinear
loop from starts inside the region.
"""

from __future__ import annotations

import numpy as np
import pytest

from geovs_drake.analysis.linear.region import (
    _minimal,
    _vdot,
    check_inside,
    lyapunov_region,
    sample_inside,
    states_of,
)
from geovs_drake.batch.engine import loop_parameters
from geovs_drake.scenario import Dynamic, Kinematic, ScenarioConfig, variant_name


@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_near_the_goal_vdot_is_the_lyapunov_equations(plant):
    config = ScenarioConfig(plant=plant)
    region = lyapunov_region(config, rays=4)
    assert np.allclose(region.A.T @ region.P + region.P @ region.A, -np.eye(len(region.A)))
    u = sample_inside(region, 6)
    x = 1e-4 * u / np.linalg.norm(u, axis=1, keepdims=True)  # |x| = 1e-4: linear to ~1e-4
    X_BC, s = states_of(config, x)
    assert np.allclose(_minimal(config, s), x, atol=1e-14)
    vdot = _vdot(config, region.P, s, loop_parameters(config))
    assert np.allclose(vdot / -np.sum(x * x, axis=1), 1.0, atol=2e-3)


def test_every_start_inside_the_sampled_region_converges_small():
    config = ScenarioConfig(plant=Kinematic())
    region = lyapunov_region(config, rays=20)
    assert region.rho > 0 and region.failed_by in ("Vdot >= 0", "leaves D")
    batch = check_inside(config, region, 200)
    assert np.all(batch.status_code == 0), np.unique(batch.status_code, return_counts=True)


@pytest.mark.slow
@pytest.mark.parametrize("plant", [Kinematic(), Dynamic()], ids=variant_name)
def test_every_start_inside_the_sampled_region_converges(plant):
    """The issue's check: 10^4 starts inside the region (200 rays), all converge."""
    config = ScenarioConfig(plant=plant)
    region = lyapunov_region(config, rays=200)
    batch = check_inside(config, region, 10_000)
    assert np.all(batch.status_code == 0), np.unique(batch.status_code, return_counts=True)
