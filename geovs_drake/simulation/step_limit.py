"""The integrator's step limit from the loop's fastest mode at the goal.

A run that has converged sits at the goal, where the loop is its linearisation. An
explicit Runge-Kutta step h is stable there only while every ``h lambda`` (lambda an
eigenvalue of the goal's A) lies in the method's region of absolute stability,
``abs(R(h lambda)) <= 1`` with R the method's stability polynomial. Beyond it the error
control keeps rejecting and shrinking steps around the bound, and the pose error stalls
or grows (measured: the kinematic loop from a small move ended 2.9e-7 m from the goal
after 40 s with RK3's 0.05 s limit, where its fastest mode is -70.9 1/s; ``h abs(lambda)`` =
3.5 against RK3's real-axis bound 2.51).

:func:`step_limit` finds the largest h whose ``h lambda`` stay in the region, for every
eigenvalue of the closed form (:func:`closed_form_A`), and takes
:data:`STABILITY_MARGIN` of it. The simulator runs with the smaller of that and
``simulator.max_step_size``. Explicit methods whose stability polynomial is the
truncated exponential only (``runge_kutta2``, ``runge_kutta3``: as many stages as their
order); the NF's law on the free rig in the hand only (the closed form is the free
body's). Elsewhere the configured limit stands.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import InitializeAutoDiff
from pydrake.math import RigidTransform

from geovs_drake.geometry.camera import ImageFeatures, image_jacobian
from geovs_drake.geometry.navigation import (
    NavigationFunction,
    chart_basis,
    navigation_differential,
)
from geovs_drake.geometry.so3 import hat, so3_exp
from geovs_drake.scenario import Nf, ResolvedScenario, ScenarioConfig

__all__ = [
    "STABILITY_MARGIN",
    "STABILITY_POLYNOMIALS",
    "StepLimit",
    "chart_jacobian",
    "closed_form_A",
    "navigation_hessian",
    "rig_spatial_inertia",
    "step_limit",
    "velocity_adjoint",
]

#: The fraction of the stability bound the step may use: the error control wants room
#: below the bound, not a step that sits on it.
STABILITY_MARGIN = 0.8
#: Each explicit scheme's stability polynomial's coefficients (R(z) = sum c_k z^k): the
#: truncated exponential, since each has as many stages as its order.
STABILITY_POLYNOMIALS: dict[str, tuple[float, ...]] = {
    "runge_kutta2": (1.0, 1.0, 1 / 2),
    "runge_kutta3": (1.0, 1.0, 1 / 2, 1 / 6),
}


@dataclass(frozen=True)
class StepLimit:
    """The goal's fastest mode and the step limit it sets.

    ``fastest_mode``: the eigenvalue of largest modulus [1/s]; ``stable_step``: the
    largest h with every ``h lambda`` in the method's region [s]; ``max_step_size``: what
    the simulator runs with, ``min(configured, STABILITY_MARGIN * stable_step)``;
    ``configured``: ``simulator.max_step_size``.
    """

    fastest_mode: complex
    stable_step: float
    max_step_size: float
    configured: float

    @property
    def configured_is_unstable(self) -> bool:
        """The configured limit alone would let the step leave the stability region."""
        return self.configured > self.stable_step

    def warning(self, scheme: str) -> str:
        """The one line a user gets when the configured limit is beyond the bound."""
        lam = self.fastest_mode
        return (
            f"simulator.max_step_size {self.configured:g} s puts the goal's fastest mode "
            f"({lam.real:.4g}{lam.imag:+.4g}j 1/s) outside {scheme}'s stability region "
            f"(h |lambda| = {self.configured * abs(lam):.3g}); the step is limited to "
            f"{self.max_step_size:.3g} s"
        )


def navigation_hessian(nf: NavigationFunction, y: ImageFeatures) -> np.ndarray:
    """The chart Hessian of phi at y by AutoDiffXd of dphi (exact to rounding)."""
    B = chart_basis(y.s)
    d = InitializeAutoDiff(np.zeros(6)).ravel()
    s = y.s + B @ d[4:6]
    s = s / np.sqrt(np.sum(s * s))
    ya = ImageFeatures(so3_exp(d[0:3]) @ y.Q, np.asarray(y.lam + d[3]), s)
    _, dphi = navigation_differential(ya, nf.goal, nf.domain, nf.gains)
    F = np.concatenate([dphi[0:4], B.T @ dphi[4:7]])
    H = np.stack([f.derivatives() for f in F])
    return 0.5 * (H + H.T)


def chart_jacobian(y: ImageFeatures, radius: float) -> np.ndarray:
    """C(y) in the NF's chart, ``diag(I_4, B^T) C(y)`` (6 x 6, invertible)."""
    C = image_jacobian(y, radius)
    B = chart_basis(y.s)
    return np.vstack([C[0:4], B.T @ C[4:7]])


def velocity_adjoint(X: RigidTransform) -> np.ndarray:
    """Ad_X on (omega, v): velocities in the child frame to the parent frame."""
    R, p = X.rotation().matrix(), X.translation()
    out = np.zeros((6, 6))
    out[:3, :3] = R
    out[3:, :3] = hat(p) @ R
    out[3:, 3:] = R
    return out


def rig_spatial_inertia(config: ScenarioConfig) -> np.ndarray:
    """M, the rig's spatial inertia about the camera origin in C (Appendix C.0.6:
    ``Ad^T M_R Ad``), on (Omega, V)."""
    Ad = velocity_adjoint(config.X_RC)
    M_R = np.zeros((6, 6))
    M_R[:3, :3] = np.diag(config.rig.inertia_diagonal)
    M_R[3:, 3:] = config.rig.mass * np.eye(3)
    return Ad.T @ M_R @ Ad


def closed_form_A(
    config: ScenarioConfig, plant: str | None = None, damping: tuple[float, ...] | None = None
) -> np.ndarray:
    """The closed-form linearisation at the goal, in minimal coordinates (the camera's
    right-trivialised displacement eps, then its twist, for the dynamic loop):

    * dynamic (Eq. 45 on Eq. 46): ``A = [[0, I], [-M^-1 K, -M^-1 B]]``,
      ``K = k_p C_chart^T H C_chart``, M the rig's spatial inertia about the camera;
    * kinematic (Eqs. 17-19): ``A = -k C_chart^-1 H C_chart``.

    ``damping``: the B the loop runs with (:attr:`ResolvedScenario.damping`), by default
    ``control.damping``. :mod:`geovs_drake.analysis.linearization` checks it against
    Drake's ``Linearize``.
    """
    plant = plant or config.plant
    y = config.goal_features()
    nf = NavigationFunction(config.domain.to_domain(), y, config.navigation.to_gains())
    H = navigation_hessian(nf, y)
    Cc = chart_jacobian(y, config.radius)
    if plant == "kinematic":
        return -config.control.kinematic_gain * np.linalg.solve(Cc, H @ Cc)
    K = config.control.potential_gain * Cc.T @ H @ Cc
    M = rig_spatial_inertia(config)
    Bd = np.diag(config.control.damping if damping is None else damping)
    A = np.zeros((12, 12))
    A[:6, 6:] = np.eye(6)
    A[6:, :6] = -np.linalg.solve(M, K)
    A[6:, 6:] = -np.linalg.solve(M, Bd)
    return A


def _stable(coefficients: tuple[float, ...], z: np.ndarray) -> bool:
    R = np.polyval(coefficients[::-1], z)
    return bool(np.all(np.abs(R) <= 1.0 + 1e-12))


def step_limit(resolved: ResolvedScenario) -> StepLimit | None:
    """The goal's :class:`StepLimit`, or None where it does not apply (a scheme without a
    stability polynomial here, a law other than the NF, a carrier other than the free
    rig in the hand: :func:`closed_form_A` is theirs only)."""
    config = resolved.config
    scheme = config.simulator.integration_scheme
    coefficients = STABILITY_POLYNOMIALS.get(scheme)
    if coefficients is None or not isinstance(resolved.law, Nf):
        return None
    if config.carrier != "free" or config.mount != "hand":
        return None
    eigenvalues = np.linalg.eigvals(closed_form_A(config, damping=resolved.damping))
    eigenvalues = eigenvalues[np.abs(eigenvalues) > 0]
    configured = float(config.simulator.max_step_size)
    if len(eigenvalues) == 0:
        return None
    fastest = complex(eigenvalues[np.argmax(np.abs(eigenvalues))])
    # Bisection on h: the region is star-shaped from 0 along each ray for these
    # polynomials, so stability is monotone in h along the eigenvalues' rays.
    lo, hi = 0.0, 10.0 / abs(fastest)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _stable(coefficients, mid * eigenvalues) else (lo, mid)
    limit = min(configured, STABILITY_MARGIN * lo)
    return StepLimit(
        fastest_mode=fastest, stable_step=lo, max_step_size=limit, configured=configured
    )
