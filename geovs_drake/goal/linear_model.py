"""The loop's closed-form linear model at the goal (the free rig, eye in hand, the NF).

At the goal the NF's loop is its linearisation, and the package writes it once, in
closed form, in minimal coordinates (the camera's right-trivialised displacement eps,
then its twist on the dynamic loop):

* dynamic (Eq. 45 on Eq. 46): ``M eps'' + B eps' + K eps = 0`` with ``K = k_p C_chart^T
  H C_chart``, M the rig's spatial inertia about the camera (Appendix C.0.6) and H the
  chart Hessian of phi at y*;
* kinematic (Eqs. 17-19): ``eps' = -k C_chart^-1 H C_chart eps``.

Its readers: the integrator's step limit (:mod:`geovs_drake.goal.step_limit`), the
linearisation studies, which check it against Drake's ``Linearize``
(:mod:`geovs_drake.analysis.linear.linearization`), gain design and the arm at the goal. It sits
below the simulation layer, as pure linear algebra over the scenario and the geometry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import InitializeAutoDiff
from pydrake.math import RigidTransform
from pydrake.systems.analysis import DiscreteTimeApproximation
from pydrake.systems.primitives import LinearSystem

from geovs_drake._json import json_ready
from geovs_drake.geometry.camera import ImageFeatures, image_jacobian
from geovs_drake.geometry.navigation import (
    NavigationFunction,
    chart_basis,
    image_chart,
    navigation_differential,
)
from geovs_drake.geometry.so3 import hat
from geovs_drake.geometry.target_motion import frame_wrench
from geovs_drake.goal.inputs import GoalInputs
from geovs_drake.scenario import PlantConfig, ScenarioConfig

__all__ = [
    "MAX_RATE_HZ",
    "LATENCY_SEARCH_FRAMES",
    "MIN_RATE_HZ",
    "SampledModel",
    "SearchedBound",
    "check_camera",
    "log_bisection",
    "chart_jacobian",
    "closed_form_A",
    "closed_form_refusal",
    "goal_stiffness",
    "navigation_hessian",
    "rig_spatial_inertia",
    "second_order_A",
    "LAG_RANGE",
    "tracking_lag",
    "tracking_lag_range",
    "tracking_transfer",
    "velocity_adjoint",
]


def closed_form_refusal(config: ScenarioConfig, who: str) -> str | None:
    """Why the closed form does not model ``config``'s loop, as ``who``'s one line, or
    None where it does: it is the free rig's with the camera in its hand (Appendix C's
    body; the fixed camera and the arm have other dynamics). The one place that decides
    it, for the step limit, the linearisation and gain design; the law (the NF's) is
    each caller's own question."""
    if config.carrier.traits.rigid_body_goal:
        return None
    return (
        f"{who}: the closed form is the eye-in-hand free rig's (carrier FreeRig), got "
        f"carrier {type(config.carrier).__name__}"
    )


def navigation_hessian(nf: NavigationFunction, y: ImageFeatures) -> np.ndarray:
    """The chart Hessian of phi at y by AutoDiffXd of dphi (exact to rounding)."""
    B = chart_basis(y.s)
    ya = image_chart(y, InitializeAutoDiff(np.zeros(6)).ravel())
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
    rig = config.carrier  # a FreeRig (closed_form_refusal)
    M_R[:3, :3] = np.diag(rig.inertia_diagonal)
    M_R[3:, 3:] = rig.mass * np.eye(3)
    return Ad.T @ M_R @ Ad


def goal_stiffness(resolved: GoalInputs) -> tuple[np.ndarray, np.ndarray]:
    """The NF's stiffness at the goal per unit gain, in minimal coordinates:
    ``K_1 = C_chart^T H C_chart`` (the dynamic loop's, times k_p) and
    ``C_chart^-1 H C_chart`` (the kinematic loop's, times k), H the chart Hessian of phi
    at y* (the resolver's, :func:`navigation_hessian`) and C_chart at the true radius."""
    H, Cc = resolved.hessian, chart_jacobian(resolved.y_goal, resolved.config.radius)
    return Cc.T @ H @ Cc, np.linalg.solve(Cc, H @ Cc)


def second_order_A(M: np.ndarray, K: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``[[0, I], [-M^-1 K, -M^-1 B]]``: ``M eps'' + B eps' + K eps = 0`` in first order."""
    n = len(M)
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = -np.linalg.solve(M, K)
    A[n:, n:] = -np.linalg.solve(M, B)
    return A


def closed_form_A(resolved: GoalInputs, plant: PlantConfig | None = None) -> np.ndarray:
    """The closed-form linearisation at the goal, in minimal coordinates (the camera's
    right-trivialised displacement eps, then its twist, for the dynamic loop):

    * dynamic (Eq. 45 on Eq. 46): ``A = [[0, I], [-M^-1 K, -M^-1 B]]``,
      ``K = k_p C_chart^T H C_chart``, M the rig's spatial inertia about the camera;
    * kinematic (Eqs. 17-19): ``A = -k C_chart^-1 H C_chart``.

    B is the damping the loop runs with, ``resolved.damping`` (one answer, the
    resolver's); ``plant`` (default: the scenario's) picks the loop.
    :mod:`geovs_drake.analysis.linear.linearization` checks it against Drake's ``Linearize``.
    """
    config = resolved.config
    plant = config.plant if plant is None else plant
    K1, KC = goal_stiffness(resolved)
    if not plant.traits.dynamic:
        return -config.control.kinematic_gain * KC
    Bd = np.diag(resolved.damping)
    return second_order_A(rig_spatial_inertia(config), config.control.potential_gain * K1, Bd)


#: How far the linear lag (:func:`tracking_lag`) holds, measured: the free rig under the
#: NF, the default start, no feed-forward, 40 s, the steady tracking error within
#: ``within`` (5 %) of the prediction while the goal camera's speed as it rides with the
#: target stays at or below ``speed_m_s`` and its turn across the line of sight (Omega's x and
#: y in C*) at or below ``turn_rad_s`` (by the plant's name). Three directions (a screw
#: about the line of sight, a slide across it, a turn across it with a slide along it) at
#: four speeds each, on both plants: 24 runs, every one inside the range within 5 % and
#: every one outside it beyond (docs/moving-target.md, "How far the lag holds").
LAG_RANGE: dict[str, float | dict[str, float]] = {
    "within": 0.05,
    "speed_m_s": 0.2,
    "turn_rad_s": {"kinematic": 0.2, "dynamic": 0.1},
}


def tracking_lag_range(config: ScenarioConfig, twist_B: np.ndarray) -> dict:
    """Whether ``twist_B`` lies where :func:`tracking_lag` holds (:data:`LAG_RANGE`):
    the goal camera's speed [m/s] and its turn across the line of sight [rad/s] under
    that twist (``nu_B = Ad_{X_C*B} xi_B``), their measured bounds, and ``holds``."""
    nu_B = velocity_adjoint(config.X_BC_goal.inverse()) @ np.asarray(twist_B, dtype=float)
    speed, turn = float(np.linalg.norm(nu_B[3:])), float(np.linalg.norm(nu_B[:2]))
    plant = "dynamic" if config.dynamic else "kinematic"
    speed_bound, turn_bound = LAG_RANGE["speed_m_s"], LAG_RANGE["turn_rad_s"][plant]
    return {
        "within": LAG_RANGE["within"],
        "speed_m_s": speed,
        "speed_up_to_m_s": speed_bound,
        "turn_across_view_rad_s": turn,
        "turn_up_to_rad_s": turn_bound,
        # (a bound measured at its own value holds there: rounding may not flip it)
        "holds": speed <= speed_bound * (1 + 1e-9) and turn <= turn_bound * (1 + 1e-9),
    }


def tracking_lag(resolved: GoalInputs, twist_B: np.ndarray) -> np.ndarray:
    """eps_ss (6): where the linearised loop settles, without feed-forward, behind a
    target moving with the constant body twist ``twist_B`` = (omega, v) in B.

    The loop runs in the target's frame (:mod:`geovs_drake.loop.targets`); at the goal
    the target's twist carried to the camera is ``nu_B = Ad_{X_C*B} xi_B`` (C* the goal's
    camera frame), and it enters as an input, ``x' = A x + E u``, A the closed form
    (:func:`closed_form_A`):

    * kinematic (Eq. 17 in the target's frame): ``eps' = A eps - nu_B``, so
      ``eps_ss = A^-1 nu_B``: Chaumette & Hutchinson's tracking lag (2007, Part II:
      ``e = b / lambda`` for ``e' = -lambda e + b``) with the loop's own gain matrix;
    * dynamic (Eq. 45 in the target's frame): the still target's law damps the rig's
      own twist, ``-B (nu + nu_B)``, and the moving frame adds its centripetal wrench
      at rest relative to the target, F_frame
      (:func:`~geovs_drake.geometry.target_motion.frame_wrench` at V_r = 0, carried from
      the rig's centre to C); so ``E u = [0,
      M^-1 (-B nu_B + F_frame)]`` and ``eps_ss = K^-1 (-B nu_B + F_frame)``.

    ``eps_ss = -A^-1 E u`` in both, with ``X_BC = X_BC* exp(eps^)`` (rotation first):
    the position error is ``|eps_ss[3:]|`` to first order; B is ``resolved.damping``.
    """
    config = resolved.config
    twist_B = np.asarray(twist_B, dtype=float)
    X_CB = config.X_BC_goal.inverse()
    nu_B = velocity_adjoint(X_CB) @ twist_B
    A = closed_form_A(resolved)
    if not config.dynamic:
        return np.linalg.solve(A, nu_B)
    rig = config.carrier  # a FreeRig (closed_form_refusal)
    xi_R = velocity_adjoint(config.X_RC @ X_CB) @ twist_B
    F_R = frame_wrench(np.zeros(6), xi_R, np.zeros(6), np.diag(rig.inertia_diagonal), rig.mass)
    F_C = velocity_adjoint(config.X_RC).T @ F_R  # the same wrench about C, in C
    Bd = np.diag(resolved.damping)
    Eu = np.concatenate(
        [np.zeros(6), np.linalg.solve(rig_spatial_inertia(config), F_C - Bd @ nu_B)]
    )
    return -np.linalg.solve(A, Eu)[:6]


def tracking_transfer(resolved: GoalInputs, frequencies_hz: np.ndarray) -> np.ndarray:
    """G(j 2 pi f) (F, 6, 6), complex: how the linearised loop's relative pose error eps
    (rotation, then position, as :func:`tracking_lag`'s) answers a target twist xi_B
    (6, (omega, v) in B) varying at each frequency f [Hz], without feed-forward.

    The target's twist at the goal, ``nu_B = Ad_{X_C*B} xi_B``, drives the loop as in
    :func:`tracking_lag`: kinematic, ``eps' = A eps - nu_B``; dynamic, the still law
    damps the rig's own twist and the moving frame's acceleration pushes it,
    ``M nu' = ... - B nu_B - M nu_B'`` (the frame wrench to first order in xi; its
    centripetal part is quadratic, outside a linear model). So
    ``eps(s) = [I 0] (sI - A)^-1 E(s) Ad xi_B(s)`` with ``E(s) = -I`` (kinematic) or
    ``[0; -M^-1 B - s I]`` (dynamic). At f = 0 it is :func:`tracking_lag` per unit twist
    for a twist whose centripetal wrench vanishes (a pure translation).
    """
    config = resolved.config
    A = closed_form_A(resolved)
    n = A.shape[0]
    Ad = velocity_adjoint(config.X_BC_goal.inverse())
    if not config.dynamic:
        E0, E1 = -np.eye(6), np.zeros((6, 6))
    else:
        Bd = np.diag(resolved.damping)
        E0 = np.vstack([np.zeros((6, 6)), -np.linalg.solve(rig_spatial_inertia(config), Bd)])
        E1 = np.vstack([np.zeros((6, 6)), -np.eye(6)])
    out = np.empty((len(np.atleast_1d(frequencies_hz)), 6, 6), dtype=complex)
    for k, f in enumerate(np.atleast_1d(np.asarray(frequencies_hz, dtype=float))):
        s = 2j * np.pi * f
        out[k] = np.linalg.solve(s * np.eye(n) - A, (E0 + s * E1) @ Ad)[:6]
    return out


# --- The goal's model split at the camera: what a sampled, delayed image does to it.

#: The slowest camera rate searched [Hz] (a loop stable there has its boundary below the
#: search: it is reported as such, not as this rate).
MIN_RATE_HZ = 0.1
#: The fastest camera rate searched [Hz] for a loop that the given rate cannot carry.
MAX_RATE_HZ = 10_000.0
#: Bisection steps on log(rate).
_RATE_BISECTIONS = 60
#: The latencies [frames] the margin's search tries, 0 to this (or to the latency asked
#: about, where that is longer): a loop stable at all of them has its margin beyond.
LATENCY_SEARCH_FRAMES = 30


@dataclass(frozen=True)
class SearchedBound:
    """What a finite search found: ``value`` (a number), or None with ``reason``, a phrase
    saying why there is none (the search's end reached, the loop stable at any latency or
    rate, or at none). A report prints the value, else the reason."""

    value: float | int | None
    reason: str | None = None


#: Why the continuous model (:meth:`SampledModel.continuous`) has no latency or rate bound:
#: the predictor between frames gives the law the image now, exactly at the goal.
_CONTINUOUS = "the prediction removes the hold and the latency at the goal"
_CONTINUOUS_UNSTABLE = (
    "not stable at any rate: with the prediction the model is the continuous loop's, "
    "and that is not stable"
)


@dataclass
class SampledModel:
    """The goal's linear model split at the camera (module docstring)."""

    A_c: np.ndarray  # what stays continuous
    B_n: np.ndarray  # the held chart coordinate's input
    C_xi: np.ndarray  # the image's chart coordinate of the state

    def continuous(self) -> SampledModel:
        """The same loop with the law reading the image continuously (a predictor between
        frames, :class:`~geovs_drake.systems.FramePredictor`, exact at the goal): the
        stiffness joins ``A_c`` and nothing is held, so the spectral radius at any rate
        and latency is that of ``exp((A_c + B_n C_xi) T)``."""
        return SampledModel(
            A_c=self.A_c + self.B_n @ self.C_xi,
            B_n=self.B_n,
            C_xi=np.zeros_like(self.C_xi),
        )

    @property
    def holds_nothing(self) -> bool:
        """Nothing is held (``C_xi = 0``, :meth:`continuous`): the delayed frames feed
        nothing back, so the latency drops out, and the radius ``exp(max Re(lambda(A_c))
        / rate)`` is below 1 at every rate or at none."""
        return not np.any(self.C_xi)

    def spectral_radius(self, rate: float, latency_frames: int) -> float:
        """The sampled, delayed loop's spectral radius (below 1: locally stable)."""
        check_camera(rate, latency_frames)
        n = len(self.A_c)
        held = DiscreteTimeApproximation(
            LinearSystem(self.A_c, self.B_n, np.eye(n), np.zeros((n, self.B_n.shape[1]))),
            1.0 / rate,
        )
        L = int(latency_frames)
        Z = np.zeros((n * (L + 1), n * (L + 1)))
        Z[:n, :n] = held.A()
        Z[:n, L * n :] += held.B() @ self.C_xi
        for k in range(1, L + 1):
            Z[k * n : (k + 1) * n, (k - 1) * n : k * n] = np.eye(n)
        return float(np.max(np.abs(np.linalg.eigvals(Z))))

    def latency_margin(self, rate: float, max_frames: int = LATENCY_SEARCH_FRAMES) -> int | None:
        """The largest latency [frames] at ``rate`` up to which every latency has a
        spectral radius below 1 (-1 when none has); None where the search found no
        unstable latency (:meth:`latency_bound` says why)."""
        return self.latency_bound(rate, max_frames).value

    def latency_bound(self, rate: float, max_frames: int = LATENCY_SEARCH_FRAMES) -> SearchedBound:
        """:meth:`latency_margin` with its reason where it has no value: the loop
        stable at every latency from 0 to ``max_frames`` (the search's end: the margin
        lies beyond it, not at it), or, where nothing is held (:attr:`holds_nothing`),
        stable at any latency."""
        if self.holds_nothing:  # the latency does not enter: one radius decides
            if self.spectral_radius(rate, 0) >= 1:
                return SearchedBound(-1)
            return SearchedBound(None, f"stable at any latency ({_CONTINUOUS})")
        for L in range(int(max_frames) + 1):
            if self.spectral_radius(rate, L) >= 1:
                return SearchedBound(L - 1)
        return SearchedBound(None, f"stable beyond {int(max_frames)} frames (the search's end)")

    def summary(self, rate: float, latency_frames: int) -> dict:
        """The camera at ``rate`` [Hz], ``latency_frames`` late, as JSON values
        (``linearize --latency --json``'s ``camera``): the spectral radius, whether it is
        stable, the latency margin at that rate (:meth:`latency_bound`, searched to
        :data:`LATENCY_SEARCH_FRAMES` or ``latency_frames`` if longer; -1: not stable
        even without latency) and the slowest stable rate at this latency
        (:meth:`rate_bound`). Each bound is None where the search found none, and its
        ``..._reason`` says why (else None)."""
        rho = self.spectral_radius(rate, latency_frames)
        margin = self.latency_bound(rate, max(LATENCY_SEARCH_FRAMES, int(latency_frames)))
        slowest = self.rate_bound(latency_frames, rate)
        return json_ready(
            {
                "rate": rate,
                "latency_frames": latency_frames,
                "spectral_radius": rho,
                "stable": rho < 1,
                "latency_margin_frames": margin.value,
                "latency_margin_reason": margin.reason,
                "slowest_stable_rate_hz": slowest.value,
                "slowest_stable_rate_reason": slowest.reason,
            }
        )

    def rate_bound(self, latency_frames: int, rate: float) -> SearchedBound:
        """:meth:`stable_rate_boundary` with its reason where it has no value: stable
        down to :data:`MIN_RATE_HZ` (the search's end), no rate up to
        :data:`MAX_RATE_HZ` stable, or, where nothing is held (:attr:`holds_nothing`),
        stable at any rate or at none."""
        if self.holds_nothing:
            if self.spectral_radius(rate, latency_frames) >= 1:
                return SearchedBound(None, _CONTINUOUS_UNSTABLE)
            return SearchedBound(None, f"stable at any rate ({_CONTINUOUS})")
        boundary = self.stable_rate_boundary(latency_frames, rate)
        if boundary is None:
            return SearchedBound(None, f"stable down to {MIN_RATE_HZ:g} Hz (the search's end)")
        if math.isnan(boundary):
            return SearchedBound(None, f"no rate up to {MAX_RATE_HZ:g} Hz is stable")
        return SearchedBound(boundary)

    def stable_rate_boundary(self, latency_frames: int, rate: float) -> float | None:
        """The slowest stable camera rate [Hz] at ``latency_frames``, searched from
        ``rate``: down from it where it is stable (:meth:`slowest_stable_rate`), else up,
        doubling to the first stable rate, then down from there (the rate the loop needs).
        NaN where no rate up to :data:`MAX_RATE_HZ` is stable; None where the loop is
        stable down to :data:`MIN_RATE_HZ` (the boundary lies below the search)."""
        top = float(rate)
        while self.spectral_radius(top, latency_frames) >= 1:
            if top >= MAX_RATE_HZ:
                return math.nan
            top = min(2 * top, MAX_RATE_HZ)
        if top == rate:
            return self.slowest_stable_rate(latency_frames, rate)
        return log_bisection(  # top / 2 unstable, top stable: the boundary between
            lambda r: self.spectral_radius(r, latency_frames) < 1, top, top / 2, _RATE_BISECTIONS
        )

    def slowest_stable_rate(self, latency_frames: int, rate: float) -> float | None:
        """The slowest camera rate [Hz] with a spectral radius below 1 at
        ``latency_frames``: bisection on log(rate) between :data:`MIN_RATE_HZ` and
        ``rate``, which must be stable (the radius need not be monotone in the rate, so
        this is the boundary nearest ``rate`` from below). NaN when ``rate`` itself is
        unstable; None when MIN_RATE_HZ is stable too: the search's end, not a boundary."""
        hi = float(rate)
        if self.spectral_radius(hi, latency_frames) >= 1:
            return math.nan
        lo = MIN_RATE_HZ
        if self.spectral_radius(lo, latency_frames) < 1:
            return None
        return log_bisection(
            lambda r: self.spectral_radius(r, latency_frames) < 1, hi, lo, _RATE_BISECTIONS
        )


def log_bisection(stable_at, stable: float, unstable: float, steps: int) -> float:
    """The edge between a ``stable`` and an ``unstable`` positive value (``stable_at``
    tells which a value is), by ``steps`` bisections on the log: its stable side. The
    camera's rates and the gains' scales are searched this way."""
    for _ in range(steps):
        mid = math.sqrt(stable * unstable)
        if stable_at(mid):
            stable = mid
        else:
            unstable = mid
    return stable


def check_camera(rate: float, latency_frames: int) -> None:
    """One line for a camera the model cannot take."""
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"camera rate must be finite and > 0 [Hz]: rate = {rate}")
    if int(latency_frames) != latency_frames or latency_frames < 0:
        raise ValueError(
            f"latency must be a whole number of frames >= 0: latency_frames = {latency_frames}"
        )
