"""A mode on a known continuum of equilibria (issue 42, item 3): the redundant Panda's
self-motion is named, and left out of the verdict, the damping ratios and the time
constants of ``geovs-drake linearize``; the 6-joint UR5 has none."""

from __future__ import annotations

import json

import numpy as np
import pytest

from geovs_drake.spectrum import SPECTRUM_RTOL, assert_spectra_close, continuum_modes

PANDA = "carrier: !Arm {model: panda}"


def null_space(M: np.ndarray) -> np.ndarray:
    """An orthonormal basis of M's null space (its right singular vectors beyond its rank,
    the rank counted above 1e-10 of the largest singular value)."""
    _, sigma, Vt = np.linalg.svd(M)
    rank = int(np.sum(sigma > 1e-10 * sigma[0]))
    return Vt[rank:].T


def test_continuum_modes_are_the_semisimple_zeros_along_the_directions():
    e1 = np.array([[1.0], [0.0]])
    # A rest along e1 (its eigenvalue 0 to rounding), a decay along e2.
    values, found = continuum_modes(np.array([[1e-15, 0.3], [0.0, -2.0]]), e1)
    assert [values[k] for k in found] == pytest.approx([1e-15])
    # A drift along e1 (a defective 0: x1' = x2, x2' = 0) is no rest: its modes count.
    assert continuum_modes(np.array([[0.0, 1.0], [0.0, 0.0]]), e1)[1] == ()
    # Directions that A does not map to 0 are no equilibria.
    assert continuum_modes(np.array([[-1.0, 0.0], [0.0, 1e-15]]), e1)[1] == ()


def _camera_jacobian_null_space(config_text: str) -> np.ndarray:
    """J_C's null space at the goal's joints, J_C by Drake's CalcJacobianSpatialVelocity."""
    from geovs_drake.goal.arm import arm_goal_model
    from geovs_drake.scenario import load_scenario

    return null_space(arm_goal_model(load_scenario(data=config_text + "\n")).J)


def test_cli_the_pandas_self_motion_is_named_and_not_counted(run_cli):
    run = run_cli("linearize", "--scenario-text", PANDA, "--json")
    assert run.code == 0, run.err
    out = json.loads(run.out)
    A = np.array(out["A"])
    lam = np.array([complex(re, im) for re, im in out["eigenvalues"]])
    # The geometry: the self-motion at rest, (n, 0) with J_C n = 0, one direction on the
    # 7-joint Panda, is an equilibrium of Drake's model (A maps it to 0).
    N = _camera_jacobian_null_space(PANDA)
    nv = A.shape[0] // 2
    assert N.shape == (nv, nv - 6) == (7, 1)
    S = np.vstack([N, np.zeros_like(N)])
    assert np.linalg.norm(A @ S) <= 1e-9 * np.linalg.norm(A)
    # With Q = [S, S_perp] orthonormal, Q^T A Q is block triangular (A S = 0): the
    # spectrum is {0} and that of S_perp^T A S_perp, which decides stability.
    S_perp = null_space(S.T)
    rest = np.linalg.eigvals(S_perp.T @ A @ S_perp)
    assert np.max(rest.real) < 0 and out["stable"] is True
    (k,) = out["continuum_modes"]
    assert abs(lam[k]) <= SPECTRUM_RTOL * np.max(np.abs(lam))
    assert "self-motion" in out["continuum"]
    assert_spectra_close(np.delete(lam, k), rest, rtol=1e-9)
    assert out["max_real_part"] == pytest.approx(np.max(rest.real), rel=1e-9)
    assert out["damping_ratios"][k] is None and out["time_constants"][k] is None
    others = [v for i, v in enumerate(out["damping_ratios"]) if i != k]
    assert all(0 < zeta <= 1 for zeta in others)
    text = run_cli("linearize", "--scenario-text", PANDA)
    assert text.code == 0, text.err
    head, *rows = text.out.splitlines()
    assert head.startswith("dynamic loop linearised at the goal: stable")
    assert out["continuum"] in head
    assert sum("a continuum of equilibria" in row for row in rows) == 1


def test_cli_the_ur5_has_no_continuum(run_cli):
    """Six joints with J_C of full rank: the goal is isolated, every mode counts."""
    run = run_cli("linearize", "--carrier", "arm", "--json")
    assert run.code == 0, run.err
    out = json.loads(run.out)
    lam = np.array([complex(re, im) for re, im in out["eigenvalues"]])
    assert _camera_jacobian_null_space("carrier: !Arm {}").shape[1] == 0
    assert out["continuum_modes"] == [] and out["continuum"] is None
    assert np.min(np.abs(lam)) > 1e-3 * np.max(np.abs(lam))  # no mode near 0
    assert out["max_real_part"] == pytest.approx(np.max(lam.real), rel=1e-12)
    assert out["stable"] is True
