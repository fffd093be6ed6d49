"""The controller's side of the LCM link: the systems that decode the robot's statuses,
track the camera's frames by their capture time, and publish the commands
(:func:`~geovs_drake.hardware.controller.build_controller` wires them to the loop's law)."""

from __future__ import annotations

import math

import numpy as np
from drake import lcmt_panda_command
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.framework import Context, LeafSystem

from geovs_drake.geometry._ops import MATH
from geovs_drake.geometry.prediction import predicted_image
from geovs_drake.geometry.rigid import quaternion_to_rotation
from geovs_drake.hardware.config import HardwareConfig
from geovs_drake.hardware.messages import (
    CAPTURE_SLACK_US,
    FRAME_INDEX,
    FRAME_SIZE,
    FRAME_STATUS,
    FRAME_UTIME,
    FRAME_VALUE_SIZE,
    FRAME_VALUE_START,
    FRAME_Y,
    STATUS_NUM_JOINTS,
    STATUS_Q,
    STATUS_UTIME,
    STATUS_V,
    STATUS_VECTOR_SIZE,
    US_PER_S,
    frame_vector_size,
)
from geovs_drake.loop.assembly import FEATURE_SIZE
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems.arm_camera import actuation_permutation
from geovs_drake.systems.arm_model import CAMERA_FRAME, ArmModel, arm_plant, camera_jacobian

__all__ = [
    "LATENCY_BINS",
    "LATENCY_BIN_MS",
    "LINK_FIELDS",
    "POSE_HISTORY",
    "STOP_REASONS",
    "CommandPublisher",
    "FrameTracker",
    "JointVelocityLaw",
    "StatusDecoder",
]

#: How many statuses' joints the tracker keeps (at 1 kHz, 0.5 s): a frame whose
#: capture is older than that is predicted from the oldest kept.
POSE_HISTORY = 512
#: Why the controller stopped commanding, by its code.
STOP_REASONS: dict[int, str] = {
    0: "",
    1: "no status within the status timeout",
    2: "no frame within the frame timeout",
    3: "no status and frame within the startup timeout",
    4: "the camera lost the target (its frame is not valid)",
    5: "the image cannot be inverted (y outside I)",
}
_NO_STATUS, _NO_FRAME, _NO_START, _FEATURE_LOST, _NOT_INVERTIBLE = 1, 2, 3, 4, 5
#: The tracker's ``link`` output: statuses recorded, frames received, frames dropped
#: (gaps in the frames' indices), the last status's arrival [s, the controller's
#: clock], the last frame's arrival [s], the frame's valid flag, the last status's
#: utime [s, the robot's clock], the held frame's capture utime [s], its index, and the
#: longest time between two new statuses [s, the controller's clock] after the first.
LINK_FIELDS = (
    "statuses",
    "frames",
    "dropped",
    "status_arrival",
    "frame_arrival",
    "valid",
    "status_utime",
    "capture",
    "index",
    "max_status_gap",
)
(_L_STATUSES, _L_FRAMES, _L_DROPPED, _L_STATUS_T, _L_FRAME_T, _L_VALID, _L_STATUS_UTIME,
 _L_CAPTURE, _L_INDEX, _L_MAX_GAP, _L_HEAD) = range(len(LINK_FIELDS) + 1)  # fmt: skip
#: Velocity mode: the fraction of each joint's velocity limit the command may reach.
VELOCITY_FRACTION = 0.5
#: The latency histogram (frame capture to the first command computed from it): bins
#: of this width [ms], the last one everything above.
LATENCY_BIN_MS = 1.0
LATENCY_BINS = 20
#: The pose's layout: quaternion (w, x, y, z), then position.
_QUATERNION, _POSITION = slice(0, 4), slice(4, POSE_SIZE)
#: The tracker's held frame: its capture [s] (-1: none), y, the camera's pose at the
#: capture, the frame's index (-1: none).
_H_CAPTURE, _H_Y = 0, slice(1, 1 + FEATURE_SIZE)
_H_POSE = slice(_H_Y.stop, _H_Y.stop + POSE_SIZE)
_H_INDEX = _H_POSE.stop
_IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
_ORIGIN = (0.0, 0.0, 0.0)


class StatusDecoder(LeafSystem):
    """The latest status (the vector of
    :func:`~geovs_drake.hardware.messages.status_vector`) -> ``arm_state`` (q, v), zeros
    before the first status (no command is sent before it), and ``status_utime`` [s]
    (0 before it)."""

    def __init__(self, num_joints: int) -> None:
        super().__init__()
        self._n = num_joints
        self.status_input = self.DeclareAbstractInputPort(
            "status", AbstractValue.Make(np.zeros(STATUS_VECTOR_SIZE))
        )
        self.arm_state_output = self.DeclareVectorOutputPort(
            "arm_state", 2 * num_joints, self._state
        )
        self.status_utime_output = self.DeclareVectorOutputPort("status_utime", 1, self._utime)

    def _state(self, context: Context, output) -> None:
        status = self.status_input.Eval(context)
        if status[STATUS_NUM_JOINTS] != self._n:
            output.SetFromVector(np.zeros(2 * self._n))
            return
        output.SetFromVector(status[STATUS_Q.start : STATUS_V.stop])

    def _utime(self, context: Context, output) -> None:
        output.SetAtIndex(0, self.status_input.Eval(context)[STATUS_UTIME] / US_PER_S)


class FrameTracker(LeafSystem):
    """The camera's frames as they arrive, moved to the camera's pose now.

    Inputs ``frame`` (the latest camera message as the vector of
    :func:`~geovs_drake.hardware.messages.frame_vector`, its ``utime`` the capture
    time), ``status_utime`` [s], ``arm_state`` (that status's q, v) and ``body_pose``
    (the camera's pose ``[q_WC, p_WC]`` now, from the joints). Every ``period`` (the
    status rate) it records each new status's joints by its utime (:data:`POSE_HISTORY`
    of them) and, on a new frame, the camera's pose at the frame's capture utime (the
    joints of the latest status not after it, through its own model of the arm).
    ``predicted_image_features``: the held frame's y carried from that pose to
    ``body_pose`` (:func:`~geovs_drake.geometry.prediction.predicted_image`, the
    believed ``radius``); NaN before a first frame. ``link``: :data:`LINK_FIELDS`.
    """

    def __init__(self, model: ArmModel, radius: float, period: float) -> None:
        super().__init__()
        self._radius = radius
        self._plant = arm_plant(model)
        self._context = self._plant.CreateDefaultContext()
        self._camera = self._plant.GetFrameByName(CAMERA_FRAME)
        self._nq = nq = self._plant.num_positions()
        self._row = 1 + nq
        self.frame_input = self.DeclareAbstractInputPort(
            "frame", AbstractValue.Make(np.full(frame_vector_size(FRAME_VALUE_SIZE), math.nan))
        )
        self.status_utime_input = self.DeclareVectorInputPort("status_utime", 1)
        self.arm_state_input = self.DeclareVectorInputPort(
            "arm_state", nq + self._plant.num_velocities()
        )
        self.body_pose_input = self.DeclareVectorInputPort("body_pose", POSE_SIZE)
        # The history of (utime, q), one row a status: the joints, not the camera's
        # pose, so that no kinematics runs at the status rate (only once a frame).
        self._history = self.DeclareDiscreteState(np.full(POSE_HISTORY * self._row, -1.0))
        self._frame = self.DeclareDiscreteState(
            np.concatenate([[-1.0], np.full(FEATURE_SIZE, math.nan), np.zeros(POSE_SIZE), [-1.0]])
        )
        # LINK_FIELDS, then the history's next row.
        link = np.zeros(len(LINK_FIELDS) + 1)
        link[[_L_STATUS_T, _L_FRAME_T, _L_STATUS_UTIME, _L_CAPTURE, _L_INDEX]] = -1.0
        self._link = self.DeclareDiscreteState(link)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.predicted_image_features_output = self.DeclareVectorOutputPort(
            "predicted_image_features",
            FEATURE_SIZE,
            self._predict,
            prerequisites_of_calc={self.all_input_ports_ticket(), self.xd_ticket()},
        )
        self.link_output = self.DeclareVectorOutputPort(
            "link", len(LINK_FIELDS), self._link_out, prerequisites_of_calc={self.xd_ticket()}
        )

    def _update(self, context: Context, state) -> None:
        t = context.get_time()
        link = context.get_discrete_state(self._link).get_value().copy()
        utime = float(self.status_utime_input.Eval(context)[0])
        if utime > 0 and utime != link[_L_STATUS_UTIME]:
            # Only the new row is written: the history (4096 numbers) is not copied.
            head = int(link[_L_HEAD])
            row = head * self._row
            history = state.get_mutable_vector(self._history).get_mutable_value()
            history[row] = utime
            history[row + 1 : row + self._row] = self.arm_state_input.Eval(context)[: self._nq]
            if link[_L_STATUSES] > 0:
                link[_L_MAX_GAP] = max(link[_L_MAX_GAP], t - link[_L_STATUS_T])
            link[_L_HEAD] = (head + 1) % POSE_HISTORY
            link[_L_STATUS_UTIME] = utime
            link[_L_STATUSES] += 1
            link[_L_STATUS_T] = t
        frame = self.frame_input.Eval(context)
        capture = frame[FRAME_UTIME] / US_PER_S
        held = context.get_discrete_state(self._frame).get_value()
        carried = frame[FRAME_SIZE] == FRAME_VALUE_SIZE
        # A new frame by its index (a frame held through latency or failures may carry
        # the capture of the one before).
        index = frame[FRAME_VALUE_START + FRAME_INDEX]
        if carried and index != held[_H_INDEX] and link[_L_STATUSES] > 0:
            value = frame[FRAME_VALUE_START:]
            if held[_H_INDEX] >= 0 and index > held[_H_INDEX] + 1:
                link[_L_DROPPED] += index - held[_H_INDEX] - 1
            # The updated history: this update's status may be the frame's.
            rows = state.get_mutable_vector(self._history).get_value()
            rows = rows.reshape(POSE_HISTORY, self._row)
            kept = rows[rows[:, 0] >= 0]
            before = kept[kept[:, 0] <= capture + CAPTURE_SLACK_US / US_PER_S]
            pick = before[np.argmax(before[:, 0])] if len(before) else kept[np.argmin(kept[:, 0])]
            state.get_mutable_vector(self._frame).SetFromVector(
                np.concatenate([[capture], value[FRAME_Y], self._pose(pick[1:]), [index]])
            )
            link[_L_FRAMES] += 1
            link[_L_FRAME_T] = t
            link[_L_VALID] = value[FRAME_STATUS][0]
            link[_L_CAPTURE], link[_L_INDEX] = capture, index
        state.get_mutable_vector(self._link).SetFromVector(link)

    def _pose(self, q: np.ndarray) -> np.ndarray:
        """The camera's pose ``[q_WC, p_WC]`` at joints q (ArmCamera's layout)."""
        self._plant.SetPositions(self._context, q)
        X_WC = self._camera.CalcPoseInWorld(self._context)
        return np.concatenate([X_WC.rotation().ToQuaternion().wxyz(), X_WC.translation()])

    def held_frame(self, context: Context) -> tuple[float, np.ndarray]:
        """The held frame's capture time [s] (-1: none yet) and its y."""
        frame = context.get_discrete_state(self._frame).get_value()
        return float(frame[_H_CAPTURE]), frame[_H_Y].copy()

    def _predict(self, context: Context, output) -> None:
        frame = context.get_discrete_state(self._frame).get_value()
        y = frame[_H_Y]
        if frame[_H_CAPTURE] < 0 or not np.all(np.isfinite(y)):
            output.SetFromVector(np.full(FEATURE_SIZE, math.nan))
            return
        then = frame[_H_POSE].tolist()
        now = self.body_pose_input.Eval(context).tolist()
        output.SetFromVector(
            predicted_image(
                tuple(y.tolist()),
                self._radius,
                quaternion_to_rotation(then[_QUATERNION], MATH),
                tuple(then[_POSITION]),
                quaternion_to_rotation(now[_QUATERNION], MATH),
                tuple(now[_POSITION]),
                _IDENTITY,
                _ORIGIN,
                MATH,
            )
        )

    def _link_out(self, context: Context, output) -> None:
        output.SetFromVector(context.get_discrete_state(self._link).get_value()[: len(LINK_FIELDS)])


class JointVelocityLaw(LeafSystem):
    """Velocity mode: the kinematic law's camera twist (Omega, V) carried to the joints,
    ``v_cmd = s J_C(q)^+ (Omega, V)`` (the arm's own model), with s <= 1 the factor that
    brings the fastest joint to ``velocity_fraction`` of its limit (the direction kept,
    as :class:`~geovs_drake.systems.KinematicArm` does: the NF's twist far from the goal
    asks for tens of rad/s). Inputs ``arm_state``, ``camera_velocity``; output
    ``joint_velocity``."""

    def __init__(self, model: ArmModel, velocity_fraction: float = VELOCITY_FRACTION) -> None:
        super().__init__()
        self._plant = arm_plant(model)
        self._context = self._plant.CreateDefaultContext()
        self._camera = self._plant.GetFrameByName(CAMERA_FRAME)
        self._limits = velocity_fraction * self._plant.GetVelocityUpperLimits()
        nq, nv = self._plant.num_positions(), self._plant.num_velocities()
        self.arm_state_input = self.DeclareVectorInputPort("arm_state", nq + nv)
        self.camera_velocity_input = self.DeclareVectorInputPort("camera_velocity", 6)
        self.joint_velocity_output = self.DeclareVectorOutputPort("joint_velocity", nv, self._calc)

    def _calc(self, context: Context, output) -> None:
        self._plant.SetPositionsAndVelocities(self._context, self.arm_state_input.Eval(context))
        J = camera_jacobian(self._plant, self._context, self._camera)
        v = np.linalg.pinv(J) @ self.camera_velocity_input.Eval(context)
        ratio = float(np.max(np.abs(v) / self._limits))
        output.SetFromVector(v if ratio <= 1.0 else v / ratio)


class CommandPublisher(LeafSystem):
    """PANDA_COMMAND at the command rate, while the link is fresh.

    Inputs ``command`` (torque mode: ArmCamera's actuation, gravity compensation
    included, which is taken back out here since the robot adds its own; velocity mode:
    the joint velocities), ``arm_state``, ``link`` (:class:`FrameTracker`'s) and
    ``image_features``. It starts once a status and a frame have come and the frame's y
    is finite; it stops for good (:data:`STOP_REASONS`) when the last status is older
    than ``status_timeout``, the last frame older than ``frame_timeout``, the frame is
    not valid, or no start came within ``startup_timeout``.

    A command's ``utime`` is on the robot's clock (what drake-franka-driver checks
    ``expire_sec`` against): the last status's utime plus the time since it arrived.
    From it and the held frame's capture utime the publisher keeps the latency
    histogram from a frame's capture to the first command computed from it
    (:data:`LATENCY_BINS` bins of :data:`LATENCY_BIN_MS`). State: ``[started, stopped,
    reason, sent, last frame index commanded]`` and the histogram.
    """

    def __init__(self, model: ArmModel, hardware: HardwareConfig, lcm: DrakeLcm) -> None:
        super().__init__()
        self._lcm, self._hardware = lcm, hardware
        self._plant = arm_plant(model)
        self._context = self._plant.CreateDefaultContext()
        self._B = actuation_permutation(self._plant)
        nq, nv = self._plant.num_positions(), self._plant.num_velocities()
        self._nq, self._nv = nq, nv
        self._velocity_mode = hardware.mode == "velocity"
        self.command_input = self.DeclareVectorInputPort("command", nv)
        self.arm_state_input = self.DeclareVectorInputPort("arm_state", nq + nv)
        self.link_input = self.DeclareVectorInputPort("link", len(LINK_FIELDS))
        self.image_features_input = self.DeclareVectorInputPort("image_features", FEATURE_SIZE)
        self._state = self.DeclareDiscreteState(np.array([0.0, 0.0, 0.0, 0.0, -1.0]))
        self._histogram = self.DeclareDiscreteState(LATENCY_BINS)
        period = 1.0 / hardware.command_rate
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclarePeriodicPublishEvent(period, 0.0, self._publish)

    def _robot_utime(self, context: Context, link: np.ndarray) -> int:
        """Now on the robot's clock [us]: the last status's utime plus its age."""
        age = context.get_time() - link[_L_STATUS_T]
        return int(round((link[_L_STATUS_UTIME] + age) * US_PER_S))

    def _update(self, context: Context, discrete_state) -> None:
        started, stopped, reason, sent, commanded = context.get_discrete_state(
            self._state
        ).get_value()
        t = context.get_time()
        link = self.link_input.Eval(context)
        h = self._hardware
        if not stopped:
            if not started:
                if link[_L_STATUSES] > 0 and link[_L_FRAMES] > 0:
                    y = self.image_features_input.Eval(context)
                    started = 1.0
                    if not np.all(np.isfinite(y)):
                        stopped, reason = 1.0, _NOT_INVERTIBLE
                elif t > h.startup_timeout:
                    stopped, reason = 1.0, _NO_START
            else:
                if t - link[_L_STATUS_T] > h.status_timeout:
                    stopped, reason = 1.0, _NO_STATUS
                elif t - link[_L_FRAME_T] > h.frame_timeout:
                    stopped, reason = 1.0, _NO_FRAME
                elif link[_L_VALID] < 1:
                    stopped, reason = 1.0, _FEATURE_LOST
            # The publish at t (just before this update, the same inputs) sent a command
            # from the held frame: the first from it adds its latency to the histogram.
            if started and not stopped:
                sent += 1
                if link[_L_INDEX] != commanded:
                    commanded = link[_L_INDEX]
                    latency_ms = self._robot_utime(context, link) / 1e3 - link[_L_CAPTURE] * 1e3
                    histogram = discrete_state.get_mutable_vector(self._histogram)
                    k = min(max(int(latency_ms // LATENCY_BIN_MS), 0), LATENCY_BINS - 1)
                    histogram.SetAtIndex(k, histogram.GetAtIndex(k) + 1)
        discrete_state.get_mutable_vector(self._state).SetFromVector(
            [started, stopped, reason, sent, commanded]
        )

    def _publish(self, context: Context) -> None:
        started, stopped = context.get_discrete_state(self._state).get_value()[:2]
        if not started or stopped:
            return
        message = lcmt_panda_command()
        message.utime = self._robot_utime(context, self.link_input.Eval(context))
        command = self.command_input.Eval(context)
        if self._velocity_mode:
            message.num_joint_velocity = self._nv
            message.joint_velocity = command.tolist()
            message.control_mode_expected = _PANDA_VELOCITY
        else:
            self._plant.SetPositions(self._context, self.arm_state_input.Eval(context)[: self._nq])
            # ArmCamera compensated gravity (-g); the robot does it itself: add g back.
            gravity = self._plant.CalcGravityGeneralizedForces(self._context)
            tau = self._B @ command + gravity
            message.num_joint_torque = self._nv
            message.joint_torque = tau.tolist()
            message.control_mode_expected = _PANDA_TORQUE
        self._lcm.Publish(self._hardware.channels.command, message.encode(), context.get_time())

    def stop_reason(self, context: Context) -> str:
        """Why it stopped, in words ("" while it commands or waits)."""
        code = int(context.get_discrete_state(self._state).get_value()[2])
        return STOP_REASONS[code]

    def commands_sent(self, context: Context) -> int:
        """How many commands it has sent."""
        return int(context.get_discrete_state(self._state).get_value()[3])

    def started(self, context: Context) -> bool:
        """Whether it has started commanding."""
        return bool(context.get_discrete_state(self._state).get_value()[0])

    def stopped(self, context: Context) -> bool:
        """Whether it has stopped for good."""
        return bool(context.get_discrete_state(self._state).get_value()[1])

    def latency_histogram(self, context: Context) -> list[int]:
        """Frames by the latency from their capture to the first command computed from
        them, in bins of :data:`LATENCY_BIN_MS` from 0 (the last bin: the rest)."""
        return [int(n) for n in context.get_discrete_state(self._histogram).get_value()]


#: drake-franka-driver's control mode constants (PandaControlMode's kVelocity, kTorque).
_PANDA_VELOCITY, _PANDA_TORQUE = 2, 4
