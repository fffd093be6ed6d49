"""Monte-Carlo studies of the closed loops over random starts in D.

Two engines over the same diagrams:

* :func:`run_scenarios`: one :func:`~geovs_drake.simulation.simulate` per
  start, optionally across processes (pydrake's Python systems hold the GIL, so
  threads would not help). Configs cross the process boundary as YAML, since
  ``SimulatorConfig`` does not pickle.
* :func:`drake_monte_carlo`: Drake's own ``MonteCarloSimulation``. Each sample's
  start is drawn from Drake's ``RandomGenerator`` inside ``make_simulator``
  and built into the diagram as the free body's *default* pose, because
  ``SetRandomContext`` (which RandomSimulation calls) would reset a state set
  on the context.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.math import RigidTransform
from pydrake.systems.analysis import MonteCarloSimulation

from geovs_drake.analysis._pool import map_scenarios
from geovs_drake.geometry.camera import camera_map_inverse
from geovs_drake.loop.build import build_loop
from geovs_drake.sampling import random_features_in_domain
from geovs_drake.scenario import PlantConfig, PoseConfig, ScenarioConfig
from geovs_drake.simulation import camera_pose_in_target, make_simulator, pose_error, simulate

__all__ = [
    "drake_monte_carlo",
    "random_initial_poses",
    "run_scenarios",
    "scenarios_from_starts",
]


def random_initial_poses(
    rng: np.random.Generator, n: int, config: ScenarioConfig, shrink: float = 0.95
) -> list[PoseConfig]:
    """Random camera poses X_BC whose images lie in D (uniform in D's model chart)."""
    y = random_features_in_domain(rng, n, config.domain.to_domain(), shrink=shrink)
    X_CB = camera_map_inverse(y, config.radius)
    return [PoseConfig.from_rigid_transform(RigidTransform(X).inverse()) for X in X_CB]


def scenarios_from_starts(
    config: ScenarioConfig, starts: Iterable[PoseConfig], plant: PlantConfig | None = None
) -> list[ScenarioConfig]:
    """A copy of ``config`` per start pose X_BC (and ``plant`` if given), in order."""
    out = []
    for pose in starts:
        c = copy.deepcopy(config)
        c.initial = pose
        if plant is not None:
            c.plant = copy.deepcopy(plant)
        out.append(c)
    return out


def _summary(config: ScenarioConfig) -> dict:
    return simulate(config).summary()


def run_scenarios(configs: list[ScenarioConfig], processes: int = 1) -> list[dict]:
    """Simulate each config; return each run's summary dict (in order).

    With ``processes > 1`` the runs go to a pool of freshly *spawned* Python
    processes (forking a process that may hold Meshcat's server thread is not
    safe). A script that calls this must therefore guard its entry point with
    ``if __name__ == "__main__":``; notebooks need nothing.
    """
    return list(map_scenarios(_summary, [(c,) for c in configs], processes))


def drake_monte_carlo(
    config: ScenarioConfig, num_samples: int, seed: int = 0, shrink: float = 0.95
) -> list[dict]:
    """Drake's MonteCarloSimulation over random starts in D (serial, in-process).

    Each result has the start X_BC(0), the final position and rotation errors
    and the smallest domain margin seen at the end.
    """
    starts: list[PoseConfig] = []

    def make(generator: RandomGenerator):
        rng = np.random.default_rng(generator())
        c = copy.deepcopy(config)
        c.initial = random_initial_poses(rng, 1, config, shrink)[0]
        starts.append(c.initial)
        simulator, _ = make_simulator(build_loop(c, log=False))
        return simulator

    outputs: list[dict] = []

    def output(system, context) -> float:
        camera = system.GetSubsystemByName("spherical_camera")
        ctx = camera.GetMyContextFromRoot(context)
        margins = camera.domain_margins_output.Eval(ctx)
        x = context.get_continuous_state_vector().CopyToVector()
        X_BC = camera_pose_in_target(config, x, config.dynamic)
        dp, dr = pose_error(X_BC, config.X_BC_goal)
        outputs.append(
            dict(position_error_m=dp, rotation_error_rad=dr, min_margin=float(min(margins)))
        )
        return dp

    results = MonteCarloSimulation(
        make_simulator=make,
        output=output,
        final_time=config.duration,
        num_samples=num_samples,
        generator=RandomGenerator(seed),
    )
    for r, o, s in zip(results, outputs, starts, strict=True):
        o["start"] = s
        o["output"] = r.output
    return outputs
