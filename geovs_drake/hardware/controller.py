"""``build_controller``: the NF law on what a real Panda and its camera give, over LCM.

Its diagram holds no model of the world: no MultibodyPlant, no target. Its inputs are
LCM subscribers alone; the arm's kinematics come from :class:`~geovs_drake.systems.ArmCamera`'s
own model of the arm (a plant of the arm alone, inside that system). A straight line::

    status   = LcmSubscriberSystem(PANDA_STATUS) -> StatusDecoder -> (q, v)
    camera   = ArmCamera(q, v): the camera's pose and velocity (its kinematics)
    frames   = LcmSubscriberSystem(camera channel) -> FrameTracker (at the status rate):
               the frame moved by the camera's motion since its capture time (the
               FramePredictor's prediction)
    nav      = NavigationController(y)
    wrench   = ImageJacobianForce(y, dphi, camera state): Eq. (45)
    torque   = ArmCamera's J_C^T F_C - B_q v (- d N v), gravity left to the robot
    command  = CommandPublisher -> PANDA_COMMAND at the command rate (250 Hz), while fresh

The subscribers hold their messages as float vectors (:mod:`.messages`: a Python LCM
message in a Context is deep-copied at every step). The law runs at the command rate,
below the status rate: in Python it costs about 0.4 ms a command, and the robot holds
the last command between.

Why its own predictor, not :class:`~geovs_drake.systems.FramePredictor`: that system
keeps the camera's pose at its own clock's frame times, which in another process are
not the station's; :class:`~geovs_drake.hardware.link.FrameTracker` keeps the joints of
the last statuses by their ``utime``, takes the camera's pose at the frame's capture
``utime`` from them, then predicts with the same kernel,
:func:`~geovs_drake.geometry.prediction.predicted_image`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from drake import lcmt_panda_status, lcmt_scope
from pydrake.lcm import DrakeLcm
from pydrake.math import RigidTransform
from pydrake.systems.framework import Context, Diagram, DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.lcm import LcmInterfaceSystem
from pydrake.systems.primitives import Demultiplexer

from geovs_drake.geometry._ops import MATH
from geovs_drake.geometry.camera import camera_map_inverse, inverse_pose
from geovs_drake.goal.arm import arm_model
from geovs_drake.hardware.config import HardwareConfig, check_hardware_arm, check_still_target
from geovs_drake.hardware.images import (
    IMAGE_HISTORY,
    ImageFeatureFrames,
    SelfFilter,
    add_masked_image,
    add_self_filter,
    subscribe_images,
)
from geovs_drake.hardware.link import (
    CommandPublisher,
    FrameTracker,
    JointVelocityLaw,
    StatusDecoder,
)
from geovs_drake.hardware.messages import (
    FRAME_VALUE_SIZE,
    STATUS_VECTOR_SIZE,
    frame_vector,
    frame_vector_size,
    status_vector,
    subscribe_vector,
)
from geovs_drake.loop.assembly import drive_carrier
from geovs_drake.loop.carriers import CarrierParts, no_initial_state
from geovs_drake.loop.laws import LAWS
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.sensors import sampled_settings
from geovs_drake.simulation.result import pose_error
from geovs_drake.systems import (
    ArmCamera,
    NavigationController,
)
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems.arm_model import ArmModel, arm_plant

__all__ = ["Controller", "build_controller"]


@dataclass
class Controller:
    """A built controller: its ``diagram``, the scenario it believes, the
    ``tracker`` (:class:`~geovs_drake.hardware.link.FrameTracker`), the ``publisher``
    (:class:`~geovs_drake.hardware.link.CommandPublisher`),
    the ``navigation`` controller and the ``law`` (the scenario's law's system, from
    the loop's registry :data:`~geovs_drake.loop.laws.LAWS`: for the NF,
    ImageJacobianForce in torque mode, KinematicController in velocity mode); with the
    rendered camera, ``images``
    (:class:`~geovs_drake.hardware.images.ImageFeatureFrames`) and the ``self_filter``
    (:class:`~geovs_drake.hardware.images.SelfFilter`), else None."""

    diagram: Diagram
    resolved: ResolvedScenario
    hardware: HardwareConfig
    tracker: FrameTracker
    publisher: CommandPublisher
    navigation: LeafSystem
    law: LeafSystem
    images: LeafSystem | None = None
    self_filter: SelfFilter | None = None

    def warm_up(self) -> None:
        """Evaluate the law once on the goal image, in contexts of its own: the NF's and
        the law's kernels are compiled (numba, its cache loaded) here, before the
        first command, not in it (measured: 0.7 s, beyond any timeout). Every output
        port of the law: each may call a kernel of its own (the force law's wrench in
        C, which the arm's command reads, is not its port 0)."""
        y = self.resolved.y_goal.to_vector()
        at_rest = np.zeros(POSE_SIZE + 6)
        at_rest[0] = 1.0  # the identity quaternion
        context = self.navigation.CreateDefaultContext()
        self.navigation.image_features_input.FixValue(context, y)
        dphi = np.array(self.navigation.dphi_output.Eval(context))
        context = self.law.CreateDefaultContext()
        for port in (self.law.get_input_port(i) for i in range(self.law.num_input_ports())):
            value = {"image_features": y, "dphi": dphi}.get(port.get_name(), at_rest)
            port.FixValue(context, np.resize(value, port.size()))
        for i in range(self.law.num_output_ports()):
            self.law.get_output_port(i).Eval(context)

    def image_error(self, root: Context) -> tuple[float, float]:
        """Its own estimate of the image error now: ``|y - y*|`` of the held frame moved
        to now, and the distance [m] of the camera from the goal that y implies
        (``c^-1(y)``, Eq. 23); NaN without a frame."""
        context = self.tracker.GetMyContextFromRoot(root)
        y = self.tracker.predicted_image_features_output.Eval(context)
        if not np.all(np.isfinite(y)):
            return math.nan, math.nan
        goal = self.resolved.y_goal.to_vector()
        p_BC, p_BC_goal = (_camera_in_target(v, self.resolved.believed_radius) for v in (y, goal))
        return float(np.linalg.norm(y - goal)), float(np.linalg.norm(p_BC - p_BC_goal))

    def estimated_pose_error(self, root: Context) -> tuple[float, float]:
        """Its own estimate of the camera's pose error from the goal now, ``(position
        [m], rotation [rad])``: the pose ``c^-1(y)`` of the held frame moved to now
        against ``c^-1(y*)`` (Eq. 23, the believed radius); NaN without a frame."""
        context = self.tracker.GetMyContextFromRoot(root)
        y = self.tracker.predicted_image_features_output.Eval(context)
        if not np.all(np.isfinite(y)):
            return math.nan, math.nan
        radius = self.resolved.believed_radius
        X_CB, X_CB_goal = (
            camera_map_inverse(np.asarray(v), radius) for v in (y, self.resolved.y_goal)
        )
        return pose_error(X_CB.inverse(), X_CB_goal.inverse())


def _no_states(states: np.ndarray, ops: object) -> tuple:
    """The LCM link has no continuous state (it is the robot's): nothing to read."""
    raise NotImplementedError("the LCM controller's link has no continuous state")


def _camera_in_target(y: np.ndarray, radius: float) -> np.ndarray:
    """p_BC, the camera's position in the target frame that y implies: X_CB = c^-1(y)
    (Eq. 23, R_CB's columns r1, r2, r3 and p_CB = d), so p_BC = -R_CB^T d."""
    r1, r2, r3, d = inverse_pose(tuple(y.tolist()), radius, MATH)
    R_CB = np.column_stack([r1, r2, r3])
    return -R_CB.T @ np.asarray(d)


def build_controller(
    resolved: ResolvedScenario, hardware: HardwareConfig, lcm: DrakeLcm
) -> Controller:
    """The controller of a Panda scenario on the bus ``lcm``: only the arm's own model
    (inside :class:`~geovs_drake.systems.ArmCamera`), no plant of the world."""
    config = resolved.config
    check_hardware_arm(config, "controller")
    check_still_target(config, "controller")
    model = arm_model(config)
    nv = arm_plant(model).num_velocities()
    builder = DiagramBuilder()
    interface = builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    status = builder.AddNamedSystem(
        "status_subscriber",
        subscribe_vector(
            hardware.channels.status,
            lcmt_panda_status,
            status_vector,
            np.zeros(STATUS_VECTOR_SIZE),
            interface,
        ),
    )
    decoder = builder.AddNamedSystem("status_decoder", StatusDecoder(nv))
    builder.Connect(status.get_output_port(), decoder.status_input)
    carrier = config.carrier
    barrier = carrier.joint_barrier_width > 0 or carrier.joint_barrier_fraction > 0
    if barrier:
        raise ValueError("the controller over LCM does not take a joint barrier yet")
    arm = builder.AddNamedSystem(
        "arm_camera",
        ArmCamera(
            model=model,
            joint_damping=carrier.joint_damping,
            null_space_damping=carrier.null_space_damping,
        ),
    )
    builder.Connect(decoder.arm_state_output, arm.arm_state_input)
    pose = builder.AddNamedSystem("camera_state_demux", Demultiplexer([POSE_SIZE, 6]))
    builder.Connect(arm.camera_state_output, pose.get_input_port())
    frame, images = _add_frames(builder, resolved, hardware, model, decoder, interface)
    tracker = builder.AddNamedSystem(
        "frame_predictor",
        # At the status rate: every status's pose kept, for the frames' capture times.
        FrameTracker(model, radius=resolved.believed_radius, period=1.0 / hardware.status_rate),
    )
    builder.Connect(frame, tracker.frame_input)
    builder.Connect(decoder.status_utime_output, tracker.status_utime_input)
    builder.Connect(decoder.arm_state_output, tracker.arm_state_input)
    builder.Connect(pose.get_output_port(0), tracker.body_pose_input)
    y = tracker.predicted_image_features_output
    nav = builder.AddNamedSystem(
        "navigation_controller",
        NavigationController(goal=resolved.y_goal, domain=resolved.domain, gains=resolved.gains),
    )
    builder.Connect(y, nav.image_features_input)
    publisher = builder.AddNamedSystem("command_publisher", CommandPublisher(model, hardware, lcm))

    # The LCM link as the loop's carrier: in torque mode it takes a wrench in C (through
    # J_C^T, ArmCamera), in velocity mode a twist in C (through J_C^+); the camera's frame
    # is C itself (X_RC = I).
    def connect_force(builder: DiagramBuilder, force: LeafSystem) -> None:
        builder.Connect(force.wrench_C_output, arm.wrench_C_input)

    link = CarrierParts(
        body_pose=pose.get_output_port(0),
        state=arm.camera_state_output,
        state_log_name="camera_state",
        X_WB=config.X_WB,
        X_RC=RigidTransform(),
        pose_of_states=_no_states,
        set_initial_state=no_initial_state,
        body_state=arm.camera_state_output,
        connect_force=connect_force if hardware.mode == "torque" else None,
    )
    if hardware.mode == "torque":
        builder.Connect(arm.actuation_output, publisher.command_input)
    else:
        joints = builder.AddNamedSystem("joint_velocity_law", JointVelocityLaw(model))
        builder.Connect(decoder.arm_state_output, joints.arm_state_input)
        builder.Connect(joints.joint_velocity_output, publisher.command_input)
        link.twist_input = joints.camera_velocity_input
    # The scenario's law from the loop's registry, connected as the loop connects it (a
    # twist on the torque link through VelocityTrackingForce).
    command = LAWS[type(resolved.law)].add(builder, resolved, y, nav, link)
    drive_carrier(builder, resolved, link, command, False)
    law = command if isinstance(command, LeafSystem) else command.get_system()
    builder.Connect(decoder.arm_state_output, publisher.arm_state_input)
    builder.Connect(tracker.link_output, publisher.link_input)
    builder.Connect(y, publisher.image_features_input)
    diagram = builder.Build()
    diagram.set_name("panda_controller")
    return Controller(
        diagram, resolved, hardware, tracker, publisher, nav, law,
        images=images[0] if images else None, self_filter=images[1] if images else None,
    )  # fmt: skip


def _add_frames(builder: DiagramBuilder, resolved, hardware, model, decoder, interface):
    """The frames the tracker reads: the rendered camera's images, extracted here (and
    the image systems), or the pinhole's feature frames as they come (None)."""
    if resolved.config.sensor.traits.renders:
        return _add_image_frames(builder, resolved, hardware, model, decoder, interface)
    frame = builder.AddNamedSystem(
        "camera_subscriber",
        subscribe_vector(
            hardware.channels.camera,
            lcmt_scope,
            frame_vector(FRAME_VALUE_SIZE),
            np.full(frame_vector_size(FRAME_VALUE_SIZE), math.nan),
            interface,
        ),
    ).get_output_port()
    return frame, None


def _add_image_frames(
    builder: DiagramBuilder,
    resolved: ResolvedScenario,
    hardware: HardwareConfig,
    model: ArmModel,
    decoder: StatusDecoder,
    interface: LcmInterfaceSystem,
) -> tuple[OutputPort, tuple[ImageFeatureFrames, SelfFilter]]:
    """The rendered camera's path: the image channel -> the colour image, masked by the
    self-filter at the joints of the frame's capture -> y, once per image. Returns the
    frame port (the pinhole camera's layout) and the two systems."""
    cam = resolved.config.sensor
    theta = resolved.domain.fov_half_angle
    believed = cam.believed_intrinsics(theta)
    color, utime = subscribe_images(builder, hardware.channels.image, interface)
    self_filter = add_self_filter(builder, resolved, model)
    masked = add_masked_image(builder, color, self_filter, believed.width, believed.height)
    nq = self_filter.plant.num_positions()
    settings = sampled_settings(resolved)
    # The statuses to keep: those of the camera's own delay (a frame is sent that long
    # after its capture), and the bus's slack.
    delay = settings["latency_frames"] * settings["period"] + settings["capture_delay"]
    frames = builder.AddNamedSystem(
        "feature_extractor",
        ImageFeatureFrames(
            believed,
            num_joints=nq,
            period=1.0 / hardware.status_rate,
            camera_period=settings["period"],
            offset=cam.capture_offset,
            max_lost_frames=settings["max_lost_frames"],
            pixel_noise=settings["pixel_noise"],
            seed=settings["seed"],
            history=IMAGE_HISTORY + math.ceil(delay * hardware.status_rate),
        ),
    )
    builder.Connect(utime, frames.image_utime_input)
    builder.Connect(masked, frames.masked_color_image_input)
    builder.Connect(decoder.status_utime_output, frames.status_utime_input)
    builder.Connect(decoder.arm_state_output, frames.arm_state_input)
    builder.Connect(frames.capture_positions_output, self_filter.positions)
    return frames.frame_output, (frames, self_filter)
