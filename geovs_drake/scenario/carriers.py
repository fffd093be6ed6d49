"""The carrier, one variant each (``ScenarioConfig.carrier``): what moves the camera.

In YAML a carrier is tagged with its class name, ``carrier: !Arm {model: panda}``; a
scenario file's bare name (``carrier: arm``, ``carrier: free``) reads as that variant
with its defaults. The loop takes each carrier's systems from
:data:`geovs_drake.loop.carriers.CARRIERS`, keyed by the variant's and the plant's types.
"""

from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from geovs_drake.scenario.plants import Dynamic, Kinematic
from geovs_drake.scenario.pose import PoseConfig, check_at_least, finite_numbers
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
    "RigidBodyConfig",
    "check_carrier",
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

#: A carrier's configuration: one of the variants above.
CarrierConfig = FreeRig | FixedCamera | Arm
#: The carrier of each name, as ``--carrier`` and a file's bare name give it.
CARRIER_VARIANTS: dict[str, type] = {"free": FreeRig, "fixed": FixedCamera, "arm": Arm}

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
