"""The fixed camera, eye-to-hand: the camera fixed in the world at the eye-in-hand goal,
the target the driven body (a wrench, or a commanded twist); the laws see G = H^-1 (Eq. 16)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import (
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from geovs_drake.geometry._ops import MATH, NUMPY
from geovs_drake.geometry.rigid import fixed_camera_relative_pose
from geovs_drake.loop.carriers.parts import (
    TARGET_BODY_NAME,
    CarrierFactory,
    CarrierParts,
    draw_at,
    drawing_plant,
    free_body,
    meshcat_with_camera,
    no_initial_state,
    out_of_view,
    pose_head,
    set_plant_state,
)
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.state import POSE, fixed_camera_pose, initial_rig_state
from geovs_drake.scenario import Dynamic, FixedCamera, Kinematic
from geovs_drake.systems import (
    FixedCameraKinematicMount,
    FixedCameraMount,
    KinematicRigidBody,
)
from geovs_drake.visualization import (
    add_camera_geometry,
    add_marked_target_geometry,
    add_target_geometry,
)

__all__ = ["ENTRIES"]


def _relative_pose(X_WC: RigidTransform) -> Callable[[np.ndarray, object], tuple]:
    """The fixed camera reads G = X_WB^-1 X_WC from the target's state."""
    q_WC = tuple(X_WC.rotation().ToQuaternion().wxyz().tolist())
    p_WC = tuple(X_WC.translation().tolist())

    def pose_of_states(states: np.ndarray, ops: object) -> tuple:
        x = np.asarray(states, dtype=float)
        if x.ndim > 1:
            return fixed_camera_relative_pose(tuple(x[..., POSE].T), q_WC, p_WC, NUMPY)
        return fixed_camera_relative_pose(tuple(x[POSE].tolist()), q_WC, p_WC, MATH)

    return pose_of_states


def _fixed_rig(builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool):
    """Fixed camera (eye-to-hand), dynamic: the target sphere is the free body, with the
    rig's mass model about its centre, and the camera stands at
    :func:`~geovs_drake.loop.state.fixed_camera_pose`. The camera system and the laws
    see the relative pose G = H^-1 (Eq. 16), with the target frame as their world
    (X_WB = X_RC = I); a :class:`~geovs_drake.systems.FixedCameraMount` turns the
    target's state into the camera's relative state and the law's camera wrench
    into the reaction on the target."""
    config = resolved.config
    X_WC = fixed_camera_pose(config)
    plant, scene_graph, target = free_body(builder, config, TARGET_BODY_NAME)
    drawing = _fixed_camera_scene(plant, resolved, target, X_WC, draws_marks)
    plant.Finalize()
    out_of_view(scene_graph, plant, drawing)
    x0 = initial_rig_state(config)
    plant.SetDefaultFloatingBaseBodyPose(target, RigidTransform(Quaternion(x0[0:4]), x0[4:7]))
    mount = builder.AddNamedSystem("fixed_camera_mount", FixedCameraMount(X_WC=X_WC))
    builder.Connect(plant.get_state_output_port(), mount.target_state_input)
    body_pose = pose_head(builder, mount.camera_state_output)

    def connect_force(builder: DiagramBuilder, force: LeafSystem) -> None:
        builder.Connect(force.wrench_C_output, mount.wrench_C_input)
        builder.Connect(
            mount.generalized_force_output, plant.get_applied_generalized_force_input_port()
        )

    return CarrierParts(
        body_pose=body_pose,
        state=plant.get_state_output_port(),
        state_log_name="log_body_state",
        X_WB=RigidTransform(),
        X_RC=RigidTransform(),
        pose_of_states=_relative_pose(X_WC),
        set_initial_state=set_plant_state(plant, config),
        body_state=mount.camera_state_output,
        connect_force=connect_force,
        add_meshcat=meshcat_with_camera(scene_graph, plant.world_body(), X_WC),
        plant=plant,
        scene_graph=scene_graph,
        # A camera model stands in the world at X_WC, looking at the target the rig moves.
        body=plant.world_body(),
        X_BodyC=X_WC,
    )


def _fixed_camera_scene(
    plant: MultibodyPlant, resolved: ResolvedScenario, target, X_WC: RigidTransform, marks: bool
) -> list:
    """The fixed camera's scene on ``plant``: the target on its body (in the extractor's
    colours with ``marks``), the goal's ghost and the camera in the world. Returns the
    drawing a camera must not see (the ghost and the camera itself) where ``marks``."""
    config = resolved.config
    if marks:
        add_marked_target_geometry(plant, config, body=target)
    else:
        add_target_geometry(plant, config, body=target)
    ghost = add_target_geometry(plant, config, X_WB=config.X_WB, alpha=0.25, prefix="goal_")
    camera = add_camera_geometry(plant, plant.world_body(), X_WC, resolved.domain.fov_half_angle)
    return ghost + camera if marks else []


def _fixed_kinematic(builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool):
    """Fixed camera, kinematic: the target is a kinematic body whose twist a
    :class:`~geovs_drake.systems.FixedCameraKinematicMount` makes from the law's
    camera twist (Eq. 16)."""
    config = resolved.config
    X_WC = fixed_camera_pose(config)
    body = builder.AddNamedSystem(
        "kinematic_rigid_body", KinematicRigidBody(X_WC0=X_WC @ config.X_BC_initial.inverse())
    )
    mount = builder.AddNamedSystem("fixed_camera_mount", FixedCameraKinematicMount(X_WC=X_WC))
    builder.Connect(body.body_pose_output, mount.target_pose_input)
    builder.Connect(mount.target_velocity_output, body.camera_velocity_input)
    parts = CarrierParts(
        body_pose=mount.camera_pose_output,
        state=body.body_pose_output,
        state_log_name="log_body_pose",
        X_WB=RigidTransform(),
        X_RC=RigidTransform(),
        pose_of_states=_relative_pose(X_WC),
        set_initial_state=no_initial_state,
        twist_input=mount.camera_velocity_input,
    )
    if not draws_marks:
        return parts
    # A camera model: the scene drawn by a plant with no dynamics, the target at the
    # kinematic body's pose (the kinematic free rig's drawing, eye-to-hand).
    scene_graph = builder.AddNamedSystem("scene_graph", SceneGraph())
    plant, (target,) = drawing_plant(scene_graph, TARGET_BODY_NAME)
    drawing = _fixed_camera_scene(plant, resolved, target, X_WC, draws_marks)
    plant.Finalize()
    out_of_view(scene_graph, plant, drawing)
    draw_at(builder, plant, scene_graph, body.body_pose_output, "target_drawing")
    return dataclasses.replace(
        parts,
        add_meshcat=meshcat_with_camera(scene_graph, plant.world_body(), X_WC),
        plant=plant,
        scene_graph=scene_graph,
        body=plant.world_body(),
        X_BodyC=X_WC,
    )


#: The fixed camera's factories, by the plant's type.
ENTRIES: dict[tuple[type, type], CarrierFactory] = {
    (FixedCamera, Dynamic): _fixed_rig,
    (FixedCamera, Kinematic): _fixed_kinematic,
}
