"""The control laws, one variant each (``ScenarioConfig.controller``).

Each law holds its own fields; in YAML a law is tagged with its class name, as in
Drake's hardware_sim scenarios: ``controller: !Ibvs {depth: mean}``. A scenario file's
bare name (``controller: ibvs``) reads as that variant with its defaults
(:func:`~geovs_drake.scenario.load_scenario`); in Python the law is always its variant,
and the code asks ``isinstance``: the loop takes each law's systems from
:data:`geovs_drake.loop.laws.LAWS`, keyed by the variant's type.
"""

import math
from dataclasses import dataclass
from typing import ClassVar

from geovs_drake.geometry.baselines import IBVS_DEPTHS
from geovs_drake.scenario.traits import LawTraits

__all__ = [
    "CONTROLLERS",
    "HamelMahony",
    "IBVS_DEPTHS",
    "LAW_VARIANTS",
    "Ibvs",
    "LawConfig",
    "Nf",
    "PathFollowing",
    "Pbvs",
    "Spherical",
    "check_law",
]

#: The control laws (``ScenarioConfig.controller``): the navigation function
#: ("nf"), the baselines point IBVS, PBVS and sphere features
#: (:mod:`geovs_drake.geometry.baselines`), the path follower, and Hamel & Mahony's
#: law for the quadrotor ("hamel_mahony").
CONTROLLERS = ("nf", "ibvs", "pbvs", "spherical", "path", "hamel_mahony")


@dataclass
class Nf:
    """The navigation function: Eq. (45)'s wrench on a force-driven carrier, the
    twist ``-Tc^-1 grad phi`` (Eqs. 18-19) on a twist-driven one. Its gains are
    ``control.potential_gain``, the damping and ``control.kinematic_gain``."""

    traits: ClassVar[LawTraits] = LawTraits(
        navigation=True, commands="wrench", plans=False, batch_kernel=True
    )


@dataclass
class Ibvs:
    """Point IBVS on four points (:mod:`geovs_drake.geometry.baselines`). ``depth``:
    "true" (the current interaction matrix with the true depths, from c^-1(y)),
    "desired" (the matrix at the goal, L_e*) or "mean" ((L_e + L_e*) / 2).

    Behind a moving target (``target_motion``) it adds Chaumette & Hutchinson's
    (2007, Part II) ``-L^+ de/dt`` for the twist the loop believes
    (:func:`~geovs_drake.systems.ibvs_controller.ibvs_target_term`)."""

    depth: str = "true"

    traits: ClassVar[LawTraits] = LawTraits(
        navigation=False,
        commands="twist",
        plans=False,
        batch_kernel=False,
        feature_points=True,
        depth_label="depth",
    )


@dataclass
class Pbvs:
    """PBVS on ``(c*t_c, theta u)``, the pose from c^-1(y) (Eq. 23). Behind a moving
    target it adds the believed twist carried to C (the loop's feed-forward,
    :mod:`geovs_drake.loop.targets`)."""

    traits: ClassVar[LawTraits] = LawTraits(
        navigation=False, commands="twist", plans=False, batch_kernel=False
    )


@dataclass
class Spherical:
    """The sphere features ``(s / lambda, theta u)`` and their interaction matrix."""

    traits: ClassVar[LawTraits] = LawTraits(
        navigation=False, commands="twist", plans=False, batch_kernel=False
    )


@dataclass
class PathFollowing:
    """The path follower (Sec. 4, Eq. 18).

    The planner plans y_d(t) from y(0) to y* in ``duration`` seconds (geodesic
    in I, quintic time law; if that leaves D and ``fallback``, the NF's
    gradient flow). ``feedback_gain`` k [1/s] adds ``k log_y(y_d)`` to the
    feed-forward; 0 is Eq. (18) as written, open loop. ``radius_scale`` scales
    the radius the follower believes (1: the loop's believed radius; 1.1: rho
    off by 10% more, a model error).
    """

    duration: float = 8.0
    feedback_gain: float = 2.0
    fallback: bool = True
    radius_scale: float = 1.0

    traits: ClassVar[LawTraits] = LawTraits(
        navigation=False, commands="twist", plans=True, batch_kernel=False
    )


@dataclass
class HamelMahony:
    """Hamel & Mahony's image-based law for an underactuated body (IEEE TRA 18(2),
    2002), the quadrotor's only (:class:`~geovs_drake.systems.HamelMahonyController`):
    the sphere's spherical centroid q, the thrust vector ``k_1 k_2 W (q_W - q*_W) - m k_2
    v + m g e_z`` to the cascade's attitude loop and rotors, the heading from the marked
    point and the arrow. ``image_gain`` k_1 [N s], ``velocity_gain`` k_2 [1/s] (with the
    default quadrotor and goal, a double pole at -2 rad/s laterally; their gain condition
    ``k_2 > (k_1 / m) f / d`` holds by a factor of 4), ``depth_balance`` [-] (1: the
    depth as stiff as the lateral motion at the goal; 0: the paper's W = I, whose depth
    converges about 50 times slower)."""

    image_gain: float = 0.4
    velocity_gain: float = 4.0
    depth_balance: float = 1.0

    traits: ClassVar[LawTraits] = LawTraits(
        navigation=False, commands="rotors", plans=False, batch_kernel=False
    )


#: A law's configuration: one of the variants above.
LawConfig = Nf | Ibvs | Pbvs | Spherical | PathFollowing | HamelMahony
#: The law of each name in :data:`CONTROLLERS` (``path`` is :class:`PathFollowing`).
LAW_VARIANTS: dict[str, type] = {
    "nf": Nf,
    "ibvs": Ibvs,
    "pbvs": Pbvs,
    "spherical": Spherical,
    "path": PathFollowing,
    "hamel_mahony": HamelMahony,
}


def _check_fields(law: object, fields: tuple[tuple[str, bool, str], ...]) -> None:
    """Each ``(name, strict, unit)``: the law's field finite and > 0 (strict) or >= 0."""
    for name, strict, unit in fields:
        value = getattr(law, name)
        if not (math.isfinite(value) and (value > 0 if strict else value >= 0)):
            raise ValueError(
                f"controller.{name} must be finite and {'>' if strict else '>='} 0{unit}: "
                f"{name} = {value}"
            )


def check_law(law: object) -> None:
    """The law variant's own fields, each named ``controller.<field>``."""
    if isinstance(law, Ibvs) and law.depth not in IBVS_DEPTHS:
        raise ValueError(
            f"controller.depth must be one of {', '.join(IBVS_DEPTHS)}, got {law.depth!r}"
        )
    if isinstance(law, HamelMahony):
        _check_fields(
            law,
            (
                ("image_gain", True, " [N s]"),
                ("velocity_gain", True, " [1/s]"),
                ("depth_balance", False, ""),
            ),
        )
    if isinstance(law, PathFollowing):
        _check_fields(
            law,
            (
                ("duration", True, " [s]"),
                ("feedback_gain", False, " [1/s]"),
                ("radius_scale", True, ""),
            ),
        )
