"""What each variant of a loop's axes can do, declared once on the variant itself.

Every variant class carries a ``traits`` class attribute (a frozen record below): the
rest of the package asks ``config.carrier.traits.joints``, never ``isinstance(carrier,
Arm)``. So a new variant declares what it can do in one place, and the code that
branches on a capability needs no edit for it (docs/adding-a-part).
"""

from dataclasses import dataclass

__all__ = [
    "CarrierTraits",
    "LawTraits",
    "PlantTraits",
    "SensorTraits",
    "TargetTraits",
    "traits_of",
]


@dataclass(frozen=True)
class CarrierTraits:
    """What a carrier is and takes.

    ``camera_in_hand``: the camera rides the carrier and the target stands in the world
    (eye-in-hand); False: the camera is fixed in the world and the carrier drives the
    target (eye-to-hand, the laws see G = H^-1, Eq. 16). ``joints``: a chain of joints
    (IK, joint limits, M(q), J_C(q)): the arm's reports and checks apply.
    ``rigid_body_goal``: the closed-form model at the goal of the rigid body of
    Appendix C (:mod:`geovs_drake.goal.linear_model`) is this carrier's. ``goal_model``:
    some model at the goal covers it (the rigid body's, or the arm's through J_C), so
    the camera fit and the step limit apply. ``moving_target``: it can follow a moving
    target. ``batch_kernel``: the batch engine integrates it. ``gain_scale``: it has a
    ``gain_scale`` field that scales the law's gains (``auto``: fitted by the resolver).
    ``effort_limits``: its dynamic plant clamps torques at effort limits (the effort
    check applies). ``takes``: what it takes on each plant (by the plant's name).
    ``energy_exclusion``: why Appendix C's energy argument does not cover a loop on this
    carrier, in a phrase (the run's ``energy_guarantee`` is then null with it), or empty.
    ``turning_target``: where it follows a moving target, it follows one that turns too
    (False: a translating one only, the quadrotor's, whose cascade holds the goal's
    heading and a level hover). ``rotors``: a law may drive its rotors itself (a law
    whose traits' ``commands`` is ``"rotors"``, Hamel & Mahony's on the quadrotor).
    ``integration_scheme``: Drake's integrator for a loop on this carrier where the
    scenario leaves ``simulator.integration_scheme`` unset (the resolver fills it);
    ``dynamic_integration_scheme``: the same on a dynamic plant under the NF's law, where
    it differs (empty: ``integration_scheme`` on both plants and under every law).
    ``hover``: it flies and holds a level hover only (the quadrotor): its start is a
    position and a heading, the body level, so a sweep draws its starts level and at
    rest, and its runs report the rotors' saturation and the peak tilt (the sweep's
    :data:`~geovs_drake.analysis.sweep.parts.HOVER_FIELDS`)."""

    camera_in_hand: bool
    joints: bool
    rigid_body_goal: bool
    goal_model: bool
    moving_target: bool
    batch_kernel: bool
    gain_scale: bool
    effort_limits: bool
    takes: tuple[tuple[str, str], ...]
    energy_exclusion: str = ""
    turning_target: bool = True
    rotors: bool = False
    integration_scheme: str = "runge_kutta3"
    dynamic_integration_scheme: str = ""
    hover: bool = False


@dataclass(frozen=True)
class PlantTraits:
    """How a plant drives its carrier. ``dynamic``: second order (a wrench or joint
    torques, Appendix C; the state holds velocities); else first order (the velocity is
    commanded, Eqs. 17-19)."""

    dynamic: bool


@dataclass(frozen=True)
class SensorTraits:
    """What a sensor is. ``camera``: a camera model (a rate, latency, its own damping:
    :class:`~geovs_drake.scenario.CameraModel`'s fields), so the sampled-data fit
    applies; ``renders``: it draws the scene (a renderer, label images); ``batch_kernel``:
    the batch engine runs it."""

    camera: bool
    renders: bool
    batch_kernel: bool


@dataclass(frozen=True)
class LawTraits:
    """What a law is. ``navigation``: the navigation function's own law (Eq. 45 or Eqs.
    18-19): its energy bound, its saddle, its model at the goal and the gain fits belong
    to it; ``commands``: what it commands a carrier (``"wrench"`` on a force-driven
    carrier where ``navigation``, ``"rotors"``: the rotor thrusts of a carrier whose
    traits have ``rotors``, else ``"twist"``); ``plans``: it follows a planned
    image path in time (no constant-twist steady state); ``batch_kernel``: the batch
    engine runs it; ``feature_points``: it servos on image points that must stay in view
    (point IBVS), checked besides D; ``depth_label``: its field that names a variant of
    it in tables (IBVS's ``depth``), or empty."""

    navigation: bool
    commands: str
    plans: bool
    batch_kernel: bool
    feature_points: bool = False
    depth_label: str = ""


@dataclass(frozen=True)
class TargetTraits:
    """How a target moves. ``moving``: it moves; ``constant_twist``: with a constant body
    twist (a steady lag exists, :func:`~geovs_drake.goal.linear_model.tracking_lag`)."""

    moving: bool
    constant_twist: bool


def traits_of(variant: object):
    """``variant``'s traits (its class's ``traits``), or ValueError in one line for a part
    that declares none."""
    traits = getattr(type(variant), "traits", None)
    if traits is None:
        raise ValueError(
            f"{type(variant).__name__} declares no traits: give its class a ``traits`` "
            "class attribute (geovs_drake.scenario.traits, docs/adding-a-part)"
        )
    return traits
