"""Frame bookkeeping of the camera rig, in scalar style on named components.

Rotations are 9-tuples, row-major (``R[3 i + j]``); vectors are 3-tuples. Any
number type (float, float batches, AutoDiffXd, Expression), so the Drake
systems and the batch engine share these formulas.

Frames (monogram notation): W world, B target sphere (the paper's F_b), R the
camera rig's body frame (origin at its centre of mass), C the camera. The
paper's H is X_CB, its G is X_BC.
"""

from __future__ import annotations

from geovs_drake.geometry._ops import Ops

__all__ = [
    "apply",
    "camera_pose_error",
    "free_body_derivative",
    "kinematic_body_derivative",
    "kinetic_energy",
    "apply_transpose",
    "camera_body_velocity",
    "cross",
    "matmul",
    "quaternion_to_rotation",
    "rig_velocity",
    "target_in_camera",
    "wrench_to_rig",
]


def quaternion_to_rotation(q: tuple, xp: Ops) -> tuple:
    """R(q) for q = (w, x, y, z), normalised first (as MultibodyPlant does)."""
    w, x, y, z = q
    n = xp.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return (
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
    )  # fmt: skip


def apply(R: tuple, v: tuple) -> tuple:
    """R v."""
    return (
        R[0] * v[0] + R[1] * v[1] + R[2] * v[2],
        R[3] * v[0] + R[4] * v[1] + R[5] * v[2],
        R[6] * v[0] + R[7] * v[1] + R[8] * v[2],
    )


def apply_transpose(R: tuple, v: tuple) -> tuple:
    """R^T v."""
    return (
        R[0] * v[0] + R[3] * v[1] + R[6] * v[2],
        R[1] * v[0] + R[4] * v[1] + R[7] * v[2],
        R[2] * v[0] + R[5] * v[1] + R[8] * v[2],
    )


def matmul(A: tuple, B: tuple) -> tuple:
    """A B (unrolled: a comprehension would cost three times as much)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B
    return (
        a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
        a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
        a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8,
    )  # fmt: skip


def cross(a: tuple, b: tuple) -> tuple:
    """a x b."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def target_in_camera(
    R_WR: tuple, p_WR: tuple, R_RC: tuple, p_RC: tuple, R_WB: tuple, p_WB: tuple
) -> tuple[tuple, tuple, tuple]:
    """``(r2, r3, d)`` of the paper's ``H = X_CB = (X_WR X_RC)^-1 X_WB``.

    The columns r2, r3 of R_CB and d = p_CB are all the camera map (Eqs. 3-7)
    and the visibility (Eq. 5) need.
    """
    R_WC = matmul(R_WR, R_RC)
    o = apply(R_WR, p_RC)
    p_CoBo_W = (p_WB[0] - p_WR[0] - o[0], p_WB[1] - p_WR[1] - o[1], p_WB[2] - p_WR[2] - o[2])
    r2 = apply_transpose(R_WC, (R_WB[1], R_WB[4], R_WB[7]))
    r3 = apply_transpose(R_WC, (R_WB[2], R_WB[5], R_WB[8]))
    return r2, r3, apply_transpose(R_WC, p_CoBo_W)


def camera_body_velocity(
    R_WR: tuple, R_WC: tuple, w_WR_W: tuple, v_WRo_W: tuple, p_RC: tuple
) -> tuple:
    """``(Omega, V)``: the camera's body velocity in C at Co, from the rig's state.

    With B fixed in W this is ``G^-1 Gdot`` of Eq. (16) for G = X_BC.
    """
    wxo = cross(w_WR_W, apply(R_WR, p_RC))
    v_WCo_W = (v_WRo_W[0] + wxo[0], v_WRo_W[1] + wxo[1], v_WRo_W[2] + wxo[2])
    return apply_transpose(R_WC, w_WR_W) + apply_transpose(R_WC, v_WCo_W)


def free_body_derivative(x: tuple, F: tuple, body: tuple, xp: Ops) -> tuple:
    """``xdot`` of a free rigid body in MultibodyPlant's state layout, gravity off.

    ``x = [q_WR (4), p_WR (3), w_WR_W (3), v_WRo_W (3)]`` with R's origin at
    the centre of mass and its axes principal; ``F = [tau_Ro_W, f_W]`` (the
    plant's generalized force); ``body = (mass, Ixx, Iyy, Izz)``. Newton for
    the centre of mass, Euler's equations with the gyroscopic term in the body
    frame, ``qdot = 1/2 (0, w_W) (x) q`` for the world-frame angular velocity.
    """
    qw, qx, qy, qz = x[0:4]
    wx, wy, wz = x[7:10]
    m, Ixx, Iyy, Izz = body
    R = quaternion_to_rotation(x[0:4], xp)
    # (0, w) (x) q = (-w . v, qw w + w x v), v = (qx, qy, qz).
    qdot = (
        -0.5 * (wx * qx + wy * qy + wz * qz),
        0.5 * (qw * wx + wy * qz - wz * qy),
        0.5 * (qw * wy + wz * qx - wx * qz),
        0.5 * (qw * wz + wx * qy - wy * qx),
    )
    # Euler: I wdot_B = tau_B - w_B x (I w_B), then back to W.
    w_B = apply_transpose(R, x[7:10])
    tau_B = apply_transpose(R, F[0:3])
    Iw = (Ixx * w_B[0], Iyy * w_B[1], Izz * w_B[2])
    gyro = cross(w_B, Iw)
    wdot_B = ((tau_B[0] - gyro[0]) / Ixx, (tau_B[1] - gyro[1]) / Iyy, (tau_B[2] - gyro[2]) / Izz)
    return qdot + tuple(x[10:13]) + apply(R, wdot_B) + (F[3] / m, F[4] / m, F[5] / m)


def kinetic_energy(x: tuple, body: tuple, xp: Ops) -> object:
    """``1/2 (m |v|^2 + w_B^T I w_B)`` of the free body of :func:`free_body_derivative`."""
    m, Ixx, Iyy, Izz = body
    w_B = apply_transpose(quaternion_to_rotation(x[0:4], xp), x[7:10])
    vx, vy, vz = x[10:13]
    return 0.5 * (
        m * (vx * vx + vy * vy + vz * vz)
        + Ixx * w_B[0] * w_B[0]
        + Iyy * w_B[1] * w_B[1]
        + Izz * w_B[2] * w_B[2]
    )


def kinematic_body_derivative(x: tuple, twist: tuple, xp: Ops) -> tuple:
    """``xdot`` of a pose ``x = [q_WC, p_WC]`` moving with body twist ``(Omega, V)`` in C.

    Eq. (17) with the target fixed in W: ``qdot = 1/2 q (x) (0, Omega)``,
    ``pdot = R(q) V``.
    """
    qw, qx, qy, qz = x[0:4]
    ox, oy, oz = twist[0:3]
    # q (x) (0, Omega) = (-v . Omega, qw Omega + v x Omega), v = (qx, qy, qz).
    qdot = (
        -0.5 * (qx * ox + qy * oy + qz * oz),
        0.5 * (qw * ox + qy * oz - qz * oy),
        0.5 * (qw * oy + qz * ox - qx * oz),
        0.5 * (qw * oz + qx * oy - qy * ox),
    )
    return qdot + apply(quaternion_to_rotation(x[0:4], xp), twist[3:6])


def camera_pose_error(
    x: tuple, R_RC: tuple, p_RC: tuple, R_WC_goal: tuple, p_WC_goal: tuple, xp: Ops
) -> tuple:
    """``(|p_WC - p_WC*|^2, |R_WC - R_WC*|_F^2)`` for the rig pose ``x = [q_WR, p_WR]``.

    Both are invariant under the target's pose, so they equal the errors of
    X_BC against X_BC*. The rotation angle is ``2 asin(|dR|_F / sqrt(8))``
    (``|R - R*|_F^2 = 8 sin^2(angle / 2)``), accurate near 0 where the trace
    formula is not.
    """
    R_WR = quaternion_to_rotation(x[0:4], xp)
    R_WC = matmul(R_WR, R_RC)
    o = apply(R_WR, p_RC)
    dx = x[4] + o[0] - p_WC_goal[0]
    dy = x[5] + o[1] - p_WC_goal[1]
    dz = x[6] + o[2] - p_WC_goal[2]
    dR = 0
    for i in range(9):
        dR = dR + (R_WC[i] - R_WC_goal[i]) * (R_WC[i] - R_WC_goal[i])
    return dx * dx + dy * dy + dz * dz, dR


def rig_velocity(R_WR: tuple, R_WC: tuple, twist_C: tuple, p_RC: tuple) -> tuple:
    """The rig's ``(w_WR_W, v_WRo_W)`` for a camera body twist ``(Omega, V)`` in C.

    The inverse of :func:`camera_body_velocity`: ``w = R_WC Omega``,
    ``v_WCo = R_WC V`` and ``v_WRo = v_WCo - w x p_RoCo`` (B fixed in W, so
    ``(Omega, V) = G^-1 Gdot`` of Eqs. 16-17 for G = X_BC).
    """
    w = apply(R_WC, twist_C[0:3])
    v_Co = apply(R_WC, twist_C[3:6])
    wxo = cross(w, apply(R_WR, p_RC))
    return w + (v_Co[0] - wxo[0], v_Co[1] - wxo[1], v_Co[2] - wxo[2])


def wrench_to_rig(F_C: tuple, R_WR: tuple, R_WC: tuple, p_RC: tuple) -> tuple:
    """A wrench on the camera (torque about Co, force; both in C) as ``[tau_Ro_W, f_W]``.

    The torque is shifted to the rig's origin Ro and both are expressed in W
    (Appendix C.0.6's ``Ad*``): MultibodyPlant's generalized force of a
    quaternion floating body.
    """
    tau_W = apply(R_WC, F_C[0:3])
    f_W = apply(R_WC, F_C[3:6])
    # tau_Ro = tau_Co + p_RoCo x f.
    shift = cross(apply(R_WR, p_RC), f_W)
    return (tau_W[0] + shift[0], tau_W[1] + shift[1], tau_W[2] + shift[2]) + f_W
