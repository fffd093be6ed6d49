"""What the camera's rate and latency do to the loop, predicted from its linearisation and
checked against the pinhole-sensor loop.

A camera gives y every ``T = 1 / sensor.rate`` seconds, ``sensor.latency_frames`` (L)
frames late, and the law holds it between frames
(:class:`~geovs_drake.systems.PinholeFeatureSensor`). The loop's linearisation at the
goal (:func:`~geovs_drake.analysis.linear.linearization.linearize`, Drake's ``Linearize``)
splits along its feature-noise input: the law reads the image's chart coordinate
``xi = C_xi x`` (``C_xi`` = y's rows of C in the NF's chart) through ``B_n``, so

    xdot = A_c x + B_n xi_held,   A_c = A - B_n C_xi,

``A_c`` being what stays continuous (the rig's kinematics and the damping, which reads
the rig's own velocity; nothing on the kinematic body) and ``xi_held = C_xi x_{k-L}``
over frame k. Drake's ``DiscreteTimeApproximation`` gives the exact zero-order-hold
discretisation (Phi, Gamma) of ``(A_c, B_n)``; with ``z_k = (x_k, x_{k-1}, ...,
x_{k-L})`` the sampled loop is ``x_{k+1} = Phi x_k + Gamma C_xi x_{k-L}``, locally
stable iff its spectral radius is below 1.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import DiscreteTimeApproximation
from pydrake.systems.primitives import LinearSystem

from geovs_drake._json import json_ready
from geovs_drake.analysis.linear.linearization import INPUTS, OUTPUTS, linearize, noise_directions
from geovs_drake.scenario import CameraModel, Pinhole, PoseConfig, ScenarioConfig, camera_like
from geovs_drake.simulation import simulate

__all__ = [
    "LatencyCase",
    "SampledModel",
    "camera_of",
    "latency_margin",
    "latency_study",
    "sampled_model",
    "slowest_stable_rate",
    "spectral_radius",
]

#: The slowest camera rate searched [Hz] (below it the answer is "none stable").
MIN_RATE_HZ = 0.1
#: The fastest camera rate searched [Hz] for a loop that the given rate cannot carry.
MAX_RATE_HZ = 10_000.0
#: Bisection steps on log(rate).
_RATE_BISECTIONS = 60


@dataclass
class SampledModel:
    """The goal's linear model split at the camera (module docstring)."""

    A_c: np.ndarray  # what stays continuous
    B_n: np.ndarray  # the held chart coordinate's input
    C_xi: np.ndarray  # the image's chart coordinate of the state

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

    def latency_margin(self, rate: float, max_frames: int = 30) -> int:
        """The largest latency [frames] at ``rate`` with a spectral radius below 1 (-1
        when none is, ``max_frames`` when all up to it are)."""
        best = -1
        for L in range(max_frames + 1):
            if self.spectral_radius(rate, L) >= 1:
                break
            best = L
        return best

    def summary(self, rate: float, latency_frames: int) -> dict:
        """The camera at ``rate`` [Hz], ``latency_frames`` late, as JSON values
        (``linearize --latency --json``'s ``camera``): the spectral radius, whether it is
        stable, the latency margin at that rate (-1: not stable even without latency) and
        the slowest stable rate at this latency (:meth:`stable_rate_boundary`; None where
        none up to :data:`MAX_RATE_HZ` is)."""
        rho = self.spectral_radius(rate, latency_frames)
        return json_ready(
            {
                "rate": rate,
                "latency_frames": latency_frames,
                "spectral_radius": rho,
                "stable": rho < 1,
                "latency_margin_frames": self.latency_margin(rate),
                "slowest_stable_rate_hz": self.stable_rate_boundary(latency_frames, rate),
            }
        )

    def stable_rate_boundary(self, latency_frames: int, rate: float) -> float:
        """The slowest stable camera rate [Hz] at ``latency_frames``, searched from
        ``rate``: down from it where it is stable (:meth:`slowest_stable_rate`), else up,
        doubling to the first stable rate, then down from there (the rate the loop needs).
        NaN where no rate up to :data:`MAX_RATE_HZ` is stable."""
        top = float(rate)
        while self.spectral_radius(top, latency_frames) >= 1:
            if top >= MAX_RATE_HZ:
                return math.nan
            top = min(2 * top, MAX_RATE_HZ)
        if top == rate:
            return self.slowest_stable_rate(latency_frames, rate)
        lo, hi = top / 2, top  # lo unstable, hi stable: the boundary between
        for _ in range(_RATE_BISECTIONS):
            mid = math.sqrt(lo * hi)
            if self.spectral_radius(mid, latency_frames) < 1:
                hi = mid
            else:
                lo = mid
        return hi

    def slowest_stable_rate(self, latency_frames: int, rate: float) -> float:
        """The slowest camera rate [Hz] with a spectral radius below 1 at
        ``latency_frames``: bisection on log(rate) between :data:`MIN_RATE_HZ` and
        ``rate``, which must be stable (the radius need not be monotone in the rate, so
        this is the boundary nearest ``rate`` from below). NaN when ``rate`` itself is
        unstable; MIN_RATE_HZ when even that is stable."""
        hi = float(rate)
        if self.spectral_radius(hi, latency_frames) >= 1:
            return math.nan
        lo = MIN_RATE_HZ
        if self.spectral_radius(lo, latency_frames) < 1:
            return lo
        for _ in range(_RATE_BISECTIONS):
            mid = math.sqrt(lo * hi)
            if self.spectral_radius(mid, latency_frames) < 1:
                hi = mid
            else:
                lo = mid
        return hi


def check_camera(rate: float, latency_frames: int) -> None:
    """One line for a camera the model cannot take."""
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"camera rate must be finite and > 0 [Hz]: rate = {rate}")
    if int(latency_frames) != latency_frames or latency_frames < 0:
        raise ValueError(
            f"latency must be a whole number of frames >= 0: latency_frames = {latency_frames}"
        )


def camera_of(config: ScenarioConfig) -> CameraModel:
    """The camera whose rate and latency the sampled model takes: the scenario's sensor
    where it is a camera, else the default :class:`~geovs_drake.scenario.Pinhole` (with
    the sensor's ``radius_error``), the camera an exact loop would get."""
    sensor = config.sensor
    return sensor if isinstance(sensor, CameraModel) else camera_like(sensor, Pinhole)


def _camera_gains(config: ScenarioConfig) -> ScenarioConfig:
    """The loop a camera closes runs with the camera's ``damping``
    (ResolvedScenario.damping); the linearisation is of the exact-y loop, so it gets that
    damping as its own."""
    c = copy.deepcopy(config)
    c.control.damping = list(camera_of(config).damping)
    if isinstance(c.sensor, CameraModel):
        c.sensor.latency_frames = 0  # the model adds it (and the exact y has none)
    return c


def sampled_model(config: ScenarioConfig) -> SampledModel:
    """The goal's :class:`SampledModel` of ``config``'s loop (both plants)."""
    lin = linearize(_camera_gains(config))
    B_n = lin.B[:, INPUTS["feature_noise"]]
    C_y = lin.C[OUTPUTS["image_features"]]
    y_goal = config.goal_features().to_vector()
    C_xi = np.linalg.pinv(noise_directions(y_goal)) @ C_y
    return SampledModel(A_c=lin.A - B_n @ C_xi, B_n=B_n, C_xi=C_xi)


def spectral_radius(config: ScenarioConfig, rate: float | None = None, latency_frames=None):
    """The spectral radius at ``rate`` [Hz] and ``latency_frames`` (default: the
    scenario's camera)."""
    rate = camera_of(config).rate if rate is None else rate
    L = camera_of(config).latency_frames if latency_frames is None else latency_frames
    return sampled_model(config).spectral_radius(rate, L)


def latency_margin(config: ScenarioConfig, rate: float | None = None, max_frames: int = 30) -> int:
    """:meth:`SampledModel.latency_margin` of ``config``'s loop at ``rate`` (default: the
    scenario's camera rate)."""
    rate = camera_of(config).rate if rate is None else rate
    return sampled_model(config).latency_margin(rate, max_frames)


def slowest_stable_rate(config: ScenarioConfig, latency_frames: int | None = None) -> float:
    """:meth:`SampledModel.slowest_stable_rate` of ``config``'s loop below the scenario's
    camera rate, at ``latency_frames`` (default: the scenario's)."""
    L = camera_of(config).latency_frames if latency_frames is None else latency_frames
    return sampled_model(config).slowest_stable_rate(L, camera_of(config).rate)


@dataclass
class LatencyCase:
    """One camera (rate, latency) with its prediction and the pinhole loop's outcome."""

    gains: str
    rate: float
    latency_frames: int
    spectral_radius: float
    predicted_stable: bool
    status: str
    final_position_error_m: float

    @property
    def agrees(self) -> bool:
        """The prediction (radius below 1) matches the run (converged)."""
        return self.predicted_stable == (self.status == "converged")


#: The start of the check: a small move from the goal (local), at rest.
CHECK_START = PoseConfig(xyz=[0.02, -0.01, -0.52], rpy=[0.02, -0.01, 0.1])


def latency_study(
    configs: dict[str, ScenarioConfig],
    rates: tuple[float, ...] = (30.0, 60.0),
    latencies: tuple[int, ...] = tuple(range(7)),
    duration: float = 15.0,
    start: PoseConfig = CHECK_START,
) -> list[LatencyCase]:
    """Each named gain set at each rate and latency: the predicted spectral radius and
    the pinhole-sensor loop (no noise, no calibration error) from ``start``."""
    cases = []
    for name, config in configs.items():
        model = sampled_model(config)
        for rate in rates:
            for L in latencies:
                c = copy.deepcopy(config)
                c.sensor = camera_like(
                    c.sensor, Pinhole, rate=float(rate), latency_frames=int(L), pixel_noise=0.0
                )
                c.initial, c.duration = copy.deepcopy(start), duration
                result = simulate(c)
                rho = model.spectral_radius(rate, L)
                err = float(
                    np.linalg.norm(result.final_X_BC.translation() - c.X_BC_goal.translation())
                )
                cases.append(
                    LatencyCase(name, float(rate), int(L), rho, rho < 1, result.status, err)
                )
    return cases
