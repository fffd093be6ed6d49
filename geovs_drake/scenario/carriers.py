"""The carrier, one variant each (``ScenarioConfig.carrier``): what moves the camera.

In YAML a carrier is tagged with its class name, ``carrier: !Arm {model: panda}``; a
scenario file's bare name (``carrier: arm``, ``carrier: free``) reads as that variant
with its defaults. The loop takes each carrier's systems from
:data:`geovs_drake.loop.carriers.CARRIERS`, keyed by the variant's and the plant's types.
"""

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RotationMatrix

from geovs_drake.scenario.plants import Dynamic, Kinematic
from geovs_drake.scenario.pose import PoseConfig, check_at_least, finite_numbers
from geovs_drake.scenario.targets import Trajectory, Twist, target_trajectory
from geovs_drake.scenario.traits import CarrierTraits

__all__ = [
    "AUTO",
    "CARRIER_VARIANTS",
    "NOMINAL_GAIN_SCALES",
    "TORQUE_LIMITS",
    "Arm",
    "CarrierConfig",
    "FixedCamera",
    "FreeRig",
    "QUADROTOR_MOUNTS",
    "QUADROTOR_HEADINGS",
    "QUADROTOR_START_ATTITUDES",
    "Quadrotor",
    "RigidBodyConfig",
    "carrier_start",
    "check_carrier",
    "level_start",
    "target_turn",
]


#: ``Arm.gain_scale``'s value that asks for the gain to be chosen.
AUTO = "auto"


@dataclass
class RigidBodyConfig:
    """The driven free body's mass model: ``mass`` [kg] and principal inertia about its
    centre of mass [kg m^2] (what :class:`FreeRig` and :class:`FixedCamera` share)."""

    mass: float = 1.0
    inertia_diagonal: list[float] = field(default_factory=lambda: [0.02, 0.02, 0.02])


@dataclass
class FreeRig(RigidBodyConfig):
    """The free camera rig of Appendix C, eye-in-hand: the camera rides at
    ``camera_offset`` (X_RC, the camera frame's pose in the rig's body frame, whose origin
    is the centre of mass) on a rigid body of ``mass`` and ``inertia_diagonal``."""

    camera_offset: PoseConfig = field(default_factory=PoseConfig)

    traits: ClassVar[CarrierTraits] = CarrierTraits(
        camera_in_hand=True,
        joints=False,
        rigid_body_goal=True,
        goal_model=True,
        moving_target=True,
        batch_kernel=True,
        gain_scale=False,
        effort_limits=False,
        takes=(("dynamic", "wrench"), ("kinematic", "twist")),
        # RK5 on the dynamic plant, as the arm's: the default start in 303 steps against
        # RK3's 1384 at the same accuracy, about twice as fast (docs/performance.md).
        dynamic_integration_scheme="runge_kutta5",
    )


@dataclass
class FixedCamera(RigidBodyConfig):
    """Eye-to-hand: the camera is fixed in the world where the eye-in-hand camera's goal
    is (``X_WB X_BC*``), and the target sphere is the driven body, of ``mass`` and
    ``inertia_diagonal`` about its centre; the laws see G = H^-1 (Eq. 16)."""

    traits: ClassVar[CarrierTraits] = CarrierTraits(
        camera_in_hand=False,
        joints=False,
        rigid_body_goal=False,
        goal_model=False,
        moving_target=False,
        batch_kernel=False,
        gain_scale=False,
        effort_limits=False,
        takes=(("dynamic", "wrench"), ("kinematic", "twist")),
    )


@dataclass
class Arm:
    """A robot arm that carries the camera in its hand.

    ``model``: an arm known by name, "default" (the 6-axis arm shipped in the package,
    a UR5's published parameters, ``geovs_drake/models/ur5.urdf``) or "panda" (the
    7-axis Franka Panda of example-robot-data, the ``panda`` extra), or the path of a
    URDF or SDFormat file. Its first body is welded to the world at ``base_pose``; the
    camera frame C sits at ``camera_offset`` (X_EC, the optical axis along z_C) on
    ``end_effector_frame``. Left unset, these three are the named arm's own
    (:data:`geovs_drake.goal.arm.ARMS`: a scene where the goal, the default start and
    the comparison suite's starts are all reachable); a model file needs
    ``end_effector_frame``, and its base and camera default to the world's origin and
    the frame itself. The start is ``initial_joints`` [rad] if given, else the
    scenario's ``initial`` (X_BC(0)) solved by Drake's InverseKinematics within the
    joint limits; ``initial_joint_velocity`` [rad/s] (dynamic plant; empty: at rest).
    ``joint_damping`` B_q [N m s/rad] adds ``-B_q qdot`` to the torque;
    ``null_space_damping`` [N m s/rad] adds ``-d N qdot``, N the projector on J_C's
    null space, which damps a redundant arm's self-motion (dynamic arm);
    ``joint_barrier_width`` [rad] > 0 puts the joint limits inside the NF's guarantee
    (the dynamic arm under the NF: :mod:`geovs_drake.geometry.joint_barrier`, 0: off);
    ``joint_barrier_fraction`` in (0, 0.5) instead gives each joint the width of that
    fraction of its range (ViSP's joint-limit task: 0.1, the last 10 %), exclusive with
    ``joint_barrier_width``;
    the kinematic arm's ``null_space_gain`` [1/s] centres a redundant arm's
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
    #: Each joint's barrier width as a fraction of its range (0: off; docstring). Its
    #: own field, not a second meaning of ``joint_barrier_width``: a number's unit
    #: (rad or a share of the range) never depends on another field.
    joint_barrier_fraction: float = 0.0
    null_space_gain: float = 1.0
    singularity_damping: float = 0.05
    #: The factor on the law's gains, applied once by
    #: :func:`~geovs_drake.scenario.resolve`: k_p and B, and the twist laws' velocity
    #: tracking, on the dynamic arm (the loop's energy bound is the scaled k_p);
    #: ``control.kinematic_gain`` on the kinematic one. ``auto`` (the default): the
    #: plant's :data:`NOMINAL_GAIN_SCALES` (10 on the dynamic arm, whose inertia at the
    #: camera is about ten times the default rig's, which keeps the free rig's time
    #: constants; 1 on the kinematic one), at most the largest that the camera's rate and
    #: latency carry with a gain margin of 2 (:func:`geovs_drake.loop.resolve`).
    gain_scale: float | str = AUTO
    #: What the dynamic arm's effort limits do to the gains (:data:`TORQUE_LIMITS`,
    #: :mod:`geovs_drake.goal.effort_fit`): ``warn``, one warning line where the run's
    #: torques over its energy level set can pass a limit; ``respect``, ``gain_scale:
    #: auto`` also stays at or below the largest scale that keeps them inside.
    torque_limits: str = "warn"

    traits: ClassVar[CarrierTraits] = CarrierTraits(
        camera_in_hand=True,
        joints=True,
        rigid_body_goal=False,
        goal_model=True,
        moving_target=True,
        batch_kernel=False,
        gain_scale=True,
        effort_limits=True,
        takes=(("dynamic", "joint torques"), ("kinematic", "joint velocities")),
        # RK5 on the dynamic plant: the UR5's small move in a quarter of RK3's steps at
        # the same accuracy (339 against 1333), 1.7x less CPU, within 2.3 um of a tight
        # run; the kinematic arm's RK3 is faster there (docs/performance.md, The arm loop).
        dynamic_integration_scheme="runge_kutta5",
    )


#: What the dynamic arm's effort limits do to its gains (``Arm.torque_limits``). Why
#: ``warn`` is the default: over the whole level set the UR5's torques stay inside only
#: at gain_scale 0.85 from the default start, where it has not converged in 30 s (7 cm
#: off), while at the nominal 10 the clamped run converges (docs/arm.md).
TORQUE_LIMITS: dict[str, str] = {
    "warn": "one warning line where the torques over the run's energy level set pass a limit",
    "respect": "gain_scale auto also keeps those torques inside the effort limits",
}

#: The arm's gain scale that keeps the free rig's time constants, by the plant's type:
#: ``auto`` without a camera.
NOMINAL_GAIN_SCALES: dict[type, float] = {Dynamic: 10.0, Kinematic: 1.0}

#: Standard gravity [m/s^2], Drake's default gravity field's magnitude.
GRAVITY = 9.81

#: The quadrotor's camera mounts (``Quadrotor.mount``): X_RC, the camera frame C on the
#: body frame R (x forward, z along the thrust), as C's axes in R (the columns of R_RC)
#: and C's origin in R [m]. ``forward``: the optical axis z_C along the body's x, the
#: image's y axis along the body's z (the scenario's convention, where the target's arrow
#: points up), at the box's front face; ``down``: z_C along -z of the body, y_C along
#: its x, under the box.
QUADROTOR_MOUNTS: dict[str, tuple[tuple[tuple[float, ...], ...], tuple[float, float, float]]] = {
    "forward": (((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)), (0.06, 0.0, 0.0)),
    "down": (((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0)), (0.0, 0.0, -0.03)),
}

#: The quadrotor's attitudes at t = 0 (``Quadrotor.initial_attitude``), what each does.
QUADROTOR_START_ATTITUDES: dict[str, str] = {
    "level": "the start's camera position and the body's heading, the body level",
    "given": "the start as given (refused past the tilt the rotors hold the weight at)",
}

#: What turns the quadrotor's heading (``Quadrotor.heading``), what each does.
QUADROTOR_HEADINGS: dict[str, str] = {
    "goal": "the cascade's attitude loop turns the body to the goal's heading",
    "nf": "the NF's torque about the body's z axis turns it (Lee's loop leaves the yaw)",
}

#: A goal attitude within this tilt [rad] of level is level: a tenth of the 1 mrad
#: convergence tolerance, so that the body held level leaves the camera within it.
LEVEL_TOLERANCE_RAD = 1e-4


@dataclass
class Quadrotor:
    """A quadrotor that carries the camera: a free body of ``mass`` [kg] and principal
    inertia ``inertia_diagonal`` [kg m^2] about its centre of mass (Drake's quadrotor
    example's), driven by four of Drake's ``Propeller`` systems in a + at ``arm_length`` [m]
    from the centre, each a thrust in [0, ``max_rotor_thrust``] [N] along the body's z
    and a drag moment of ``moment_ratio`` [m] times it about z (alternating signs).
    Gravity is on. The camera rides at ``mount`` (:data:`QUADROTOR_MOUNTS`: ``forward``
    or ``down``). The NF's force, plus m g, sets the thrust and the attitude it wants;
    Lee, Leok & McClamroch's geometric controller on SO(3) turns the attitude with
    ``attitude_gains`` = (k_R [1/s^2], k_Omega [1/s]), per unit of inertia
    (:class:`~geovs_drake.systems.AttitudeCascade`), which also damps the body's velocity
    with ``velocity_damping`` [N s/m]. Dynamic plant only; the goal must be a level
    hover, and a moving target must translate (the landing platform: its believed
    velocity and acceleration enter the thrust vector). ``initial_attitude`` says whether
    the start's body is levelled (``level``) or kept as given."""

    mass: float = 0.775
    inertia_diagonal: list[float] = field(default_factory=lambda: [0.0015, 0.0025, 0.0035])
    arm_length: float = 0.15
    moment_ratio: float = 0.0245
    #: 4 x 4.75 N = 19 N, about 2.5 m g with the default mass: room to accelerate and
    #: to tilt while the weight is held.
    max_rotor_thrust: float = 4.75
    #: Why forward by default: the default scenario's goal looks horizontally at the
    #: target (1 m up), which a level body holds only with the camera looking forward;
    #: ``down`` needs a target below it (a landing pad, docs/quadrotor.md).
    mount: str = "forward"
    #: (k_R, k_Omega): 60 rad/s, damping ratio 0.9 on each axis. Why this fast: the NF's
    #: translation across the optical axis at the goal has modes near 19 rad/s (the
    #: down camera; 12 the forward one), and the thrust's direction lags the NF's force
    #: by this loop: at 40 rad/s the down camera's loop at hover is unstable (0.62 +-
    #: 18.97j 1/s), at 20 rad/s the forward one's (2.5 +- 10.3j); docs/quadrotor.md.
    attitude_gains: list[float] = field(default_factory=lambda: [3600.0, 108.0])
    #: b [N s/m], the cascade's damping of the body's velocity, added to the NF's B on
    #: the translation: with the NF's default 4 N s/m alone the forward camera's lateral
    #: mode at hover is unstable at 40 rad/s attitude gains (0.71 +- 11.92j 1/s).
    velocity_damping: float = 4.0
    #: The largest tilt [deg] the cascade asks of the body. A tilt turns the camera by as
    #: much, and D is the real camera's: at 30 deg the down camera's loop left D within
    #: 0.05 s from (0.05, -0.03, -0.6); at 10 it converged there in 3.6 s, and the
    #: forward camera's starts converge as fast as at 30 (docs/quadrotor.md).
    max_tilt_deg: float = 10.0
    #: The body's attitude at t = 0 (:data:`QUADROTOR_START_ATTITUDES`): ``level`` keeps
    #: the start's camera position and the body's heading and drops its roll and pitch (a
    #: quadrotor hovers level before the servo starts; the resolver derives it,
    #: :func:`level_start`); ``given`` keeps the start as it is, refused past the tilt the
    #: rotors can hold the weight at.
    initial_attitude: str = "level"
    #: What turns the body's heading (:data:`QUADROTOR_HEADINGS`): ``goal``, the cascade's
    #: attitude loop turns it to the goal's at once; ``nf``, the NF's own torque about z_B
    #: (the yaw is fully actuated, through the rotors' drag), the field-of-view barrier
    #: keeping the target in view while it turns (docs/quadrotor.md, The basin).
    heading: str = "goal"

    traits: ClassVar[CarrierTraits] = CarrierTraits(
        camera_in_hand=True,
        joints=False,
        rigid_body_goal=False,
        goal_model=False,
        moving_target=True,
        batch_kernel=False,
        gain_scale=False,
        effort_limits=False,
        takes=(("dynamic", "rotor thrusts"),),
        energy_exclusion=(
            "the attitude cascade turns the NF's wrench into one thrust and an attitude "
            "(underactuated), and Appendix C's energy argument needs the wrench applied"
        ),
        turning_target=False,
        rotors=True,
        # RK5: the 60 rad/s attitude loop's transient in a third of RK3's steps at the
        # same accuracy, the same statuses and convergence times (docs/quadrotor.md, Speed).
        integration_scheme="runge_kutta5",
        hover=True,
    )

    @property
    def X_RC(self) -> RigidTransform:
        """The camera's pose on the body, ``mount``'s (:data:`QUADROTOR_MOUNTS`)."""
        axes, origin = QUADROTOR_MOUNTS[self.mount]
        return RigidTransform(RotationMatrix(np.array(axes).T), np.array(origin))


#: A carrier's configuration: one of the variants above.
CarrierConfig = FreeRig | FixedCamera | Arm | Quadrotor
#: The carrier of each name, as ``--carrier`` and a file's bare name give it.
CARRIER_VARIANTS: dict[str, type] = {
    "free": FreeRig,
    "fixed": FixedCamera,
    "arm": Arm,
    "quadrotor": Quadrotor,
}

#: The arm's scalar fields with a lower bound: name -> (bound, strict, unit).
_ARM_BOUNDS: dict[str, tuple[float, bool, str]] = {
    "joint_damping": (0.0, False, " [N m s/rad]"),
    "null_space_damping": (0.0, False, " [N m s/rad]"),
    "joint_barrier_width": (0.0, False, " [rad]"),
    "joint_barrier_fraction": (0.0, False, ""),
    "null_space_gain": (0.0, False, " [1/s]"),
    "singularity_damping": (0.0, False, ""),
}


def check_carrier(carrier: object) -> None:
    """The carrier variant's own fields: ValueError naming the first bad one,
    ``carrier.<field>``, and its value."""
    if isinstance(carrier, RigidBodyConfig):
        check_at_least("carrier.mass", carrier.mass, 0.0, True, " [kg]")
        inertia = finite_numbers(carrier.inertia_diagonal, 3)
        if inertia is None or not all(v > 0 for v in inertia):
            raise ValueError(
                "carrier.inertia_diagonal must be exactly 3 positive numbers [kg m^2], "
                f"got {carrier.inertia_diagonal!r}"
            )
        if isinstance(carrier, FreeRig):
            carrier.camera_offset.to_rigid_transform()
        return
    if isinstance(carrier, Quadrotor):
        _check_quadrotor(carrier)
        return
    if not isinstance(carrier, Arm):
        return
    for name, (low, strict, unit) in _ARM_BOUNDS.items():
        check_at_least(f"carrier.{name}", getattr(carrier, name), low, strict, unit)
    # Below one half: the two sides' steps of a joint would otherwise overlap, and no
    # configuration would be free of the barrier (phi_q > 0 everywhere: no goal is a
    # minimum of phi_total).
    if carrier.joint_barrier_fraction >= 0.5:
        raise ValueError(
            "carrier.joint_barrier_fraction must be < 0.5 (a share of each joint's range): "
            f"joint_barrier_fraction = {carrier.joint_barrier_fraction!r}"
        )
    if carrier.joint_barrier_fraction > 0 and carrier.joint_barrier_width > 0:
        raise ValueError(
            "carrier.joint_barrier_fraction and carrier.joint_barrier_width are exclusive "
            f"(give one): joint_barrier_fraction = {carrier.joint_barrier_fraction!r}, "
            f"joint_barrier_width = {carrier.joint_barrier_width!r}"
        )
    if carrier.gain_scale != AUTO:
        if isinstance(carrier.gain_scale, str):
            raise ValueError(
                f"carrier.gain_scale must be a number > 0 or {AUTO}, got {carrier.gain_scale!r}"
            )
        check_at_least("carrier.gain_scale", carrier.gain_scale, 0.0, True)
    # Here, not at the top: the command line starts without the loop's modules.
    from geovs_drake.systems.arm_model import ARMS

    if carrier.model in ARMS:
        ARMS[carrier.model].locate()  # its package installed (MissingExtra names the extra)
    elif not Path(carrier.model).is_file():
        path = Path(carrier.model)
        # A name the way a path is written (a suffix or a folder) is a file the user
        # meant: say it is missing, not that the name is unknown.
        if path.suffix or path.is_absolute() or len(path.parts) > 1:
            what = "is a folder, not a model file" if path.is_dir() else "no such file"
            raise ValueError(f"carrier.model {carrier.model}: {what}")
        raise ValueError(
            f"carrier.model must be {', '.join(repr(name) for name in ARMS)} or a model "
            f"file's path, got {carrier.model!r}"
        )
    for name, folder in carrier.packages.items():
        if not Path(folder).is_dir():
            raise ValueError(f"carrier.packages.{name} must be a folder, got {folder!r}")
    if carrier.model not in ARMS and not carrier.end_effector_frame:
        raise ValueError(
            f"carrier.end_effector_frame must name the frame the camera rides on in "
            f"{carrier.model} (a model file has no default), got {carrier.end_effector_frame!r}"
        )
    if carrier.torque_limits not in TORQUE_LIMITS:
        raise ValueError(
            f"carrier.torque_limits must be one of {', '.join(TORQUE_LIMITS)}, "
            f"got {carrier.torque_limits!r}"
        )
    for name in ("initial_joints", "initial_joint_velocity"):
        values = getattr(carrier, name)
        if finite_numbers(values, len(values)) is None:
            raise ValueError(f"carrier.{name} must be finite numbers [rad, rad/s], got {values!r}")


def _check_quadrotor(quad: Quadrotor) -> None:
    """The quadrotor's own fields: ValueError naming the first bad one and its value."""
    check_at_least("carrier.mass", quad.mass, 0.0, True, " [kg]")
    inertia = finite_numbers(quad.inertia_diagonal, 3)
    if inertia is None or not all(v > 0 for v in inertia):
        raise ValueError(
            "carrier.inertia_diagonal must be exactly 3 positive numbers [kg m^2], "
            f"got {quad.inertia_diagonal!r}"
        )
    check_at_least("carrier.arm_length", quad.arm_length, 0.0, True, " [m]")
    check_at_least("carrier.moment_ratio", quad.moment_ratio, 0.0, True, " [m]")
    check_at_least("carrier.max_rotor_thrust", quad.max_rotor_thrust, 0.0, True, " [N]")
    check_at_least("carrier.velocity_damping", quad.velocity_damping, 0.0, False, " [N s/m]")
    check_at_least("carrier.max_tilt_deg", quad.max_tilt_deg, 0.0, True, " [deg]")
    if quad.max_tilt_deg >= 90:
        raise ValueError(
            f"carrier.max_tilt_deg must be < 90 [deg]: max_tilt_deg = {quad.max_tilt_deg!r}"
        )
    weight = quad.mass * GRAVITY
    if 4 * quad.max_rotor_thrust <= weight:
        raise ValueError(
            f"carrier.max_rotor_thrust cannot hover: 4 x {quad.max_rotor_thrust:g} N = "
            f"{4 * quad.max_rotor_thrust:.4g} N <= m g = {weight:.4g} N"
        )
    if quad.mount not in QUADROTOR_MOUNTS:
        raise ValueError(
            f"carrier.mount must be one of {', '.join(QUADROTOR_MOUNTS)}, got {quad.mount!r}"
        )
    gains = finite_numbers(quad.attitude_gains, 2)
    if gains is None or not all(v > 0 for v in gains):
        raise ValueError(
            "carrier.attitude_gains must be 2 numbers > 0 (k_R [1/s^2], k_Omega [1/s]), "
            f"got {quad.attitude_gains!r}"
        )
    if quad.initial_attitude not in QUADROTOR_START_ATTITUDES:
        raise ValueError(
            f"carrier.initial_attitude must be one of {', '.join(QUADROTOR_START_ATTITUDES)}, "
            f"got {quad.initial_attitude!r}"
        )
    if quad.heading not in QUADROTOR_HEADINGS:
        raise ValueError(
            f"carrier.heading must be one of {', '.join(QUADROTOR_HEADINGS)}, got {quad.heading!r}"
        )


def goal_tilt(X_WC_goal: RigidTransform, X_RC: RigidTransform) -> float:
    """The tilt [rad] of a carrier's body from level where its camera is at
    ``X_WC_goal``, the camera at ``X_RC`` on the body: the angle between the body's z
    axis and the world's."""
    z_body = (X_WC_goal @ X_RC.inverse()).rotation().matrix()[:, 2]
    return float(math.acos(max(-1.0, min(1.0, z_body[2]))))


def check_quadrotor_scenario(
    quad: Quadrotor,
    X_WB: RigidTransform,
    X_BC_goal: RigidTransform,
    X_BC_initial: RigidTransform,
    dynamic: bool,
    fov_half_angle: float,
    target_motion: object = None,
) -> None:
    """What the quadrotor asks of the scenario around it, one line each: the dynamic
    plant (its rotors push; a velocity-commanded quadrotor is another carrier), a mount
    that sees the target from the goal with the body level, a goal held level, a target
    that translates only (``target_motion``; the goal's heading is the cascade's, held),
    and with ``initial_attitude: given`` a start whose tilt the rotors can hold the
    weight at (``level`` levels it: :func:`level_start`)."""
    if not dynamic:
        raise ValueError(
            "carrier Quadrotor runs on the dynamic plant only (its rotors push; a "
            "velocity-commanded quadrotor is not this carrier), got plant Kinematic()"
        )
    _check_goal_level(quad, X_WB, X_BC_goal, fov_half_angle)
    turn = target_turn(target_motion)
    if turn > 0:
        # The cascade holds the goal's heading and a level hover: a turning target would
        # turn the goal's attitude (off level, about any axis but the vertical).
        raise ValueError(
            "carrier Quadrotor follows a translating target only (the cascade holds the "
            f"goal's heading and a level hover): target_motion turns by up to {turn:.4g} "
            "rad (its twist's angular part, or its trajectory's orientations)"
        )
    if quad.initial_attitude == "level":
        return
    start_tilt = goal_tilt(X_WB @ X_BC_initial, quad.X_RC)
    # Past this tilt the rotors at full thrust no longer hold the weight: the body falls
    # while it levels (the default scenario's start, 115 deg with the forward mount,
    # left D at t = 0.23 s, measured).
    most = math.acos(min(1.0, quad.mass * GRAVITY / (4 * quad.max_rotor_thrust)))
    if start_tilt > most:
        raise ValueError(
            f"the start tilts the quadrotor by {math.degrees(start_tilt):.3g} deg, past "
            f"{math.degrees(most):.3g} deg, where its rotors at full thrust no longer hold "
            "its weight: start it nearer a level hover (the forward mount: initial rpy "
            "[0, heading, 0], e.g. --initial=0.12,-0.08,-0.8,0,0.3,0)"
        )


def target_turn(target_motion: object) -> float:
    """How far a target's motion turns it: its twist's angular speed [rad/s] (a
    :class:`~geovs_drake.scenario.Twist`), the largest angle [rad] of its trajectory's
    orientations from the start's (a :class:`~geovs_drake.scenario.Trajectory`), else 0."""
    if isinstance(target_motion, Twist):
        return float(np.linalg.norm(np.asarray(target_motion.twist[0:3], dtype=float)))
    if not isinstance(target_motion, Trajectory):
        return 0.0
    pose = target_trajectory(target_motion)
    angles = [
        AngleAxis(pose.GetPose(t).rotation().ToQuaternion()).angle()
        for t in pose.get_segment_times()
    ]
    return float(max(angles))


def level_start(
    quad: Quadrotor, X_WB: RigidTransform, X_BC_initial: RigidTransform
) -> tuple[RigidTransform, float]:
    """``initial_attitude: level``'s start: X_BC(0) of the camera on the level body with
    the start's camera position and the body's heading (its x axis's, as the cascade's
    heading and :class:`~geovs_drake.systems.LevelView` read it; the y axis's turned by
    -90 deg where x is vertical), and the tilt [rad] dropped, the angle between the
    start's body z axis and the world's."""
    X_WC = X_WB @ X_BC_initial
    R = (X_WC @ quad.X_RC.inverse()).rotation().matrix()
    x, y = R[:, 0], R[:, 1]
    heading = math.atan2(x[1], x[0]) if math.hypot(x[0], x[1]) > 1e-6 else math.atan2(-y[0], y[1])
    R_level = RotationMatrix.MakeZRotation(heading)
    # The camera's origin kept: p_WR = p_WC - R_level p_RC.
    X_WR = RigidTransform(R_level, X_WC.translation() - R_level.matrix() @ quad.X_RC.translation())
    tilt = math.acos(max(-1.0, min(1.0, float(R[2, 2]))))
    return X_WB.inverse() @ X_WR @ quad.X_RC, tilt


def carrier_start(
    carrier: object, X_WB: RigidTransform, X_BC_initial: RigidTransform
) -> tuple[RigidTransform, str] | None:
    """Where a carrier changes the start it is given: the X_BC(0) it starts at and the
    run's warning line that says so, or None (the start as given). The quadrotor with
    ``initial_attitude: level`` and a tilted start: :func:`level_start`."""
    if not (isinstance(carrier, Quadrotor) and carrier.initial_attitude == "level"):
        return None
    X_BC, tilt = level_start(carrier, X_WB, X_BC_initial)
    if tilt <= 1e-9:  # level already (a leveled start read back through its rpy)
        return None
    return X_BC, (
        f"carrier.initial_attitude level: the quadrotor starts level, its body's roll and "
        f"pitch at the start dropped (a tilt of {math.degrees(tilt):.3g} deg); the camera's "
        "position and the body's heading kept (initial_attitude: given keeps the tilt)"
    )


def _check_goal_level(
    quad: Quadrotor, X_WB: RigidTransform, X_BC_goal: RigidTransform, fov_half_angle: float
) -> None:
    """The goal's body level, else one line: the mount that cannot see the target from
    a level body, or the tilt the goal needs."""
    X_WC = X_WB @ X_BC_goal
    X_WR = X_WC @ quad.X_RC.inverse()
    tilt = goal_tilt(X_WC, quad.X_RC)
    if tilt <= LEVEL_TOLERANCE_RAD:
        return
    # The level body nearest the goal's (turned about the horizontal axis that levels it):
    # where would its camera look?
    z_body = X_WR.rotation().matrix()[:, 2]
    axis = np.cross(z_body, [0.0, 0.0, 1.0])
    norm = np.linalg.norm(axis)
    axis = axis / norm if norm > 1e-12 else np.array([1.0, 0.0, 0.0])
    R_level = RotationMatrix(AngleAxis(tilt, axis)) @ X_WR.rotation()
    optical_axis = (R_level @ quad.X_RC.rotation()).matrix()[:, 2]
    to_target = X_WB.translation() - X_WC.translation()
    off_axis = math.acos(
        max(-1.0, min(1.0, float(optical_axis @ to_target / np.linalg.norm(to_target))))
    )
    if off_axis >= fov_half_angle:
        raise ValueError(
            f"carrier.mount {quad.mount} does not see the target at the goal: with the body "
            f"level the target is {math.degrees(off_axis):.1f} deg off the optical axis "
            f"(field of view {math.degrees(fov_half_angle):.1f} deg)"
        )
    raise ValueError(
        f"the goal needs the quadrotor tilted by {math.degrees(tilt):.3g} deg (with carrier."
        f"mount {quad.mount}): a quadrotor holds a level hover only; give a goal whose "
        "camera, on the mount, leaves the body level"
    )
