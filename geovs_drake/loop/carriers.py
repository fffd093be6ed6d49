"""Carriers: what moves the camera (a loop is carrier + sensor + law, :mod:`.build`).

A carrier adds its bodies to the builder and returns :class:`CarrierParts`:
what it *offers* (the pose the camera system reads, the body state a force law
damps, its own state for the loggers) and what it *takes* (a wrench through
:attr:`CarrierParts.connect_force`, or a twist at :attr:`CarrierParts.twist_input`).
:data:`CARRIERS` registers one factory per carrier variant and plant
(:func:`carrier_key`: the types of ``config.carrier`` and ``config.plant``); adding a
carrier is one variant (:mod:`geovs_drake.scenario.carriers`), one factory and its entries.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import (
    CollisionFilterDeclaration,
    Meshcat,
    MeshcatVisualizer,
    PerceptionProperties,
    RenderLabel,
    Role,
    SceneGraph,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import BodyIndex, RigidBody, RotationalInertia, SpatialInertia
from pydrake.systems.framework import Context, DiagramBuilder, InputPort, LeafSystem, OutputPort
from pydrake.systems.primitives import Demultiplexer, Multiplexer
from pydrake.systems.rendering import MultibodyPositionToGeometryPose

from geovs_drake.geometry._ops import MATH, NUMPY
from geovs_drake.geometry.joint_barrier import joint_widths
from geovs_drake.geometry.rigid import fixed_camera_relative_pose
from geovs_drake.goal.arm import arm_model, initial_joints
from geovs_drake.loop.state import POSE, fixed_camera_pose, initial_rig_pose, initial_rig_state
from geovs_drake.scenario import (
    Arm,
    Dynamic,
    FixedCamera,
    FreeRig,
    Kinematic,
    ResolvedScenario,
    ScenarioConfig,
)
from geovs_drake.systems import (
    ArmCamera,
    FixedCameraKinematicMount,
    FixedCameraMount,
    KinematicArm,
    KinematicRigidBody,
)
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems.arm_model import CAMERA_FRAME, ArmModel, add_arm, arm_plant
from geovs_drake.visualization import (
    add_camera_geometry,
    add_goal_ghost,
    add_marked_target_geometry,
    add_target_geometry,
)

__all__ = [
    "CARRIERS",
    "RIG_BODY_NAME",
    "TARGET_BODY_NAME",
    "CarrierParts",
    "add_arm_scene",
    "carrier_key",
    "leading_pose",
    "no_initial_state",
    "world_view_meshcat",
]

RIG_BODY_NAME = "camera_rig"
TARGET_BODY_NAME = "target_sphere"
#: The render label of a moving target drawn apart from the carrier's plant: no body
#: index of an arm (MultibodyPlant's labels) reaches it.
TARGET_RENDER_LABEL = 30000
#: The frame triad drawn at the camera in Meshcat [m].
_TRIAD_LENGTH, _TRIAD_RADIUS = 0.08, 0.003


@dataclass
class CarrierParts:
    """What a carrier offers the loop and what it takes.

    Offers: ``body_pose``, the ``[q, p]`` (7) of the body the camera rides on, in
    the camera system's world, where the target stands at ``X_WB`` and the camera
    at ``X_RC`` on the body; ``body_state`` (13, a free body's layout), what a
    force law's damping reads (the loop connects it to the law's ``body_state``
    input; ``connect_force`` wires the law's output); ``state``, the carrier's own
    state for the loggers (logged as ``state_log_name``). Takes either a force system
    (``ImageJacobianForce`` or ``VelocityTrackingForce``) that ``connect_force`` wires
    in (:attr:`takes_wrench`), or the camera's body twist (Omega, V) at ``twist_input``.

    ``pose_of_states`` maps the loop's continuous states (n,) or (N, n) to the
    components of ``body_pose`` without evaluating the diagram (the monitor's and
    the logs' fast path); ``set_initial_state`` puts the start into a simulator's
    context. ``plant``, ``scene_graph`` and ``body`` (where the camera rides, for
    the rendered sensor) are None for a carrier without geometry.
    """

    body_pose: OutputPort
    state: OutputPort
    state_log_name: str
    X_WB: RigidTransform
    X_RC: RigidTransform
    pose_of_states: Callable[[np.ndarray, object], tuple]
    set_initial_state: Callable[[Context], None]
    body_state: OutputPort | None = None
    twist_input: InputPort | None = None
    connect_force: Callable[[DiagramBuilder, LeafSystem], None] | None = None
    #: An input for the NF's value phi, where the carrier's drive reads it (the dynamic
    #: arm's joint-limit barrier); the loop builder connects the NF to it.
    phi_input: InputPort | None = None
    add_meshcat: Callable[[DiagramBuilder, Meshcat], None] | None = None
    plant: MultibodyPlant | None = None
    scene_graph: SceneGraph | None = None
    body: RigidBody | None = None
    #: The camera's pose on ``body`` for a renderer, where it differs from X_RC (the arm:
    #: the camera system reads C's own pose, X_RC = I, while C rides on the last link).
    X_BodyC: RigidTransform | None = None
    #: The arm's model (carrier "arm"), for the reports that need its kinematics.
    arm: ArmModel | None = None
    #: The carrier's own limits on a continuous state: a message naming the one it
    #: breaks (the monitor stops the run with status ``joint_limit``), else None.
    limit_check: Callable[[np.ndarray], str | None] | None = None
    #: A carrier that stays in the world and draws a moving target apart from its own
    #: plant (the arms): ``draw_target(builder, target_pose)`` draws the target at the
    #: ``[q, p]`` (7) of X_WB(t) that ``target_pose`` gives (the scene, the renderer,
    #: Meshcat). None where the carrier's scene holds the target itself.
    draw_target: Callable[[DiagramBuilder, OutputPort], None] | None = None
    #: Where the target moves and the carrier stays in the world (the arms,
    #: :mod:`geovs_drake.loop.targets`): X_W'W(t), the world's pose (4 x 4) in the frame
    #: W' where the target stands still, at the time t. :meth:`loop_pose_of_states`
    #: carries ``pose_of_states``' world poses into W' with it. None: the carrier's world
    #: is the loop's.
    world_in_loop: Callable[[float], np.ndarray] | None = None
    #: Where a carrier driven by a wrench takes the camera twist a moving target's
    #: believed motion asks of it (6, in C: the dynamic arm adds the torque of the joint
    #: motion that follows it), else None.
    feedforward_input: InputPort | None = None

    @property
    def takes_wrench(self) -> bool:
        """Whether the carrier is driven by a wrench (``connect_force``), not a twist."""
        return self.connect_force is not None

    def loop_pose_of_states(
        self, states: np.ndarray, ops: object, times: np.ndarray | float | None = None
    ) -> tuple:
        """The components of ``body_pose`` (the loop's frame) for continuous states, as
        ``pose_of_states`` gives them: a state (n,) at the time ``times``, or states
        (N, n) at the times (N,). ``times`` matters only with :attr:`world_in_loop`."""
        components = self.pose_of_states(states, ops)
        if self.world_in_loop is None:
            return components
        return _carried(components, self.world_in_loop, times)

    def camera_poses(
        self, states: np.ndarray, times: np.ndarray | float | None = None
    ) -> np.ndarray:
        """X_BC (N, 4, 4) for the loop's continuous states (N, n) at the ``times`` (N,)
        (needed where the target moves and the carrier stays in the world): the body
        pose the carrier offers, then ``X_WB^-1 X_W,body X_RC``."""
        states = np.atleast_2d(states)
        if times is not None:
            times = np.broadcast_to(np.asarray(times, dtype=float), (len(states),))
        components = self.loop_pose_of_states(states, NUMPY, times)
        q = np.stack(np.broadcast_arrays(*components[0:4]), axis=-1)
        p = np.stack(np.broadcast_arrays(*components[4:7]), axis=-1)
        X_B_W = self.X_WB.inverse()
        out = np.empty((len(q), 4, 4))
        for i in range(len(q)):
            R = RotationMatrix(Quaternion(q[i] / np.linalg.norm(q[i])))
            out[i] = (X_B_W @ RigidTransform(R, p[i]) @ self.X_RC).GetAsMatrix4()
        return out


def _carried(components: tuple, world_in_loop: Callable[[float], np.ndarray], times) -> tuple:
    """Pose components ``[q, p]`` (floats, or arrays (N,)) of world poses X_WR carried to
    the loop's frame, ``X_W'W(t) X_WR``, at the times (a float, or (N,))."""
    if times is None:
        raise ValueError("the target moves: the poses in its frame need the times")
    scalar = np.ndim(components[0]) == 0
    q = np.atleast_2d(np.stack(np.broadcast_arrays(*components[0:4]), axis=-1))
    p = np.atleast_2d(np.stack(np.broadcast_arrays(*components[4:7]), axis=-1))
    t = np.broadcast_to(np.asarray(times, dtype=float), (len(q),))
    out = np.empty((len(q), 7))
    for i in range(len(q)):
        X_WR = RigidTransform(Quaternion(q[i] / np.linalg.norm(q[i])), p[i]).GetAsMatrix4()
        X = world_in_loop(float(t[i])) @ X_WR
        out[i, 0:4] = RotationMatrix(X[:3, :3]).ToQuaternion().wxyz()
        out[i, 4:7] = X[:3, 3]
    return tuple(out[0].tolist()) if scalar else tuple(out.T)


#: A carrier factory: ``factory(builder, resolved, draws_marks)`` adds the carrier;
#: ``draws_marks`` asks for the target drawn in the extractor's colours (a camera sensor).
CarrierFactory = Callable[[DiagramBuilder, ResolvedScenario, bool], CarrierParts]


def carrier_key(config: ScenarioConfig) -> tuple[type, type]:
    """The :data:`CARRIERS` key of a scenario: the types of its carrier and its plant."""
    return type(config.carrier), type(config.plant)


def leading_pose(states: np.ndarray, ops: object) -> tuple:
    """The pose at the head of a state (the body the camera system reads): the
    ``pose_of_states`` of a carrier whose state starts with the body's ``[q, p]``."""
    x = np.asarray(states, dtype=float)
    return tuple(x[..., POSE].T) if x.ndim > 1 else x[POSE]


def no_initial_state(context: Context) -> None:
    """The carrier's system holds its start as its default state."""


def _free_body(builder: DiagramBuilder, config: ScenarioConfig, name: str):
    """A continuous MultibodyPlant with one free body of the rig's mass model, gravity off
    (the paper's Appendix C assumes it cancelled)."""
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    body = plant.AddRigidBody(
        name,
        SpatialInertia.MakeFromCentralInertia(
            config.carrier.mass, np.zeros(3), RotationalInertia(*config.carrier.inertia_diagonal)
        ),
    )
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    return plant, scene_graph, body


def _meshcat_with_camera(
    scene_graph: SceneGraph, body: RigidBody, X_BodyC: RigidTransform
) -> Callable[[DiagramBuilder, Meshcat], None]:
    """Meshcat for the scene, with the camera frame C's axes drawn on the body it rides."""

    def add_meshcat(builder: DiagramBuilder, meshcat: Meshcat) -> None:
        # Imported here: pydrake.visualization imports matplotlib (0.5 s), which every
        # loop without Meshcat, the LCM controller's start among them, would pay.
        from pydrake.visualization import AddFrameTriadIllustration

        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
        AddFrameTriadIllustration(
            scene_graph=scene_graph,
            body=body,
            X_FT=X_BodyC,
            length=_TRIAD_LENGTH,
            radius=_TRIAD_RADIUS,
            name="C",
        )

    return add_meshcat


def _pose_head(builder: DiagramBuilder, state: OutputPort) -> OutputPort:
    """The ``[q, p]`` head (7) of a state in a free body's layout (13): the pose the
    camera system reads."""
    demux = builder.AddNamedSystem("state_demux", Demultiplexer([7, 6]))
    builder.Connect(state, demux.get_input_port())
    return demux.get_output_port(0)


def _set_plant_state(plant: MultibodyPlant, config: ScenarioConfig) -> Callable[[Context], None]:
    def set_initial_state(root: Context) -> None:
        # The plant has no default velocity: the start's twist is set here.
        plant.SetPositionsAndVelocities(
            plant.GetMyMutableContextFromRoot(root), initial_rig_state(config)
        )

    return set_initial_state


def _free_rig(builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool):
    """Eye-in-hand, dynamic: the rig is a MultibodyPlant free body pushed by a wrench.

    The rig's body frame R has its origin at the centre of mass; the camera sits at
    X_RC on it (Appendix C.0.6). With ``draws_marks`` the target is drawn in the
    extractor's colours and the camera's own drawing and the goal ghost are kept out
    of the renderer (illustration only).
    """
    config = resolved.config
    plant, scene_graph, rig = _free_body(builder, config, RIG_BODY_NAME)
    theta = resolved.domain.fov_half_angle
    (add_marked_target_geometry if draws_marks else add_target_geometry)(plant, config)
    drawing = add_camera_geometry(plant, rig, config.X_RC, theta) + add_goal_ghost(plant, config)
    plant.Finalize()
    plant.SetDefaultFloatingBaseBodyPose(rig, initial_rig_pose(config))
    if draws_marks:
        for geometry_id in drawing:
            scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kPerception)
    body_pose = _pose_head(builder, plant.get_state_output_port())

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
        set_initial_state=_set_plant_state(plant, config),
        body_state=plant.get_state_output_port(),
        connect_force=connect_force,
        add_meshcat=_meshcat_with_camera(scene_graph, rig, config.X_RC),
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
    plant, (rig,) = _drawing_plant(scene_graph, RIG_BODY_NAME)
    add_marked_target_geometry(plant, config)
    drawing = add_camera_geometry(plant, rig, RigidTransform(), resolved.domain.fov_half_angle)
    drawing += add_goal_ghost(plant, config)
    plant.Finalize()
    _out_of_view(scene_graph, plant, drawing)
    # The plant's positions are the free body's [q, p]: the kinematic body's pose.
    _draw_at(builder, plant, scene_graph, body.body_pose_output, "rig_drawing")
    return dataclasses.replace(
        parts,
        add_meshcat=_meshcat_with_camera(scene_graph, rig, RigidTransform()),
        plant=plant,
        scene_graph=scene_graph,
        body=rig,
    )


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
    plant, scene_graph, target = _free_body(builder, config, TARGET_BODY_NAME)
    drawing = _fixed_camera_scene(plant, resolved, target, X_WC, draws_marks)
    plant.Finalize()
    _out_of_view(scene_graph, plant, drawing)
    x0 = initial_rig_state(config)
    plant.SetDefaultFloatingBaseBodyPose(target, RigidTransform(Quaternion(x0[0:4]), x0[4:7]))
    mount = builder.AddNamedSystem("fixed_camera_mount", FixedCameraMount(X_WC=X_WC))
    builder.Connect(plant.get_state_output_port(), mount.target_state_input)
    body_pose = _pose_head(builder, mount.camera_state_output)

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
        set_initial_state=_set_plant_state(plant, config),
        body_state=mount.camera_state_output,
        connect_force=connect_force,
        add_meshcat=_meshcat_with_camera(scene_graph, plant.world_body(), X_WC),
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


def _out_of_view(scene_graph: SceneGraph, plant: MultibodyPlant, drawing: list) -> None:
    """Illustration only: ``drawing`` (the camera's own, the goal's ghost) kept out of
    the renderer's view."""
    for geometry_id in drawing:
        scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kPerception)


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
    plant, (target,) = _drawing_plant(scene_graph, TARGET_BODY_NAME)
    drawing = _fixed_camera_scene(plant, resolved, target, X_WC, draws_marks)
    plant.Finalize()
    _out_of_view(scene_graph, plant, drawing)
    _draw_at(builder, plant, scene_graph, body.body_pose_output, "target_drawing")
    return dataclasses.replace(
        parts,
        add_meshcat=_meshcat_with_camera(scene_graph, plant.world_body(), X_WC),
        plant=plant,
        scene_graph=scene_graph,
        body=plant.world_body(),
        X_BodyC=X_WC,
    )


def _drawing_plant(scene_graph: SceneGraph, *names: str) -> tuple[MultibodyPlant, list[RigidBody]]:
    """A MultibodyPlant with no dynamics of its own, a source of ``scene_graph``, holding
    one free body per name (in that order, their ``[q, p]`` its positions): what
    :func:`_draw_at` poses. Its bodies' mass model is a placeholder (never simulated)."""
    plant = MultibodyPlant(time_step=0.0)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    inertia = SpatialInertia.SolidSphereWithMass(1.0, 0.01)
    return plant, [plant.AddRigidBody(name, inertia) for name in names]


def _draw_at(builder, plant: MultibodyPlant, scene_graph: SceneGraph, positions, name: str):
    """The drawing ``plant`` (no dynamics of its own) at ``positions``, as Drake's
    MultibodyPositionToGeometryPose draws a plant from given positions."""
    to_pose = builder.AddNamedSystem(name, MultibodyPositionToGeometryPose(plant))
    builder.Connect(positions, to_pose.get_input_port())
    builder.Connect(
        to_pose.get_output_port(), scene_graph.get_source_pose_port(plant.get_source_id())
    )


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
        q = np.asarray(x[:nq])
        outside = np.flatnonzero((q < lower) | (q > upper))
        if len(outside) == 0:
            return None
        i = int(outside[0])
        name = names[i] if len(names) == nq else f"joint {i}"
        return f"joint limit: {name} = {q[i]:.4g} rad outside [{lower[i]:.4g}, {upper[i]:.4g}]"

    return limit_check


def add_arm_scene(
    builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool, dynamic: bool
) -> tuple[ArmModel, MultibodyPlant, SceneGraph, RigidBody, RigidTransform]:
    """A continuous MultibodyPlant (gravity on) with the arm and the target fixed at X_WB
    (a moving target is drawn apart, :func:`_target_drawing`); returns ``(model, plant,
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
    if not config.moving_target:  # a moving one: _target_drawing, at its pose X_WB(t)
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


def _target_drawing(
    scene_graph: SceneGraph, resolved: ResolvedScenario, draws_marks: bool
) -> Callable[[DiagramBuilder, OutputPort], None]:
    """A moving target drawn in a carrier's scene at X_WB(t): a plant with no dynamics of
    its own holds the target (in the extractor's colours with ``draws_marks``) and the
    goal's ghost, X_BC* on it, both on one free body placed at the pose the port gives
    (as the kinematic free rig draws its body)."""
    config = resolved.config

    def draw_target(builder: DiagramBuilder, target_pose: OutputPort) -> None:
        plant, (body,) = _drawing_plant(scene_graph, TARGET_BODY_NAME)
        target = (add_marked_target_geometry if draws_marks else add_target_geometry)(
            plant, config, body=body
        )
        ghost = add_goal_ghost(plant, config, body=body)
        plant.Finalize()
        if draws_marks:
            _out_of_view(scene_graph, plant, ghost)
            _relabel(scene_graph, plant, target, TARGET_RENDER_LABEL)
        _draw_at(builder, plant, scene_graph, target_pose, "target_drawing")

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
        plant, (rig, target) = _drawing_plant(scene_graph, RIG_BODY_NAME, TARGET_BODY_NAME)
        add_target_geometry(plant, config, body=target)
        add_goal_ghost(plant, config, body=target)
        add_camera_geometry(plant, rig, X_RC, resolved.domain.fov_half_angle)
        plant.Finalize()
        poses = builder.AddNamedSystem("world_drawing_poses", Multiplexer([POSE_SIZE, POSE_SIZE]))
        builder.Connect(rig_pose, poses.get_input_port(0))
        builder.Connect(target_pose, poses.get_input_port(1))
        _draw_at(builder, plant, scene_graph, poses.get_output_port(), "world_drawing")
        _meshcat_with_camera(scene_graph, rig, X_RC)(builder, meshcat)

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
        add_meshcat=_meshcat_with_camera(scene_graph, link, X_LinkC),
        plant=plant,
        scene_graph=scene_graph,
        body=link,
        X_BodyC=X_LinkC,
        arm=model,
        limit_check=_joint_limits(model),
        draw_target=(
            _target_drawing(scene_graph, resolved, draws_marks) if config.moving_target else None
        ),
        **drive,
    )


def _arm_dynamic(builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool):
    """Eye-in-hand on a torque-driven arm: the law's wrench becomes joint torques through
    the camera frame's Jacobian, with gravity compensated (:class:`ArmCamera`)."""
    config = resolved.config
    model, plant, scene_graph, link, X_LinkC = add_arm_scene(builder, resolved, draws_marks, True)
    q0 = initial_joints(config)
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
    body_pose = _pose_head(builder, arm.camera_state_output)

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
    q0 = initial_joints(config)
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
CARRIERS: dict[tuple[type, type], CarrierFactory] = {
    (FreeRig, Dynamic): _free_rig,
    (FreeRig, Kinematic): _kinematic_body,
    (FixedCamera, Dynamic): _fixed_rig,
    (FixedCamera, Kinematic): _fixed_kinematic,
    (Arm, Dynamic): _arm_dynamic,
    (Arm, Kinematic): _arm_kinematic,
}
