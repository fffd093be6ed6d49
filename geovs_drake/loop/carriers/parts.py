"""What every carrier offers the loop and takes from it (:class:`CarrierParts`), and the
helpers the carriers share (a free body, Meshcat with the camera's axes, a drawing
plant); each carrier is a module of its own beside this one."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import (
    Meshcat,
    MeshcatVisualizer,
    Role,
    SceneGraph,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import RigidBody, RotationalInertia, SpatialInertia
from pydrake.systems.framework import Context, DiagramBuilder, InputPort, LeafSystem, OutputPort
from pydrake.systems.primitives import Demultiplexer
from pydrake.systems.rendering import MultibodyPositionToGeometryPose

from geovs_drake.geometry._ops import NUMPY
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.state import POSE, initial_rig_state
from geovs_drake.scenario import ScenarioConfig
from geovs_drake.systems.arm_model import ArmModel

__all__ = [
    "RIG_BODY_NAME",
    "RotorDrive",
    "TARGET_BODY_NAME",
    "TARGET_RENDER_LABEL",
    "CarrierFactory",
    "CarrierParts",
    "carrier_key",
    "draw_at",
    "drawing_plant",
    "free_body",
    "leading_pose",
    "meshcat_with_camera",
    "no_initial_state",
    "out_of_view",
    "pose_head",
    "set_plant_state",
]

RIG_BODY_NAME = "camera_rig"
TARGET_BODY_NAME = "target_sphere"
#: The render label of a moving target drawn apart from the carrier's plant: no body
#: index of an arm (MultibodyPlant's labels) reaches it.
TARGET_RENDER_LABEL = 30000
#: The frame triad drawn at the camera in Meshcat [m].
_TRIAD_LENGTH, _TRIAD_RADIUS = 0.08, 0.003


@dataclass(frozen=True)
class RotorDrive:
    """Where a law that drives a carrier's rotors itself (its traits' ``commands`` is
    ``"rotors"``) plugs in: ``connect(builder, law)`` wires the carrier's state to the
    law's ``body_state`` input and its ``rotor_thrusts`` output to the rotors (the run's
    saturation is then read at its ``saturated`` output); ``body`` is the body's model as
    keyword arguments of such a system (``mass``, ``inertia_diagonal``, ``gravity``,
    ``attitude_gains``, ``mixer_matrix``, ``max_thrust``, ``max_tilt``)."""

    connect: Callable[[DiagramBuilder, LeafSystem], None]
    body: dict


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
    #: Where a carrier takes the believed target twist's rate (6, in the target's frame:
    #: the quadrotor's cascade adds the acceleration it asks), else None.
    feedforward_rate_input: InputPort | None = None
    #: The carrier's own entries in the run's JSON summary (the quadrotor's rotor
    #: saturation), ``run_entries(root, states, times)`` from the run's root context and
    #: its logged continuous states (N, n) at the times (N,) (a moving target's pose
    #: depends on them); None where it has none.
    run_entries: Callable[[Context, np.ndarray, np.ndarray], dict] | None = None
    #: What the NF and the law read instead of the sensor's y, where the carrier turns
    #: it (the quadrotor's image on the level body, :class:`~geovs_drake.systems.LevelView`):
    #: ``view(builder, y)`` returns that port; None: the sensor's y as it is.
    view: Callable[[DiagramBuilder, OutputPort], OutputPort] | None = None
    #: Where a law drives the rotors itself (the quadrotor under Hamel & Mahony's law,
    #: :class:`RotorDrive`); None: the carrier has no rotors a law may drive, or drives
    #: them itself from a wrench or a twist.
    rotors: RotorDrive | None = None

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


def free_body(builder: DiagramBuilder, config: ScenarioConfig, name: str):
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


def meshcat_with_camera(
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


def pose_head(builder: DiagramBuilder, state: OutputPort) -> OutputPort:
    """The ``[q, p]`` head (7) of a state in a free body's layout (13): the pose the
    camera system reads."""
    demux = builder.AddNamedSystem("state_demux", Demultiplexer([7, 6]))
    builder.Connect(state, demux.get_input_port())
    return demux.get_output_port(0)


def set_plant_state(plant: MultibodyPlant, config: ScenarioConfig) -> Callable[[Context], None]:
    """A carrier's ``set_initial_state`` for a free body on ``plant``: its start pose, and
    the velocity that gives the camera ``config.initial_velocity``."""

    def set_initial_state(root: Context) -> None:
        # The plant has no default velocity: the start's twist is set here.
        plant.SetPositionsAndVelocities(
            plant.GetMyMutableContextFromRoot(root), initial_rig_state(config)
        )

    return set_initial_state


def out_of_view(scene_graph: SceneGraph, plant: MultibodyPlant, drawing: list) -> None:
    """Illustration only: ``drawing`` (the camera's own, the goal's ghost) kept out of
    the renderer's view."""
    for geometry_id in drawing:
        scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kPerception)


def drawing_plant(scene_graph: SceneGraph, *names: str) -> tuple[MultibodyPlant, list[RigidBody]]:
    """A MultibodyPlant with no dynamics of its own, a source of ``scene_graph``, holding
    one free body per name (in that order, their ``[q, p]`` its positions): what
    :func:`draw_at` poses. Its bodies' mass model is a placeholder (never simulated)."""
    plant = MultibodyPlant(time_step=0.0)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    inertia = SpatialInertia.SolidSphereWithMass(1.0, 0.01)
    return plant, [plant.AddRigidBody(name, inertia) for name in names]


def draw_at(builder, plant: MultibodyPlant, scene_graph: SceneGraph, positions, name: str):
    """The drawing ``plant`` (no dynamics of its own) at ``positions``, as Drake's
    MultibodyPositionToGeometryPose draws a plant from given positions."""
    to_pose = builder.AddNamedSystem(name, MultibodyPositionToGeometryPose(plant))
    builder.Connect(positions, to_pose.get_input_port())
    builder.Connect(
        to_pose.get_output_port(), scene_graph.get_source_pose_port(plant.get_source_id())
    )
