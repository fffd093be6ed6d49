"""The free rig of Appendix C, eye-in-hand: a MultibodyPlant free body driven by a wrench
(the dynamic plant), or a kinematic body whose twist is commanded (Eqs. 17-19)."""

from __future__ import annotations

import dataclasses

from pydrake.geometry import (
    Role,
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from geovs_drake.loop.carriers.parts import (
    RIG_BODY_NAME,
    CarrierFactory,
    CarrierParts,
    draw_at,
    drawing_plant,
    free_body,
    leading_pose,
    meshcat_with_camera,
    no_initial_state,
    out_of_view,
    pose_head,
    set_plant_state,
)
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.state import initial_rig_pose
from geovs_drake.scenario import Dynamic, FreeRig, Kinematic
from geovs_drake.systems import (
    KinematicRigidBody,
)
from geovs_drake.visualization import (
    add_camera_geometry,
    add_goal_ghost,
    add_marked_target_geometry,
    add_target_geometry,
)

__all__ = ["ENTRIES"]


def _free_rig(builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool):
    """Eye-in-hand, dynamic: the rig is a MultibodyPlant free body pushed by a wrench.

    The rig's body frame R has its origin at the centre of mass; the camera sits at
    X_RC on it (Appendix C.0.6). With ``draws_marks`` the target is drawn in the
    extractor's colours and the camera's own drawing and the goal ghost are kept out
    of the renderer (illustration only).
    """
    config = resolved.config
    plant, scene_graph, rig = free_body(builder, config, RIG_BODY_NAME)
    theta = resolved.domain.fov_half_angle
    (add_marked_target_geometry if draws_marks else add_target_geometry)(plant, config)
    drawing = add_camera_geometry(plant, rig, config.X_RC, theta) + add_goal_ghost(plant, config)
    plant.Finalize()
    plant.SetDefaultFloatingBaseBodyPose(rig, initial_rig_pose(config))
    if draws_marks:
        for geometry_id in drawing:
            scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kPerception)
    body_pose = pose_head(builder, plant.get_state_output_port())

    def connect_force(builder: DiagramBuilder, force: LeafSystem) -> None:
        # The force system shifts its wrench to the rig's origin in W itself: one
        # kernel call gives both (no system in between on the hot path).
        builder.Connect(
            force.generalized_force_output, plant.get_applied_generalized_force_input_port()
        )

    return CarrierParts(
        body_pose=body_pose,
        state=plant.get_state_output_port(),
        state_log_name="log_body_state",
        X_WB=config.X_WB,
        X_RC=config.X_RC,
        pose_of_states=leading_pose,
        set_initial_state=set_plant_state(plant, config),
        body_state=plant.get_state_output_port(),
        connect_force=connect_force,
        add_meshcat=meshcat_with_camera(scene_graph, rig, config.X_RC),
        plant=plant,
        scene_graph=scene_graph,
        body=rig,
    )


def _kinematic_body(builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool):
    """Eye-in-hand, kinematic (Eqs. 17-19): the body *is* the camera frame (X_RC = I),
    its body twist commanded. With ``draws_marks`` (a camera) a plant with no dynamics of
    its own draws the scene at the body's pose, as the kinematic arm's does, for the
    renderer and Meshcat."""
    config = resolved.config
    body = builder.AddNamedSystem(
        "kinematic_rigid_body", KinematicRigidBody(X_WC0=config.X_WB @ config.X_BC_initial)
    )
    parts = CarrierParts(
        body_pose=body.body_pose_output,
        state=body.body_pose_output,
        state_log_name="log_body_pose",
        X_WB=config.X_WB,
        X_RC=RigidTransform(),
        pose_of_states=leading_pose,
        set_initial_state=no_initial_state,
        twist_input=body.camera_velocity_input,
    )
    if not draws_marks:
        return parts
    scene_graph = builder.AddNamedSystem("scene_graph", SceneGraph())
    plant, (rig,) = drawing_plant(scene_graph, RIG_BODY_NAME)
    add_marked_target_geometry(plant, config)
    drawing = add_camera_geometry(plant, rig, RigidTransform(), resolved.domain.fov_half_angle)
    drawing += add_goal_ghost(plant, config)
    plant.Finalize()
    out_of_view(scene_graph, plant, drawing)
    # The plant's positions are the free body's [q, p]: the kinematic body's pose.
    draw_at(builder, plant, scene_graph, body.body_pose_output, "rig_drawing")
    return dataclasses.replace(
        parts,
        add_meshcat=meshcat_with_camera(scene_graph, rig, RigidTransform()),
        plant=plant,
        scene_graph=scene_graph,
        body=rig,
    )


#: The free rig's factories, by the plant's type.
ENTRIES: dict[tuple[type, type], CarrierFactory] = {
    (FreeRig, Dynamic): _free_rig,
    (FreeRig, Kinematic): _kinematic_body,
}
