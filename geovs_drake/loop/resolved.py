"""The resolved scenario: a validated scenario and everything a run derives from it,
made once by :func:`~geovs_drake.loop.resolver` and read by everything downstream (the
loop's parts, the simulator, the batch engine, the studies, the hardware builders and
the command line), which never derive it again."""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.domain import SafeDomain
from geovs_drake.geometry.navigation import NavigationFunction, NavigationGains
from geovs_drake.scenario import (
    Exact,
    FreeRig,
    LawConfig,
    ScenarioConfig,
    radius_error_of,
    variant_name,
)

if TYPE_CHECKING:  # the goal's records, named in annotations only: importing this
    # module (a sweep's worker unpickling a resolved scenario) loads no arm model.
    from geovs_drake.goal.camera_fit import CameraFit
    from geovs_drake.goal.effort_fit import EffortFit
    from geovs_drake.goal.step_limit import GoalModel, StepLimit
    from geovs_drake.goal.target_reach import TargetReach

__all__ = ["ResolvedScenario", "exact_twin", "free_twin"]


@dataclass(frozen=True)
class ResolvedScenario:
    """A validated scenario with what follows from it, resolved once
    (:func:`~geovs_drake.loop.resolver`).

    ``config`` is the validated scenario with the arm's ``gain_scale`` applied (k_p, B,
    the tracking gains, or k, already times ``gain_scale``; its carrier's ``gain_scale``
    then 1). ``law`` is ``config.controller``; ``believed_radius`` what every law and
    C(y) believe; ``damping`` the B the loop runs with
    (:func:`~geovs_drake.scenario.damping_of`, the one answer); ``domain`` D; ``y_goal``
    y* = c(X_CB*) for the believed radius; ``nf`` the navigation function on D with goal
    y* and ``gains``; ``hessian`` its chart Hessian at y*.

    The model at the goal (:mod:`geovs_drake.goal`): ``goal`` the loop's A there
    (None where no model covers the loop), ``camera_fit`` the gains against the camera's
    rate and latency (None without a camera or a model), ``step_limit`` the integrator's
    step, ``effort`` the dynamic arm's torques against its effort limits (where the
    resolver was asked for it, or fitted the gains to it; else None),
    ``predicted_lag`` the NF's position lag [m] behind a constant-twist target without
    feed-forward (closed form; None where it does not model the loop), and ``reach``
    where a moving target leaves an arm's reach or speed (where asked).
    """

    config: ScenarioConfig
    #: The scenario as given, its arm's ``gain_scale: auto`` replaced by the scale chosen
    #: and its gains not yet scaled: what a sweep varies start by start (each start's
    #: resolve then keeps this scale) and its free rig's twin reads.
    fitted_config: ScenarioConfig
    law: LawConfig
    believed_radius: float
    damping: tuple[float, ...]
    y_goal: ImageFeatures
    domain: SafeDomain
    gains: NavigationGains
    nf: NavigationFunction
    hessian: np.ndarray
    #: The factor the law's gains were scaled by (the arm's ``gain_scale``; 1 elsewhere).
    gain_scale: float = 1.0
    goal: GoalModel | None = None
    camera_fit: CameraFit | None = None
    step_limit: StepLimit | None = None
    effort: EffortFit | None = None
    predicted_lag: float | None = None
    #: An arm behind a moving target: where its motion leaves the arm's reach or speed
    #: (:class:`~geovs_drake.goal.target_reach.TargetReach`), checked with the effort
    #: check (where asked: a warning line's); else None.
    reach: TargetReach | None = None
    #: Where the carrier changed the start it was given (the quadrotor's level start,
    #: ``config.initial`` already the changed one): the run's warning line; else None.
    start_note: str | None = None

    @property
    def controller(self) -> str:
        """The law's name (:func:`~geovs_drake.scenario.variant_name`)."""
        return variant_name(self.law)


def free_twin(config: ScenarioConfig) -> ScenarioConfig:
    """The same scenario on the default free rig (:class:`~geovs_drake.scenario.FreeRig`):
    the camera, domain, NF and law the batch engine's kernels and the sweep's start
    sampler read, for a loop whose own carrier (the arm) they do not integrate."""
    return dataclasses.replace(config, carrier=FreeRig())


def exact_twin(config: ScenarioConfig) -> ScenarioConfig:
    """The same scenario with the exact sensor, y = c(H): a camera model's own errors
    (noise, focal error, latency) dropped, since they need a camera, and the radius the
    controller believes (``sensor.radius_error``) kept. What a study of the continuous
    loop (Drake's ``Linearize``, the batch engine's parameters) builds."""
    twin = copy.deepcopy(config)  # a copy of its own: callers vary it further
    twin.sensor = Exact(radius_error=radius_error_of(config.sensor))
    return twin
