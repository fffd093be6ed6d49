"""How well the path follower of Eq. (18) tracks its plan, with and without model error.

The truth of each run is its own plan: ``y_d(t)`` of
:func:`~geovs_drake.planning.plan_for_scenario`, compared with the image the
camera saw, factor by factor, as the three geodesic distances of
:func:`~geovs_drake.geometry.image_path.image_distance` (rotation angle of
``Q_d Q^T`` [rad], ``|lambda_d - lambda|``, angle between s and s_d [rad]).
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass

import numpy as np

from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.image_path import image_distance
from geovs_drake.planning import PathPlan, plan_for_scenario
from geovs_drake.scenario import (
    Dynamic,
    Kinematic,
    PathFollowing,
    ScenarioConfig,
    variant_name,
)
from geovs_drake.simulation import SimulationResult, simulate

__all__ = ["ERROR_NAMES", "TrackingRun", "follow_path", "model_error_study", "tracking_errors"]

#: The columns of :func:`tracking_errors`.
ERROR_NAMES = ("rotation [rad]", "lambda", "s angle [rad]")


def tracking_errors(result: SimulationResult, plan: PathPlan) -> np.ndarray:
    """(N, 3) geodesic errors between the logged image and ``y_d`` at the log's times."""
    desired, _ = plan.desired(result.times)
    return image_distance(
        ImageFeatures.from_vector(result.image_features), ImageFeatures.from_vector(desired)
    )


@dataclass
class TrackingRun:
    """One run of the path follower and its errors against the plan."""

    label: str
    result: SimulationResult
    plan: PathPlan
    errors: np.ndarray  # (N, 3), columns ERROR_NAMES

    @property
    def times(self) -> np.ndarray:
        """The log's sample times [s]."""
        return self.result.times

    @property
    def max_errors(self) -> np.ndarray:
        """The largest of each error over the run."""
        return self.errors.max(axis=0)

    @property
    def final_errors(self) -> np.ndarray:
        """Each error at the end of the run (the plan then holds y*)."""
        return self.errors[-1]

    def line(self) -> str:
        """The run in one line: the errors' maxima and final values, the pose error."""
        m, f = self.max_errors, self.final_errors
        dp, dr = self.result.final_errors
        return (
            f"{self.label}: max error along the path: rotation {m[0]:.2e} rad, lambda "
            f"{m[1]:.2e}, s {m[2]:.2e} rad | at the end: {f[0]:.2e}, {f[1]:.2e}, {f[2]:.2e} | "
            f"camera pose error {dp:.2e} m, {dr:.2e} rad | {self.result.status}"
        )


def follow_path(config: ScenarioConfig, label: str = "") -> TrackingRun:
    """Simulate ``config`` (``controller: !PathFollowing``) and compare the image with its
    plan."""
    if not config.controller.traits.plans:
        raise ValueError(
            f"follow_path needs controller PathFollowing, got {variant_name(config.controller)}"
        )
    result = simulate(config)
    plan = plan_for_scenario(config)
    return TrackingRun(
        label or variant_name(config.plant), result, plan, tracking_errors(result, plan)
    )


def model_error_study(
    config: ScenarioConfig | None = None, radius_scale: float = 1.1, gain: float = 2.0
) -> dict[str, TrackingRun]:
    """Open loop against feedback, with an exact model and with model errors.

    Runs (each the path follower on ``config``'s start, goal and path duration):

    * ``kinematic, exact, open loop``: Eq. (18) as written on the plant it
      assumes; tracks to the integrator's accuracy;
    * ``kinematic, rho x{radius_scale}, open loop`` and ``... feedback k``:
      the controller's radius off (its Tc^-1 scales the translation wrongly);
    * ``dynamic, open loop`` and ``dynamic, feedback k``: the kinematic law
      on the free body through the velocity-tracking wrench, whose lag the law
      does not model.
    """
    base = copy.deepcopy(config or ScenarioConfig())
    if not base.controller.traits.plans:
        base.controller = PathFollowing()
    runs: dict[str, TrackingRun] = {}
    cases = [
        (Kinematic(), 1.0, 0.0, "kinematic, exact, open loop"),
        (Kinematic(), radius_scale, 0.0, f"kinematic, rho x{radius_scale:g}, open loop"),
        (Kinematic(), radius_scale, gain, f"kinematic, rho x{radius_scale:g}, feedback k={gain:g}"),
        (Dynamic(), 1.0, 0.0, "dynamic, open loop"),
        (Dynamic(), 1.0, gain, f"dynamic, feedback k={gain:g}"),
    ]
    for plant, scale, k, label in cases:
        c = copy.deepcopy(base)
        c.plant = plant
        c.controller = dataclasses.replace(c.controller, radius_scale=scale, feedback_gain=k)
        runs[label] = follow_path(c, label)
    return runs
