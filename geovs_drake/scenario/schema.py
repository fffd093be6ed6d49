"""The scenario's schema: dataclasses loadable with Drake's ``yaml_load_typed``, each
with its own checks (``validate``), and the quantities derived from them.

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
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import GetIntegrationSchemes, SimulatorConfig

from geovs_drake.geometry.camera import ImageFeatures, camera_map
from geovs_drake.geometry.domain import SafeDomain
from geovs_drake.geometry.navigation import NavigationGains
from geovs_drake.geometry.pinhole import PinholeIntrinsics
from geovs_drake.scenario.laws import (
    CONTROLLERS,
    LAW_VARIANTS,
    Ibvs,
    Nf,
    PathFollowing,
    Pbvs,
    Spherical,
    check_law,
    law_name,
)

__all__ = [
    "CARRIER_NAMES",
    "DEFAULT_MAX_STEP",
    "MOUNTS",
    "PLANTS",
    "SENSOR_NAMES",
    "ArmConfig",
    "CameraConfig",
    "ControlConfig",
    "DomainConfig",
    "NavigationGainsConfig",
    "PoseConfig",
    "RigConfig",
    "ScenarioConfig",
    "SimulatorSettings",
    "damping_of",
]

#: The plants a scenario can run on.
PLANTS = ("dynamic", "kinematic")
#: Where the camera is: on the moving rig (eye-in-hand) or fixed in the world.
MOUNTS = ("hand", "fixed")
#: How the loop sees the target (``ScenarioConfig.camera.sensor``).
SENSOR_NAMES = ("exact", "rendered", "pinhole")
#: What carries the camera (``ScenarioConfig.carrier``): the free rigid body of
#: Appendix C (its ``mount`` and ``plant`` say how), or a robot arm (``arm``).
CARRIER_NAMES = ("free", "arm")


@dataclass
class PoseConfig:
    """A pose as translation [m] and Drake RollPitchYaw [rad]."""

    xyz: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    rpy: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])

    def to_rigid_transform(self) -> RigidTransform:
        """The pose as a RigidTransform; ValueError for a wrong length or a non-finite entry."""
        if len(self.xyz) != 3 or len(self.rpy) != 3:
            raise ValueError(f"a pose needs 3 xyz and 3 rpy numbers, got {self.xyz}, {self.rpy}")
        values = list(self.xyz) + list(self.rpy)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"pose has a non-finite entry: xyz = {self.xyz}, rpy = {self.rpy}")
        return RigidTransform(RollPitchYaw(self.rpy), np.asarray(self.xyz, dtype=float))

    @staticmethod
    def from_rigid_transform(X: RigidTransform) -> "PoseConfig":
        """The PoseConfig of a RigidTransform (translation and RollPitchYaw)."""
        return PoseConfig(
            xyz=[float(v) for v in X.translation()],
            rpy=[float(v) for v in RollPitchYaw(X.rotation()).vector()],
        )


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
class RigConfig:
    """The free camera rig: mass [kg], principal inertia about its CoM [kg m^2], and
    X_RC, the camera frame's pose in the rig's body frame (origin at the CoM)."""

    mass: float = 1.0
    inertia_diagonal: list[float] = field(default_factory=lambda: [0.02, 0.02, 0.02])
    camera_offset: PoseConfig = field(default_factory=PoseConfig)


@dataclass
class ArmConfig:
    """The arm that carries the camera with ``carrier: arm`` (eye-in-hand).

    ``model``: an arm known by name, "default" (the 6-axis arm shipped in the
    package, a UR5's published parameters, ``geovs_drake/models/ur5.urdf``) or
    "panda" (the 7-axis Franka Panda of example-robot-data, the ``panda`` extra), or
    the path of a URDF or SDFormat file. Its first body is welded to the world at
    ``base_pose``; the camera frame C sits at ``camera_offset`` (X_EC, the optical
    axis along z_C) on ``end_effector_frame``. Left unset, these three are the named
    arm's own (:data:`geovs_drake.loop.arm.ARMS`: a scene where the goal,
    the default start and the comparison suite's starts are all reachable); a model
    file needs ``end_effector_frame``, and its base and camera default to the world's
    origin and the frame itself. The start is ``initial_joints`` [rad] if given, else
    ``initial`` (X_BC(0)) solved by Drake's InverseKinematics within the joint
    limits; ``initial_joint_velocity`` [rad/s] (dynamic plant; empty: at rest).
    ``joint_damping`` B_q [N m s/rad] adds ``-B_q qdot`` to the torque;
    ``null_space_damping`` [N m s/rad] adds ``-d N qdot``, N the projector on J_C's
    null space, which damps a redundant arm's self-motion (dynamic arm);
    ``joint_barrier_width`` [rad] > 0 puts the joint limits inside the NF's guarantee
    (the dynamic arm under the NF: :mod:`geovs_drake.geometry.joint_barrier`, 0: off); the
    kinematic arm's ``null_space_gain`` [1/s] centres a redundant arm's
    self-motion, and its ``singularity_damping`` m damps its pseudo-inverse where
    sigma_min(J_C) < m (:class:`~geovs_drake.systems.KinematicArm`; 0: off).
    """

    model: str = "default"
    end_effector_frame: str = ""
    base_pose: PoseConfig | None = None
    camera_offset: PoseConfig | None = None
    #: The ``package://`` names a model file's meshes use, and their folders (Drake's
    #: package map), e.g. ``{my_robot_description: /path/to/my_robot_description}``.
    packages: dict[str, str] = field(default_factory=dict)
    initial_joints: list[float] = field(default_factory=list)
    initial_joint_velocity: list[float] = field(default_factory=list)
    joint_damping: float = 0.5
    null_space_damping: float = 2.0
    joint_barrier_width: float = 0.0
    null_space_gain: float = 1.0
    singularity_damping: float = 0.05
    #: The arm's inertia at the camera is about ten times the default rig's (1 kg): the
    #: dynamic arm runs the NF with k_p and B, and the twist laws' velocity tracking
    #: with its gains, multiplied by this factor, which keeps the free rig's time
    #: constants. :func:`resolve` applies it, once; the loop's
    #: energy bound is the scaled k_p.
    gain_scale: float = 10.0


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


@dataclass
class CameraConfig:
    """How the loop sees the target.

    ``sensor``: ``exact``, the camera map y = c(H) read continuously (the paper's
    spherical camera); ``rendered``, the scene drawn by Drake's RgbdSensor
    (RenderEngineVtk) every frame and y extracted from the colour image
    (:class:`~geovs_drake.systems.FeatureExtractor`); ``pinhole``, the same
    measurement on the exact image points, without rendering
    (:class:`~geovs_drake.systems.PinholeFeatureSensor`, for fast sweeps). The
    last two run at ``rate`` frames per second with a zero-order hold, on the
    dynamic plant.

    The camera is a pinhole of ``resolution`` [W, H] px, square pixels, the
    principal point at the centre, and the focal length whose inscribed cone,
    ``border_px`` in from the image's edges, is the domain's field of view
    (:meth:`intrinsics`): every pose of D keeps the whole sphere in the image.

    Errors, for robustness studies: ``pixel_noise`` [px], Gaussian, per axis, on
    every extracted image point; ``focal_error``: the extractor believes the focal
    lengths ``(1 + focal_error)`` times the true ones; ``latency_frames``: the
    controller acts on the frame taken that many periods ago; ``max_lost_frames``:
    how many frames in a row may give no y (the last good y held) before the run
    stops with ``feature_lost``; ``radius_error``
    (any sensor): the controller believes rho ``(1 + radius_error)`` times the true
    radius, in C(y) and in the goal image y* = c(X_CB*) (see the README: it moves
    the equilibrium's distance, not its image). ``seed`` draws the noise.

    ``damping``: the damping B of the loops with a camera (rendered, pinhole),
    rotational first, in place of ``control.damping``. Why a second one: the
    default gains give the exact loop a mode at 36 rad/s damped only 0.19 of
    critical; a 30 Hz zero-order hold delays the force by half a frame, 34 deg
    of phase at that frequency, and that mode grows: the default start leaves D
    at t = 1.6 s. Rotational damping 0.6 brings it home as fast as the exact
    loop (3.7 s). The damping reads the rig's own velocity, not the camera.
    """

    sensor: str = "exact"
    rate: float = 30.0
    resolution: list[int] = field(default_factory=lambda: [320, 240])
    border_px: float = 2.0
    pixel_noise: float = 0.0
    focal_error: float = 0.0
    latency_frames: int = 0
    max_lost_frames: int = 3
    radius_error: float = 0.0
    seed: int = 0
    damping: list[float] = field(default_factory=lambda: [0.6, 0.6, 0.6, 4.0, 4.0, 4.0])

    def intrinsics(self, fov_half_angle: float) -> PinholeIntrinsics:
        """The true camera: its inscribed cone (``border_px`` in) is ``fov_half_angle``."""
        width, height = (int(v) for v in self.resolution)
        return PinholeIntrinsics.for_fov(width, height, fov_half_angle, self.border_px)

    def believed_intrinsics(self, fov_half_angle: float) -> PinholeIntrinsics:
        """The camera the extractor believes in: focal lengths scaled by 1 + focal_error."""
        return self.intrinsics(fov_half_angle).scaled(1 + self.focal_error)

    def validate(self, plant: str) -> None:
        """Raise ValueError naming the first bad field ``camera.<name>`` and its value."""
        if self.sensor not in SENSOR_NAMES:
            raise ValueError(
                f"camera.sensor must be one of {', '.join(SENSOR_NAMES)}, got {self.sensor!r}"
            )
        if not (math.isfinite(self.rate) and self.rate > 0):
            raise ValueError(f"camera.rate must be finite and > 0 [Hz]: rate = {self.rate}")
        size = _finite_numbers(self.resolution, 2)
        if size is None or not all(v == int(v) and v >= 16 for v in size):
            raise ValueError(
                f"camera.resolution must be 2 integers >= 16 [px], got {self.resolution!r}"
            )
        if not (math.isfinite(self.border_px) and 0 <= self.border_px < min(size) / 4):
            raise ValueError(
                f"camera.border_px must be in [0, {min(size) / 4:g}) [px]: "
                f"border_px = {self.border_px}"
            )
        if not (math.isfinite(self.pixel_noise) and self.pixel_noise >= 0):
            raise ValueError(
                f"camera.pixel_noise must be finite and >= 0 [px]: pixel_noise = {self.pixel_noise}"
            )
        for name in ("focal_error", "radius_error"):
            value = getattr(self, name)
            if not (math.isfinite(value) and -0.5 <= value <= 0.5):
                raise ValueError(f"camera.{name} must be in [-0.5, 0.5]: {name} = {value}")
        damping = _finite_numbers(self.damping, 6)
        if damping is None or not all(v >= 0 for v in damping):
            raise ValueError(
                f"camera.damping must be 6 finite non-negative numbers, got {self.damping!r}"
            )
        for name in ("latency_frames", "max_lost_frames"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (value == int(value) and value >= 0):
                raise ValueError(f"camera.{name} must be an integer >= 0, got {value!r}")
        if self.sensor == "exact":
            for name in ("pixel_noise", "focal_error", "latency_frames"):
                if getattr(self, name) != 0:
                    raise ValueError(
                        f"camera.{name} = {getattr(self, name)} needs a camera: sensor "
                        "rendered or pinhole (the exact sensor reads c(H))"
                    )
        elif plant != "dynamic":
            raise ValueError(
                f"camera.sensor {self.sensor!r} runs on the dynamic plant only, got plant {plant!r}"
            )


def _is_real(value: object) -> bool:
    """A number that is not a bool."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def _finite_numbers(values, n: int) -> list[float] | None:
    """``values`` as n finite floats, or None if it is not that."""
    try:
        out = [float(v) for v in values]
    except (TypeError, ValueError):
        return None
    return out if len(out) == n and all(math.isfinite(v) for v in out) else None


#: The automatic step limit's cap [s]; the NF's loops on the free rig run with the
#: smaller of it and their goal's stability bound (:mod:`geovs_drake.simulation.step_limit`).
DEFAULT_MAX_STEP = 0.05


@dataclass
class SimulatorSettings:
    """The simulator: Drake's ``SimulatorConfig`` fields, the same names in YAML, with the
    project's defaults (RK3 at accuracy 1e-6). ``max_step_size`` [s] left unset (None,
    ``null`` in YAML) is automatic: the goal's stability bound, at most
    :data:`DEFAULT_MAX_STEP` (:func:`geovs_drake.simulation.step_limit.step_limit`); a
    value is the user's and is used as given. :meth:`to_drake` gives Drake's struct for
    ``ApplySimulatorConfig``."""

    integration_scheme: str = "runge_kutta3"
    max_step_size: float | None = None
    accuracy: float = 1e-6
    use_error_control: bool = True
    start_time: float = 0.0
    target_realtime_rate: float = 0.0
    publish_every_time_step: bool = False

    def to_drake(self, max_step_size: float | None = None) -> SimulatorConfig:
        """Drake's ``SimulatorConfig`` of these settings, its maximum step
        ``max_step_size`` (the loop's step limit) where given, else the configured one
        (Drake's own default where that is automatic)."""
        step = self.max_step_size if max_step_size is None else max_step_size
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        fields["max_step_size"] = SimulatorConfig().max_step_size if step is None else step
        return SimulatorConfig(**fields)


@dataclass
class ScenarioConfig:
    """A scenario: the target, the goal and start, D, the navigation function, the
    rig, the gains, the plant and law, and the simulator (defaults: the project's
    default scenario, see the module docstring). Load one from YAML with
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
    #: first; dynamic loop only. The sign convention of Eqs. (16)-(17): (Omega, V)
    #: = G^-1 Gdot for G = X_BC, the camera's body velocity relative to the fixed
    #: target, i.e. minus the right-trivialised velocity (omega, v) of H = X_CB.
    #: The kinematic loop is first order (its velocity is commanded), so there it
    #: must stay zero.
    initial_velocity: list[float] = field(default_factory=lambda: [0.0] * 6)
    domain: DomainConfig = field(default_factory=DomainConfig)
    navigation: NavigationGainsConfig = field(default_factory=NavigationGainsConfig)
    rig: RigConfig = field(default_factory=RigConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    #: How the loop sees the target: the exact camera map, or a camera (CameraConfig).
    camera: CameraConfig = field(default_factory=CameraConfig)
    #: The plant: "dynamic" (the MultibodyPlant free body of Appendix C, driven by a
    #: wrench) or "kinematic" (the camera's body twist is commanded, Eqs. 17-19).
    plant: str = "dynamic"
    #: The control law, a variant holding its own fields (:data:`LawConfig`), in YAML
    #: e.g. ``controller: !Ibvs {depth: mean}``: :class:`Nf`, the navigation function
    #: of this project; :class:`Ibvs` (four points), :class:`Pbvs` and
    #: :class:`Spherical`, baselines that command the camera's twist;
    #: :class:`PathFollowing`, a planned image path followed (Eq. 18).
    controller: Nf | Ibvs | Pbvs | Spherical | PathFollowing = field(default_factory=Nf)
    #: What carries the camera (:data:`CARRIER_NAMES`): "free", the rigid body of
    #: Appendix C, or "arm", the robot arm of ``arm``.
    carrier: str = "free"
    #: The arm, with ``carrier: arm``.
    arm: ArmConfig = field(default_factory=ArmConfig)
    #: "hand": the camera rides on the driven body (eye-in-hand); "fixed": the
    #: camera is fixed in the world and the target sphere is the driven body
    #: (eye-to-hand, G = H^-1 of Eq. 16).
    mount: str = "hand"
    duration: float = 30.0
    #: Samples per second of the logged signals.
    log_rate: float = 50.0
    simulator: SimulatorSettings = field(default_factory=SimulatorSettings)

    def validate(self) -> None:
        """Raise ValueError naming the first bad field and its value.

        Called once at each edge (:func:`load_scenario`, the command line,
        :func:`resolve` and so the public ``simulate`` and ``build_loop``); what
        is built from a :class:`ResolvedScenario` trusts it.
        """
        for name, choices in (
            ("plant", PLANTS),
            ("carrier", CARRIER_NAMES),
            ("mount", MOUNTS),
        ):
            value = getattr(self, name)
            if value not in choices:
                raise ValueError(f"{name} must be one of {', '.join(choices)}, got {value!r}")
        law = self.controller
        if isinstance(law, str):
            raise ValueError(_law_by_name(law))
        if not dataclasses.is_dataclass(law) or isinstance(law, type):
            raise ValueError(
                f"controller must be a law variant ({', '.join(_LAW_SPELLING.values())}), "
                f"got {law!r}"
            )
        for path, (low, strict, unit) in _POSITIVE.items():
            value = _field(self, path)
            ok = isinstance(value, int | float) and not isinstance(value, bool)
            if not (ok and math.isfinite(value) and (value > low if strict else value >= low)):
                where = path.removeprefix("control.")  # the gains by their own names
                raise ValueError(
                    f"{path} must be finite and {'>' if strict else '>='} {low:g}{unit}: "
                    f"{where} = {value!r}"
                )
        check_law(law)
        inertia = _finite_numbers(self.rig.inertia_diagonal, 3)
        if inertia is None or not all(v > 0 for v in inertia):
            raise ValueError(
                "rig.inertia_diagonal must be exactly 3 positive numbers [kg m^2], "
                f"got {self.rig.inertia_diagonal!r}"
            )
        damping = _finite_numbers(self.control.damping, 6)
        if damping is None or not all(v >= 0 for v in damping):
            raise ValueError(
                "control.damping must be 6 finite non-negative numbers, "
                f"got {self.control.damping!r}"
            )
        gains = _finite_numbers(self.control.tracking_gains, 6)
        if gains is None or not all(v > 0 for v in gains):
            raise ValueError(
                "control.tracking_gains must be 6 finite numbers > 0, "
                f"got {self.control.tracking_gains!r}"
            )
        schemes = GetIntegrationSchemes()
        if self.simulator.integration_scheme not in schemes:
            raise ValueError(
                f"simulator.integration_scheme {self.simulator.integration_scheme!r} is not "
                f"one Drake knows ({', '.join(schemes)})"
            )
        step = self.simulator.max_step_size
        if step is not None and not (_is_real(step) and math.isfinite(step) and step > 0):
            raise ValueError(
                "simulator.max_step_size must be finite and > 0 [s], or unset (null: "
                f"automatic, from the goal's stability bound), got {step!r}"
            )
        twist = _finite_numbers(self.initial_velocity, 6)
        if twist is None:
            raise ValueError(
                "initial_velocity must be 6 finite numbers (Omega, V) in C [rad/s, m/s], "
                f"got {self.initial_velocity!r}"
            )
        if self.plant == "kinematic" and any(v != 0 for v in twist):
            raise ValueError(
                "initial_velocity applies to the dynamic loop only (the kinematic loop "
                f"commands the camera's velocity): got initial_velocity = {twist} "
                "with plant 'kinematic'"
            )
        self.domain.to_domain()
        self.navigation.to_gains()
        self.camera.validate(self.plant)
        if self.carrier == "arm":
            self._validate_arm(twist)
        if self.camera.sensor != "exact" and self.mount != "hand":
            raise ValueError(
                f"camera.sensor {self.camera.sensor!r} runs eye-in-hand only (the camera "
                f"rides on the rig), got mount {self.mount!r}"
            )

    def _validate_arm(self, twist: list[float]) -> None:
        """The arm's own fields, and what the arm rules out."""
        if self.mount != "hand":
            raise ValueError(
                f"carrier 'arm' carries the camera in its hand, got mount {self.mount!r}"
            )
        if any(v != 0 for v in twist):
            raise ValueError(
                "initial_velocity (a free camera's twist) does not apply to carrier 'arm': "
                f"give arm.initial_joint_velocity instead, got initial_velocity = {twist}"
            )
        # Here, not at the top: the command line starts without the loop's modules.
        from geovs_drake.systems._arm_model import ARMS

        arm = self.arm
        if arm.model in ARMS:
            ARMS[arm.model].locate()  # its package installed (MissingExtra names the extra)
        elif not Path(arm.model).is_file():
            raise ValueError(
                f"arm.model must be {', '.join(repr(name) for name in ARMS)} or a model "
                f"file's path, got {arm.model!r}"
            )
        for name, folder in arm.packages.items():
            if not Path(folder).is_dir():
                raise ValueError(f"arm.packages.{name} must be a folder, got {folder!r}")
        if arm.model not in ARMS and not arm.end_effector_frame:
            raise ValueError(
                f"arm.end_effector_frame must name the frame the camera rides on in "
                f"{arm.model} (a model file has no default), got {arm.end_effector_frame!r}"
            )
        for name in ("initial_joints", "initial_joint_velocity"):
            values = getattr(arm, name)
            if _finite_numbers(values, len(values)) is None:
                raise ValueError(f"arm.{name} must be finite numbers [rad, rad/s], got {values!r}")
        if arm.joint_barrier_width > 0 and (
            self.plant != "dynamic" or not isinstance(self.controller, Nf)
        ):
            raise ValueError(
                "arm.joint_barrier_width applies to the dynamic arm under the NF (it is a "
                f"term of the NF's energy), got plant {self.plant!r}, controller "
                f"{law_name(self.controller)!r}"
            )
        if arm.initial_joint_velocity and self.plant != "dynamic":
            raise ValueError(
                "arm.initial_joint_velocity applies to the dynamic arm only (the kinematic "
                f"arm commands its joint velocities), got {arm.initial_joint_velocity!r}"
            )

    # Derived quantities, in the names the code uses.
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
        """X_RC, the camera frame's pose on the rig."""
        return self.rig.camera_offset.to_rigid_transform()

    @property
    def damping(self) -> list[float]:
        """The damping B the loop runs with (:func:`damping_of`)."""
        return damping_of(self)

    @property
    def believed_radius(self) -> float:
        """The radius the controller believes: ``radius (1 + camera.radius_error)``."""
        return self.radius * (1 + self.camera.radius_error)

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
    "rig.mass": (0.0, True, " [kg]"),
    "control.potential_gain": (0.0, True, ""),
    "control.kinematic_gain": (0.0, True, ""),
    "control.baseline_gain": (0.0, True, ""),
    "arm.joint_damping": (0.0, False, " [N m s/rad]"),
    "arm.null_space_damping": (0.0, False, " [N m s/rad]"),
    "arm.joint_barrier_width": (0.0, False, " [rad]"),
    "arm.null_space_gain": (0.0, False, " [1/s]"),
    "arm.singularity_damping": (0.0, False, ""),
    "arm.gain_scale": (0.0, True, ""),
}


def _field(config: object, path: str) -> object:
    for key in path.split("."):
        config = getattr(config, key)
    return config


#: How each law is written, in Python and as its YAML tag.
_LAW_SPELLING = {name: f"{variant.__name__}()" for name, variant in LAW_VARIANTS.items()}


def _law_by_name(name: str) -> str:
    """The one line for a law given by a name that is none (or, in Python, by its name):
    the spelling to write."""
    if name in PLANTS:
        return (
            f"controller {name!r} names a plant: write plant: {name} (the controller is "
            f"the law, one of {', '.join(CONTROLLERS)})"
        )
    if name in LAW_VARIANTS:
        variant = LAW_VARIANTS[name].__name__
        return (
            f"controller {name!r}: give the law as its variant, controller={variant}() "
            f"(in YAML, controller: !{variant} {{}} or controller: {name})"
        )
    return f"controller must be one of {', '.join(CONTROLLERS)}, got {name!r}"


def damping_of(config: ScenarioConfig) -> list[float]:
    """The damping B the loop runs with, decided here only: ``camera.damping`` with a
    camera (rendered, pinhole), else ``control.damping`` (see :class:`CameraConfig`
    for why a sampled camera needs more)."""
    return config.control.damping if config.camera.sensor == "exact" else config.camera.damping
