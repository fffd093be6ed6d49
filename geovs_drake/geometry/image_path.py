"""Paths in the image space I and the error between two images (Sec. 4, Eq. 18).

I = SO(3) x (0, 1) x S^2 carries the product of three metrics: the
bi-invariant one on SO(3) through ``xi = (Qdot Q^T)^vee`` (Eq. 13), the line's
on lambda and the round one on S^2 (the identification of Eq. 12). Its
geodesics are products of the factors' geodesics: a one-parameter subgroup
times Q for Q (what a quaternion slerp traces), a straight segment for
lambda, a great-circle arc for s.

This module holds the formulas the path follower and the planner share, in
scalar style on the named components of :mod:`geovs_drake.geometry.camera`
(13-vectors ``[q1, q2, q3, lambda, s]``):

* :func:`angle_over_sine`: ``theta / sin theta`` from ``cos theta`` and
  ``sin^2 theta``, the factor of both logarithms below, smooth through 0;
* :func:`image_error`: the log map ``log_y(y_d)`` in ``T_y I``, i.e. the
  tangent at y of the geodesic that reaches y_d at parameter 1:
  ``(log(Q_d Q^T)^vee, lambda_d - lambda, log_s(s_d))``;
* :func:`image_rate`: ``(xi, lambda_dot, s_dot)`` from the time derivative of
  the 13-vector;
* :func:`tracking_rate`: the commanded image velocity of the path follower,
  ``ydot_d`` carried to ``T_y I`` plus ``k log_y(y_d)``;
* :data:`QUINTIC_TIME_LAW`: ``h(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5``,
  zero velocity and acceleration at both ends;
* float batch helpers for the planner and the analysis: :func:`image_distance`
  and :func:`exp_image`.
"""

from __future__ import annotations

import math

import numpy as np

from geovs_drake.geometry._ops import Ops, to_float
from geovs_drake.geometry.camera import ImageFeatures
from geovs_drake.geometry.so3 import so3_exp

__all__ = [
    "QUINTIC_TIME_LAW",
    "angle_over_sine",
    "exp_image",
    "image_distance",
    "image_error",
    "image_rate",
    "tracking_rate",
    "transport_on_sphere",
]

#: Below this ``sin^2 / cos^2`` (and for cos > 0) :func:`angle_over_sine` uses its series.
_SERIES_BELOW = 1e-6


def angle_over_sine(c: object, s2: object, xp: Ops) -> object:
    """``theta / sin theta`` for ``cos theta = c``, ``sin^2 theta = s2``, theta in [0, pi).

    Both logarithms (SO(3) and S^2) are ``theta / sin theta`` times a vector of
    length ``sin theta``. The closed form ``atan2(sqrt(s2), c) / sqrt(s2)`` is
    0/0 at theta = 0 (the path follower's operating point, where AutoDiffXd
    would give NaN); there, with ``x^2 = s2 / c^2``, ``atan(x) / x = 1 - x^2/3
    + x^4/5 - x^6/7 + ...`` is used, exact to rounding below x^2 = 1e-6. The
    choice is made on the value (floats, AutoDiffXd, constant Expressions;
    elementwise for float arrays); a symbolic argument with free variables gets
    the closed form. Near theta = pi the logarithm itself is not defined and
    the factor grows without bound.
    """
    if type(s2) is np.ndarray or type(c) is np.ndarray:
        s2a, ca = np.asarray(s2, dtype=float), np.asarray(c, dtype=float)
        x2 = s2a / np.where(ca > 0, ca * ca, 1.0)
        small = (ca > 0) & (x2 < _SERIES_BELOW)
        r = np.sqrt(np.where(small, 1.0, s2a))
        with np.errstate(invalid="ignore", divide="ignore"):
            closed = np.arctan2(r, ca) / r
        series = (1 - x2 / 3 + x2 * x2 / 5 - x2 * x2 * x2 / 7) / np.where(small, ca, 1.0)
        return np.where(small, series, closed)
    if type(c) is float and type(s2) is float:  # the systems' float path: no array
        values = (c, s2)
    else:
        values = to_float(np.array([c, s2], dtype=object))
    if values is not None and not values[1] > 0 and not values[0] > 0:
        return c * math.nan  # theta = pi (or NaN): no logarithm
    if values is not None and values[0] > 0 and values[1] < _SERIES_BELOW * values[0] ** 2:
        x2 = s2 / (c * c)
        return (1 - x2 / 3 + x2 * x2 / 5 - x2 * x2 * x2 / 7) / c
    r = xp.sqrt(s2)
    return xp.atan2(r, c) / r


def transport_on_sphere(a: tuple, b: tuple, x: tuple) -> tuple:
    """``R x`` for the minimal rotation R taking the unit vector a to b.

    Rodrigues' form without the normalised axis, ``R = c I + hat(v) + v v^T /
    (1 + c)`` with ``v = a x b``, ``c = a.b``: smooth at a = b (R = I) and
    defined for every a != -b. On S^2 it is the parallel transport along the
    great circle from a to b, and it maps ``T_a S^2`` onto ``T_b S^2``.
    """
    vx, vy, vz = a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]
    c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    k = (vx * x[0] + vy * x[1] + vz * x[2]) / (1 + c)
    return (
        c * x[0] + vy * x[2] - vz * x[1] + k * vx,
        c * x[1] + vz * x[0] - vx * x[2] + k * vy,
        c * x[2] + vx * x[1] - vy * x[0] + k * vz,
    )


def image_rate(y: tuple, ydot: tuple) -> tuple:
    """``(xi, lambda_dot, s_dot)`` of Eq. (12) from the 13-vector y and its time derivative.

    ``xi = (Qdot Q^T)^vee = 1/2 sum_k q_k x qdot_k`` (for ``qdot_k = xi x q_k``,
    ``q_k x (xi x q_k) = xi - (q_k.xi) q_k`` and the three terms add to 2 xi).
    """
    xi = [0, 0, 0]
    for k in range(3):
        qx, qy, qz = y[3 * k], y[3 * k + 1], y[3 * k + 2]
        dx, dy, dz = ydot[3 * k], ydot[3 * k + 1], ydot[3 * k + 2]
        xi[0] = xi[0] + 0.5 * (qy * dz - qz * dy)
        xi[1] = xi[1] + 0.5 * (qz * dx - qx * dz)
        xi[2] = xi[2] + 0.5 * (qx * dy - qy * dx)
    return (xi[0], xi[1], xi[2], ydot[9], ydot[10], ydot[11], ydot[12])


def image_error(y: tuple, y_d: tuple, xp: Ops) -> tuple:
    """``log_y(y_d)``: the 7-vector in ``T_y I`` (Eq. 12) pointing along the geodesic to y_d.

    * SO(3): ``E = Q_d Q^T = exp(hat(e_xi))``, so moving Q along ``xi = e_xi``
      for unit time reaches Q_d (Q moves as ``Qdot = hat(xi) Q``, Eq. 13).
      ``(E - E^T)^vee / 2 = 1/2 sum_k q_k x q_d,k = sin(theta) axis`` and
      ``tr E = sum_k q_k . q_d,k = 1 + 2 cos theta``.
    * lambda: ``lambda_d - lambda``.
    * S^2: ``(theta / sin theta) (s_d - (s.s_d) s)``, orthogonal to s, of length
      the angle theta between s and s_d.

    Its three parts have the lengths of the three geodesic distances. Defined
    while both angles are below pi.
    """
    wx = wy = wz = tr = 0
    for k in range(3):
        qx, qy, qz = y[3 * k], y[3 * k + 1], y[3 * k + 2]
        dx, dy, dz = y_d[3 * k], y_d[3 * k + 1], y_d[3 * k + 2]
        wx = wx + 0.5 * (qy * dz - qz * dy)
        wy = wy + 0.5 * (qz * dx - qx * dz)
        wz = wz + 0.5 * (qx * dy - qy * dx)
        tr = tr + qx * dx + qy * dy + qz * dz
    f = angle_over_sine(0.5 * (tr - 1), wx * wx + wy * wy + wz * wz, xp)
    sx, sy, sz = y[10], y[11], y[12]
    tx, ty, tz = y_d[10], y_d[11], y_d[12]
    c = sx * tx + sy * ty + sz * tz
    ux, uy, uz = sy * tz - sz * ty, sz * tx - sx * tz, sx * ty - sy * tx
    g = angle_over_sine(c, ux * ux + uy * uy + uz * uz, xp)
    return (
        f * wx,
        f * wy,
        f * wz,
        y_d[9] - y[9],
        g * (tx - c * sx),
        g * (ty - c * sy),
        g * (tz - c * sz),
    )


def tracking_rate(y: tuple, y_d: tuple, ydot_d: tuple, gain: object, xp: Ops) -> tuple:
    """The image velocity the path follower commands at y: ``ydot_d`` at y, plus feedback.

    ``(xi_d + k e_xi, lambda_dot_d + k e_lambda, P s_dot_d + k e_s)`` with
    ``e = log_y(y_d)`` (:func:`image_error`), ``(xi_d, lambda_dot_d, s_dot_d)``
    from the 13-vector ``ydot_d`` (:func:`image_rate`) and P the parallel
    transport from s_d to s (:func:`transport_on_sphere`): ``s_dot_d`` lies in
    ``T_{s_d} S^2``, the command must lie in ``T_s S^2`` (xi and lambda_dot
    need no transport: the right trivialisation of Eq. 13 is global).

    If the image moves exactly so (an exact model, Eq. 18), each geodesic
    error obeys ``d/dt theta = -k theta``: the transported feed-forward
    changes none of the three distances (a conjugation of E = Q_d Q^T keeps its
    angle; P keeps the component along the great circle's normal and turns
    the one along it), and the feedback shortens each along its geodesic.
    With ``k = 0`` and ``y = y_d`` this is ``ydot_d`` itself: Eq. (18) as
    written.
    """
    rate = image_rate(y_d, ydot_d)
    e = image_error(y, y_d, xp)
    s, s_d = (y[10], y[11], y[12]), (y_d[10], y_d[11], y_d[12])
    sdot = transport_on_sphere(s_d, s, rate[4:7])
    return (
        rate[0] + gain * e[0],
        rate[1] + gain * e[1],
        rate[2] + gain * e[2],
        rate[3] + gain * e[3],
        sdot[0] + gain * e[4],
        sdot[1] + gain * e[5],
        sdot[2] + gain * e[6],
    )


#: ``h(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5``, coefficients from tau^0 up: the
#: lowest-degree polynomial from 0 to 1 with zero velocity and zero acceleration
#: at both ends, so a path timed by it starts and stops at rest with no jump in
#: acceleration, which a plant with inertia can follow. Peak rate h'(1/2) = 15/8.
QUINTIC_TIME_LAW = (0.0, 0.0, 0.0, 10.0, -15.0, 6.0)


# ------------------------------------------------------------------ float batches
def image_distance(y: ImageFeatures, y_d: ImageFeatures) -> np.ndarray:
    """The three geodesic distances ``(angle(Q_d Q^T), |lambda_d - lambda|, angle(s, s_d))``.

    Float batches, shape (..., 3); each angle from ``atan2(|sin|, cos)``, accurate
    near 0 and near pi.
    """
    a, b = y.to_vector(), y_d.to_vector()
    w = 0.5 * sum(np.cross(a[..., 3 * k : 3 * k + 3], b[..., 3 * k : 3 * k + 3]) for k in range(3))
    tr = sum(np.sum(a[..., 3 * k : 3 * k + 3] * b[..., 3 * k : 3 * k + 3], -1) for k in range(3))
    rot = np.arctan2(np.linalg.norm(w, axis=-1), 0.5 * (tr - 1))
    s, t = a[..., 10:13], b[..., 10:13]
    ang = np.arctan2(np.linalg.norm(np.cross(s, t), axis=-1), np.sum(s * t, -1))
    return np.stack([rot, np.abs(b[..., 9] - a[..., 9]), ang], axis=-1)


def exp_image(y: ImageFeatures, v: np.ndarray) -> ImageFeatures:
    """The geodesic from y with initial velocity ``v = (xi, lambda_dot, s_dot)`` at time 1.

    ``(exp(hat(xi)) Q, lambda + lambda_dot, cos|u| s + sin|u| u/|u|)`` with u the
    part of s_dot orthogonal to s. Float batches, ``v`` of shape (..., 7).
    """
    v = np.asarray(v, dtype=float)
    Q = so3_exp(v[..., 0:3]) @ y.Q
    s = np.asarray(y.s, dtype=float)
    u = v[..., 4:7] - np.sum(v[..., 4:7] * s, -1, keepdims=True) * s
    n = np.linalg.norm(u, axis=-1, keepdims=True)
    sinc = np.where(n > 1e-8, np.sin(n) / np.where(n > 1e-8, n, 1.0), 1 - n * n / 6)
    s_new = np.cos(n) * s + sinc * u
    s_new = s_new / np.linalg.norm(s_new, axis=-1, keepdims=True)
    return ImageFeatures(Q, np.asarray(y.lam, dtype=float) + v[..., 3], s_new)
