"""``build_station``: the simulated Panda, its camera and the target, behind LCM.

The station is what the controller cannot see: the world. It is a straight line, as
Drake's hardware_sim::

    plant, scene_graph = the arm and the target (the loop's own arm scene)
    status   = PandaStatusSender -> LcmPublisherSystem(PANDA_STATUS, 1 kHz)
    camera   = PinholeFeatureSensor on the camera's pose -> FeatureFrameEncoder
               -> LcmPublisherSystem(camera channel, the camera's rate)
    command  = LcmSubscriberSystem(PANDA_COMMAND) -> CommandGate -> the plant's actuation

Safety (:class:`CommandGate`): until the first command the arm is held at rest (joint
damping, gravity compensated) and the station waits; after it, no command for
``command_timeout`` seconds and the gate holds the arm the same way for good
(``command_lost``). A torque command is what the Panda's FCI takes: gravity excluded,
the robot compensates it; the gate adds it here.

A frame is published ``1 / status_rate`` after its capture (the transport's delay):
Drake dispatches a publish event at time t before the discrete update at t, so a
publisher at the frame time itself would send the previous frame.
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
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import Demultiplexer

from geovs_drake.hardware.config import HardwareConfig
from geovs_drake.loop.arm import initial_joints
from geovs_drake.loop.carriers import _add_arm_scene
from geovs_drake.scenario import Pinhole, ResolvedScenario
from geovs_drake.systems import ArmCamera, PinholeFeatureSensor
from geovs_drake.systems._arm_model import CAMERA_FRAME, ArmModel, arm_plant
from geovs_drake.systems.arm_camera import actuation_permutation

__all__ = [
    "FRAME_VALUE_SIZE",
    "FeatureFrameEncoder",
    "CommandGate",
    "Station",
    "build_station",
    "joint_state_size",
]

#: The camera message's ``value``: y (13), the sensor's ``[valid, code, lost]`` (3) and
#: the frame's index (1).
FRAME_Y, FRAME_STATUS, FRAME_INDEX = slice(0, 13), slice(13, 16), 16
FRAME_VALUE_SIZE = 17
#: Microseconds per second: LCM's ``utime``.
US_PER_S = 1e6
#: The gate's state: the last command's utime, when it came [s], commands received,
#: started (0/1), lost (0/1), when it was lost [s], timeouts counted.
_LAST_UTIME, _LAST_TIME, _COUNT, _STARTED, _LOST, _LOST_TIME, _TIMEOUTS = range(7)
_GATE_STATE_SIZE = 7
#: A frame's index is the floor of t / period, within this fraction of a period: the
#: encoder runs a publish delay after the frame's own time.
_FRAME_ROUNDING = 1e-6


def joint_state_size(model: ArmModel) -> int:
    """nq + nv of the arm alone."""
    plant = arm_plant(model)
    return plant.num_positions() + plant.num_velocities()


class FeatureFrameEncoder(LeafSystem):
    """A sampled camera's held frame as an ``lcmt_scope`` message: ``utime`` the frame's
    capture time [us] (the index of the frame held at t, on the camera's clock of
    ``period``), ``value`` the :data:`FRAME_VALUE_SIZE` numbers (y, the sensor's
    status, the index). Inputs ``image_features`` (13), ``feature_status`` (3)."""

    def __init__(self, period: float) -> None:
        super().__init__()
        self._period = period
        self.image_features_input = self.DeclareVectorInputPort("image_features", 13)
        self.feature_status_input = self.DeclareVectorInputPort("feature_status", 3)
        self.message_output = self.DeclareAbstractOutputPort(
            "lcmt_scope", lambda: AbstractValue.Make(lcmt_scope()), self._encode
        )

    def _encode(self, context: Context, output: AbstractValue) -> None:
        index = math.floor(context.get_time() / self._period + _FRAME_ROUNDING)
        message = lcmt_scope()
        message.utime = int(round(index * self._period * US_PER_S))
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

    Inputs ``command`` (the latest ``lcmt_panda_command``) and ``arm_state`` (q, v).
    Output ``actuation``: ``tau_cmd + g(q)`` while commands come (torque mode; in
    velocity mode ``K_v (v_cmd - v) + g(q)``), else the hold ``-D v + g(q)``, with
    ``g(q)`` the gravity compensation (the robot's own, as the FCI) and D the
    ``hold_damping``. A command is new when its ``utime`` changes. Before the first one
    the gate holds and waits; after it, a gap longer than ``command_timeout`` latches
    ``lost`` and the gate holds for good. Its discrete state, updated at the status
    rate: :meth:`commands_received`, :meth:`lost`, :meth:`lost_time`,
    :meth:`command_timeouts`.
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
            "command", AbstractValue.Make(lcmt_panda_command())
        )
        self.arm_state_input = self.DeclareVectorInputPort("arm_state", self._nq + self._nv)
        initial = np.zeros(_GATE_STATE_SIZE)
        initial[_LOST_TIME] = math.nan
        self._state = self.DeclareDiscreteState(initial)
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / hardware.status_rate, 0.0, self._update)
        self.actuation_output = self.DeclareVectorOutputPort(
            "actuation", self._B.shape[1], self._actuation
        )

    def _update(self, context: Context, discrete_state) -> None:
        s = context.get_discrete_state(self._state).get_value().copy()
        t = context.get_time()
        message = self.command_input.Eval(context)
        if message.utime != 0 and message.utime != s[_LAST_UTIME]:
            s[_LAST_UTIME], s[_LAST_TIME] = message.utime, t
            s[_COUNT] += 1
            s[_STARTED] = 1.0
        if s[_STARTED] and not s[_LOST] and t - s[_LAST_TIME] > self._timeout:
            s[_LOST], s[_LOST_TIME] = 1.0, t
            s[_TIMEOUTS] += 1
        discrete_state.get_mutable_vector(self._state).SetFromVector(s)

    def _live_command(self, context: Context) -> np.ndarray | None:
        """The torque the latest command asks for (gravity excluded), None to hold."""
        s = context.get_discrete_state(self._state).get_value()
        if not s[_STARTED] or s[_LOST]:
            return None
        message = self.command_input.Eval(context)
        v = self._plant.GetVelocities(self._context)
        if self._velocity_mode:
            if message.num_joint_velocity != self._nv:
                return None
            return self._velocity_gain * (np.asarray(message.joint_velocity) - v)
        if message.num_joint_torque != self._nv:
            return None
        return np.asarray(message.joint_torque, dtype=float)

    def _actuation(self, context: Context, output) -> None:
        self._plant.SetPositionsAndVelocities(self._context, self.arm_state_input.Eval(context))
        gravity = -self._plant.CalcGravityGeneralizedForces(self._context)
        tau = self._live_command(context)
        if tau is None:  # hold: joint damping, gravity compensated
            tau = -self._damping * self._plant.GetVelocities(self._context)
        output.SetFromVector(self._B.T @ (tau + gravity))

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

    def command_timeouts(self, context: Context) -> int:
        """How many gaps longer than the timeout the gate has seen."""
        return int(self._value(context, _TIMEOUTS))

    def started(self, context: Context) -> bool:
        """Whether a first command has arrived."""
        return bool(self._value(context, _STARTED))


@dataclass
class Station:
    """A built station: its ``diagram``, the scenario, the ``plant`` (the arm and the
    target), the ``gate`` (:class:`CommandGate`), the arm's ``model`` and start ``q0``."""

    diagram: Diagram
    resolved: ResolvedScenario
    hardware: HardwareConfig
    plant: MultibodyPlant
    gate: CommandGate
    model: ArmModel
    q0: np.ndarray

    def set_initial_state(self, root: Context) -> None:
        """The arm at rest at its start ``q0``."""
        context = self.plant.GetMyMutableContextFromRoot(root)
        self.plant.SetPositionsAndVelocities(
            context, np.concatenate([self.q0, np.zeros(self.plant.num_velocities())])
        )

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
    if not isinstance(config.sensor, Pinhole):
        raise ValueError(
            f"the station's camera must be the pinhole sensor (--sensor pinhole), got "
            f"{type(config.sensor).__name__}: the rendered camera over LCM is not built yet"
        )
    if not config.dynamic:
        raise ValueError("the station simulates the arm's dynamics: plant must be !Dynamic {}")
    builder = DiagramBuilder()
    interface = builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    model, plant, _scene_graph, _link, _X_LinkC = _add_arm_scene(builder, resolved, True, True)
    q0 = initial_joints(config)
    nq, nv = plant.num_positions(), plant.num_velocities()
    demux = builder.AddNamedSystem("arm_state_demux", Demultiplexer([nq, nv]))
    builder.Connect(plant.get_state_output_port(), demux.get_input_port())

    # PANDA_COMMAND -> the gate -> the plant.
    command = builder.AddNamedSystem(
        "command_subscriber",
        LcmSubscriberSystem.Make(hardware.channels.command, lcmt_panda_command, interface),
    )
    gate = builder.AddNamedSystem("command_gate", CommandGate(model, hardware))
    builder.Connect(command.get_output_port(), gate.command_input)
    builder.Connect(plant.get_state_output_port(), gate.arm_state_input)
    builder.Connect(gate.actuation_output, plant.get_actuation_input_port())

    # The plant -> PANDA_STATUS at the status rate.
    status = builder.AddNamedSystem("status_sender", PandaStatusSender(nv))
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

    # The camera: its pose from the joints (ArmCamera), its frames on the camera channel.
    arm = builder.AddNamedSystem("arm_camera", ArmCamera(model=model))
    builder.Connect(plant.get_state_output_port(), arm.arm_state_input)
    pose = builder.AddNamedSystem("camera_state_demux", Demultiplexer([7, 6]))
    builder.Connect(arm.camera_state_output, pose.get_input_port())
    cam = config.sensor
    theta = resolved.domain.fov_half_angle
    period = 1.0 / cam.rate
    sensor = builder.AddNamedSystem(
        "feature_sensor",
        PinholeFeatureSensor(
            radius=config.radius,
            intrinsics=cam.intrinsics(theta),
            believed=cam.believed_intrinsics(theta),
            X_WB=config.X_WB,
            X_RC=RigidTransform(),  # the arm's camera_state is C's own pose
            period=period,
            latency_frames=int(cam.latency_frames),
            max_lost_frames=int(cam.max_lost_frames),
            pixel_noise=cam.pixel_noise,
            seed=int(cam.seed),
        ),
    )
    builder.Connect(pose.get_output_port(0), sensor.body_pose_input)
    encoder = builder.AddNamedSystem("frame_encoder", FeatureFrameEncoder(period))
    builder.Connect(sensor.image_features_output, encoder.image_features_input)
    builder.Connect(sensor.feature_status_output, encoder.feature_status_input)
    frames = builder.AddNamedSystem(
        "camera_publisher",
        LcmPublisherSystem.Make(
            hardware.channels.camera,
            lcmt_scope,
            interface,
            publish_period=period,
            publish_offset=1.0 / hardware.status_rate,  # after the frame's update
        ),
    )
    builder.Connect(encoder.message_output, frames.get_input_port())
    diagram = builder.Build()
    diagram.set_name("panda_station")
    return Station(diagram, resolved, hardware, plant, gate, model, q0)
