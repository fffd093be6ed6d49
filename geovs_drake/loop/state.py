"""Initial states and pose conversions, shared by the loops, the simulator and the batch engine.

A loop's continuous state is its carrier's: a free body's 13 numbers
``[qw, qx, qy, qz, x, y, z, wx, wy, wz, vx, vy, vz]`` (pose first), or a
kinematic body's 7. What the state is the pose *of* depends on the carrier: the
rig R (eye-in-hand; the camera sits at X_RC on it), the camera C itself
(kinematic eye-in-hand), or the target B (fixed camera, G = H^-1 of Eq. 16).
These functions turn camera poses X_BC into states and back, for every free carrier.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix

from geovs_drake.geometry._ops import MATH, NUMPY
from geovs_drake.geometry.rigid import (
    apply,
    matmul,
    quaternion_to_rotation,
    rig_velocity,
    target_twist_from_camera,
)
from geovs_drake.geometry.so3 import rotations_to_quaternions
from geovs_drake.scenario import ScenarioConfig

__all__ = [
    "POSE",
    "VELOCITY",
    "camera_pose_in_target",
    "fixed_camera_pose",
    "initial_body_states",
    "initial_rig_pose",
    "initial_rig_state",
    "poses_in_target",
]

#: The pose ``[q (4), p (3)]`` at the head of every carrier state.
POSE = slice(0, 7)
#: The quaternion and the position within it.
QUATERNION, POSITION = slice(0, 4), slice(4, 7)
#: A free body's spatial velocity ``[w_W (3), v_W (3)]`` after its pose.
VELOCITY = slice(7, 13)
ANGULAR, TRANSLATIONAL = slice(7, 10), slice(10, 13)


def initial_rig_pose(config: ScenarioConfig) -> RigidTransform:
    """X_WR(0) = X_WB X_BC(0) X_RC^-1."""
    return config.X_WB @ config.X_BC_initial @ config.X_RC.inverse()


def fixed_camera_pose(config: ScenarioConfig) -> RigidTransform:
    """X_WC of the fixed camera (carrier :class:`~geovs_drake.scenario.FixedCamera`): where
    the eye-in-hand camera's goal is, ``X_WB X_BC*``, so the target comes to rest at
    ``config.X_WB``, where it stands in the eye-in-hand scene."""
    return config.X_WB @ config.X_BC_goal


def initial_body_states(
    config: ScenarioConfig, X_BC: np.ndarray, twists: np.ndarray | None = None
) -> np.ndarray:
    """The loop's body states for camera poses X_BC (N, 4, 4) and body twists (N, 6).

    Dynamic loop: the rig's free-body state in the plant's layout (N, 13),
    ``[qw, qx, qy, qz, x, y, z, wx, wy, wz, vx, vy, vz]``: ``X_WR = X_WB X_BC
    X_RC^-1``, then the angular velocity of R in W and the translational
    velocity of R's origin in W, both expressed in W, that give the camera the
    body twist (Omega, V) = G^-1 Gdot of Eqs. (16)-(17)
    (:func:`~geovs_drake.geometry.rigid.rig_velocity`). Kinematic loop: the
    camera's pose ``X_WC = X_WB X_BC`` as (N, 7); that loop is first order, so
    a non-zero twist is an error. Fixed camera: the target's states
    (:func:`_initial_target_states`).
    """
    X_BC = np.asarray(X_BC, dtype=float).reshape(-1, 4, 4)
    n = len(X_BC)
    dynamic = config.dynamic
    if twists is not None and not dynamic and np.any(np.asarray(twists) != 0):
        raise ValueError(
            "an initial twist applies to the dynamic loop only (first-order kinematic)"
        )
    if not config.carrier.traits.camera_in_hand:
        return _initial_target_states(config, X_BC, twists)
    X_RC = config.X_RC if dynamic else RigidTransform()
    X_RC_inv = X_RC.inverse()
    # X_W = X_WB X_BC X_RC^-1 for all starts at once, the quaternions compiled (a sweep's
    # 10^4: one RigidTransform each cost 22 us a start, twice per sweep, the sampler's
    # energy and the engine's).
    X_W = config.X_WB.GetAsMatrix4() @ X_BC @ X_RC_inv.GetAsMatrix4()
    states = np.zeros((n, 13 if dynamic else 7))
    states[:, QUATERNION] = rotations_to_quaternions(np.ascontiguousarray(X_W[:, :3, :3]))
    states[:, POSITION] = X_W[:, :3, 3]
    if dynamic and twists is not None:
        twists = np.asarray(twists, dtype=float).reshape(n, 6)
        R_WR = quaternion_to_rotation(tuple(states[:, QUATERNION].T), NUMPY)
        R_RC = tuple(X_RC.rotation().matrix().ravel())
        velocity = rig_velocity(
            R_WR, matmul(R_WR, R_RC), tuple(twists.T), tuple(X_RC.translation())
        )
        states[:, VELOCITY] = np.stack(np.broadcast_arrays(*velocity), axis=-1)
    return states


def _initial_target_states(
    config: ScenarioConfig, X_BC: np.ndarray, twists: np.ndarray | None
) -> np.ndarray:
    """The fixed-camera loop's target states for relative poses G = X_BC and camera twists.

    ``X_WB = X_WC X_BC^-1`` with the camera fixed at :func:`fixed_camera_pose`;
    the target's twist is ``-Ad_G (Omega, V)`` in B (Eq. 16), then expressed in W
    as the plant's ``(w_WB_W, v_WBo_W)``.
    """
    dynamic = config.dynamic
    X_WC = fixed_camera_pose(config)
    R_WC = tuple(X_WC.rotation().matrix().ravel())
    p_WC = tuple(X_WC.translation())
    states = np.zeros((len(X_BC), 13 if dynamic else 7))
    if twists is not None:
        twists = np.asarray(twists, dtype=float).reshape(len(X_BC), 6)
    for i, G in enumerate(X_BC):
        X_WB = X_WC @ RigidTransform(G).inverse()
        states[i, QUATERNION] = X_WB.rotation().ToQuaternion().wxyz()
        states[i, POSITION] = X_WB.translation()
        if dynamic and twists is not None:
            x = tuple(states[i, POSE].tolist())
            twist = target_twist_from_camera(tuple(twists[i].tolist()), x, R_WC, p_WC, MATH)
            R_WB = tuple(X_WB.rotation().matrix().ravel())
            states[i, ANGULAR] = apply(R_WB, twist[0:3])
            states[i, TRANSLATIONAL] = apply(R_WB, twist[3:6])
    return states


def initial_rig_state(config: ScenarioConfig) -> np.ndarray:
    """The driven body's free-body state at t = 0 (13 numbers, :func:`initial_body_states`):
    X_BC(0) and ``config.initial_velocity``. For
    :meth:`MultibodyPlant.SetPositionsAndVelocities` (the plant has no default
    velocity, so a simulator's context must be set)."""
    return initial_body_states(
        config, config.X_BC_initial.GetAsMatrix4(), np.asarray(config.initial_velocity)
    )[0]


def camera_pose_in_target(config: ScenarioConfig, x: np.ndarray, dynamic: bool) -> RigidTransform:
    """X_BC from a state whose first 7 entries are X_WR (dynamic) or X_WC (kinematic),
    or, for the fixed camera, the target's X_WB (then X_BC = X_WB^-1 X_WC)."""
    q = np.asarray(x[QUATERNION], dtype=float)
    X_W = RigidTransform(RotationMatrix(Quaternion(q / np.linalg.norm(q))), x[POSITION])
    if not config.carrier.traits.camera_in_hand:
        return X_W.inverse() @ fixed_camera_pose(config)
    X_RC = config.X_RC if dynamic else RigidTransform()
    return config.X_WB.inverse() @ X_W @ X_RC


def poses_in_target(config: ScenarioConfig, states: np.ndarray) -> np.ndarray:
    """X_BC (N, 4, 4) for states (N, n) of ``config``'s loop: :func:`camera_pose_in_target`
    for every row at once (the quaternions normalised, then numpy on the batch)."""
    dynamic = config.dynamic
    states = np.asarray(states, dtype=float).reshape(-1, np.shape(states)[-1])
    q = states[:, QUATERNION]
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    X_W = np.zeros((len(states), 4, 4))
    X_W[:, 0, :3] = np.stack(
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1
    )
    X_W[:, 1, :3] = np.stack(
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1
    )
    X_W[:, 2, :3] = np.stack(
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1
    )
    X_W[:, :3, 3] = states[:, POSITION]
    X_W[:, 3, 3] = 1.0
    if not config.carrier.traits.camera_in_hand:  # X_BC = X_WB^-1 X_WC with the target's state X_WB
        R_T = np.swapaxes(X_W[:, :3, :3], 1, 2)
        inverse = np.zeros_like(X_W)
        inverse[:, :3, :3] = R_T
        inverse[:, :3, 3] = -np.einsum("nij,nj->ni", R_T, X_W[:, :3, 3])
        inverse[:, 3, 3] = 1.0
        return inverse @ fixed_camera_pose(config).GetAsMatrix4()
    X_after = (config.X_RC if dynamic else RigidTransform()).GetAsMatrix4()
    return config.X_WB.inverse().GetAsMatrix4() @ X_W @ X_after
