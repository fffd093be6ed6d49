"""SO(3) helpers: hat, vee, the exponential and its inverse (theta u), scalar-generic;
and a rotation's quaternion, compiled.

Used by the tests, the Hessian and the chart of :mod:`geovs_drake.analysis`,
and by the position-based baselines' theta u (:mod:`geovs_drake.geometry.baselines`);
not on the NF servo's hot path. :func:`rotation_to_quaternion` (numba) is the one
Shepperd's method of the package: the arm's compiled kernels call it for a state, the
loop's initial states (:func:`rotations_to_quaternions`) for a batch of poses.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from geovs_drake.geometry._ops import namespace, to_float


def hat(w: np.ndarray) -> np.ndarray:
    """The skew matrix of ``w``: ``hat(w) @ x == cross(w, x)`` (paper, Sec. 3)."""
    w = np.asarray(w)
    if w.shape[-1:] != (3,):
        raise ValueError(f"hat expects a (..., 3) array, got shape {w.shape}")
    z = w[..., 0] * 0
    w1, w2, w3 = w[..., 0], w[..., 1], w[..., 2]
    rows = [
        np.stack([z, -w3, w2], axis=-1),
        np.stack([w3, z, -w1], axis=-1),
        np.stack([-w2, w1, z], axis=-1),
    ]
    return np.stack(rows, axis=-2)


def vee(W: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hat`, taking the skew part: ``vee(hat(w)) == w``."""
    W = np.asarray(W)
    if W.shape[-2:] != (3, 3):
        raise ValueError(f"vee expects a (..., 3, 3) array, got shape {W.shape}")
    return 0.5 * np.stack(
        [W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0], W[..., 1, 0] - W[..., 0, 1]],
        axis=-1,
    )


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation ``exp(hat(w))`` by Rodrigues' formula.

    ``I + a W + b W^2`` with ``a = sin t / t`` and ``b = (1 - cos t) / t^2``;
    small angles use the series, so the result is defined and accurate at 0.
    """
    w = np.asarray(w)
    if w.dtype != object:
        w = w.astype(float)
    W = hat(w)
    t2 = np.asarray(np.sum(w * w, axis=-1))
    if w.dtype != object:
        t = np.sqrt(t2)
        small = t < 1e-4
        ts = np.where(small, 1.0, t)
        a = np.where(small, 1 - t2 / 6 + t2 * t2 / 120, np.sin(ts) / ts)
        b = np.where(small, 0.5 - t2 / 24 + t2 * t2 / 720, (1 - np.cos(ts)) / ts**2)
    else:
        # Object arrays (AutoDiffXd, Expression). Where every angle's value is
        # below 1e-2 the series to t^6 is exact to 1e-19 and, unlike the closed
        # form, is defined at w = 0 (where AutoDiffXd tests seed a curve).
        # Symbolic input with free variables gets the closed form.
        values = to_float(t2)
        if values is not None and np.all(values < 1e-4):
            a = 1 - t2 / 6 + t2 * t2 / 120 - t2 * t2 * t2 / 5040
            b = 0.5 - t2 / 24 + t2 * t2 / 720 - t2 * t2 * t2 / 40320
        else:
            t = np.sqrt(t2)
            a = np.sin(t) / t
            b = (1 - np.cos(t)) / t2
    a, b = np.asarray(a)[..., None, None], np.asarray(b)[..., None, None]
    return np.eye(3) + a * W + b * (W @ W)


def so3_log(R: np.ndarray) -> np.ndarray:
    """``theta u`` of a rotation: ``so3_exp(so3_log(R)) == R``, theta in [0, pi].

    Floats and AutoDiffXd (one 3x3 matrix). Away from pi it is
    ``theta / (2 sin theta) vee(R - R^T)`` (the series near 0, where it is
    smooth); within 0.1 rad of pi, where that quotient loses its digits, the
    axis comes from the symmetric part ``(R + R^T)/2 - cos(theta) I = (1 - cos
    theta) u u^T``, its sign from ``vee(R - R^T)``. At exactly pi both signs are
    the same rotation; the one with ``u . vee(R - R^T) >= 0`` and, failing
    that, a positive largest component is returned.
    """
    R = np.asarray(R)
    if R.shape != (3, 3):
        raise ValueError(f"so3_log expects one 3x3 rotation, got shape {R.shape}")
    if R.dtype != object:
        R = R.astype(float)
    sv = vee(R)  # sin(theta) u
    c = (R[0, 0] + R[1, 1] + R[2, 2] - 1) / 2
    s2 = sv[0] * sv[0] + sv[1] * sv[1] + sv[2] * sv[2]
    xp = namespace(c)
    s = xp.sqrt(s2)
    theta = xp.atan2(s, c)
    t_value, s_value = float(to_float(theta)), float(to_float(s))
    if t_value < np.pi - 0.1:
        # theta / sin(theta), with its series where sin(theta) ~ theta ~ 0.
        factor = 1 + s2 / 6 + 3 * s2 * s2 / 40 if s_value < 1e-4 else theta / s
        return factor * sv
    B = (R + R.T) / 2 - c * np.eye(3)
    diag = to_float(np.array([B[0, 0], B[1, 1], B[2, 2]]))
    col = B[:, int(np.argmax(diag))]
    u = col / xp.sqrt(col[0] * col[0] + col[1] * col[1] + col[2] * col[2])
    dot = float(to_float(u[0] * sv[0] + u[1] * sv[1] + u[2] * sv[2]))
    if dot < 0 or (dot == 0 and float(to_float(u[np.argmax(np.abs(to_float(u)))])) < 0):
        u = -u
    return theta * u


@njit(cache=True, nogil=True, error_model="numpy")
def rotation_to_quaternion(R, out):
    """The unit quaternion [w, x, y, z] of R (3 x 3) into ``out``, w >= 0, by the branch
    on the largest of the trace and the diagonal (Shepperd's method, as Drake's
    ``RotationMatrix::ToQuaternion``)."""
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    if trace >= R[0, 0] and trace >= R[1, 1] and trace >= R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + trace)
        w, x, y, z = (
            0.25 * s,
            (R[2, 1] - R[1, 2]) / s,
            (R[0, 2] - R[2, 0]) / s,
            (R[1, 0] - R[0, 1]) / s,
        )
    elif R[0, 0] >= R[1, 1] and R[0, 0] >= R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        w, x, y, z = (
            (R[2, 1] - R[1, 2]) / s,
            0.25 * s,
            (R[0, 1] + R[1, 0]) / s,
            (R[0, 2] + R[2, 0]) / s,
        )
    elif R[1, 1] >= R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        w, x, y, z = (
            (R[0, 2] - R[2, 0]) / s,
            (R[0, 1] + R[1, 0]) / s,
            0.25 * s,
            (R[1, 2] + R[2, 1]) / s,
        )
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        w, x, y, z = (
            (R[1, 0] - R[0, 1]) / s,
            (R[0, 2] + R[2, 0]) / s,
            (R[1, 2] + R[2, 1]) / s,
            0.25 * s,
        )
    sign = -1.0 if w < 0.0 else 1.0
    norm = sign / math.sqrt(w * w + x * x + y * y + z * z)
    out[0], out[1], out[2], out[3] = w * norm, x * norm, y * norm, z * norm


@njit(cache=True, nogil=True, error_model="numpy")
def rotations_to_quaternions(R):
    """:func:`rotation_to_quaternion` of each rotation R (N, 3, 3): the quaternions (N, 4)."""
    out = np.empty((R.shape[0], 4))
    for i in range(R.shape[0]):
        rotation_to_quaternion(R[i], out[i])
    return out
