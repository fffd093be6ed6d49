"""The arm a camera rides on: how to load it, once, into any MultibodyPlant.

:class:`ArmModel` says which model file, where its base stands and where the
camera sits on which frame; :func:`add_arm` puts it into a plant (the
simulated one, with a SceneGraph, or a system's own model for its Jacobians);
:func:`arm_plant` builds and caches the model alone, Finalized, of any scalar
type (a TemplateSystem's conversion gets the plant of its own T).
"""

from __future__ import annotations

import functools
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

__all__ = [
    "CAMERA_FRAME",
    "DEFAULT_ARM",
    "ArmError",
    "ArmModel",
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


def _pose(xyz_rpy: tuple[float, ...]) -> RigidTransform:
    return RigidTransform(RollPitchYaw(np.array(xyz_rpy[3:6])), np.array(xyz_rpy[0:3]))


def add_arm(plant: MultibodyPlant, model: ArmModel) -> tuple[ModelInstanceIndex, Frame]:
    """Parse the arm into ``plant`` (not Finalized), weld its base, add the camera frame.

    Returns the model instance and the camera frame C. Raises :class:`ArmError` in one
    line for a file Drake cannot load or a missing frame. (The actuators can only be
    counted once the plant is Finalized: :func:`arm_plant` checks them.)
    """
    try:
        (instance,) = Parser(plant, "arm").AddModels(model.path)
    except (RuntimeError, ValueError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ArmError(f"arm.model {model.path}: Drake cannot load it: {first}") from e
    names = [plant.get_frame(i).name() for i in plant.GetFrameIndices(instance)]
    if model.end_effector_frame not in names:
        raise ArmError(
            f"arm.end_effector_frame {model.end_effector_frame!r} is not a frame of "
            f"{model.path} (frames: {', '.join(names)})"
        )
    # The first body of the model is its root: the base, welded where the scenario puts it.
    base = plant.get_body(plant.GetBodyIndices(instance)[0])
    plant.WeldFrames(plant.world_frame(), base.body_frame(), model.X_W_base)
    end_effector = plant.GetFrameByName(model.end_effector_frame, instance)
    camera = plant.AddFrame(FixedOffsetFrame(CAMERA_FRAME, end_effector, model.X_EC))
    return instance, camera


@functools.lru_cache(maxsize=8)
def _float_plant(model: ArmModel) -> MultibodyPlant:
    plant = MultibodyPlant(time_step=0.0)
    add_arm(plant, model)
    plant.Finalize()
    if plant.num_actuators() == 0:
        raise ArmError(f"arm.model {model.path}: no actuated joint (add <transmission>s)")
    return plant


def arm_plant(model: ArmModel, T: type = float) -> MultibodyPlant_:
    """The arm alone in a continuous MultibodyPlant_[T], Finalized, gravity on (cached
    for float; a converted copy for another T)."""
    plant = _float_plant(model)
    return plant if T is float else plant.ToScalarType[T]()
