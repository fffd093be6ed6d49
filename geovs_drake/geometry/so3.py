"""SO(3) helpers: hat, vee and the exponential, scalar-generic and batched.

Used by the tests, the Hessian and the chart of :mod:`geovs_drake.analysis`,
not on the servo's hot path.
"""

from __future__ import annotations

import numpy as np

from geovs_drake.geometry._ops import to_float


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
