"""A moving target's kinematics on SE(3), and what its motion does to a body that follows it.

Twists are (omega, v), angular part first, as the rest of the package writes them; a pose
is a 4 x 4 homogeneous matrix. A target with the constant body twist xi_B moves as
``X_WB(t) = X_WB(0) exp(t xi_B^)`` (:func:`se3_exp`, closed form).

The loop runs in the target's frame: a body R whose pose relative to the target is X_BR
has the world body twist ``V = V_r + Ad_{X_RB} xi_B`` (V_r its twist relative to B, both
in R). Newton-Euler about R's centre of mass, ``M V' + C(V) = F`` with ``C(V) =
(omega x J omega, m omega x v)``, then reads in the target's frame

    M V_r' + C(V_r) = F + F_frame,   F_frame = C(V_r) - C(V) - M d/dt(Ad_{X_RB} xi_B),

with ``d/dt(Ad_{X_RB} xi_B) = Ad_{X_RB} xi_B' - ad_{V_r} Ad_{X_RB} xi_B``
(:func:`frame_wrench`): the wrench of the target frame's motion (its acceleration, the
Coriolis and centripetal terms). A feed-forward of ``-F_frame`` makes the relative
dynamics those of a still target.

A target along a trajectory (Drake's ``PiecewisePose``) gives its frame's spatial velocity
and acceleration in the world (the frame it is measured from), of the frame's origin;
:func:`body_twist_of_spatial` and :func:`body_twist_rate_of_spatial` make them the body
twist xi_B and its rate xi_B' that the rest reads.
"""

from __future__ import annotations

import numpy as np

from geovs_drake.geometry.rigid import cross
from geovs_drake.geometry.so3 import hat, so3_exp, so3_log

__all__ = [
    "adjoint",
    "body_twist_of_spatial",
    "body_twist_rate_of_spatial",
    "frame_wrench",
    "lie_bracket",
    "se3_exp",
    "se3_log",
    "target_pose",
    "twist_rate",
]

#: Below this |omega| [rad] the V matrix is its series to theta^2 (error below theta^4).
_SMALL_ANGLE = 1e-4


def _v_matrix(w: np.ndarray) -> np.ndarray:
    """V(w) of ``exp((w, v)^) = [[exp(w^), V(w) v], [0, 1]]`` (the left Jacobian of SO(3))."""
    theta = float(np.linalg.norm(w))
    W = hat(w)
    if theta < _SMALL_ANGLE:
        t2 = theta**2
        return np.eye(3) + (0.5 - t2 / 24.0) * W + (1.0 / 6.0 - t2 / 120.0) * W @ W
    a = (1.0 - np.cos(theta)) / theta**2
    b = (theta - np.sin(theta)) / theta**3
    return np.eye(3) + a * W + b * W @ W


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """``exp(xi^)`` of a twist xi = (omega, v) (6,), as a 4 x 4 pose (closed form)."""
    xi = np.asarray(xi, dtype=float)
    X = np.eye(4)
    X[:3, :3] = so3_exp(xi[:3])
    X[:3, 3] = _v_matrix(xi[:3]) @ xi[3:]
    return X


def se3_log(X: np.ndarray) -> np.ndarray:
    """The twist xi = (omega, v) with ``exp(xi^) = X`` (rotation angle below pi)."""
    w = so3_log(X[:3, :3])
    return np.concatenate([w, np.linalg.solve(_v_matrix(w), X[:3, 3])])


def target_pose(X_WB0: np.ndarray, xi_B: np.ndarray, t: float) -> np.ndarray:
    """X_WB(t) = X_WB(0) exp(t xi_B^): the target with the constant body twist xi_B."""
    return np.asarray(X_WB0, dtype=float) @ se3_exp(t * np.asarray(xi_B, dtype=float))


def body_twist_of_spatial(R_WB: np.ndarray, V_W: np.ndarray) -> np.ndarray:
    """The body twist xi_B = (R^T omega_W, R^T v_W) of a frame B whose spatial velocity in
    W is V_W = (omega_W, v_W), v_W the velocity of B's origin: ``X_WB^-1 dX_WB/dt``."""
    R_BW = np.asarray(R_WB, dtype=float).T
    V_W = np.asarray(V_W, dtype=float)
    return np.concatenate([R_BW @ V_W[:3], R_BW @ V_W[3:]])


def body_twist_rate_of_spatial(R_WB: np.ndarray, V_W: np.ndarray, A_W: np.ndarray) -> np.ndarray:
    """xi_B', the rate of :func:`body_twist_of_spatial`, given B's spatial acceleration
    A_W = (alpha_W, a_W) in W (a_W that of B's origin): ``(R^T alpha_W, R^T a_W - omega_B x
    R^T v_W)``, since d/dt R^T = -omega_B^ R^T (the angular part's own term, omega_B x
    omega_B, is zero)."""
    R_BW = np.asarray(R_WB, dtype=float).T
    V_W, A_W = np.asarray(V_W, dtype=float), np.asarray(A_W, dtype=float)
    w_B, v_B = R_BW @ V_W[:3], R_BW @ V_W[3:]
    return np.concatenate([R_BW @ A_W[:3], R_BW @ A_W[3:] - cross(tuple(w_B), tuple(v_B))])


def adjoint(X_AB: np.ndarray) -> np.ndarray:
    """Ad_{X_AB} (6 x 6): a twist (omega, v) in B to the same motion's twist in A."""
    R, p = X_AB[:3, :3], X_AB[:3, 3]
    out = np.zeros((6, 6))
    out[:3, :3] = R
    out[3:, :3] = hat(p) @ R
    out[3:, 3:] = R
    return out


def lie_bracket(V: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """``ad_V xi`` = [V, xi] of two twists (omega, v)."""
    w, v, xw, xv = (tuple(part) for part in (V[:3], V[3:], xi[:3], xi[3:]))
    wxv, vxw = cross(w, xv), cross(v, xw)
    return np.array([*cross(w, xw), *(a + b for a, b in zip(wxv, vxw, strict=True))])


def twist_rate(xi_R: np.ndarray, V_r: np.ndarray, xi_dot_R: np.ndarray) -> np.ndarray:
    """d/dt (Ad_{X_RB} xi_B) in R: ``Ad_{X_RB} xi_B' - ad_{V_r} (Ad_{X_RB} xi_B)``, given
    ``xi_R = Ad_{X_RB} xi_B``, ``xi_dot_R = Ad_{X_RB} xi_B'`` and R's relative twist V_r."""
    return xi_dot_R - lie_bracket(V_r, xi_R)


def _bias(V: np.ndarray, inertia: np.ndarray, mass: float) -> np.ndarray:
    """C(V) = (omega x J omega, m omega x v): Newton-Euler's velocity terms about the
    centre of mass, in the body's frame."""
    w, v = tuple(V[:3]), tuple(V[3:])
    return np.array([*cross(w, tuple(inertia @ V[:3])), *(mass * c for c in cross(w, v))])


def frame_wrench(
    V_r: np.ndarray,
    xi_R: np.ndarray,
    xi_dot_R: np.ndarray,
    inertia: np.ndarray,
    mass: float,
) -> np.ndarray:
    """F_frame (module docstring): the wrench (torque, force) in R, about its centre of
    mass, that the target frame's motion adds to the body's relative dynamics.

    ``V_r``: R's twist relative to the target, in R; ``xi_R``: the target's twist carried
    to R, ``Ad_{X_RB} xi_B``; ``xi_dot_R``: ``Ad_{X_RB} xi_B'``; ``inertia``: J (3 x 3)
    about the centre of mass in R; ``mass``: m [kg].
    """
    V_r, xi_R = np.asarray(V_r, dtype=float), np.asarray(xi_R, dtype=float)
    M = np.zeros((6, 6))
    M[:3, :3] = inertia
    M[3:, 3:] = mass * np.eye(3)
    rate = twist_rate(xi_R, V_r, np.asarray(xi_dot_R, dtype=float))
    return _bias(V_r, inertia, mass) - _bias(V_r + xi_R, inertia, mass) - M @ rate
