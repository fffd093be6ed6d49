"""The arm a camera rides on: how to load it, once, into any MultibodyPlant.

:class:`ArmModel` says which model file, where its base stands and where the
camera sits on which frame; :func:`add_arm` puts it into a plant (the
simulated one, with a SceneGraph, or a system's own model for its Jacobians);
:func:`arm_plant` builds and caches the model alone, Finalized, of any scalar
type (a TemplateSystem's conversion gets the plant of its own T). :data:`ARMS`
holds the arms known by name (``Arm.model``: ``default``, ``panda``), each with
the scene that suits it.
"""

from __future__ import annotations

import functools
import importlib.metadata
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant, MultibodyPlant_
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    Frame,
    JacobianWrtVariable,
    ModelInstanceIndex,
)

from geovs_drake._optional import MissingExtra

__all__ = [
    "ARMS",
    "CAMERA_FRAME",
    "DEFAULT_ARM",
    "ArmError",
    "ArmModel",
    "NamedArm",
    "add_arm",
    "arm_plant",
    "camera_jacobian",
    "default_arm_model",
]

#: The name of the camera's frame C, added on the end-effector frame.
CAMERA_FRAME = "camera"
#: The arm shipped in the package (a UR5's published parameters; see its header).
DEFAULT_ARM = str(files("geovs_drake.models").joinpath("ur5.urdf"))


class ArmError(ValueError):
    """The arm's model cannot be used: unloadable, no such frame, no actuated joint."""


@dataclass(frozen=True)
class ArmModel:
    """The arm: ``path`` (URDF or SDFormat), its base at ``X_W_base`` (xyz, rpy) welded
    to the world, the camera frame C at ``X_EC`` (xyz, rpy) on ``end_effector_frame``.
    Hashable, so built plants are cached per model."""

    path: str
    end_effector_frame: str
    base_xyz_rpy: tuple[float, ...]
    camera_xyz_rpy: tuple[float, ...]
    #: Joints welded where they stand at zero (a URDF's ``fixed``): a gripper's fingers,
    #: whose ``<mimic>`` coupling a continuous plant (``time_step=0``) cannot take.
    welded_joints: tuple[str, ...] = ()
    #: Actuators added for joints the file leaves without one (no ``<transmission>``):
    #: ``(joint, reflected inertia [kg m^2])``, the effort limit the joint's own.
    added_actuators: tuple[tuple[str, float], ...] = ()
    #: ``package://`` names the file's meshes use, and their folders.
    packages: tuple[tuple[str, str], ...] = ()

    @property
    def X_W_base(self) -> RigidTransform:
        """The base's pose in the world."""
        return _pose(self.base_xyz_rpy)

    @property
    def X_EC(self) -> RigidTransform:
        """The camera frame C on the end-effector frame E."""
        return _pose(self.camera_xyz_rpy)


def camera_jacobian(plant: MultibodyPlant_, context, camera: Frame) -> np.ndarray:
    """J_C (6 x nv): the camera frame's spatial-velocity Jacobian in W, expressed in C, so
    that ``J_C v = (Omega, V)``, the body twist of Eqs. (16)-(17), rotational first."""
    return plant.CalcJacobianSpatialVelocity(
        context, JacobianWrtVariable.kV, camera, np.zeros(3), plant.world_frame(), camera
    )


def default_arm_model() -> ArmModel:
    """The shipped arm, its base at the world's origin, the camera on tool0: what the
    arm systems build when given no model (their documentation, a quick look)."""
    return ArmModel(DEFAULT_ARM, "tool0", (0.0,) * 6, (0.0,) * 6)


@dataclass(frozen=True)
class NamedArm:
    """An arm known by name in ``Arm.model``: where its file is, how it is made ready for
    the loop, and the scene that suits it (the scenario's ``arm`` fields left unset take
    these)."""

    #: The model file and its ``package://`` folders; :class:`MissingExtra` when the
    #: package that brings it is not installed.
    locate: Callable[[], tuple[str, tuple[tuple[str, str], ...]]]
    end_effector_frame: str
    base_xyz_rpy: tuple[float, ...]
    camera_xyz_rpy: tuple[float, ...]
    welded_joints: tuple[str, ...] = ()
    added_actuators: tuple[tuple[str, float], ...] = ()

    def model(
        self,
        end_effector_frame: str | None = None,
        base_xyz_rpy: tuple[float, ...] | None = None,
        camera_xyz_rpy: tuple[float, ...] | None = None,
    ) -> ArmModel:
        """The :class:`ArmModel`, with this arm's frame, base and camera where not given."""
        path, packages = self.locate()
        return ArmModel(
            path=path,
            end_effector_frame=end_effector_frame or self.end_effector_frame,
            base_xyz_rpy=self.base_xyz_rpy if base_xyz_rpy is None else base_xyz_rpy,
            camera_xyz_rpy=self.camera_xyz_rpy if camera_xyz_rpy is None else camera_xyz_rpy,
            welded_joints=self.welded_joints,
            added_actuators=self.added_actuators,
            packages=packages,
        )


#: Where example-robot-data's files lie in its wheel (a cmeel prefix in site-packages).
_ROBOT_DATA = "cmeel.prefix/share/example-robot-data"
_PANDA_URDF = "robots/panda_description/urdf/panda_collision.urdf"
#: Franka's published reflected inertias of the seven axes [kg m^2] (Franka FR-3 data,
#: as Drake's own franka_description model cites them); example-robot-data's Panda
#: has no transmissions, hence none.
PANDA_REFLECTED_INERTIA = (0.605721456, 0.605721456, 0.462474144, 0.462474144, 0.205544064,
                           0.205544064, 0.205544064)  # fmt: skip


def _shipped_ur5() -> tuple[str, tuple[tuple[str, str], ...]]:
    return DEFAULT_ARM, ()


def _robot_data_panda() -> tuple[str, tuple[tuple[str, str], ...]]:
    """example-robot-data's Panda (Apache-2.0), its collision model: spheres and
    capsules that load offline (its visuals are .dae meshes: Meshcat draws them, the
    VTK renderer does not)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise MissingExtra("example-robot-data", "panda", "arm 'panda'") from None
    root = dist.locate_file(_ROBOT_DATA)
    path = root / _PANDA_URDF
    if not path.is_file():
        raise ArmError(f"arm 'panda': example-robot-data {dist.version} has no {_PANDA_URDF}")
    return str(path), (("example-robot-data", str(root)),)


#: The arms known by name: ``Arm.model`` is one of these or a model file's path.
ARMS: dict[str, NamedArm] = {
    "default": NamedArm(
        locate=_shipped_ur5,
        end_effector_frame="tool0",
        # The base on a pedestal beside the line of sight, 0.65 m to the side of the
        # target's axis, level with the target and 0.85 m back from it, facing the axis:
        # the goal, the default start and every start of the comparison suite are
        # reachable, the nearest joint limit at least 1.6 rad away (chosen on a grid of
        # base positions; tests/test_arm.py holds it).
        base_xyz_rpy=(-0.85, 0.65, 1.0, 0.0, 0.0, -np.pi / 2),
        camera_xyz_rpy=(0.0, 0.0, 0.03, 0.0, 0.0, 0.0),
    ),
    "panda": NamedArm(
        locate=_robot_data_panda,
        # The camera at the tool centre point, looking out of the hand (z), turned a
        # quarter turn about it; the base on a table 0.25 m below the target, 1.0 m back
        # from it and 0.6 m to the side, facing the target's axis: the goal, the default
        # start and every start of the comparison suite are reachable, every joint at
        # least 0.58 rad from its limits (the Panda's ranges are narrow: joint 4 spans
        # 3.0 rad, joint 6 3.8) and sigma_min(J_C) >= 0.08 (the best of 405 bases and
        # camera turns on a grid; tests/test_arm_panda.py holds it).
        end_effector_frame="panda_hand_tcp",
        base_xyz_rpy=(-1.0, 0.6, 0.75, 0.0, 0.0, -np.pi / 2),
        camera_xyz_rpy=(0.0, 0.0, 0.0, 0.0, 0.0, -np.pi / 2),
        welded_joints=("panda_finger_joint1", "panda_finger_joint2"),
        added_actuators=tuple(
            (f"panda_joint{i + 1}", inertia) for i, inertia in enumerate(PANDA_REFLECTED_INERTIA)
        ),
    ),
}


def _pose(xyz_rpy: tuple[float, ...]) -> RigidTransform:
    return RigidTransform(RollPitchYaw(np.array(xyz_rpy[3:6])), np.array(xyz_rpy[0:3]))


def add_arm(plant: MultibodyPlant, model: ArmModel) -> tuple[ModelInstanceIndex, Frame]:
    """Parse the arm into ``plant`` (not Finalized), weld its base, add the camera frame.

    Returns the model instance and the camera frame C. Raises :class:`ArmError` in one
    line for a file Drake cannot load or a missing frame. (The actuators can only be
    counted once the plant is Finalized: :func:`arm_plant` checks them.)
    """
    parser = Parser(plant, "arm")
    for name, folder in model.packages:
        parser.package_map().Add(name, folder)
    try:
        if model.welded_joints or model.added_actuators:
            (instance,) = parser.AddModelsFromString(_prepared_urdf(model), "urdf")
        else:
            (instance,) = parser.AddModels(model.path)
    except (RuntimeError, ValueError, ET.ParseError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        if "unknown package" in first:  # a package:// URI: the user can name its folder
            first += " (name its folder in carrier.packages)"
        raise ArmError(f"carrier.model {model.path}: Drake cannot load it: {first}") from e
    names = [plant.get_frame(i).name() for i in plant.GetFrameIndices(instance)]
    if model.end_effector_frame not in names:
        raise ArmError(
            f"carrier.end_effector_frame {model.end_effector_frame!r} is not a frame of "
            f"{model.path} (frames: {', '.join(names)})"
        )
    # The first body of the model is its root: the base, welded where the scenario puts it.
    base = plant.get_body(plant.GetBodyIndices(instance)[0])
    plant.WeldFrames(plant.world_frame(), base.body_frame(), model.X_W_base)
    end_effector = plant.GetFrameByName(model.end_effector_frame, instance)
    camera = plant.AddFrame(FixedOffsetFrame(CAMERA_FRAME, end_effector, model.X_EC))
    return instance, camera


_DRAKE_NS = "http://drake.mit.edu"


def _prepared_urdf(model: ArmModel) -> str:
    """The URDF's text with ``welded_joints`` fixed, ``added_actuators``' transmissions
    written in (Drake's URDF transmission: the actuator's effort limit is the joint's
    ``<limit effort>``; the reflected inertia as ``drake:rotor_inertia`` with gear ratio
    1) and ROS's ``safety_controller`` tags left out. ArmError for a joint the file does
    not have."""
    ET.register_namespace("drake", _DRAKE_NS)
    robot = ET.parse(model.path).getroot()
    joints = {joint.get("name"): joint for joint in robot.iter("joint")}
    for name in (*model.welded_joints, *(joint for joint, _ in model.added_actuators)):
        if name not in joints:
            raise ArmError(f"carrier.model {model.path}: it has no joint {name!r}")
    for joint in joints.values():  # ROS's tag, which Drake ignores with a warning each
        for child in joint.findall("safety_controller"):
            joint.remove(child)
    for name in model.welded_joints:
        joint = joints[name]
        joint.set("type", "fixed")
        for tag in ("axis", "limit", "mimic", "dynamics", "calibration"):
            for child in joint.findall(tag):
                joint.remove(child)
    for name, inertia in model.added_actuators:
        transmission = ET.SubElement(robot, "transmission", name=f"{name}_transmission")
        ET.SubElement(transmission, "type").text = "transmission_interface/SimpleTransmission"
        ET.SubElement(transmission, "joint", name=name)
        actuator = ET.SubElement(transmission, "actuator", name=f"{name}_motor")
        ET.SubElement(actuator, f"{{{_DRAKE_NS}}}rotor_inertia", value=repr(float(inertia)))
        ET.SubElement(actuator, f"{{{_DRAKE_NS}}}gear_ratio", value="1.0")
    return ET.tostring(robot, encoding="unicode")


@functools.lru_cache(maxsize=8)
def _float_plant(model: ArmModel) -> MultibodyPlant:
    plant = MultibodyPlant(time_step=0.0)
    add_arm(plant, model)
    plant.Finalize()
    if plant.num_actuators() == 0:
        raise ArmError(f"carrier.model {model.path}: no actuated joint (add <transmission>s)")
    return plant


def arm_plant(model: ArmModel, T: type = float) -> MultibodyPlant_:
    """The arm alone in a continuous MultibodyPlant_[T], Finalized, gravity on (cached
    for float; a converted copy for another T)."""
    plant = _float_plant(model)
    return plant if T is float else plant.ToScalarType[T]()
