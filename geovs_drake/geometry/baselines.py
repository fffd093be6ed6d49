"""The baseline laws' features and interaction matrices: point IBVS, PBVS, sphere features.

The laws a user knows, on this project's target (a sphere of radius rho marked
with the point ``b_B = (0, 0, -rho)`` and the arrow ``a_B = e2``), so that they
run in the same plant as the navigation function:

* **point IBVS** (Chaumette & Hutchinson, *Visual servo control I: basic
  approaches*, IEEE RAM 2006, Sec. III): four points on the target, their
  normalised image coordinates ``(x, y) = (X / Z, Y / Z)``, the classic
  interaction matrix of a point (their Eq. 11) and ``v = -lambda L^+ e``
  (Eq. 5) with one of three estimates of L: the current matrix with the true
  depths, the desired one ``L_e*``, or their mean ``(L_e + L_e*) / 2``;
* **PBVS** (the same, Sec. IV): ``s = (c*t_c, theta u)``, where ``c*t_c`` is
  the current camera's origin in the desired camera frame and ``theta u`` the
  angle-axis of ``c*R_c``; ``v = -lambda R^T c*t_c``, ``omega = -lambda theta u``
  (Eq. 24-25's variant whose camera origin moves on a straight line);
* **sphere features** (after Tatsambon Fomena & Chaumette, *Improvements on
  visual servoing from spherical targets using a spherical projection model*,
  IEEE T-RO 25(4), 2009): the sphere's centre over its radius,
  ``p = p_CB / rho = s / lambda``, whose interaction matrix
  ``[-(1 / rho) I, [p]x]`` is linear in the translation and needs no depth,
  completed by ``theta u`` of the target's rotation, which depends on the
  rotation only. The sphere part is the feature of their sphere target; we
  could not retrieve the paper's own text for the sphere marked with a tangent
  vector, so the rotational part here is our derivation in the same spirit
  (decoupled, block-triangular L), not a transcription of theirs.

Every pose here comes from the image through the paper's inverse map c^-1(y)
(Eq. 23): the four points' depths are the "true depth" oracle a real system
would estimate.

Conventions. Chaumette & Hutchinson order the camera's velocity
``v_c = (v, omega)``, translation first, and a point fixed in the scene moves
in the camera frame as ``Xdot = -v - omega x X`` (their Eq. 10). Ours is
``(Omega, V) = G^-1 Gdot`` for G = X_BC (Eq. 16), under which a point fixed in
B moves in C as ``pdot = -Omega x p - V`` (Eq. 11 with ``(omega, v) = -(Omega,
V)``). So ``v = V`` and ``omega = Omega``: the same velocity in the other
order. :func:`vw_from_twist` and :func:`twist_from_vw` are that one conversion;
every interaction matrix below maps ``(v, omega) = vw_from_twist((Omega, V))``.

Number types: float and AutoDiffXd (numpy object arrays), one pose at a time;
the log of a rotation branches on its value (:func:`so3_log`), so symbolic
Expressions are not supported.
"""

from __future__ import annotations

import numpy as np
import pydrake.math as pm

from geovs_drake.geometry._ops import components, namespace, to_float
from geovs_drake.geometry.camera import inverse_pose
from geovs_drake.geometry.so3 import hat, so3_log

__all__ = [
    "DEFAULT_SQUARE_SIDE",
    "IBVS_DEPTHS",
    "TARGET_POINT_NAMES",
    "ibvs_features",
    "ibvs_interaction",
    "ibvs_velocity",
    "image_points",
    "pbvs_features",
    "pbvs_interaction",
    "pbvs_velocity",
    "point_fov_margins",
    "point_interaction_matrix",
    "points_in_camera",
    "pose_from_image",
    "pseudo_inverse_times",
    "relative_rotation_and_translation",
    "sphere_features",
    "sphere_interaction",
    "spherical_velocity",
    "target_points",
    "theta_u_interaction",
    "twist_from_vw",
    "vw_from_twist",
]

#: The depth estimates of point IBVS (Chaumette & Hutchinson 2006, Sec. III.B), each
#: the L it makes from the current and the goal's interaction matrices (computed only
#: where it reads them): "true" the current matrix L_e with the true depths, "desired"
#: L_e* (at s* and Z*, constant), "mean" (L_e + L_e*) / 2.
_DEPTH_ESTIMATES = {
    "true": lambda current, goal: current(),
    "desired": lambda current, goal: goal(),
    "mean": lambda current, goal: (current() + goal()) / 2,
}
IBVS_DEPTHS = tuple(_DEPTH_ESTIMATES)

#: Names of the :func:`target_points`, in order (a = the arrow e2, n = e1).
TARGET_POINT_NAMES = ("b", "b + side a", "b + side (a + n)", "b + side n")

#: The IBVS square's side, in radii: 0.05 m for the default rho = 0.1 m. Small
#: enough that the four points stay in a 35-degree field of view from 0.25 m
#: (lambda_max = 0.4), large enough to condition L at 2 m.
DEFAULT_SQUARE_SIDE = 0.5


def vw_from_twist(twist: np.ndarray) -> np.ndarray:
    """``(v, omega)`` of Chaumette & Hutchinson from our ``(Omega, V)`` (see the module)."""
    a = np.asarray(twist)
    return np.concatenate([a[3:6], a[0:3]])


def twist_from_vw(vw: np.ndarray) -> np.ndarray:
    """Our ``(Omega, V)`` from ``(v, omega)``: the inverse of :func:`vw_from_twist`."""
    return vw_from_twist(vw)  # swapping the halves is its own inverse


def target_points(rho: object, side: object) -> np.ndarray:
    """The IBVS points in B, shape (4, 3): b and three corners of a square.

    The square lies in the plane tangent to the sphere at ``b_B = (0, 0, -rho)``,
    spanned by the arrow ``a_B = e2`` and its normal ``e1`` in that plane, with
    b as one corner: ``b, b + side e2, b + side (e1 + e2), b + side e1``. The
    plane touches the sphere only at b, so whenever b is visible (nu > 0) the
    sphere hides none of them.
    """
    z = -rho
    return np.array([[0.0, 0.0, z], [0.0, side, z], [side, side, z], [side, 0.0, z]])


def pose_from_image(y: np.ndarray, rho: object) -> tuple[np.ndarray, np.ndarray]:
    """``(R_CB, p_CB)`` of ``H = c^-1(y)`` (Eq. 23), as a 3x3 matrix and a 3-vector."""
    comps = components(np.asarray(y), 13, "y")
    r1, r2, r3, d = inverse_pose(comps, rho, namespace(comps[9]))
    return np.array([r1, r2, r3]).T, np.array(d)


def points_in_camera(R_CB: np.ndarray, p_CB: np.ndarray, P_B: np.ndarray) -> np.ndarray:
    """Points given in B, expressed in C: ``p_C = R_CB p_B + p_CB`` (rows)."""
    return P_B @ R_CB.T + p_CB


def image_points(P_C: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised image coordinates ``x = X / Z``, ``y = Y / Z`` and the depths Z."""
    Z = P_C[:, 2]
    return P_C[:, 0] / Z, P_C[:, 1] / Z, Z


def point_fov_margins(P_C: np.ndarray, cos_theta: float) -> np.ndarray:
    """``Z / |p| - cos(theta)`` per point: >= 0 inside the field-of-view cone of
    half-angle theta about e3 (and so in front of the camera, theta < pi / 2)."""
    norms = np.sqrt(np.sum(P_C * P_C, axis=1))
    return P_C[:, 2] / norms - cos_theta


def point_interaction_matrix(x: np.ndarray, y: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """L of n normalised image points, shape (2n, 6), rows ``(x_i, y_i)`` in turn.

    Chaumette & Hutchinson 2006, Eq. (11): ``d/dt (x, y) = L (v, omega)`` with::

        L_x = [[-1/Z, 0, x/Z, x y, -(1 + x^2), y],
               [0, -1/Z, y/Z, 1 + y^2, -x y, -x]]
    """
    rows = []
    for xi, yi, Zi in zip(x, y, Z, strict=True):
        rows.append([-1 / Zi, 0.0 * xi, xi / Zi, xi * yi, -(1 + xi * xi), yi])
        rows.append([0.0 * yi, -1 / Zi, yi / Zi, 1 + yi * yi, -xi * yi, -xi])
    return np.array(rows)


def ibvs_features(y: np.ndarray, rho: object, P_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``s = (x_1, y_1, ..., x_n, y_n)`` of the points P_B seen from c^-1(y), and their depths."""
    R_CB, p_CB = pose_from_image(y, rho)
    x, yy, Z = image_points(points_in_camera(R_CB, p_CB, P_B))
    return np.stack([x, yy], axis=-1).reshape(-1), Z


def ibvs_interaction(
    s: np.ndarray, Z: np.ndarray, s_goal: np.ndarray, Z_goal: np.ndarray, depth: str
) -> np.ndarray:
    """The estimate of L that the IBVS law inverts (``depth`` in :data:`IBVS_DEPTHS`)."""
    estimate = _DEPTH_ESTIMATES.get(depth)
    if estimate is None:
        raise ValueError(f"ibvs depth must be one of {', '.join(IBVS_DEPTHS)}, got {depth!r}")
    return estimate(
        lambda: point_interaction_matrix(s[0::2], s[1::2], Z),
        lambda: point_interaction_matrix(s_goal[0::2], s_goal[1::2], Z_goal),
    )


def pseudo_inverse_times(L: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``L^+ e``, the Moore-Penrose pseudo-inverse of Chaumette & Hutchinson's Eq. (5).

    Floats: numpy's SVD pseudo-inverse (defined at rank-deficient L too).
    AutoDiffXd: ``(L^T L)^-1 L^T e``, the same matrix wherever L has full
    column rank (four points in general position), differentiable there.
    """
    if L.dtype != object:
        return np.linalg.pinv(L) @ e
    return pm.inv(L.T @ L) @ (L.T @ e)


def ibvs_velocity(
    y: np.ndarray,
    y_goal: np.ndarray,
    rho: object,
    P_B: np.ndarray,
    gain: object,
    depth: str,
) -> np.ndarray:
    """Point IBVS: ``(v, omega) = -lambda L^+ (s - s*)`` (C&H 2006 Eq. 5), as (Omega, V)."""
    s, Z = ibvs_features(y, rho, P_B)
    s_goal, Z_goal = ibvs_features(y_goal, rho, P_B)
    L = ibvs_interaction(s, Z, s_goal, Z_goal, depth)
    return twist_from_vw(-gain * pseudo_inverse_times(L, s - s_goal))


def relative_rotation_and_translation(
    y: np.ndarray, y_goal: np.ndarray, rho: object
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(c*R_c, c*t_c, p_CB)``: the current camera in the desired camera's frame, from
    c^-1(y) and c^-1(y*) (Eq. 23), and the target's centre in the current camera.

    With ``H = X_CB`` and ``H* = X_C*B``: ``X_C*C = H* H^-1``, so ``c*R_c = R* R^T``
    and ``c*t_c = p* - c*R_c p``.
    """
    R, p = pose_from_image(y, rho)
    R_goal, p_goal = pose_from_image(y_goal, rho)
    E = R_goal @ R.T
    return E, p_goal - E @ p, p


def theta_u_interaction(theta_u: np.ndarray) -> np.ndarray:
    """``L_theta_u`` with ``d/dt (theta u) = L_theta_u omega`` for ``E = c*R_c``,
    ``Edot = E [omega]x`` (Chaumette & Hutchinson 2006, Sec. IV; Malis 1999)::

        L = I + (theta / 2) [u]x + (1 - sinc(theta) / sinc^2(theta / 2)) [u]x^2

    written on ``w = theta u``: ``I + [w]x / 2 + k(theta) [w]x^2`` with
    ``k = (1 - sinc(theta) / sinc^2(theta / 2)) / theta^2`` (1/12 at 0). The
    tutorial prints ``-(theta / 2) [u]x``; for this parameterisation (theta u of
    c*R_c, omega in the current camera frame) central differences give the
    ``+`` sign (tests). The law never uses the sign: ``L^-1 theta u = theta u``.
    """
    w = np.asarray(theta_u)
    t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
    xp = namespace(t2)
    if float(to_float(t2)) < 1e-8:
        k = 1.0 / 12 + t2 / 720
    else:
        t = xp.sqrt(t2)
        sinc = xp.sin(t) / t
        sinc_half = xp.sin(t / 2) / (t / 2)
        k = (1 - sinc / (sinc_half * sinc_half)) / t2
    W = hat(w)
    return np.eye(3) + W / 2 + k * (W @ W)


def pbvs_features(
    y: np.ndarray, y_goal: np.ndarray, rho: object
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(c*t_c, theta u, c*R_c)`` of PBVS (C&H 2006 Sec. IV); the goal is (0, 0)."""
    E, t, _ = relative_rotation_and_translation(y, y_goal, rho)
    return t, so3_log(E), E


def pbvs_interaction(E: np.ndarray, theta_u: np.ndarray) -> np.ndarray:
    """``d/dt (c*t_c, theta u) = [[c*R_c, 0], [0, L_theta_u]] (v, omega)``."""
    L = np.zeros((6, 6), dtype=E.dtype if E.dtype == object else float)
    L[0:3, 0:3] = E
    L[3:6, 3:6] = theta_u_interaction(theta_u)
    return L


def pbvs_velocity(y: np.ndarray, y_goal: np.ndarray, rho: object, gain: object) -> np.ndarray:
    """PBVS, straight line in Cartesian space: ``v = -lambda c*R_c^T c*t_c``,
    ``omega = -lambda theta u`` (``L_theta_u^-1 theta u = theta u``), as (Omega, V).

    Then ``d/dt c*t_c = -lambda c*t_c``: the camera's origin goes straight to the
    goal, and ``theta u`` decays along a fixed axis.
    """
    t, theta_u, E = pbvs_features(y, y_goal, rho)
    return np.concatenate([-gain * theta_u, -gain * (E.T @ t)])


def sphere_features(
    y: np.ndarray, y_goal: np.ndarray, rho: object
) -> tuple[np.ndarray, np.ndarray]:
    """``(p, theta u)``: ``p = s / lambda = p_CB / rho``, the sphere's centre over its
    radius, read straight from the image (Eq. 3), and theta u of ``c*R_c``."""
    E, _, _ = relative_rotation_and_translation(y, y_goal, rho)
    y = np.asarray(y)
    return y[10:13] / y[9], so3_log(E)


def sphere_interaction(p: np.ndarray, theta_u: np.ndarray, rho: object) -> np.ndarray:
    """``d/dt (p, theta u) = [[-(1 / rho) I, [p]x], [0, L_theta_u]] (v, omega)``.

    ``pdot = -(V + Omega x p_CB) / rho = -V / rho + p x Omega``: linear in the
    translation, no depth in it (Tatsambon Fomena & Chaumette's sphere block).
    """
    obj = p.dtype == object or np.asarray(theta_u).dtype == object
    L = np.zeros((6, 6), dtype=object if obj else float)
    L[0:3, 0:3] = -np.eye(3) / rho
    L[0:3, 3:6] = hat(p)
    L[3:6, 3:6] = theta_u_interaction(theta_u)
    return L


def spherical_velocity(y: np.ndarray, y_goal: np.ndarray, rho: object, gain: object) -> np.ndarray:
    """``(v, omega) = -lambda L^-1 (p - p*, theta u)`` in closed form, as (Omega, V):
    ``omega = -lambda theta u`` and ``v = rho (lambda (p - p*) + p x omega)``.

    Then ``pdot = -lambda (p - p*)``: the sphere's centre moves on a straight line
    in the camera frame, so its direction stays in a convex field-of-view cone
    that holds both ends.
    """
    p, theta_u = sphere_features(y, y_goal, rho)
    y_goal = np.asarray(y_goal)
    p_goal = y_goal[10:13] / y_goal[9]
    omega = -gain * theta_u
    v = rho * (gain * (p - p_goal) + hat(p) @ omega)
    return np.concatenate([omega, v])
