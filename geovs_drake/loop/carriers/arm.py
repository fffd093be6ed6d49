"""A robot arm carrying the camera in its hand: joint torques through J_C^T (the dynamic
plant, :class:`~geovs_drake.systems.ArmCamera`) or joint velocities J_C^+ (Omega, V)
(the kinematic plant, :class:`~geovs_drake.systems.KinematicArm`), its scene shared with
the hardware station (:func:`add_arm_scene`)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit
from pydrake.geometry import (
    CollisionFilterDeclaration,
    Meshcat,
    PerceptionProperties,
    RenderLabel,
    Role,
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import BodyIndex, RigidBody
from pydrake.systems.framework import Context, DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.primitives import Multiplexer
from pydrake.systems.rendering import MultibodyPositionToGeometryPose

from geovs_drake.geometry.joint_barrier import joint_widths
from geovs_drake.goal.arm import arm_model, initial_joints
from geovs_drake.loop.carriers.parts import (
    RIG_BODY_NAME,
    TARGET_BODY_NAME,
    TARGET_RENDER_LABEL,
    CarrierFactory,
    CarrierParts,
    draw_at,
    drawing_plant,
    meshcat_with_camera,
    no_initial_state,
    out_of_view,
    pose_head,
)
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.scenario import Arm, Dynamic, Kinematic
from geovs_drake.systems import (
    ArmCamera,
    KinematicArm,
)
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems.arm_model import CAMERA_FRAME, ArmModel, add_arm, arm_plant
from geovs_drake.visualization import (
    add_camera_geometry,
    add_goal_ghost,
    add_marked_target_geometry,
    add_target_geometry,
)

__all__ = ["ENTRIES", "add_arm_scene", "target_drawing", "world_view_meshcat"]


def _arm_forward(model: ArmModel) -> Callable[[np.ndarray, object], tuple]:
    """The camera pose ``[q_WC, p_WC]`` of arm states (q first), by the arm's own model:
    the monitor's and the logs' path, without the diagram."""
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    camera = plant.GetFrameByName(CAMERA_FRAME)
    nq = plant.num_positions()

    def one(q: np.ndarray) -> np.ndarray:
        plant.SetPositions(context, q)
        X = camera.CalcPoseInWorld(context)
        return np.concatenate([X.rotation().ToQuaternion().wxyz(), X.translation()])

    def pose_of_states(states: np.ndarray, ops: object) -> tuple:
        x = np.asarray(states, dtype=float)
        if x.ndim == 1:
            return tuple(one(x[:nq]).tolist())
        return tuple(np.stack([one(row[:nq]) for row in x]).T)

    return pose_of_states


@njit(cache=True, nogil=True)
def _first_outside(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> int:
    """The first joint with ``q < lower`` or ``q > upper`` (a NaN is neither), else -1:
    numpy's three calls' verdict in 0.3 us instead of 2.4 us."""
    for i in range(q.shape[0]):
        if q[i] < lower[i] or q[i] > upper[i]:
            return i
    return -1


def _joint_limits(model: ArmModel) -> Callable[[np.ndarray], str | None]:
    """The arm's joint limits on a state whose head is q (neither plant enforces them:
    a continuous MultibodyPlant does not, and the kinematic arm integrates freely)."""
    plant = arm_plant(model)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    names = [
        plant.get_joint(j).name()
        for j in plant.GetJointIndices()
        if plant.get_joint(j).num_positions() == 1
    ]
    nq = plant.num_positions()

    def limit_check(x: np.ndarray) -> str | None:
        q = np.asarray(x[:nq], dtype=float)
        i = _first_outside(q, lower, upper)  # the monitor's every step: compiled
        if i < 0:
            return None
        name = names[i] if len(names) == nq else f"joint {i}"
        return f"joint limit: {name} = {q[i]:.4g} rad outside [{lower[i]:.4g}, {upper[i]:.4g}]"

    return limit_check


def add_arm_scene(
    builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool, dynamic: bool
) -> tuple[ArmModel, MultibodyPlant, SceneGraph, RigidBody, RigidTransform]:
    """A continuous MultibodyPlant (gravity on) with the arm and the target fixed at X_WB
    (a moving target is drawn apart, :func:`target_drawing`); returns ``(model, plant,
    scene_graph, link, X_LinkC)``, the camera on ``link`` at ``X_LinkC`` (the loop's arm
    carriers, and the LCM station's simulated Panda).

    ``dynamic``: the plant is the diagram's (it integrates the arm). Otherwise it only
    registers the arm's geometry with the SceneGraph and stays out of the diagram (no
    state of its own), as in Drake's examples that draw a plant from given positions.
    """
    config = resolved.config
    model = arm_model(config)
    if dynamic:
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    else:
        scene_graph = builder.AddNamedSystem("scene_graph", SceneGraph())
        plant = MultibodyPlant(time_step=0.0)
        plant.RegisterAsSourceForSceneGraph(scene_graph)
    instance, camera = add_arm(plant, model)
    X_LinkC = camera.GetFixedPoseInBodyFrame()
    drawing = add_camera_geometry(plant, camera.body(), X_LinkC, resolved.domain.fov_half_angle)
    if not config.moving_target:  # a moving one: target_drawing, at its pose X_WB(t)
        (add_marked_target_geometry if draws_marks else add_target_geometry)(plant, config)
        drawing += add_goal_ghost(plant, config)
    plant.Finalize()
    # The loop models no contact: an arm's collision geometry (the Panda's spheres, whose
    # links 1 and 3 overlap at home) would otherwise push the links apart with stiff
    # penalty forces in the continuous plant. Every pair of the plant's bodies filtered.
    bodies = [plant.get_body(BodyIndex(index)) for index in range(plant.num_bodies())]
    scene_graph.collision_filter_manager().Apply(
        CollisionFilterDeclaration().ExcludeWithin(plant.CollectRegisteredGeometries(bodies))
    )
    if draws_marks:
        for geometry_id in drawing:
            scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kPerception)
    return model, plant, scene_graph, camera.body(), X_LinkC


def target_drawing(
    scene_graph: SceneGraph, resolved: ResolvedScenario, draws_marks: bool
) -> Callable[[DiagramBuilder, OutputPort], None]:
    """A moving target drawn in a carrier's scene at X_WB(t): a plant with no dynamics of
    its own holds the target (in the extractor's colours with ``draws_marks``) and the
    goal's ghost, X_BC* on it, both on one free body placed at the pose the port gives
    (as the kinematic free rig draws its body)."""
    config = resolved.config

    def draw_target(builder: DiagramBuilder, target_pose: OutputPort) -> None:
        plant, (body,) = drawing_plant(scene_graph, TARGET_BODY_NAME)
        target = (add_marked_target_geometry if draws_marks else add_target_geometry)(
            plant, config, body=body
        )
        ghost = add_goal_ghost(plant, config, body=body)
        plant.Finalize()
        if draws_marks:
            out_of_view(scene_graph, plant, ghost)
            _relabel(scene_graph, plant, target, TARGET_RENDER_LABEL)
        draw_at(builder, plant, scene_graph, target_pose, "target_drawing")

    return draw_target


def world_view_meshcat(
    resolved: ResolvedScenario, X_RC: RigidTransform, rig_pose: OutputPort, target_pose: OutputPort
) -> Callable[[DiagramBuilder, Meshcat], None]:
    """Meshcat for a carrier simulated in a moving target's frame (the free rig), drawn in
    the world: a scene graph of its own, for illustration, with the rig at its world pose
    ``rig_pose`` (its camera at X_RC, the frame triad) and the target, the goal's ghost
    on it, at X_WB(t) ``target_pose`` (both ``[q, p]``, 7). The loop's own scene (the
    renderer's) stays in the target's frame, where the camera sees the same image."""
    config = resolved.config

    def add_meshcat(builder: DiagramBuilder, meshcat: Meshcat) -> None:
        scene_graph = builder.AddNamedSystem("world_scene_graph", SceneGraph())
        # The positions: the rig's [q, p] (0-6), then the target's.
        plant, (rig, target) = drawing_plant(scene_graph, RIG_BODY_NAME, TARGET_BODY_NAME)
        add_target_geometry(plant, config, body=target)
        add_goal_ghost(plant, config, body=target)
        add_camera_geometry(plant, rig, X_RC, resolved.domain.fov_half_angle)
        plant.Finalize()
        poses = builder.AddNamedSystem("world_drawing_poses", Multiplexer([POSE_SIZE, POSE_SIZE]))
        builder.Connect(rig_pose, poses.get_input_port(0))
        builder.Connect(target_pose, poses.get_input_port(1))
        draw_at(builder, plant, scene_graph, poses.get_output_port(), "world_drawing")
        meshcat_with_camera(scene_graph, rig, X_RC)(builder, meshcat)

    return add_meshcat


def _relabel(scene_graph: SceneGraph, plant: MultibodyPlant, ids: list, label: int) -> None:
    """Give ``ids``' perception the render label ``label``: a MultibodyPlant labels a
    body's geometry by its body index, which a second plant in the scene repeats (the
    arm's self-mask, which masks the arm's labels, would mask the target too)."""
    inspector = scene_graph.model_inspector()
    for geometry_id in ids:
        properties = PerceptionProperties(inspector.GetPerceptionProperties(geometry_id))
        properties.UpdateProperty("label", "id", RenderLabel(label))
        # SceneGraph replaces no perception role in place: removed, then assigned anew.
        scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kPerception)
        scene_graph.AssignRole(plant.get_source_id(), geometry_id, properties)


def _arm_parts(
    resolved: ResolvedScenario, draws_marks: bool, scene: tuple, **drive
) -> CarrierParts:
    """What both arms offer alike (the camera's own pose, X_RC = I; the arm's
    kinematics, drawing and limits), with ``drive``'s entries (how each is driven)."""
    config = resolved.config
    model, plant, scene_graph, link, X_LinkC = scene
    return CarrierParts(
        X_WB=config.X_WB,
        X_RC=RigidTransform(),
        pose_of_states=_arm_forward(model),
        add_meshcat=meshcat_with_camera(scene_graph, link, X_LinkC),
        plant=plant,
        scene_graph=scene_graph,
        body=link,
        X_BodyC=X_LinkC,
        arm=model,
        limit_check=_joint_limits(model),
        draw_target=(
            target_drawing(scene_graph, resolved, draws_marks) if config.moving_target else None
        ),
        **drive,
    )


def _clamp_entries(arm: LeafSystem, limits: np.ndarray):
    """The run's JSON entry ``torque_clamped_fraction``: the share of logged states at which
    the arm's torque (ArmCamera's, before the plant) passes an actuator's effort limit,
    where MultibodyPlant clamps it (the one term of the loop that Appendix C's energy
    argument does not cover; the sweep's ``torque_clamped`` column)."""

    def run_entries(root: Context, states: np.ndarray, times: np.ndarray) -> dict:
        context = root.Clone()  # the diagram evaluated at each logged state, at its time
        port = arm.actuation_output
        clamped = np.zeros(len(states), bool)
        for k, x in enumerate(states):
            context.SetTime(float(times[k]))
            context.SetContinuousState(x)
            clamped[k] = np.any(np.abs(port.Eval(arm.GetMyContextFromRoot(context))) > limits)
        return {"torque_clamped_fraction": float(np.mean(clamped)) if len(states) else 0.0}

    return run_entries


def _arm_dynamic(builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool):
    """Eye-in-hand on a torque-driven arm: the law's wrench becomes joint torques through
    the camera frame's Jacobian, with gravity compensated (:class:`ArmCamera`)."""
    config = resolved.config
    model, plant, scene_graph, link, X_LinkC = add_arm_scene(builder, resolved, draws_marks, True)
    q0 = initial_joints(config, resolved.domain)
    v0 = np.asarray(config.carrier.initial_joint_velocity or np.zeros(plant.num_velocities()))
    if len(v0) != plant.num_velocities():
        raise ValueError(
            f"carrier.initial_joint_velocity must give the arm's {plant.num_velocities()} joints, "
            f"got {len(v0)}"
        )
    plant.SetDefaultPositions(q0)
    # The barrier's width per joint: the carrier's width for all, or its fraction of each
    # joint's range (None: no barrier).
    barrier = joint_widths(
        plant.GetPositionLowerLimits(),
        plant.GetPositionUpperLimits(),
        config.carrier.joint_barrier_width,
        config.carrier.joint_barrier_fraction,
    )
    arm = builder.AddNamedSystem(
        "arm_camera",
        ArmCamera(
            model=model,
            joint_damping=config.carrier.joint_damping,
            joint_barrier_width=0.0 if barrier is None else barrier,
            null_space_damping=config.carrier.null_space_damping,
        ),
    )
    builder.Connect(plant.get_state_output_port(), arm.arm_state_input)
    builder.Connect(arm.actuation_output, plant.get_actuation_input_port())
    body_pose = pose_head(builder, arm.camera_state_output)

    def connect_force(builder: DiagramBuilder, force: LeafSystem) -> None:
        builder.Connect(force.wrench_C_output, arm.wrench_C_input)
        if barrier is not None:  # the barrier's k_p is the NF wrench's own (ImageJacobianForce)
            builder.Connect(force.potential_gain_output, arm.potential_gain_input)

    def set_initial_state(root: Context) -> None:
        plant.SetPositionsAndVelocities(
            plant.GetMyMutableContextFromRoot(root), np.concatenate([q0, v0])
        )

    return _arm_parts(
        resolved,
        draws_marks,
        (model, plant, scene_graph, link, X_LinkC),
        body_pose=body_pose,
        state=plant.get_state_output_port(),
        run_entries=_clamp_entries(arm, plant.GetEffortUpperLimits()),
        state_log_name="log_arm_state",
        set_initial_state=set_initial_state,
        body_state=arm.camera_state_output,
        connect_force=connect_force,
        feedforward_input=arm.feedforward_twist_input,
        phi_input=arm.phi_input if barrier is not None else None,
    )


def _arm_kinematic(builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool):
    """Eye-in-hand on a velocity-commanded arm: qdot = J_C^+ (Omega, V), scaled to the
    joints' velocity limits (:class:`KinematicArm`). The plant draws the arm (Meshcat,
    the renderer) at the positions the KinematicArm integrates."""
    config = resolved.config
    model, plant, scene_graph, link, X_LinkC = add_arm_scene(builder, resolved, draws_marks, False)
    q0 = initial_joints(config, resolved.domain)
    arm = builder.AddNamedSystem(
        "kinematic_arm",
        KinematicArm(
            model=model,
            q0=q0,
            null_space_gain=config.carrier.null_space_gain,
            singularity_damping=config.carrier.singularity_damping,
        ),
    )
    # The drawing follows q: the plant's positions from the arm's state, as Drake's
    # MultibodyPositionToGeometryPose does for a plant with no dynamics of its own.
    to_pose = builder.AddNamedSystem("arm_drawing", MultibodyPositionToGeometryPose(plant))
    builder.Connect(arm.arm_position_output, to_pose.get_input_port())
    builder.Connect(
        to_pose.get_output_port(), scene_graph.get_source_pose_port(plant.get_source_id())
    )
    return _arm_parts(
        resolved,
        draws_marks,
        (model, plant, scene_graph, link, X_LinkC),
        body_pose=arm.camera_pose_output,
        state=arm.arm_position_output,
        state_log_name="log_arm_position",
        set_initial_state=no_initial_state,
        twist_input=arm.camera_velocity_input,
    )


#: The carriers, by the carrier variant's and the plant's types (:func:`carrier_key`).


#: The arm's factories, by the plant's type.
ENTRIES: dict[tuple[type, type], CarrierFactory] = {
    (Arm, Dynamic): _arm_dynamic,
    (Arm, Kinematic): _arm_kinematic,
}
