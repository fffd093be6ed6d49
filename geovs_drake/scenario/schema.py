"""The scenario's schema: dataclasses loadable with Drake's ``yaml_load_typed``, each
with its own checks, and the quantities derived from them.

A loop is carrier + sensor + law on a plant, and each of the four is a typed union
(:mod:`~geovs_drake.scenario.carriers`, :mod:`~geovs_drake.scenario.sensors`,
:mod:`~geovs_drake.scenario.laws`, :mod:`~geovs_drake.scenario.plants`): in YAML,
``carrier: !Arm {model: panda}``, ``sensor: !Pinhole {rate: 15}``,
``controller: !Ibvs {depth: mean}``, ``plant: !Kinematic {}``. Each variant holds its
own fields, so a field that does not apply to a variant cannot be written.

Defaults are the project's default scenario: rho = 0.1 m, theta = 35 deg,
lambda in [0.05, 0.4], kappa = 0.1, goal X_BC* = translation (0, 0, -0.5) with
identity rotation (so y* has q1 = s = e3, q2 = e2, lambda* = 0.2), a 1 kg
camera rig, gravity off (the paper's Appendix C assumes it cancelled).

Poses of the camera are given in the *target* frame B, as X_BC (metres,
radians, Drake's RollPitchYaw), the natural way to say where the camera is.
"""

import dataclasses
import math
from dataclasses import dataclass, field

from pydrake.math import RigidTransform
from pydrake.systems.analysis import GetIntegrationSchemes, SimulatorConfig

from geovs_drake.geometry.camera import ImageFeatures, camera_map
from geovs_drake.geometry.domain import SafeDomain
from geovs_drake.geometry.navigation import NavigationGains
from geovs_drake.scenario.carriers import (
    CARRIER_VARIANTS,
    Arm,
    FixedCamera,
    FreeRig,
    Quadrotor,
    check_carrier,
    check_quadrotor_scenario,
)
from geovs_drake.scenario.laws import (
    LAW_VARIANTS,
    HamelMahony,
    Ibvs,
    Nf,
    PathFollowing,
    Pbvs,
    Spherical,
    check_law,
)
from geovs_drake.scenario.plants import PLANT_VARIANTS, Dynamic, Kinematic
from geovs_drake.scenario.pose import PoseConfig, check_at_least, finite_numbers
from geovs_drake.scenario.sensors import (
    SENSOR_VARIANTS,
    CameraModel,
    Exact,
    Pinhole,
    Rendered,
    check_sensor,
    radius_error_of,
)
from geovs_drake.scenario.targets import (
    TARGET_VARIANTS,
    Still,
    Trajectory,
    Twist,
    check_target_motion,
)

__all__ = [
    "DEFAULT_MAX_STEP",
    "ControlConfig",
    "DomainConfig",
    "NavigationGainsConfig",
    "ScenarioConfig",
    "SimulatorSettings",
    "damping_of",
    "variant_name",
]

#: Every axis of a loop: the ScenarioConfig field, and its variants by name (the names
#: ``--carrier``, ``--plant``, ``--sensor`` and ``--controller`` take, and a file's bare
#: name). The variants' YAML tags are their class names.
AXES: dict[str, dict[str, type]] = {
    "carrier": CARRIER_VARIANTS,
    "plant": PLANT_VARIANTS,
    "sensor": SENSOR_VARIANTS,
    "controller": LAW_VARIANTS,
    "target_motion": TARGET_VARIANTS,
}


def variant_name(variant: object) -> str:
    """A variant's name (``"pinhole"`` for ``Pinhole(...)``): the name its axis gives it
    in :data:`AXES`, or its class's name for a part a user registered."""
    for variants in AXES.values():
        for name, kind in variants.items():
            if type(variant) is kind:
                return name
    return type(variant).__name__


#: The geometry's own defaults (the default scenario's D and NF), which the configs below
#: read: each default is written once, in its geometry dataclass.
_DOMAIN, _GAINS = SafeDomain(), NavigationGains()


@dataclass
class DomainConfig:
    """The safe domain D: the field of view's half-angle [deg], the bounds on
    ``lambda = rho / |p_CB|`` (distance from ``radius / lam_max`` to ``radius / lam_min``),
    and the occlusion margin kappa in (0, 1) (see :class:`~geovs_drake.geometry.domain.SafeDomain`).
    """

    fov_half_angle_deg: float = math.degrees(_DOMAIN.fov_half_angle)
    lam_min: float = _DOMAIN.lam_min
    lam_max: float = _DOMAIN.lam_max
    occlusion_margin: float = _DOMAIN.occlusion_margin

    def to_domain(self) -> SafeDomain:
        """The :class:`~geovs_drake.geometry.domain.SafeDomain` (degrees to radians); ValueError
        if it is empty.
        """
        return SafeDomain(
            math.radians(self.fov_half_angle_deg), self.lam_min, self.lam_max, self.occlusion_margin
        )


@dataclass
class NavigationGainsConfig:
    """The navigation function's shape: the gains of its lambda, field-of-view and
    occlusion factors and the circle factor's weight (the saddle's value of phi), see
    :class:`~geovs_drake.geometry.navigation.NavigationGains`.
    """

    k_lam: float = _GAINS.k_lam
    k_fov: float = _GAINS.k_fov
    k_occ: float = _GAINS.k_occ
    circle_weight: float = _GAINS.circle_weight

    def to_gains(self) -> NavigationGains:
        """The :class:`~geovs_drake.geometry.navigation.NavigationGains`."""
        return NavigationGains(self.k_lam, self.k_fov, self.k_occ, self.circle_weight)


@dataclass
class ControlConfig:
    """Gains. The dynamic loop's potential is ``potential_gain * phi`` [J]; the
    damping B is diagonal on (Omega, V) (rotational first); the kinematic loop is
    ``ydot = -kinematic_gain * grad phi``."""

    potential_gain: float = 4.0
    damping: list[float] = field(default_factory=lambda: [0.3, 0.3, 0.3, 4.0, 4.0, 4.0])
    kinematic_gain: float = 4.0
    #: B of the velocity-tracking wrench F = B (nu_cmd - nu) that runs every
    #: twist-commanding law (not the NF) on the dynamic plant, rotational first
    #: [N m s, N s/m]. With the default rig (1 kg, 0.02 kg m^2) the time
    #: constants are 0.05 s (rotation) and 0.125 s (translation): fast against
    #: the laws' own (about 1 s), slow enough to keep the loop non-stiff.
    tracking_gains: list[float] = field(default_factory=lambda: [0.4, 0.4, 0.4, 8.0, 8.0, 8.0])
    #: lambda [1/s] of the baselines' ``e_dot = -lambda e`` (controller ibvs, pbvs,
    #: spherical): Chaumette & Hutchinson's gain, the same for the three.
    baseline_gain: float = 1.0


#: The automatic step limit's cap [s]; the NF's loops on the free rig run with the
#: smaller of it and their goal's stability bound (:mod:`geovs_drake.goal.step_limit`).
DEFAULT_MAX_STEP = 0.05


@dataclass
class SimulatorSettings:
    """The simulator: Drake's ``SimulatorConfig`` fields, the same names in YAML, with the
    project's defaults (accuracy 1e-6). ``integration_scheme`` left unset (None, ``null``
    in YAML) is the carrier's (its traits': RK5 on the quadrotor, and on the free rig's
    and the arm's dynamic plant under the NF's law; RK3 elsewhere), filled in by the
    resolver; a name is the user's and is used as given.
    ``max_step_size`` [s] left unset (None, ``null`` in YAML) is automatic: the goal's
    stability bound, at most :data:`DEFAULT_MAX_STEP`
    (:func:`geovs_drake.goal.step_limit.step_limit`); a value is the user's and is used as
    given. :meth:`to_drake` gives Drake's struct for ``ApplySimulatorConfig``."""

    integration_scheme: str | None = None
    max_step_size: float | None = None
    accuracy: float = 1e-6
    use_error_control: bool = True
    start_time: float = 0.0
    target_realtime_rate: float = 0.0
    publish_every_time_step: bool = False

    def to_drake(self, max_step_size: float | None = None) -> SimulatorConfig:
        """Drake's ``SimulatorConfig`` of these settings, its maximum step
        ``max_step_size`` (the loop's step limit) where given, else the configured one
        (Drake's own default where that is automatic), and Drake's default integrator
        where the scheme is unset (a resolved scenario's is its carrier's)."""
        step = self.max_step_size if max_step_size is None else max_step_size
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        fields["max_step_size"] = SimulatorConfig().max_step_size if step is None else step
        if self.integration_scheme is None:  # unset: the resolver fills in the carrier's
            fields["integration_scheme"] = SimulatorConfig().integration_scheme
        return SimulatorConfig(**fields)


@dataclass
class ScenarioConfig:
    """A scenario: the target, the goal and start, D, the navigation function, the
    gains, the loop's carrier, plant, sensor and law, and the simulator (defaults: the
    project's default scenario, see the module docstring). Load one from YAML with
    :func:`load_scenario`; :meth:`validate` checks the values.
    """

    radius: float = 0.1
    #: X_WB, the target sphere in the world: 1 m up, its z axis (towards the
    #: camera's goal, from the marked point's side) along -x of the world and its
    #: arrow a = e2 pointing up, so the camera approaches horizontally.
    target: PoseConfig = field(
        default_factory=lambda: PoseConfig(xyz=[0.0, 0.0, 1.0], rpy=[math.pi / 2, 0.0, math.pi / 2])
    )
    #: X_BC*, the goal camera pose in the target frame.
    goal: PoseConfig = field(default_factory=lambda: PoseConfig(xyz=[0.0, 0.0, -0.5]))
    #: X_BC(0), the initial camera pose in the target frame.
    initial: PoseConfig = field(
        default_factory=lambda: PoseConfig(xyz=[0.12, -0.08, -0.8], rpy=[0.15, -0.1, 2.0])
    )
    #: (Omega, V)(0), the camera's initial body twist in C [rad/s, m/s], rotational
    #: first; the dynamic free body only. The sign convention of Eqs. (16)-(17): (Omega, V)
    #: = G^-1 Gdot for G = X_BC, the camera's body velocity relative to the fixed
    #: target, i.e. minus the right-trivialised velocity (omega, v) of H = X_CB.
    #: The kinematic loop is first order (its velocity is commanded), so there it
    #: must stay zero; an arm starts with ``Arm.initial_joint_velocity``.
    initial_velocity: list[float] = field(default_factory=lambda: [0.0] * 6)
    domain: DomainConfig = field(default_factory=DomainConfig)
    navigation: NavigationGainsConfig = field(default_factory=NavigationGainsConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    #: What carries the camera: :class:`FreeRig`, the rigid body of Appendix C
    #: (eye-in-hand); :class:`FixedCamera`, the camera fixed in the world and the target
    #: driven (eye-to-hand); :class:`Arm`, a robot arm. In YAML ``carrier: !Arm {...}``.
    carrier: FreeRig | FixedCamera | Arm | Quadrotor = field(default_factory=FreeRig)
    #: How the carrier is driven: :class:`Dynamic` (a wrench or joint torques, Appendix C)
    #: or :class:`Kinematic` (its velocity commanded, Eqs. 17-19).
    plant: Dynamic | Kinematic = field(default_factory=Dynamic)
    #: How the loop sees the target: :class:`Exact` (y = c(H)), or a camera,
    #: :class:`Pinhole` or :class:`Rendered` (:class:`CameraModel`'s fields).
    sensor: Exact | Pinhole | Rendered = field(default_factory=Exact)
    #: The control law, in YAML e.g. ``controller: !Ibvs {depth: mean}``: :class:`Nf`,
    #: the navigation function of this project; :class:`Ibvs` (four points),
    #: :class:`Pbvs` and :class:`Spherical`, baselines that command the camera's twist;
    #: :class:`PathFollowing`, a planned image path followed (Eq. 18); :class:`HamelMahony`,
    #: Hamel & Mahony's law, which drives a quadrotor's rotors itself.
    controller: Nf | Ibvs | Pbvs | Spherical | PathFollowing | HamelMahony = field(
        default_factory=Nf
    )
    #: How the target moves from ``target``: :class:`Still` (the paper's loop) or
    #: :class:`Twist`, a constant body twist in B, with the loop's feed-forward
    #: (:mod:`geovs_drake.scenario.targets`). In YAML ``target_motion: !Twist {twist: [...]}``.
    target_motion: Still | Twist | Trajectory = field(default_factory=Still)
    duration: float = 30.0
    #: Samples per second of the logged signals.
    log_rate: float = 50.0
    simulator: SimulatorSettings = field(default_factory=SimulatorSettings)

    def validate(self) -> tuple[SafeDomain, NavigationGains]:
        """Raise ValueError naming the first bad field and its value; return the safe
        domain D and the NF's gains it built to check them, which
        :func:`~geovs_drake.loop.resolver` keeps (so D is made once).

        Called once at each edge (:func:`load_scenario` and
        :func:`~geovs_drake.loop.resolver`, and so the command line, ``simulate`` and
        ``build_loop``); what is built from a resolved scenario trusts it.
        """
        for axis in AXES:
            _check_variant(axis, getattr(self, axis))
        if not isinstance(self.plant, Dynamic | Kinematic):
            raise ValueError(f"plant must be Dynamic() or Kinematic(), got {self.plant!r}")
        for path, (low, strict, unit) in _POSITIVE.items():
            check_at_least(path, _field(self, path), low, strict, unit)
        check_carrier(self.carrier)
        check_sensor(self.sensor)
        check_law(self.controller)
        check_target_motion(self.target_motion)
        for name, positive, kind in (
            ("damping", False, "non-negative numbers"),
            ("tracking_gains", True, "numbers > 0"),
        ):
            values = finite_numbers(getattr(self.control, name), 6)
            if values is None or not all(v > 0 if positive else v >= 0 for v in values):
                raise ValueError(
                    f"control.{name} must be 6 finite {kind}, got {getattr(self.control, name)!r}"
                )
        schemes = GetIntegrationSchemes()
        scheme = self.simulator.integration_scheme
        if scheme is not None and scheme not in schemes:
            raise ValueError(
                f"simulator.integration_scheme {self.simulator.integration_scheme!r} is not "
                f"one Drake knows ({', '.join(schemes)})"
            )
        step = self.simulator.max_step_size
        real = isinstance(step, int | float) and not isinstance(step, bool)
        if step is not None and not (real and math.isfinite(step) and step > 0):
            raise ValueError(
                "simulator.max_step_size must be finite and > 0 [s], or unset (null: "
                f"automatic, from the goal's stability bound), got {step!r}"
            )
        twist = finite_numbers(self.initial_velocity, 6)
        if twist is None:
            raise ValueError(
                "initial_velocity must be 6 finite numbers (Omega, V) in C [rad/s, m/s], "
                f"got {self.initial_velocity!r}"
            )
        domain, gains = self.domain.to_domain(), self.navigation.to_gains()
        self._check_combination(twist)
        return domain, gains

    def _check_combination(self, twist: list[float]) -> None:
        """What no union can say: the combinations of the variants that make no loop."""
        moving = any(v != 0 for v in twist)
        if isinstance(self.carrier, Quadrotor):  # what it asks of the scene around it
            check_quadrotor_scenario(
                self.carrier,
                self.X_WB,
                self.X_BC_goal,
                self.X_BC_initial,
                self.dynamic,
                math.radians(self.domain.fov_half_angle_deg),
                self.target_motion,
            )
        if self.controller.traits.commands == "rotors" and not self.carrier.traits.rotors:
            raise ValueError(
                f"controller {variant_name(self.controller)} drives a quadrotor's rotors: "
                f"it needs carrier quadrotor, got carrier {variant_name(self.carrier)}"
            )
        if self.controller.traits.commands == "rotors" and self.moving_target:
            # Its rotors are its own: no cascade takes the target's believed motion.
            raise ValueError(
                f"controller {variant_name(self.controller)} drives a quadrotor's rotors "
                "behind a still target only (the target's motion is fed forward through the "
                f"NF's attitude cascade), got target_motion {type(self.target_motion).__name__}()"
            )
        if moving and not self.dynamic:
            raise ValueError(
                "initial_velocity applies to the dynamic loop only (the kinematic loop "
                f"commands the camera's velocity): got initial_velocity = {twist} "
                "with plant Kinematic()"
            )
        if self.moving_target and not self.carrier.traits.moving_target:
            # Eye-to-hand, the target is the body the loop moves: it has no motion of its
            # own; a carrier in the hand says in its traits whether it follows one.
            why = (
                "its traits say it follows no moving target"
                if self.carrier.traits.camera_in_hand
                else "the fixed camera's loop moves the target itself"
            )
            followers = " or ".join(
                c.__name__ for c in CARRIER_VARIANTS.values() if c.traits.moving_target
            )
            raise ValueError(
                f"target_motion {type(self.target_motion).__name__}() needs a carrier that "
                f"follows a moving target (carrier {followers}): {why}, got carrier "
                f"{type(self.carrier).__name__}()"
            )
        if (
            self.moving_target
            and self.target_motion.feedforward == "estimated"
            and isinstance(self.sensor, CameraModel)
            and self.sensor.first_frame_time > 0
        ):
            # The estimator pairs each frame with the body's pose on the k / rate clock
            # (loop.targets); a frame taken at capture_offset and read output_delay later
            # would be paired with the wrong pose.
            raise ValueError(
                "target_motion's estimated feed-forward reads frames on the camera's k / rate "
                "clock: set sensor.capture_offset and sensor.output_delay to 0 (use "
                "latency_frames for whole frames of delay), or feedforward known or none; got "
                f"capture_offset = {self.sensor.capture_offset}, "
                f"output_delay = {self.sensor.output_delay}"
            )
        arm = self.carrier
        if not isinstance(arm, Arm):
            return
        if moving:
            raise ValueError(
                "initial_velocity (a free camera's twist) does not apply to carrier Arm: "
                f"give carrier.initial_joint_velocity instead, got initial_velocity = {twist}"
            )
        barrier = next(
            (f for f in ("joint_barrier_width", "joint_barrier_fraction") if getattr(arm, f) > 0),
            None,
        )
        if barrier and not (self.dynamic and isinstance(self.controller, Nf)):
            raise ValueError(
                f"carrier.{barrier} applies to the dynamic arm under the NF (it is "
                f"a term of the NF's energy), got plant {type(self.plant).__name__}(), "
                f"controller {type(self.controller).__name__}()"
            )
        if arm.initial_joint_velocity and not self.dynamic:
            raise ValueError(
                "carrier.initial_joint_velocity applies to the dynamic arm only (the kinematic "
                f"arm commands its joint velocities), got {arm.initial_joint_velocity!r}"
            )

    # Derived quantities, in the names the code uses.
    @property
    def dynamic(self) -> bool:
        """Whether the plant is :class:`Dynamic` (second order: a state of 12 numbers at
        the goal, a wrench or torques), not :class:`Kinematic`."""
        return isinstance(self.plant, Dynamic)

    @property
    def moving_target(self) -> bool:
        """Whether the target moves (``target_motion`` is not :class:`Still`)."""
        return not isinstance(self.target_motion, Still)

    @property
    def X_WB(self) -> RigidTransform:
        """X_WB, the target sphere's pose in the world."""
        return self.target.to_rigid_transform()

    @property
    def X_BC_goal(self) -> RigidTransform:
        """X_BC*, the goal camera pose in the target frame."""
        return self.goal.to_rigid_transform()

    @property
    def X_BC_initial(self) -> RigidTransform:
        """X_BC(0), the initial camera pose in the target frame."""
        return self.initial.to_rigid_transform()

    @property
    def X_RC(self) -> RigidTransform:
        """X_RC, the camera frame's pose on the free body that carries it
        (:class:`FreeRig`'s ``camera_offset``, :class:`Quadrotor`'s ``mount``); the
        identity for another carrier."""
        if isinstance(self.carrier, FreeRig):
            return self.carrier.camera_offset.to_rigid_transform()
        if isinstance(self.carrier, Quadrotor):
            return self.carrier.X_RC
        return RigidTransform()

    @property
    def damping(self) -> list[float]:
        """The damping B the loop runs with (:func:`damping_of`)."""
        return damping_of(self)

    @property
    def believed_radius(self) -> float:
        """The radius the controller believes: ``radius (1 + sensor.radius_error)``."""
        return self.radius * (1 + radius_error_of(self.sensor))

    def goal_features(self) -> ImageFeatures:
        """y* = c(X_CB*) = c((X_BC*)^-1), for the radius the controller believes."""
        return camera_map(self.X_BC_goal.inverse(), self.believed_radius)

    def initial_features(self) -> ImageFeatures:
        """y(0) = c((X_BC(0))^-1), the initial image."""
        return camera_map(self.X_BC_initial.inverse(), self.radius)


#: The scalar fields that must be finite and above a bound: path -> (bound, strict, unit).
_POSITIVE: dict[str, tuple[float, bool, str]] = {
    "radius": (0.0, True, ""),
    "duration": (0.0, True, " [s]"),
    "log_rate": (0.0, True, " [1/s]"),
    "control.potential_gain": (0.0, True, ""),
    "control.kinematic_gain": (0.0, True, ""),
    "control.baseline_gain": (0.0, True, ""),
}


def _field(config: object, path: str) -> object:
    for key in path.split("."):
        config = getattr(config, key)
    return config


def _check_variant(axis: str, value: object) -> None:
    """``value`` is a variant of ``axis`` (or, for a part, one a user registered): a
    dataclass instance. A name gets the one line that spells the variant."""
    if isinstance(value, str):
        raise ValueError(variant_by_name(axis, value))
    if not dataclasses.is_dataclass(value) or isinstance(value, type):
        spelled = ", ".join(f"{kind.__name__}()" for kind in AXES[axis].values())
        raise ValueError(f"{axis} must be a variant ({spelled}), got {value!r}")
    kind = type(AXES[axis][next(iter(AXES[axis]))].traits).__name__
    if getattr(type(value), "traits", None) is None:
        # What a part can do is declared on it, and the package asks that, never its type.
        raise ValueError(
            f"{axis} {type(value).__name__} declares no traits: give its class "
            f"traits: ClassVar[{kind}] = {kind}(...) (geovs_drake.scenario.traits, "
            "docs/adding-a-part)"
        )


def variant_by_name(axis: str, name: str) -> str:
    """The one line for a variant given by a name, where the variant is needed: the
    spelling to write in Python and in YAML (or the names there are, if it is none)."""
    variants = AXES[axis]
    for other, others in AXES.items():
        if other != axis and name in others and name not in variants:
            return (
                f"{axis} {name!r} names a {other}: write {other}: {name} (the {axis} is one "
                f"of {', '.join(variants)})"
            )
    if name in variants:
        kind = variants[name].__name__
        return (
            f"{axis} {name!r}: give the {axis} as its variant, {axis}={kind}() "
            f"(in YAML, {axis}: !{kind} {{}} or {axis}: {name})"
        )
    return f"{axis} must be one of {', '.join(variants)}, got {name!r}"


def damping_of(config: ScenarioConfig) -> list[float]:
    """The damping B the loop runs with, decided here only: the camera's ``damping`` with
    a camera (:class:`CameraModel`), else ``control.damping`` (see :class:`CameraModel`
    for why a sampled camera needs more)."""
    if isinstance(config.sensor, CameraModel):
        return config.sensor.damping
    return config.control.damping
