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

With ``prediction: odometry`` (:class:`~geovs_drake.systems.FramePredictor`) the law
reads the held frame moved by the rig's motion since its capture: at the goal that is
the continuous loop's y, so the model is :meth:`SampledModel.continuous` (nothing held)
and the rate and latency drop out of the local model. :func:`latency_study` runs both,
so its maps show where prediction matters.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from geovs_drake.analysis.linear.linearization import INPUTS, OUTPUTS, linearize, noise_directions
from geovs_drake.goal.linear_model import LATENCY_SEARCH_FRAMES, SampledModel
from geovs_drake.scenario import (
    PREDICTIONS,
    CameraModel,
    Pinhole,
    PoseConfig,
    ScenarioConfig,
    camera_like,
)
from geovs_drake.simulation import simulate

__all__ = [
    "CameraCase",
    "LatencyCase",
    "MapCase",
    "camera_map",
    "camera_model",
    "map_table",
    "camera_of",
    "latency_margin",
    "latency_study",
    "sampled_model",
    "slowest_stable_rate",
    "spectral_radius",
]


def camera_of(config: ScenarioConfig) -> CameraModel:
    """The camera whose rate and latency the sampled model takes: the scenario's sensor
    where it is a camera, else the default :class:`~geovs_drake.scenario.Pinhole` (with
    the sensor's ``radius_error``), the camera an exact loop would get."""
    sensor = config.sensor
    return sensor if sensor.traits.camera else camera_like(sensor, Pinhole)


def _camera_gains(config: ScenarioConfig) -> ScenarioConfig:
    """The loop a camera closes runs with the camera's ``damping``
    (ResolvedScenario.damping); the linearisation is of the exact-y loop, so it gets that
    damping as its own."""
    c = copy.deepcopy(config)
    c.control.damping = list(camera_of(config).damping)
    if c.sensor.traits.camera:
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


def camera_model(config: ScenarioConfig) -> SampledModel:
    """The goal's model of ``config``'s loop as its camera runs it: :func:`sampled_model`,
    made continuous where the camera predicts between frames (``sensor.prediction``)."""
    model = sampled_model(config)
    return model.continuous() if PREDICTIONS[camera_of(config).prediction].continuous else model


def spectral_radius(config: ScenarioConfig, rate: float | None = None, latency_frames=None):
    """The spectral radius at ``rate`` [Hz] and ``latency_frames`` (default: the
    scenario's camera), of the loop as its camera runs it (:func:`camera_model`)."""
    rate = camera_of(config).rate if rate is None else rate
    L = camera_of(config).model_latency_frames if latency_frames is None else latency_frames
    return camera_model(config).spectral_radius(rate, L)


def latency_margin(
    config: ScenarioConfig, rate: float | None = None, max_frames: int = LATENCY_SEARCH_FRAMES
) -> int | None:
    """:meth:`SampledModel.latency_margin` of ``config``'s loop (:func:`camera_model`) at
    ``rate`` (default: the scenario's camera rate): None where no latency up to
    ``max_frames`` is unstable (:meth:`SampledModel.latency_bound` says why)."""
    rate = camera_of(config).rate if rate is None else rate
    return camera_model(config).latency_margin(rate, max_frames)


def slowest_stable_rate(config: ScenarioConfig, latency_frames: int | None = None) -> float | None:
    """:meth:`SampledModel.slowest_stable_rate` of ``config``'s loop (:func:`camera_model`)
    below the scenario's camera rate, at ``latency_frames`` (default: the scenario's): NaN
    where that rate is unstable, None where the loop is stable down to the search's end
    (:meth:`SampledModel.rate_bound` says why)."""
    L = camera_of(config).model_latency_frames if latency_frames is None else latency_frames
    return camera_model(config).slowest_stable_rate(L, camera_of(config).rate)


@dataclass
class CameraCase:
    """One camera (rate, latency, what the law sees between frames) with the model's
    spectral radius and verdict, and the pinhole loop's outcome."""

    rate: float
    latency_frames: int
    prediction: str
    spectral_radius: float
    status: str
    final_position_error_m: float

    @property
    def predicted_stable(self) -> bool:
        """The model's verdict: a spectral radius below 1."""
        return self.spectral_radius < 1

    @property
    def agrees(self) -> bool:
        """The model's verdict matches the run (converged)."""
        return self.predicted_stable == (self.status == "converged")


@dataclass
class LatencyCase(CameraCase):
    """A :class:`CameraCase` of :func:`latency_study`, with the name of its gain set."""

    gains: str = ""


#: The start of the check: a small move from the goal (local), at rest.
CHECK_START = PoseConfig(xyz=[0.02, -0.01, -0.52], rpy=[0.02, -0.01, 0.1])


def latency_study(
    configs: dict[str, ScenarioConfig],
    rates: tuple[float, ...] = (30.0, 60.0),
    latencies: tuple[int, ...] = tuple(range(7)),
    duration: float = 15.0,
    start: PoseConfig = CHECK_START,
    predictions: tuple[str, ...] = ("none",),
) -> list[LatencyCase]:
    """Each named gain set at each rate, latency and ``prediction``
    (:data:`~geovs_drake.scenario.PREDICTIONS`): the model's spectral radius and the
    pinhole-sensor loop (no noise, no calibration error) from ``start``."""
    unknown = [p for p in predictions if p not in PREDICTIONS]
    if unknown:
        raise ValueError(f"predictions must be in {', '.join(PREDICTIONS)}: got {unknown[0]!r}")
    cases = []
    for name, config in configs.items():
        held = sampled_model(config)
        for prediction in predictions:
            model = held.continuous() if PREDICTIONS[prediction].continuous else held
            for rate in rates:
                for L in latencies:
                    fields = _run_case(config, model, rate, L, prediction, duration, start)
                    cases.append(LatencyCase(**fields, gains=name))
    return cases


@dataclass
class MapCase(CameraCase):
    """A :class:`CameraCase` of :func:`camera_map`, with the arm's ``gain_scale``."""

    gain_scale: float = 1.0


def _run_case(
    config: ScenarioConfig,
    model: SampledModel,
    rate: float,
    latency: int,
    prediction: str,
    duration: float,
    start: PoseConfig,
) -> dict:
    """The pinhole loop of ``config`` at this camera (no noise) from ``start``, and the
    model's radius there: a :class:`CameraCase`'s fields."""
    c = copy.deepcopy(config)
    c.sensor = camera_like(
        c.sensor,
        Pinhole,
        rate=float(rate),
        latency_frames=int(latency),
        pixel_noise=0.0,
        prediction=prediction,
    )
    c.initial, c.duration = copy.deepcopy(start), duration
    result = simulate(c)
    goal = c.X_BC_goal.translation()
    return dict(
        rate=float(rate),
        latency_frames=int(latency),
        prediction=prediction,
        spectral_radius=model.spectral_radius(rate, latency),
        status=result.status,
        final_position_error_m=float(np.linalg.norm(result.final_X_BC.translation() - goal)),
    )


def camera_map(
    config: ScenarioConfig,
    gain_scales: tuple[float, ...],
    rates: tuple[float, ...] = (10.0, 15.0, 30.0, 60.0),
    latencies: tuple[int, ...] = (0, 1, 2),
    predictions: tuple[str, ...] = tuple(PREDICTIONS),
    duration: float = 15.0,
    start: PoseConfig = CHECK_START,
) -> list[MapCase]:
    """Issue 31's maps on the arm: each ``gain_scale`` x camera rate x latency x
    ``prediction``, the goal's closed-form sampled model
    (:func:`~geovs_drake.goal.camera_fit.goal_sampled_model`) against the pinhole loop
    from ``start`` (no noise, no calibration error). ``config``'s carrier must be an
    :class:`~geovs_drake.scenario.Arm` (the scale is its ``gain_scale``)."""
    from geovs_drake.goal.camera_fit import goal_sampled_model
    from geovs_drake.loop import resolve

    if not config.carrier.traits.gain_scale:
        raise ValueError(f"camera_map scales an arm's gain_scale: carrier = {config.carrier!r}")
    cases = []
    for scale in gain_scales:
        scaled = copy.deepcopy(config)
        scaled.carrier.gain_scale = float(scale)
        for prediction in predictions:
            if prediction not in PREDICTIONS:
                raise ValueError(f"prediction must be in {', '.join(PREDICTIONS)}: {prediction!r}")
            for rate in rates:
                for L in latencies:
                    camera = copy.deepcopy(scaled)
                    camera.sensor = camera_like(
                        camera.sensor, Pinhole, rate=float(rate), latency_frames=int(L),
                        prediction=prediction,
                    )  # fmt: skip
                    model = goal_sampled_model(
                        resolve(camera), continuous=PREDICTIONS[prediction].continuous
                    )
                    fields = _run_case(scaled, model, rate, L, prediction, duration, start)
                    cases.append(MapCase(**fields, gain_scale=float(scale)))
    return cases


#: How :func:`map_table` writes a run's outcome.
_OUTCOME = {"converged": "ok", "left_domain": "left D", "not_converged": "slow"}


def map_table(cases: list[MapCase]) -> str:
    """:func:`camera_map`'s cases as Markdown: one table per prediction, a row per gain
    scale and latency, a column per rate; each cell the run's outcome, then the model's
    spectral radius, starred where the model and the run disagree."""
    out = []
    for prediction in dict.fromkeys(c.prediction for c in cases):
        mine = [c for c in cases if c.prediction == prediction]
        rates = sorted({c.rate for c in mine})
        out.append(f"prediction: {prediction}\n")
        out.append("| gain_scale | latency | " + " | ".join(f"{r:g} Hz" for r in rates) + " |")
        out.append("|---|---|" + "---|" * len(rates))
        rows = dict.fromkeys((c.gain_scale, c.latency_frames) for c in mine)
        for scale, L in rows:
            cells = []
            for r in rates:
                (c,) = [
                    c for c in mine if (c.gain_scale, c.latency_frames, c.rate) == (scale, L, r)
                ]
                flag = "" if c.agrees else " *"
                cells.append(f"{_OUTCOME.get(c.status, c.status)} ({c.spectral_radius:.3f}){flag}")
            out.append(f"| {scale:g} | {L} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)
