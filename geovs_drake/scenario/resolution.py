"""Resolution: a validated scenario and what follows from it, computed once."""

import copy
import dataclasses
from dataclasses import dataclass

from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.domain import SafeDomain
from geovs_drake.geometry.navigation import NavigationGains
from geovs_drake.scenario.carriers import AUTO, NOMINAL_GAIN_SCALES, Arm, FreeRig
from geovs_drake.scenario.laws import LawConfig
from geovs_drake.scenario.schema import ScenarioConfig, damping_of, variant_name
from geovs_drake.scenario.sensors import CameraModel, Exact, radius_error_of

__all__ = ["ResolvedScenario", "exact_twin", "free_twin", "resolve"]


def free_twin(config: ScenarioConfig) -> ScenarioConfig:
    """The same scenario on the default free rig (:class:`FreeRig`): the camera, domain,
    NF and law the batch engine's kernels and the sweep's start sampler read, for a loop
    whose own carrier (the arm) they do not integrate."""
    return dataclasses.replace(config, carrier=FreeRig())


def exact_twin(config: ScenarioConfig) -> ScenarioConfig:
    """The same scenario with the exact sensor, y = c(H): a camera model's own errors
    (noise, focal error, latency) dropped, since they need a camera, and the radius the
    controller believes (``sensor.radius_error``) kept. What a study of the continuous
    loop (Drake's ``Linearize``, the batch engine's parameters) builds."""
    twin = copy.deepcopy(config)  # a copy of its own: callers vary it further
    twin.sensor = Exact(radius_error=radius_error_of(config.sensor))
    return twin


@dataclass(frozen=True)
class ResolvedScenario:
    """A validated scenario with its derived quantities, resolved once (:func:`resolve`).

    The loop builders, the simulator and the batch engine read these, never the
    rules that make them: ``law`` (the variant, ``config.controller``), ``believed_radius``
    (what every law and C(y) believe), ``damping`` (:func:`damping_of`), the goal
    image ``y_goal`` = c(X_CB*) for the believed radius, and the safe domain ``domain``.
    """

    config: ScenarioConfig
    law: LawConfig
    believed_radius: float
    damping: tuple[float, ...]
    y_goal: ImageFeatures
    domain: SafeDomain
    gains: NavigationGains
    #: The factor the law's gains were scaled by (the arm's ``gain_scale``; 1 elsewhere):
    #: ``config`` holds the scaled gains, and its arm a gain_scale of 1.
    gain_scale: float = 1.0

    @property
    def controller(self) -> str:
        """The law's name (:func:`variant_name`)."""
        return variant_name(self.law)


def resolve(config: ScenarioConfig | ResolvedScenario | None = None) -> ResolvedScenario:
    """Validate ``config`` (default: the default scenario) and resolve what follows from
    it, in one step; a :class:`ResolvedScenario` passes through unchanged."""
    if isinstance(config, ResolvedScenario):
        return config
    config = ScenarioConfig() if config is None else config
    config.validate()
    scale = 1.0
    if isinstance(config.carrier, Arm) and config.carrier.gain_scale == AUTO:
        if isinstance(config.sensor, CameraModel):
            # The camera's bound needs the arm's model at the goal (the loop's layer).
            raise ValueError(
                "carrier.gain_scale auto with a camera is fitted to the camera by "
                "geovs_drake.loop.fit_gains (build_loop and simulate call it): "
                "resolve(fit_gains(config))"
            )
        config = copy.deepcopy(config)
        config.carrier.gain_scale = NOMINAL_GAIN_SCALES[type(config.plant)]  # no camera
    if isinstance(config.carrier, Arm) and not config.dynamic and config.carrier.gain_scale != 1:
        # The kinematic arm's one gain, k of Eq. (19).
        config = copy.deepcopy(config)
        scale = config.carrier.gain_scale
        config.control.kinematic_gain *= scale
        config.carrier.gain_scale = 1.0
    if isinstance(config.carrier, Arm) and config.dynamic and config.carrier.gain_scale != 1:
        # The arm's gains (Arm.gain_scale): a scaled copy, so that every part of
        # the loop, the energy bound included, reads one k_p and one B.
        config = copy.deepcopy(config)
        scale = config.carrier.gain_scale
        config.control.potential_gain *= scale
        config.control.damping = [scale * v for v in config.control.damping]
        config.control.tracking_gains = [scale * v for v in config.control.tracking_gains]
        if isinstance(config.sensor, CameraModel):  # a camera's loop damps with its own B
            config.sensor.damping = [scale * v for v in config.sensor.damping]
        config.carrier.gain_scale = 1.0
    return ResolvedScenario(
        config=config,
        law=config.controller,
        believed_radius=config.believed_radius,
        damping=tuple(float(v) for v in damping_of(config)),
        y_goal=config.goal_features(),
        domain=config.domain.to_domain(),
        gains=config.navigation.to_gains(),
        gain_scale=scale,
    )
