"""``build_station``: the simulated Panda, its camera and the target, behind LCM.

The station is what the controller cannot see: the world. It is a straight line, as
Drake's hardware_sim::

    plant    = the arm alone (the loop's own arm; no SceneGraph: no contact modelled)
    status   = PandaStatusSender -> LcmPublisherSystem(PANDA_STATUS, 1 kHz)
    camera   = PinholeFeatureSensor on the camera's pose (the loop's own,
               loop.sensors.add_pinhole_sensor) -> FeatureFrameEncoder (utime: the
               held y's capture) -> FramePublisher(camera channel, the camera's rate)
    (rendered: the arm and the target in a SceneGraph of the camera's own, posed from
               the plant's state at each frame -> RgbdSensor on the camera ->
               ImageToLcmImageArrayT -> LcmPublisherSystem (image channel, stamped at
               each capture, sent latency later: :mod:`.images`))
    command  = LcmSubscriberSystem(PANDA_COMMAND, as a vector) -> CommandGate
               -> the plant's actuation (held at the status rate)

Safety (:class:`CommandGate`): until the first command the arm is held at rest (joint
damping, gravity compensated) and the station waits; after it, no command for
``command_timeout`` seconds and the gate holds the arm the same way for good
(``command_lost``). A torque command is what the Panda's FCI takes: gravity excluded,
the robot compensates it; the gate adds it here.

A frame is published ``1 / status_rate`` after it is read (the transport's delay):
Drake dispatches a publish event at time t before the discrete update at t, so a
publisher at the frame time itself would send the previous frame. Its ``utime`` is
its capture, which the sensor says (``capture_time``): with ``latency_frames`` the
frame read at t was taken ``latency_frames`` periods earlier, and the controller moves
it by the joints' motion since then.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from drake import lcmt_panda_command, lcmt_panda_status, lcmt_scope
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.manipulation import PandaStatusSender
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Context, Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem
from pydrake.systems.primitives import Demultiplexer, DiscreteTimeDelay
from pydrake.systems.sensors import RgbdSensor

from geovs_drake.goal.arm import arm_model, initial_joints
from geovs_drake.hardware.config import HardwareConfig, check_hardware_arm, check_still_target
from geovs_drake.hardware.images import CameraScene, add_image_camera, check_rendered_over_lcm
from geovs_drake.hardware.messages import (
    COMMAND_NUM_TORQUE,
    COMMAND_NUM_VELOCITY,
    COMMAND_TORQUE,
    COMMAND_UTIME,
    COMMAND_VECTOR_SIZE,
    COMMAND_VELOCITY,
    FRAME_INDEX,
    FRAME_VALUE_SIZE,
    US_PER_S,
    command_vector,
    subscribe_vector,
)
from geovs_drake.loop.assembly import FEATURE_SIZE
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.sensors import add_pinhole_sensor
from geovs_drake.systems import ArmCamera
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems.arm_camera import actuation_permutation
from geovs_drake.systems.arm_model import CAMERA_FRAME, ArmModel, add_arm, arm_plant

__all__ = [
    "CommandGate",
    "FeatureFrameEncoder",
    "FramePublisher",
    "Station",
    "build_station",
    "joint_state_size",
]

#: The gate's state: the last command's utime, when it came [s], commands received,
#: started (0/1), lost (0/1), when it was lost [s], timeouts counted, commands refused
#: (not of the station's mode: the arm is held for them).
_LAST_UTIME, _LAST_TIME, _COUNT, _STARTED, _LOST, _LOST_TIME, _TIMEOUTS, _REFUSED = range(8)
_GATE_STATE_SIZE = 8
#: A frame's index is the floor of (t - offset) / period, within this fraction of a
#: period: the encoder runs a publish delay after the frame's own time.
_FRAME_ROUNDING = 1e-6


def joint_state_size(model: ArmModel) -> int:
    """nq + nv of the arm alone."""
    plant = arm_plant(model)
    return plant.num_positions() + plant.num_velocities()


class FeatureFrameEncoder(LeafSystem):
    """A sampled camera's held frame as an ``lcmt_scope`` message: ``utime`` the capture
    time [us] of its y (the sensor's ``capture_time``; a frame with no y yet, the time
    it was read), ``value`` the :data:`~.messages.FRAME_VALUE_SIZE` numbers (y, the
    sensor's status, the index of the frame read last on the camera's clock of
    ``period`` from ``offset``). Inputs ``image_features`` (13), ``feature_status``
    (3), ``capture_time`` (1, [s])."""

    def __init__(self, period: float, offset: float = 0.0) -> None:
        super().__init__()
        self._period, self._offset = period, offset
        self.image_features_input = self.DeclareVectorInputPort("image_features", FEATURE_SIZE)
        self.feature_status_input = self.DeclareVectorInputPort("feature_status", 3)
        self.capture_time_input = self.DeclareVectorInputPort("capture_time", 1)
        self.message_output = self.DeclareAbstractOutputPort(
            "lcmt_scope", lambda: AbstractValue.Make(lcmt_scope()), self._encode
        )

    def _encode(self, context: Context, output: AbstractValue) -> None:
        index = math.floor((context.get_time() - self._offset) / self._period + _FRAME_ROUNDING)
        capture = float(self.capture_time_input.Eval(context)[0])
        if not math.isfinite(capture):  # no y yet: the frame read, its own time
            capture = self._offset + index * self._period
        message = lcmt_scope()
        message.utime = int(round(capture * US_PER_S))
        values = np.concatenate(
            [
                self.image_features_input.Eval(context),
                self.feature_status_input.Eval(context),
                [float(index)],
            ]
        )
        message.size = FRAME_VALUE_SIZE
        message.value = [float(v) for v in values]  # NaN before a first good frame
        output.set_value(message)


class CommandGate(LeafSystem):
    """The driver's side of PANDA_COMMAND: the command applied while it is fresh, the arm
    held otherwise.

    Inputs ``command`` (the latest command as the vector of
    :func:`~geovs_drake.hardware.messages.command_vector`) and ``arm_state`` (q, v).
    Output ``actuation``: ``tau_cmd + g(q)`` while commands come (torque mode; in
    velocity mode ``K_v (v_cmd - v) + g(q)``), else the hold ``-D v + g(q)``, with
    ``g(q)`` the gravity compensation (the robot's own, as the FCI) and D the
    ``hold_damping``. The actuation is computed at the status rate and held between
    (the FCI's own 1 kHz loop): why, the integrator evaluates the actuation several
    times a step, and a Python evaluation each time cost the station its real time. A
    command is new when its ``utime`` changes. Before the first one the gate holds and
    waits; after it, a gap longer than ``command_timeout`` latches ``lost`` and the
    gate holds for good. A command not of the station's mode (a velocity command in
    torque mode) holds the arm and is counted. Its discrete state:
    :meth:`commands_received`, :meth:`commands_refused`, :meth:`lost`,
    :meth:`lost_time`, :meth:`command_timeouts`, :meth:`last_command_time`.
    """

    def __init__(self, model: ArmModel, hardware: HardwareConfig) -> None:
        super().__init__()
        self._plant = arm_plant(model)
        self._context = self._plant.CreateDefaultContext()
        self._B = actuation_permutation(self._plant)
        self._nq, self._nv = self._plant.num_positions(), self._plant.num_velocities()
        self._velocity_mode = hardware.mode == "velocity"
        self._timeout = hardware.command_timeout
        self._damping = hardware.hold_damping
        self._velocity_gain = hardware.velocity_gain
        self.command_input = self.DeclareAbstractInputPort(
            "command", AbstractValue.Make(np.zeros(COMMAND_VECTOR_SIZE))
        )
        self.arm_state_input = self.DeclareVectorInputPort("arm_state", self._nq + self._nv)
        initial = np.zeros(_GATE_STATE_SIZE)
        initial[_LOST_TIME] = math.nan
        self._state = self.DeclareDiscreteState(initial)
        self._actuation_state = self.DeclareDiscreteState(self._B.shape[1])
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / hardware.status_rate, 0.0, self._update)
        self.actuation_output = self.DeclareStateOutputPort("actuation", self._actuation_state)

    def _update(self, context: Context, discrete_state) -> None:
        s = context.get_discrete_state(self._state).get_value().copy()
        t = context.get_time()
        command = self.command_input.Eval(context)
        utime = command[COMMAND_UTIME]
        if utime != 0 and utime != s[_LAST_UTIME]:
            s[_LAST_UTIME], s[_LAST_TIME] = utime, t
            s[_COUNT] += 1
            s[_STARTED] = 1.0
            if self._live_command(command, np.zeros(self._nv)) is None:
                s[_REFUSED] += 1
        if s[_STARTED] and not s[_LOST] and t - s[_LAST_TIME] > self._timeout:
            s[_LOST], s[_LOST_TIME] = 1.0, t
            s[_TIMEOUTS] += 1
        discrete_state.get_mutable_vector(self._state).SetFromVector(s)
        x = self.arm_state_input.Eval(context)
        self._plant.SetPositionsAndVelocities(self._context, x)
        v = x[self._nq :]
        gravity = -self._plant.CalcGravityGeneralizedForces(self._context)
        tau = None if not s[_STARTED] or s[_LOST] else self._live_command(command, v)
        if tau is None:  # hold: joint damping, gravity compensated
            tau = -self._damping * v
        discrete_state.get_mutable_vector(self._actuation_state).SetFromVector(
            self._B.T @ (tau + gravity)
        )

    def _live_command(self, command: np.ndarray, v: np.ndarray) -> np.ndarray | None:
        """The torque the latest command asks for (gravity excluded), None to hold."""
        if self._velocity_mode:
            if command[COMMAND_NUM_VELOCITY] != self._nv:
                return None
            return self._velocity_gain * (command[COMMAND_VELOCITY] - v)
        if command[COMMAND_NUM_TORQUE] != self._nv:
            return None
        return command[COMMAND_TORQUE]

    def _value(self, context: Context, index: int) -> float:
        return float(context.get_discrete_state(self._state).get_value()[index])

    def commands_received(self, context: Context) -> int:
        """How many distinct commands (by ``utime``) have arrived."""
        return int(self._value(context, _COUNT))

    def lost(self, context: Context) -> bool:
        """Whether commands stopped for longer than the timeout after the first."""
        return bool(self._value(context, _LOST))

    def lost_time(self, context: Context) -> float:
        """When the gate latched ``lost`` [s] (NaN while commands come)."""
        return self._value(context, _LOST_TIME)

    def last_command_time(self, context: Context) -> float:
        """When the last new command arrived [s] (0 before one)."""
        return self._value(context, _LAST_TIME)

    def commands_refused(self, context: Context) -> int:
        """How many commands were not of the station's mode (drake-franka-driver
        throws on one; the gate holds the arm for it and counts it)."""
        return int(self._value(context, _REFUSED))

    def command_timeouts(self, context: Context) -> int:
        """How many gaps longer than the timeout the gate has seen."""
        return int(self._value(context, _TIMEOUTS))

    def started(self, context: Context) -> bool:
        """Whether a first command has arrived."""
        return bool(self._value(context, _STARTED))


class FramePublisher(LeafSystem):
    """The camera channel's publisher: the encoder's ``lcmt_scope`` every ``period``
    (after ``offset``), except every ``drop_every``-th frame (by its index; 0: none)
    when ``drop_every`` > 0, to show what a lost frame does."""

    def __init__(
        self, channel: str, lcm: DrakeLcm, period: float, offset: float, drop_every: int
    ) -> None:
        super().__init__()
        self._channel, self._lcm, self._drop_every = channel, lcm, drop_every
        self.message_input = self.DeclareAbstractInputPort(
            "lcmt_scope", AbstractValue.Make(lcmt_scope())
        )
        self.DeclarePeriodicPublishEvent(period, offset, self._publish)

    def _publish(self, context: Context) -> None:
        message = self.message_input.Eval(context)
        index = int(message.value[FRAME_INDEX]) if message.size == FRAME_VALUE_SIZE else 0
        if self._drop_every > 0 and index % self._drop_every == self._drop_every - 1:
            return
        self._lcm.Publish(self._channel, message.encode(), context.get_time())


@dataclass
class Station:
    """A built station: its ``diagram``, the scenario, the ``plant`` (the arm and the
    target), the ``gate`` (:class:`CommandGate`), the arm's ``model``, start ``q0``, the
    camera's ``frame_period`` [s], the ``status_delay`` line (None without), the
    rendered camera's ``RgbdSensor`` (``camera``; None for the pinhole camera: its
    label image is the station's truth of the arm's pixels, never published),
    ``frame_offset`` [s], when the first frame is published, and the rendered camera's
    own scene (``camera_scene``, :class:`~geovs_drake.hardware.images.CameraScene`;
    None for the pinhole camera)."""

    diagram: Diagram
    resolved: ResolvedScenario
    hardware: HardwareConfig
    plant: MultibodyPlant
    gate: CommandGate
    model: ArmModel
    q0: np.ndarray
    frame_period: float
    status_delay: LeafSystem | None = None
    camera: RgbdSensor | None = None
    frame_offset: float = 0.0
    camera_scene: CameraScene | None = None

    def set_initial_state(self, root: Context) -> None:
        """The arm at rest at its start ``q0`` (and, with a status delay, as if it had
        been there all along)."""
        context = self.plant.GetMyMutableContextFromRoot(root)
        x0 = np.concatenate([self.q0, np.zeros(self.plant.num_velocities())])
        self.plant.SetPositionsAndVelocities(context, x0)
        if self.status_delay is not None:
            delay = self.status_delay.GetMyMutableContextFromRoot(root)
            state = delay.get_mutable_discrete_state(0)
            state.SetFromVector(np.tile(x0, state.size() // len(x0)))

    def arm_state(self, root: Context) -> np.ndarray:
        """The arm's (q, v) now."""
        return self.plant.GetPositionsAndVelocities(self.plant.GetMyContextFromRoot(root))

    def X_BC(self, root: Context) -> RigidTransform:
        """The camera's true pose in the target frame now (the ground truth)."""
        plant = arm_plant(self.model)
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, self.arm_state(root)[: plant.num_positions()])
        X_WC = plant.GetFrameByName(CAMERA_FRAME).CalcPoseInWorld(context)
        return self.resolved.config.X_WB.inverse() @ X_WC


def build_station(resolved: ResolvedScenario, hardware: HardwareConfig, lcm: DrakeLcm) -> Station:
    """The station of a Panda scenario (carrier ``!Arm``, the dynamic plant, a
    ``!Pinhole`` camera) on the bus ``lcm``. ValueError in one line for a scenario the
    station cannot run."""
    config = resolved.config
    _check_station(resolved, hardware)
    rendered = config.sensor.traits.renders
    builder = DiagramBuilder()
    interface = builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    model, plant = _station_plant(builder, resolved)
    q0 = initial_joints(config, resolved.domain)
    demux, delay = _arm_status_state(builder, plant, hardware)

    # PANDA_COMMAND -> the gate -> the plant.
    command = builder.AddNamedSystem(
        "command_subscriber",
        subscribe_vector(
            hardware.channels.command,
            lcmt_panda_command,
            command_vector,
            np.zeros(COMMAND_VECTOR_SIZE),
            interface,
        ),
    )
    gate = builder.AddNamedSystem("command_gate", CommandGate(model, hardware))
    builder.Connect(command.get_output_port(), gate.command_input)
    builder.Connect(plant.get_state_output_port(), gate.arm_state_input)
    builder.Connect(gate.actuation_output, plant.get_actuation_input_port())

    # The plant -> PANDA_STATUS at the status rate.
    status = builder.AddNamedSystem("status_sender", PandaStatusSender(plant.num_velocities()))
    builder.Connect(demux.get_output_port(0), status.get_position_measured_input_port())
    builder.Connect(demux.get_output_port(1), status.get_velocity_measured_input_port())
    builder.Connect(gate.actuation_output, status.get_torque_commanded_input_port())
    builder.Connect(gate.actuation_output, status.get_torque_measured_input_port())
    publisher = builder.AddNamedSystem(
        "status_publisher",
        LcmPublisherSystem.Make(
            hardware.channels.status,
            lcmt_panda_status,
            interface,
            publish_period=1.0 / hardware.status_rate,
            use_cpp_serializer=True,
        ),
    )
    builder.Connect(status.get_output_port(), publisher.get_input_port())

    cam = config.sensor
    period = 1.0 / cam.rate
    if rendered:  # the scene drawn on the arm's camera, its images on the image channel
        scene, first_publish = add_image_camera(
            builder,
            resolved,
            plant.get_state_output_port(),
            hardware.channels.image,
            interface,
            transport_delay=1.0 / hardware.status_rate,
        )
        diagram = builder.Build()
        diagram.set_name("panda_station")
        return Station(
            diagram, resolved, hardware, plant, gate, model, q0, period, delay,
            camera=scene.rgbd, camera_scene=scene, frame_offset=first_publish,
        )  # fmt: skip

    first_publish = _pinhole_frames(builder, resolved, hardware, model, plant, lcm)
    diagram = builder.Build()
    diagram.set_name("panda_station")
    return Station(
        diagram, resolved, hardware, plant, gate, model, q0, period, delay,
        frame_offset=first_publish,
    )  # fmt: skip


def _station_plant(
    builder: DiagramBuilder, resolved: ResolvedScenario
) -> tuple[ArmModel, MultibodyPlant]:
    """The arm the station integrates (``plant``, continuous, gravity on): the loop's
    arm (:func:`~geovs_drake.systems.arm_model.add_arm`, the same bodies and joints as
    :func:`~geovs_drake.loop.carriers.add_arm_scene`'s plant) with no SceneGraph.

    Why none: the loop models no contact (``add_arm_scene`` filters every pair of its
    geometry), yet a plant with collision geometry asks its SceneGraph for point pairs
    at every derivative evaluation (about 3 a step at 1 kHz), each a pose update of
    every geometry. The target is fixed in the world and has no dynamics; the cameras
    draw the scene apart (the pinhole from the joints, the rendered camera on a
    SceneGraph of its own, :func:`~geovs_drake.hardware.images.add_camera_scene`)."""
    model = arm_model(resolved.config)
    plant = builder.AddNamedSystem("plant", MultibodyPlant(time_step=0.0))
    add_arm(plant, model)
    plant.Finalize()
    return model, plant


def _check_station(resolved: ResolvedScenario, hardware: HardwareConfig) -> None:
    """ValueError in one line for a scenario the station cannot run."""
    config = resolved.config
    check_hardware_arm(config, "station")
    if not config.sensor.traits.camera:
        raise ValueError(
            f"the station's camera must be pinhole or rendered (--sensor), got "
            f"{type(config.sensor).__name__}"
        )
    if config.sensor.traits.renders:
        check_rendered_over_lcm(hardware.drop_every_frame)
    if not config.dynamic:
        raise ValueError("the station simulates the arm's dynamics: plant must be !Dynamic {}")
    check_still_target(config, "station")


def _arm_status_state(builder: DiagramBuilder, plant, hardware: HardwareConfig):
    """The arm's (q, v) as the statuses report them, split: ``status_delay`` late where
    it is set (a DiscreteTimeDelay at the status rate). The demultiplexer and the delay."""
    nq, nv = plant.num_positions(), plant.num_velocities()
    demux = builder.AddNamedSystem("arm_state_demux", Demultiplexer([nq, nv]))
    delay_steps = round(hardware.status_delay * hardware.status_rate)
    if delay_steps <= 0:
        builder.Connect(plant.get_state_output_port(), demux.get_input_port())
        return demux, None
    # Statuses that report the joints as they were status_delay ago.
    delay = builder.AddNamedSystem(
        "status_delay", DiscreteTimeDelay(1.0 / hardware.status_rate, delay_steps, nq + nv)
    )
    builder.Connect(plant.get_state_output_port(), delay.get_input_port())
    builder.Connect(delay.get_output_port(), demux.get_input_port())
    return demux, delay


def _pinhole_frames(
    builder: DiagramBuilder,
    resolved: ResolvedScenario,
    hardware: HardwareConfig,
    model: ArmModel,
    plant,
    lcm: DrakeLcm,
) -> float:
    """The camera: its pose from the joints (ArmCamera), the loop's own pinhole sensor
    on it (the scenario's settings, latency and output delay included), its frames on
    the camera channel, each stamped with its capture. When the first frame is published."""
    config = resolved.config
    cam = config.sensor
    period = 1.0 / cam.rate
    arm = builder.AddNamedSystem("arm_camera", ArmCamera(model=model))
    builder.Connect(plant.get_state_output_port(), arm.arm_state_input)
    pose = builder.AddNamedSystem(
        "camera_state_demux", Demultiplexer([POSE_SIZE, arm.camera_state_output.size() - POSE_SIZE])
    )
    builder.Connect(arm.camera_state_output, pose.get_input_port())
    # The arm's camera_state is C's own pose: X_RC = I.
    sensor, _ = add_pinhole_sensor(
        builder, resolved, pose.get_output_port(0), config.X_WB, RigidTransform()
    )
    first_read = cam.first_frame_time
    encoder = builder.AddNamedSystem("frame_encoder", FeatureFrameEncoder(period, first_read))
    builder.Connect(sensor.image_features_output, encoder.image_features_input)
    builder.Connect(sensor.feature_status_output, encoder.feature_status_input)
    builder.Connect(sensor.capture_time_output, encoder.capture_time_input)
    first_publish = first_read + 1.0 / hardware.status_rate  # after the frame's update
    frames = builder.AddNamedSystem(
        "camera_publisher",
        FramePublisher(
            hardware.channels.camera, lcm, period, first_publish, hardware.drop_every_frame
        ),
    )
    builder.Connect(encoder.message_output, frames.message_input)
    return first_publish
