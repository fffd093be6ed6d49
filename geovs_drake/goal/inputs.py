"""What the model at the goal reads of a resolved scenario: an interface, so that this
room stays below the loop's, where :class:`~geovs_drake.loop.ResolvedScenario` (which
has these attributes) is made."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.domain import SafeDomain
from geovs_drake.geometry.navigation import NavigationFunction, NavigationGains
from geovs_drake.scenario import LawConfig, ScenarioConfig

__all__ = ["GoalInputs"]


class GoalInputs(Protocol):
    """A resolved scenario as the goal's models read it: the validated ``config`` (the
    law's gains already scaled), its ``law``, the ``damping`` B the loop runs with, the
    ``believed_radius``, D (``domain``), y* (``y_goal``), the NF (``nf``, with its
    ``gains``) and its chart Hessian at y* (``hessian``), and ``gain_scale``, the factor
    the arm's gains were scaled by (1 elsewhere)."""

    config: ScenarioConfig
    law: LawConfig
    damping: tuple[float, ...]
    believed_radius: float
    domain: SafeDomain
    y_goal: ImageFeatures
    gains: NavigationGains
    nf: NavigationFunction
    hessian: np.ndarray
    gain_scale: float
