"""LCM messages held in a Context as float vectors (numpy arrays), not as messages.

Why: a Python LCM message in a Drake ``AbstractValue`` is copied with ``copy.deepcopy``
at every subscriber update and every ``Eval`` of its port; for ``lcmt_panda_status``
(eight arrays) that is 43 us a copy, three copies a step, at 1 kHz. A numpy vector
copies in about 3 us. :class:`VectorSerializer` is a Drake ``SerializerInterface``
(as Drake's own ``PySerializer``) whose value is the vector made of each message's
bytes; the layouts below are the ones the station and the controller read.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

import numpy as np
from drake import lcmt_panda_command, lcmt_panda_status, lcmt_scope
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.lcm import LcmInterfaceSystem, LcmSubscriberSystem, SerializerInterface

from geovs_drake.loop.assembly import FEATURE_SIZE

__all__ = [
    "CAPTURE_SLACK_US",
    "COMMAND_VECTOR_SIZE",
    "FRAME_INDEX",
    "FRAME_STATUS",
    "FRAME_VALUE_SIZE",
    "FRAME_Y",
    "NUM_JOINTS",
    "US_PER_S",
    "VectorSerializer",
    "command_vector",
    "decode_status_vector",
    "frame_vector",
    "frame_vector_size",
    "status_vector",
    "subscribe_vector",
]

#: The Panda's joints.
NUM_JOINTS = 7

# A status: [utime [us], num_joints, q (7), v (7)]; q and v zero unless num_joints is 7.
STATUS_UTIME, STATUS_NUM_JOINTS = 0, 1
STATUS_Q = slice(2, 2 + NUM_JOINTS)
STATUS_V = slice(2 + NUM_JOINTS, 2 + 2 * NUM_JOINTS)
STATUS_VECTOR_SIZE = 2 + 2 * NUM_JOINTS

# A command: [utime [us], control_mode_expected, num_joint_torque, tau (7),
# num_joint_velocity, v (7)]; an array zero unless its count is 7.
COMMAND_UTIME, COMMAND_MODE, COMMAND_NUM_TORQUE = 0, 1, 2
COMMAND_TORQUE = slice(3, 3 + NUM_JOINTS)
COMMAND_NUM_VELOCITY = 3 + NUM_JOINTS
COMMAND_VELOCITY = slice(4 + NUM_JOINTS, 4 + 2 * NUM_JOINTS)
COMMAND_VECTOR_SIZE = 4 + 2 * NUM_JOINTS

#: Microseconds per second: LCM's ``utime``.
US_PER_S = 1e6
#: A status counts as taken at or before a frame's capture within this [us]: Drake
#: stamps statuses and images with ``int64(t * 1e6)``, a truncation, so a stamp may
#: read a microsecond early (0.1 s * 1e6 is 99999.99...); statuses are a millisecond
#: apart.
CAPTURE_SLACK_US = 1.5

# A camera frame (lcmt_scope): [utime [us], size, value (FRAME_VALUE_SIZE)]; the values
# NaN unless size is FRAME_VALUE_SIZE. ``utime`` is the capture of the frame's y (not
# when it is read or sent: with latency, or held through failed frames, it is older).
FRAME_UTIME, FRAME_SIZE, FRAME_VALUE_START = 0, 1, 2
#: The frame's ``value``: y (13), the sensor's ``[valid, code, lost]`` (3) and the
#: frame's index (1), its sequence number on the camera's clock (a gap is a frame lost).
FRAME_Y = slice(0, FEATURE_SIZE)
FRAME_STATUS = slice(FEATURE_SIZE, FEATURE_SIZE + 3)
FRAME_INDEX = FEATURE_SIZE + 3
FRAME_VALUE_SIZE = FRAME_INDEX + 1


def status_vector(message: lcmt_panda_status) -> np.ndarray:
    """The status layout (``STATUS_*``) of ``message``."""
    out = np.zeros(STATUS_VECTOR_SIZE)
    out[STATUS_UTIME], out[STATUS_NUM_JOINTS] = message.utime, message.num_joints
    if message.num_joints == NUM_JOINTS:
        out[STATUS_Q] = message.joint_position
        out[STATUS_V] = message.joint_velocity
    return out


#: The status's LCM fingerprint and its head (utime, num_joints), then its arrays in
#: order: joint_position, joint_position_desired, joint_velocity, ... (8 bytes a value).
_STATUS_FINGERPRINT = lcmt_panda_status._get_packed_fingerprint()
_STATUS_HEAD = struct.Struct(">qi")
_STATUS_ARRAYS_START = len(_STATUS_FINGERPRINT) + _STATUS_HEAD.size
_BIG_ENDIAN_DOUBLE = np.dtype(">f8")


def decode_status_vector(data: bytes) -> np.ndarray:
    """:func:`status_vector` of an encoded ``lcmt_panda_status``, reading only the head,
    q and v from the LCM wire format (why: the generated decoder unpacks all eight
    arrays, 35 us a message, 1000 a second). ValueError if ``data`` is not one."""
    if data[: len(_STATUS_FINGERPRINT)] != _STATUS_FINGERPRINT:
        raise ValueError("not an lcmt_panda_status (its fingerprint differs)")
    utime, n = _STATUS_HEAD.unpack_from(data, len(_STATUS_FINGERPRINT))
    out = np.zeros(STATUS_VECTOR_SIZE)
    out[STATUS_UTIME], out[STATUS_NUM_JOINTS] = utime, n
    if n == NUM_JOINTS:
        width = n * _BIG_ENDIAN_DOUBLE.itemsize
        q_at, v_at = _STATUS_ARRAYS_START, _STATUS_ARRAYS_START + 2 * width  # v after q_d
        out[STATUS_Q] = np.frombuffer(data, _BIG_ENDIAN_DOUBLE, n, q_at)
        out[STATUS_V] = np.frombuffer(data, _BIG_ENDIAN_DOUBLE, n, v_at)
    return out


def command_vector(message: lcmt_panda_command) -> np.ndarray:
    """The command layout (``COMMAND_*``) of ``message``."""
    out = np.zeros(COMMAND_VECTOR_SIZE)
    out[COMMAND_UTIME], out[COMMAND_MODE] = message.utime, message.control_mode_expected
    out[COMMAND_NUM_TORQUE] = message.num_joint_torque
    out[COMMAND_NUM_VELOCITY] = message.num_joint_velocity
    if message.num_joint_torque == NUM_JOINTS:
        out[COMMAND_TORQUE] = message.joint_torque
    if message.num_joint_velocity == NUM_JOINTS:
        out[COMMAND_VELOCITY] = message.joint_velocity
    return out


def frame_vector_size(value_size: int) -> int:
    """The length of a frame vector whose message carries ``value_size`` values."""
    return FRAME_VALUE_START + value_size


def frame_vector(value_size: int) -> Callable[[lcmt_scope], np.ndarray]:
    """The frame layout (``FRAME_*``) of a message that should carry ``value_size``
    values: utime, the size it carries, then its values (NaN if it carries another
    number of them)."""

    def convert(message: lcmt_scope) -> np.ndarray:
        out = np.full(frame_vector_size(value_size), np.nan)
        out[FRAME_UTIME], out[FRAME_SIZE] = message.utime, message.size
        if message.size == value_size == len(message.value):
            out[FRAME_VALUE_START:] = message.value
        return out

    return convert


class VectorSerializer(SerializerInterface):
    """Decodes a channel's messages into the float vector ``decode`` makes of their
    bytes (the value held in the Context); ``default`` is the value before the first
    message. Subscribe only: it does not encode."""

    def __init__(self, name: str, decode: Callable[[bytes], np.ndarray], default: np.ndarray):
        SerializerInterface.__init__(self)
        self._name, self._decode = name, decode
        self._default = np.asarray(default, dtype=float)

    def __repr__(self) -> str:
        return f"VectorSerializer({self._name})"

    def CreateDefaultValue(self) -> AbstractValue:  # noqa: N802 (Drake's name)
        return AbstractValue.Make(self._default.copy())

    def Deserialize(self, buffer: bytes, abstract_value: AbstractValue) -> None:  # noqa: N802
        abstract_value.set_value(self._decode(buffer))

    def Serialize(self, abstract_value: AbstractValue) -> bytes:  # noqa: N802
        raise NotImplementedError("VectorSerializer only decodes (a subscriber's)")


def subscribe_vector(
    channel: str,
    lcm_type: type,
    to_vector: Callable[[object], np.ndarray],
    default: np.ndarray,
    interface: LcmInterfaceSystem | DrakeLcmInterface,
) -> LcmSubscriberSystem:
    """An ``LcmSubscriberSystem`` of ``channel`` whose output is the vector of the
    latest message (``default`` before one): ``to_vector`` of the decoded message, or,
    for ``lcmt_panda_status``, :func:`decode_status_vector` of its bytes (its layout
    is :func:`status_vector`'s; ``to_vector`` is then not called)."""
    if lcm_type is lcmt_panda_status:
        decode = decode_status_vector
    else:

        def decode(data: bytes) -> np.ndarray:
            return to_vector(lcm_type.decode(data))

    serializer = VectorSerializer(lcm_type.__name__, decode, default)
    return LcmSubscriberSystem(channel, serializer, interface, 0.0)
