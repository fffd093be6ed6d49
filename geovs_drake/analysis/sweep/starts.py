"""The sweep's starts, drawn where they run: start i depends on (seed, i) only.

Starts come in blocks of :data:`START_BLOCK`. Block b is drawn from its own
stream, numpy's ``SeedSequence(seed, spawn_key=(b,))`` (the b-th child of
``SeedSequence(seed)``: independent streams by construction, see numpy's
"Parallel random number generation"), always whole. A task that runs starts
[a, b) draws the blocks it overlaps and keeps its slice, so start i is the same
bits whatever ``--starts``, ``--workers`` or ``--chunk``, and the client ships
no arrays: a task's starts cost it one (seed, range) pair.

The distribution is that of each block: images uniform in D's model chart
(:func:`~geovs_drake.sampling.random_features_in_domain` at :data:`SHRINK`),
mapped back by ``c^-1`` (Eq. 23), and, with a velocity, a twist whose direction
is uniform on the unit sphere of R^6 and whose kinetic energy is set against
the room below Appendix C's energy bound.

A carrier that holds a level hover only (``traits.hover``: the quadrotor) starts level
and at rest: each drawn pose is levelled (:func:`level_poses`: the start the carrier
takes with ``initial_attitude: level``, the camera's position and the body's heading
kept, its roll and pitch zeroed), a levelled pose outside D is dropped, and the block's
stream draws again until the block is full.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform

from geovs_drake.batch import LoopParameters, loop_parameters
from geovs_drake.geometry import kernels
from geovs_drake.geometry.camera import camera_map, camera_map_inverse
from geovs_drake.loop.state import initial_body_states
from geovs_drake.sampling import random_features_in_domain
from geovs_drake.scenario import ScenarioConfig
from geovs_drake.scenario.carriers import level_start

__all__ = [
    "ABOVE_RANGE",
    "ENERGY_FACTOR",
    "LEVEL_DRAWS",
    "SHRINK",
    "START_BLOCK",
    "VELOCITIES",
    "SampledStarts",
    "SweepError",
    "kinetic_energy",
    "level_poses",
    "sample_starts",
]

#: Starts per random block (module docstring). It divides the default chunk (1000),
#: so a default task draws exactly its own starts.
START_BLOCK = 100
#: The model chart is sampled in a ball of this radius (1 is the boundary of D): a
#: start on the boundary itself has phi0 = 1 and no room below the energy bound.
SHRINK = 0.95
#: The kinetic energy of a bounded start is this fraction, at most, of the room
#: k_p (1 - phi0) below the bound: strictly below 1, so E0 < k_p holds with a margin
#: that rounding cannot eat.
ENERGY_FACTOR = 0.99
#: With ``velocity="above"``: E0 / k_p is drawn uniformly in this interval, outside
#: the guarantee, to show how often the loop then leaves D.
ABOVE_RANGE = (1.5, 4.0)
#: none: at rest; bounded: E0 < k_p (the guarantee's starts); above: E0 / k_p in ABOVE_RANGE.
VELOCITIES = ("none", "bounded", "above")


class SweepError(ValueError):
    """A sweep's settings are wrong, its folder does not match, or its scheduler cannot
    be reached (one line, naming the condition and its value)."""


@dataclass(frozen=True)
class SampledStarts:
    """N starts drawn from ``seed`` (module docstring): what a sweep's tasks draw."""

    n: int
    seed: int = 0
    velocity: str = "none"

    def check(self, config: ScenarioConfig) -> None:
        """SweepError for an N below 1, a seed that is no integer >= 0, an unknown
        velocity, or a velocity on the first-order kinematic loop."""
        if not (isinstance(self.n, int | np.integer) and self.n >= 1):
            raise SweepError(f"the number of starts must be an integer >= 1: n = {self.n!r}")
        if not (isinstance(self.seed, int | np.integer) and self.seed >= 0):
            raise SweepError(f"the seed must be an integer >= 0: seed = {self.seed!r}")
        if self.velocity not in VELOCITIES:
            raise SweepError(f"velocity must be one of {VELOCITIES}: velocity = {self.velocity!r}")
        if self.velocity != "none" and not config.dynamic:
            raise SweepError(
                f"velocity {self.velocity!r} needs the dynamic plant (the kinematic loop is "
                f"first order and starts at rest): plant = {type(config.plant).__name__}()"
            )
        if self.velocity != "none" and config.carrier.traits.hover:
            raise SweepError(
                f"velocity {self.velocity!r}: a {type(config.carrier).__name__} starts at rest "
                "in a level hover (velocity 'none'), and Appendix C's energy bound that the "
                "velocities probe does not cover it"
            )


def sample_starts(
    config: ScenarioConfig,
    n: int,
    seed: int = 0,
    velocity: str = "none",
    first: int = 0,
    parameters: LoopParameters | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Starts ``first .. first + n - 1``: camera poses X_BC (n, 4, 4) and body twists
    (Omega, V) in C (n, 6).

    This samples the *image space*, not poses, so every start is in D by construction
    and the poses are spread the way D is parametrised, not uniformly in SE(3).

    ``velocity="bounded"`` (dynamic loop only) gives each start a twist whose
    kinetic energy KE is uniform in [0, k_p (1 - phi0)) times :data:`ENERGY_FACTOR`,
    so that E0 = k_p phi0 + KE < k_p: every start is one Appendix C's guarantee
    covers. ``velocity="above"`` draws E0 / k_p uniformly in :data:`ABOVE_RANGE`
    instead: starts the guarantee does not cover. KE is quadratic in the twist's
    scale, so the scale is sqrt(KE / KE1) with KE1 the kinetic energy of the unit
    twist, from the rig's state and the ``free_body`` kernel (the loop's own formulas).

    ``parameters``: :func:`~geovs_drake.batch.loop_parameters` of ``config``, to skip
    building its diagram (a worker passes its cached copy).
    """
    SampledStarts(n, seed, velocity).check(config)
    if not (isinstance(first, int | np.integer) and first >= 0):
        raise SweepError(f"the first start must be an integer >= 0: first = {first!r}")
    if velocity != "none" and parameters is None:
        parameters = loop_parameters(config)
    blocks = range(first // START_BLOCK, (first + n - 1) // START_BLOCK + 1)
    drawn = [_block(config, seed, b, velocity, parameters) for b in blocks]
    X_BC = np.concatenate([d[0] for d in drawn])
    twists = np.concatenate([d[1] for d in drawn])
    offset = first - blocks[0] * START_BLOCK
    return X_BC[offset : offset + n], twists[offset : offset + n]


def _block(
    config: ScenarioConfig, seed: int, block: int, velocity: str, p: LoopParameters | None
) -> tuple[np.ndarray, np.ndarray]:
    """Block ``block`` of ``seed``'s starts, whole (module docstring)."""
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(block),)))
    if config.carrier.traits.hover:
        return _level_block(config, rng), np.zeros((START_BLOCK, 6))
    y = random_features_in_domain(rng, START_BLOCK, config.domain.to_domain(), shrink=SHRINK)
    X_BC = _inverse(camera_map_inverse(y, config.radius))
    twists = np.zeros((START_BLOCK, 6))
    if velocity == "none":
        return X_BC, twists
    phi0 = np.asarray(
        kernels.navigation(tuple(y.to_vector().T), p.navigation)[kernels.NAVIGATION.phi]
    )
    direction = rng.normal(size=(START_BLOCK, 6))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    kinetic_unit = kinetic_energy(config, p, X_BC, direction)
    if velocity == "above":
        kinetic = p.potential_gain * (rng.uniform(*ABOVE_RANGE, size=START_BLOCK) - phi0)
    else:
        room = p.potential_gain * (1.0 - phi0)
        kinetic = ENERGY_FACTOR * rng.uniform(0.0, 1.0, size=START_BLOCK) * room
    return X_BC, direction * np.sqrt(kinetic / kinetic_unit)[:, None]


#: How many times a levelled block draws again before giving up: with the default scene's
#: forward mount 40 % of the levelled poses stay in D (1000 drawn), so a block fills in
#: three draws; a mount that sees almost none of D fails in one line instead of looping.
LEVEL_DRAWS = 50


def level_poses(config: ScenarioConfig, X_BC: np.ndarray) -> np.ndarray:
    """The camera poses X_BC (n, 4, 4) of the level bodies nearest ``X_BC``'s: each the
    start the carrier itself takes from it with ``initial_attitude: level``
    (:func:`~geovs_drake.scenario.carriers.level_start`, one definition: the camera's
    position and the body's heading kept, its roll and pitch zeroed)."""
    return np.stack(
        [
            level_start(config.carrier, config.X_WB, RigidTransform(X))[0].GetAsMatrix4()
            for X in np.asarray(X_BC, dtype=float)
        ]
    )


def _in_domain(config: ScenarioConfig, X_BC: np.ndarray) -> np.ndarray:
    """Whether each camera pose's image c(X_CB) lies in D (a pose that does not see the
    target is not)."""
    domain = config.domain.to_domain()
    inside = np.zeros(len(X_BC), dtype=bool)
    for i, X_CB in enumerate(_inverse(X_BC)):
        try:
            inside[i] = bool(domain.contains(camera_map(X_CB, config.radius)))
        except ValueError:  # not visible: nu(H) <= 0
            inside[i] = False
    return inside


def _level_block(config: ScenarioConfig, rng: np.random.Generator) -> np.ndarray:
    """A block of level starts in D (module docstring): the block's stream draws images
    in D, they are levelled, those outside D dropped, until :data:`START_BLOCK` remain."""
    kept: list[np.ndarray] = []
    count = 0
    for _ in range(LEVEL_DRAWS):
        y = random_features_in_domain(rng, START_BLOCK, config.domain.to_domain(), shrink=SHRINK)
        X_BC = level_poses(config, _inverse(camera_map_inverse(y, config.radius)))
        X_BC = X_BC[_in_domain(config, X_BC)]
        kept.append(X_BC)
        count += len(X_BC)
        if count >= START_BLOCK:
            return np.concatenate(kept)[:START_BLOCK]
    raise SweepError(
        f"level starts: {count} of {LEVEL_DRAWS * START_BLOCK} levelled poses stay in D "
        "with this carrier and its camera's mount: too few to draw a sweep"
    )


def _inverse(X: np.ndarray) -> np.ndarray:
    """Inverses of homogeneous transforms (N, 4, 4): [R^T, -R^T p]."""
    R_T = np.swapaxes(X[:, :3, :3], 1, 2)
    out = np.zeros_like(X)
    out[:, :3, :3] = R_T
    out[:, :3, 3] = -np.einsum("nij,nj->ni", R_T, X[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def kinetic_energy(
    config: ScenarioConfig, p: LoopParameters, X_BC: np.ndarray, twists: np.ndarray
) -> np.ndarray:
    """1/2 nu^T M nu of the rig for camera poses and twists (the ``free_body`` kernel)."""
    states = initial_body_states(config, X_BC, twists)
    zero_force = tuple(np.zeros(6))
    return np.asarray(
        kernels.free_body(tuple(states.T), zero_force, tuple(p.body))[
            kernels.FREE_BODY.kinetic_energy
        ]
    )
