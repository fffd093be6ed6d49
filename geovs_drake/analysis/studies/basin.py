"""Basin maps: one 2-D slice of starts through the batch engine.

The slice is the camera on the optical axis of the marked point, at distance
``d`` and rolled by ``roll`` about that axis: ``X_BC = (Rz(roll), (0, 0, -d))``,
at rest. The goal is roll 0 at the goal distance; roll = +-pi at the goal
distance is the NF's saddle (the arrow reversed, phi = circle_weight), and the
whole line roll = +-pi is its stable manifold within this slice: by symmetry
those starts reach the saddle, not the goal. Every other start converges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

from geovs_drake.batch import BatchResult, run_batch
from geovs_drake.scenario import ScenarioConfig

__all__ = ["BasinMap", "roll_distance_map"]


@dataclass
class BasinMap:
    """A basin map: the batch engine's result on a roll x distance grid of starts.

    Attributes:
        rolls: the rolls about the optical axis, (n_roll,) [rad].
        distances: the distances from the sphere's centre, (n_distance,) [m].
        result: one start per grid point, row-major: roll index, then distance index.
    """

    rolls: np.ndarray  # (n_roll,) [rad]
    distances: np.ndarray  # (n_distance,) [m]
    result: BatchResult  # starts in row-major order: roll index, then distance index

    def grid(self, values: np.ndarray) -> np.ndarray:
        """Per-start values as an (n_roll, n_distance) grid."""
        return np.asarray(values).reshape(len(self.rolls), len(self.distances))


def roll_distance_map(
    config: ScenarioConfig,
    n_roll: int = 100,
    n_distance: int = 100,
    duration: float | None = None,
    inset: float = 0.02,
) -> BasinMap:
    """Run the batch engine on the roll x distance slice (module docstring).

    Distances span D's lambda interval, ``rho / lam_max`` to ``rho / lam_min``,
    each end moved in by ``inset`` of the span; rolls span [-pi, pi], both
    ends included (the same pose, on the saddle's line).
    """
    if n_roll < 2 or n_distance < 2:
        raise ValueError(f"need at least a 2 x 2 grid, got {n_roll} x {n_distance}")
    domain = config.domain.to_domain()
    near, far = config.radius / domain.lam_max, config.radius / domain.lam_min
    span = far - near
    distances = np.linspace(near + inset * span, far - inset * span, n_distance)
    rolls = np.linspace(-np.pi, np.pi, n_roll)
    X_BC = np.stack(
        [
            RigidTransform(RollPitchYaw(0.0, 0.0, r), [0.0, 0.0, -d]).GetAsMatrix4()
            for r in rolls
            for d in distances
        ]
    )
    return BasinMap(rolls, distances, run_batch(config, X_BC, duration=duration))
