"""Gains from the linearisation at the goal: a requested local response, what it costs,
and how well the linear prediction holds in the nonlinear loop.

The closed form (:func:`~geovs_drake.goal.linear_model.closed_form_A`) is
``M eps'' + B eps' + k_p K_1 eps = 0`` on the dynamic rig (``K_1 = C_chart^T H
C_chart``, Appendix C) and ``eps' = -k C_chart^-1 H C_chart eps`` on the kinematic
body (Eqs. 17-19), whose eigenvalues are ``-k eig(H)``.

* **Kinematic**: the slowest mode is ``-k lambda_min(H)``; ``k`` follows from the
  settling time alone (every mode is real).
* **Dynamic**: the request is the least-damped mode's damping ratio zeta (no mode is
  less damped) and the slowest mode's settling time. The damping B keeps the
  scenario's diagonal profile (``control.damping``, the law's 6 entries), scaled by
  beta. Scaling ``k_p`` by ``c^2`` and beta by ``c`` scales every eigenvalue by ``c``
  and keeps every damping ratio, so the smallest damping ratio depends on
  ``r = beta / sqrt(k_p)`` alone (and continuously): ``r`` is found by bisection on
  zeta, then ``c`` by the settling time. Why not the slowest mode's own ratio: with a
  diagonal B it jumps (with the default profile, from 0.57 to 1 where a better-damped
  pair splits into a slow real mode), so most ratios cannot be met by it; placing
  every pair at zeta would need a full 6x6 B (modal damping
  ``M V diag(2 zeta omega) V^T M``), which the law's diagonal damping cannot hold.

The settling time is the 2 % envelope of the slowest mode:
``t_s = -ln(SETTLING_FRACTION) / sigma``, sigma its decay rate. What it costs:
``k_p`` is the energy bound of Eq. (45)'s argument (moving starts with ``E0 < k_p``
are covered), and the peak wrench (or twist) along the designed loop's run from the
scenario's start, :func:`design_gains` with ``run_start``.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from geovs_drake._json import json_ready
from geovs_drake.batch.engine import run_batch
from geovs_drake.geometry.so3 import so3_exp
from geovs_drake.goal.linear_model import (
    closed_form_A,
    closed_form_refusal,
    goal_stiffness,
    rig_spatial_inertia,
    second_order_A,
)
from geovs_drake.loop import build_loop, exact_twin, resolve
from geovs_drake.scenario import PlantConfig, ScenarioConfig, variant_name
from geovs_drake.simulation import simulate
from geovs_drake.simulation.result import CONVERGENCE_POSITION_M, CONVERGENCE_ROTATION_RAD
from geovs_drake.spectrum import canonical_eigenvalues

__all__ = [
    "SETTLING_FRACTION",
    "DecayCheck",
    "GainDesign",
    "decay_check",
    "design_gains",
    "root_locus",
    "settling_rate",
]

#: The envelope's fraction of its start at the settling time (the 2 % criterion).
SETTLING_FRACTION = 0.02
#: The bracket of r = beta / sqrt(k_p) scanned for the damping ratio, and its points.
_R_RANGE, _R_POINTS = (1e-4, 1e4), 801
#: Bisection steps on r (the bracket shrinks by 2^-steps) and the ratio's tolerance.
_BISECTIONS, _RATIO_TOL = 200, 1e-12


def settling_rate(settling_time: float) -> float:
    """sigma [1/s] of an envelope ``exp(-sigma t)`` that falls to
    :data:`SETTLING_FRACTION` at ``settling_time`` [s]."""
    return -math.log(SETTLING_FRACTION) / settling_time


def _check_request(plant: PlantConfig, settling_time: float, damping_ratio: float | None) -> None:
    if not (math.isfinite(settling_time) and settling_time > 0):
        raise ValueError(f"settling_time must be finite and > 0: settling_time = {settling_time}")
    if not plant.traits.dynamic:
        if damping_ratio is not None:
            raise ValueError(
                f"the kinematic loop's modes are all real (damping ratio 1): leave "
                f"damping_ratio out, got damping_ratio = {damping_ratio}"
            )
        return
    if damping_ratio is None or not (0 < damping_ratio < 1):
        raise ValueError(
            "damping_ratio (the dynamic loop's least-damped mode) must be in (0, 1): "
            f"damping_ratio = {damping_ratio}"
        )


@dataclass
class GainDesign:
    """Gains that give the requested slowest mode (:func:`design_gains`).

    Attributes:
        config: the scenario with the designed gains.
        settling_time: requested [s]; damping_ratio: requested (None, kinematic).
        eigenvalues: the designed loop's closed form at the goal, in the canonical order
            (:mod:`geovs_drake.spectrum`).
        stiffness: ``K = k_p K_1`` (dynamic, N m per rad and N per m) or the kinematic
            loop's ``k C_chart^-1 H C_chart`` [1/s].
        peak_torque, peak_force: the largest norms of F_C's torque and force along the
            run from the start [N m], [N] (dynamic); peak_rate, peak_speed: the largest
            norms of the commanded twist's Omega and V [rad/s], [m/s] (kinematic).
            NaN when not run.
        run_status: the designed loop's status from the scenario's start (or None).
    """

    config: ScenarioConfig
    settling_time: float
    damping_ratio: float | None
    eigenvalues: np.ndarray
    stiffness: np.ndarray
    peak_torque: float = math.nan
    peak_force: float = math.nan
    peak_rate: float = math.nan
    peak_speed: float = math.nan
    run_status: str | None = None

    @property
    def plant(self) -> str:
        """The plant's name, ``"dynamic"`` or ``"kinematic"``."""
        return variant_name(self.config.plant)

    @property
    def potential_gain(self) -> float:
        """k_p: the energy bound of the guarantee (dynamic)."""
        return float(self.config.control.potential_gain)

    @property
    def damping(self) -> np.ndarray:
        """B's diagonal (dynamic)."""
        return np.asarray(self.config.control.damping, dtype=float)

    @property
    def kinematic_gain(self) -> float:
        """k of Eq. (19) (kinematic)."""
        return float(self.config.control.kinematic_gain)

    @property
    def slowest(self) -> complex:
        """The eigenvalue with the largest real part (with Im >= 0 of a pair)."""
        lam = self.eigenvalues
        top = lam[np.isclose(lam.real, lam.real.max(), rtol=1e-9, atol=0)]
        return complex(top[np.argmax(top.imag)])

    def summary(self) -> dict:
        """The design as JSON values (``linearize --settling-time --json``'s ``design``):
        the request, the slowest mode ``[re, im]``, what is achieved, the run's status, and
        the gains with their cost: k_p (the energy bound), B and the peak torque and force
        on the dynamic plant; k and the peak rate and speed on the kinematic one."""
        out = {
            "settling_time": self.settling_time,
            "damping_ratio": self.damping_ratio,
            "slowest": self.slowest,
            "achieved_damping_ratio": self.achieved_damping_ratio,
            "achieved_settling_time": self.achieved_settling_time,
            "run_status": self.run_status,
        }
        if self.config.dynamic:
            out |= {
                "potential_gain": self.potential_gain,
                "damping": self.damping,
                "energy_bound": self.potential_gain,
                "peak_torque_Nm": self.peak_torque,
                "peak_force_N": self.peak_force,
            }
        else:
            out |= {
                "kinematic_gain": self.kinematic_gain,
                "peak_rate_rad_s": self.peak_rate,
                "peak_speed_m_s": self.peak_speed,
            }
        return json_ready(out)

    @property
    def achieved_damping_ratio(self) -> float:
        """The smallest ``-Re / |lambda|`` over the modes (what ``damping_ratio`` asks)."""
        return _min_ratio(self.eigenvalues)

    @property
    def achieved_settling_time(self) -> float:
        """The slowest mode's 2 % settling time [s]."""
        return -math.log(SETTLING_FRACTION) / -self.slowest.real

    @property
    def slowest_damping_ratio(self) -> float:
        """``-Re / |lambda|`` of the slowest mode (1 where it is real)."""
        lam = self.slowest
        return -lam.real / abs(lam)


def _dynamic_eigenvalues(M, K1, d0, k_p: float, beta: float) -> np.ndarray:
    A = second_order_A(M, k_p * K1, beta * np.diag(d0))
    return canonical_eigenvalues(A)


def _min_ratio(lam: np.ndarray) -> float:
    """The smallest damping ratio -Re / |lambda| over the eigenvalues."""
    return float(np.min(-lam.real / np.abs(lam)))


def _slowest_rate(lam: np.ndarray) -> float:
    """The slowest eigenvalue's decay rate -Re [1/s]."""
    return float(-np.max(lam.real))


def design_gains(
    config: ScenarioConfig,
    settling_time: float,
    damping_ratio: float | None = None,
    run_start: bool = True,
) -> GainDesign:
    """Gains for which the loop's slowest mode at the goal settles (2 %) in
    ``settling_time`` [s] and, on the dynamic loop, no mode is damped less than
    ``damping_ratio`` (module docstring).

    ``run_start`` also simulates the designed loop from ``config``'s start for the peak
    wrench (or twist) the request costs. Raises ValueError in one line for a request
    out of range or one that the damping profile cannot meet.
    """
    plant = config.plant
    _check_request(plant, settling_time, damping_ratio)
    refusal = closed_form_refusal(config, "design_gains")
    if refusal is not None:
        raise ValueError(refusal)
    sigma = settling_rate(settling_time)
    designed = copy.deepcopy(config)
    M = rig_spatial_inertia(config)
    K1, KC = goal_stiffness(resolve(config))
    if not plant.traits.dynamic:
        lam_min = float(np.min(np.linalg.eigvals(KC).real))
        designed.control.kinematic_gain = sigma / lam_min
        stiffness = designed.control.kinematic_gain * KC
    else:
        d0 = np.asarray(config.control.damping, dtype=float)
        if not np.any(d0 > 0):
            raise ValueError(f"control.damping's profile must have a positive entry: {d0.tolist()}")
        r = _ratio_for(M, K1, d0, damping_ratio)
        sigma_1 = _slowest_rate(_dynamic_eigenvalues(M, K1, d0, 1.0, r))
        c = sigma / sigma_1
        designed.control.potential_gain = c * c
        designed.control.damping = (c * r * d0).tolist()
        stiffness = designed.control.potential_gain * K1
    design = GainDesign(
        config=designed,
        settling_time=settling_time,
        damping_ratio=damping_ratio,
        # The design is the continuous loop's (the exact sensor, whose B is control.damping).
        eigenvalues=canonical_eigenvalues(closed_form_A(resolve(exact_twin(designed)), plant)),
        stiffness=stiffness,
    )
    if run_start:
        _peaks(design)
    return design


def _ratio_for(M, K1, d0, zeta: float) -> float:
    """r = beta / sqrt(k_p) whose least-damped mode has damping ratio zeta: the first
    crossing of a log-spaced scan, then bisection within it."""
    grid = np.geomspace(*_R_RANGE, _R_POINTS)
    ratios = np.array([_min_ratio(_dynamic_eigenvalues(M, K1, d0, 1.0, r)) for r in grid])
    crossing = np.nonzero((ratios[:-1] - zeta) * (ratios[1:] - zeta) <= 0)[0]
    if len(crossing) == 0:
        raise ValueError(
            f"no damping scale gives the least-damped mode damping ratio {zeta}: with "
            f"control.damping's profile it ranges over [{ratios.min():.3g}, {ratios.max():.3g}]"
        )
    lo, hi = grid[crossing[0]], grid[crossing[0] + 1]
    f_lo = ratios[crossing[0]] - zeta
    for _ in range(_BISECTIONS):
        mid = math.sqrt(lo * hi)
        f_mid = _min_ratio(_dynamic_eigenvalues(M, K1, d0, 1.0, mid)) - zeta
        if abs(f_mid) < _RATIO_TOL:
            return mid
        if f_mid * f_lo > 0:
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    raise ValueError(  # continuous in r, so only a 2^-200 bracket could end here
        f"the least-damped ratio did not converge to {zeta} near beta / sqrt(k_p) = "
        f"{math.sqrt(lo * hi):.4g}"
    )


def _peaks(design: GainDesign) -> None:
    """The designed loop from the scenario's start: the largest wrench (dynamic) or
    twist (kinematic) the law commands along the run (at the logged states)."""
    config = exact_twin(design.config)
    result = simulate(config)
    design.run_status = result.status
    loop = build_loop(config, log=False)
    context = loop.diagram.CreateDefaultContext()
    if config.dynamic:
        law = loop.diagram.GetSubsystemByName("image_jacobian_force")
        port = law.wrench_C_output
    else:
        law = loop.diagram.GetSubsystemByName("kinematic_controller")
        port = law.camera_velocity_output
    sub = law.GetMyContextFromRoot(context)
    top = np.zeros(2)
    for x in result.states:
        context.SetContinuousState(x)
        w = port.Eval(sub)
        top = np.maximum(top, [np.linalg.norm(w[0:3]), np.linalg.norm(w[3:6])])
    if config.dynamic:
        design.peak_torque, design.peak_force = top
    else:
        design.peak_rate, design.peak_speed = top


def root_locus(
    config: ScenarioConfig, gains: np.ndarray, gain: str = "potential_gain"
) -> np.ndarray:
    """The goal's eigenvalues (closed form) as one gain of ``control`` runs over ``gains``:
    ``potential_gain`` (k_p), ``damping_scale`` (B times each value) or
    ``kinematic_gain``. Shape (len(gains), n), each row in the canonical order
    (:mod:`geovs_drake.spectrum`)."""
    names = ("potential_gain", "damping_scale", "kinematic_gain")
    if gain not in names:
        raise ValueError(f"gain must be one of {', '.join(names)}: gain = {gain!r}")
    # The goal's stiffness once (one AutoDiffXd pass), then each gain's A.
    M = rig_spatial_inertia(config)
    K1, KC = goal_stiffness(resolve(config))
    control = config.control
    d0 = np.asarray(control.damping, dtype=float)
    rows = []
    for g in np.asarray(gains, dtype=float):
        if gain == "kinematic_gain" or not config.dynamic:
            A = -(g if gain == "kinematic_gain" else control.kinematic_gain) * KC
        else:
            k_p = g if gain == "potential_gain" else control.potential_gain
            beta = g if gain == "damping_scale" else 1.0
            A = second_order_A(M, k_p * K1, beta * np.diag(d0))
        rows.append(canonical_eigenvalues(A))
    return np.array(rows)


@dataclass
class DecayCheck:
    """The linear prediction of the tail against the nonlinear loop (:func:`decay_check`).

    Attributes:
        predicted_rate: the slowest mode's decay rate sigma [1/s].
        measured_rates: per start, the slope of ``-ln |e(t)|`` over the sample times
            (least squares), e the pose error (rad and m together).
        times: the sample times [s] (batch runs of these durations).
        t_converged: per start, when the batch engine saw the error stay within the
            convergence tolerances [s] (NaN where not within the longest run).
        predicted_t_converged: per start, ``ln(e0 / tol) / sigma`` for the rotation
            and the position (the larger): the slowest envelope's time to the
            tolerances, from the start's error (an upper estimate where the start
            excites only faster modes).
    """

    predicted_rate: float
    measured_rates: np.ndarray
    times: np.ndarray
    t_converged: np.ndarray
    predicted_t_converged: np.ndarray

    @property
    def median_rate(self) -> float:
        """The measured rates' median [1/s]."""
        return float(np.median(self.measured_rates))

    @property
    def relative_difference(self) -> float:
        """(median measured - predicted) / predicted."""
        return (self.median_rate - self.predicted_rate) / self.predicted_rate


def decay_check(
    design: GainDesign,
    starts: int = 64,
    spread: tuple[float, float] = (0.05, 0.01),
    seed: int = 0,
) -> DecayCheck:
    """Random starts about the goal (rotation and position spread [rad], [m], at rest)
    through the batch engine with the designed gains: the measured decay of the pose
    error between 1.5 and 3 settling times against the slowest mode's rate."""
    config = design.config
    rng = np.random.default_rng(seed)
    X_goal = config.X_BC_goal.GetAsMatrix4()
    X = np.repeat(X_goal[None], starts, axis=0)
    for i in range(starts):
        eps = rng.normal(size=6)
        eps[0:3] *= spread[0] / np.linalg.norm(eps[0:3])
        eps[3:6] *= spread[1] / np.linalg.norm(eps[3:6])
        X[i, 0:3, 0:3] = X_goal[0:3, 0:3] @ so3_exp(eps[0:3])
        X[i, 0:3, 3] = X_goal[0:3, 3] + X_goal[0:3, 0:3] @ eps[3:6]
    sigma = -design.slowest.real
    times = design.achieved_settling_time * np.linspace(1.5, 3.0, 7)
    errors = []
    last = None
    for T in times:
        last = run_batch(config, X, duration=float(T))
        errors.append(np.hypot(last.final_position_error_m, last.final_rotation_error_rad))
    log_e = np.log(np.array(errors))  # (times, starts)
    slope = np.polyfit(times, log_e, 1)[0]
    # The tolerances are the simulator's (SimulationResult.converged).
    to_tolerance = max(
        math.log(spread[0] / CONVERGENCE_ROTATION_RAD), math.log(spread[1] / CONVERGENCE_POSITION_M)
    )
    return DecayCheck(
        predicted_rate=sigma,
        measured_rates=-slope,
        times=times,
        t_converged=last.t_converged,
        predicted_t_converged=np.full(starts, max(0.0, to_tolerance) / sigma),
    )
