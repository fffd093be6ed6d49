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
    "fixed_camera_relative_pose",
    "camera_state_in_target",
    "cross",
    "matmul",
    "gibbs_quaternion",
    "quaternion_multiply",
    "quaternion_to_rotation",
    "rig_velocity",
    "target_in_camera",
    "target_twist_from_camera",
    "target_wrench_from_camera",
    "transpose",
    "wrench_to_rig",
]


def gibbs_quaternion(g: tuple, xp: Ops) -> tuple:
    """The unit quaternion ``(1, g/2) / |(1, g/2)|`` of a Gibbs vector g, the inverse of
    ``g = 2 vec(q) / w``: the rotation ``Cay(g)`` of the minimal coordinates about a goal
    (``analysis.linearization.pose_error``)."""
    norm = xp.sqrt(1 + (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]) / 4)
    return (1 / norm, g[0] / (2 * norm), g[1] / (2 * norm), g[2] / (2 * norm))


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


# --------------------------------------------------------------------------
# The fixed camera (eye-to-hand): the target is the moving body, G = H^-1 (Eq. 16)
# --------------------------------------------------------------------------
def quaternion_multiply(a: tuple, b: tuple) -> tuple:
    """The Hamilton product ``a (x) b`` of quaternions ``(w, x, y, z)``: R(a b) = R(a) R(b)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def fixed_camera_relative_pose(x: tuple, q_WC: tuple, p_WC: tuple, xp: Ops) -> tuple:
    """``G = X_BC = X_WB^-1 X_WC`` as ``[q_BC, p_BC]`` from the target's pose ``x = [q_WB, p_WB]``.

    The camera C is fixed in W at ``(q_WC, p_WC)`` (unit quaternion). ``q_BC =
    q_WB^-1 (x) q_WC`` with ``q_WB`` normalised first (as MultibodyPlant does),
    ``p_BC = R_WB^T (p_WC - p_WB)``. This is the pose the eye-in-hand camera
    system reads as its rig pose when the target frame B is taken as the world
    (X_WB = X_RC = identity there): one camera map, ``H = G^-1``.
    """
    qw, qx, qy, qz = x[0:4]
    n = xp.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    q_BW = (qw / n, -qx / n, -qy / n, -qz / n)
    R_WB = quaternion_to_rotation(x[0:4], xp)
    r = (p_WC[0] - x[4], p_WC[1] - x[5], p_WC[2] - x[6])
    return quaternion_multiply(q_BW, q_WC) + apply_transpose(R_WB, r)


def camera_state_in_target(x: tuple, q_WC: tuple, p_WC: tuple, xp: Ops) -> tuple:
    """The fixed camera's motion relative to the free target, as a free-body state.

    ``x`` is the target's MultibodyPlant state ``[q_WB, p_WB, w_WB_W, v_WBo_W]``.
    Returns ``[q_BC, p_BC, w_BC_B, v_BCo_B]``: the camera's pose in B
    (:func:`fixed_camera_relative_pose`) and its velocity relative to B, expressed
    in B, in the layout of a rig state whose world is B and whose camera sits
    at the rig's origin. Since C is fixed in W, ``w_BC = -w_WB`` and
    ``d/dt p_BC = -R_WB^T (v_WBo + w_WB x (p_WC - p_WB))``; from this state
    :func:`camera_body_velocity` gives ``(Omega, V) = G^-1 Gdot`` (Eq. 16),
    so the eye-in-hand systems read it unchanged.
    """
    R_WB = quaternion_to_rotation(x[0:4], xp)
    w = x[7:10]
    r = (p_WC[0] - x[4], p_WC[1] - x[5], p_WC[2] - x[6])
    wxr = cross(w, r)
    v = (x[10] + wxr[0], x[11] + wxr[1], x[12] + wxr[2])
    w_B = apply_transpose(R_WB, w)
    v_B = apply_transpose(R_WB, v)
    return (
        fixed_camera_relative_pose(x[0:7], q_WC, p_WC, xp)
        + (-w_B[0], -w_B[1], -w_B[2])
        + (-v_B[0], -v_B[1], -v_B[2])
    )


def target_wrench_from_camera(F_C: tuple, x: tuple, R_WC: tuple, p_WC: tuple) -> tuple:
    """The wrench on the free target, ``[tau_Bo_W, f_W]``, for a camera wrench F_C.

    ``F_C`` (torque about Co, force; in C) is what an eye-in-hand law would apply
    to the camera. With the camera fixed, the actuator applies the reaction
    ``-F_C`` at Co to the target instead: by Eq. (16) the camera's velocity
    relative to the target, ``(Omega, V) = G^-1 Gdot``, is minus the target's
    relative to the camera, ``(omega, v) = Hdot H^-1`` (its spatial twist at
    Co, in C, C being inertial), so ``(-F_C) . (omega, v) = F_C . (Omega, V)``:
    the target receives exactly the power the camera would. With Eq. (45)'s
    F_C, ``1/2 nu^T M nu + k_p phi`` (M the target's inertia) decreases at the
    rate ``(Omega, V)^T B (Omega, V)``, Appendix C's argument. The torque is
    shifted to the target's origin Bo and both are expressed in W, the
    plant's generalized force of a quaternion floating body.
    """
    tau = apply(R_WC, F_C[0:3])
    f = apply(R_WC, F_C[3:6])
    shift = cross((p_WC[0] - x[4], p_WC[1] - x[5], p_WC[2] - x[6]), f)
    return (-tau[0] - shift[0], -tau[1] - shift[1], -tau[2] - shift[2], -f[0], -f[1], -f[2])


def target_twist_from_camera(twist_C: tuple, x: tuple, R_WC: tuple, p_WC: tuple, xp: Ops) -> tuple:
    """The target's body twist (in B, at Bo) that gives the fixed camera the body twist
    ``(Omega, V) = G^-1 Gdot`` relative to it (Eq. 16); ``x = [q_WB, p_WB]``.

    ``H^-1 Hdot = G d/dt(G^-1) = -Ad_G (Omega, V)`` with ``G = X_BC``, and with
    C fixed ``H^-1 Hdot = X_WB^-1 d/dt X_WB`` is the target's body twist:
    ``(-R_BC Omega, -(R_BC V + p_BC x R_BC Omega))``.
    """
    R_WB = quaternion_to_rotation(x[0:4], xp)
    R_BC = matmul(transpose(R_WB), R_WC)
    p_BC = apply_transpose(R_WB, (p_WC[0] - x[4], p_WC[1] - x[5], p_WC[2] - x[6]))
    w = apply(R_BC, twist_C[0:3])
    v = apply(R_BC, twist_C[3:6])
    pxw = cross(p_BC, w)
    return (-w[0], -w[1], -w[2], -v[0] - pxw[0], -v[1] - pxw[1], -v[2] - pxw[2])


def transpose(R: tuple) -> tuple:
    """R^T (row-major 9-tuples)."""
    return (R[0], R[3], R[6], R[1], R[4], R[7], R[2], R[5], R[8])
