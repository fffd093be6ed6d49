"""The image between frames: a held frame moved by the camera's own motion (issue 31).

A camera gives y once per frame, late by its latency; the carrier's proprioception (the
arm's joint encoders, the free rig's body state) gives the camera's pose at the control
rate. For a still target the image now follows from the two:

* the held frame's y, taken at the capture time t_k, inverted to the relative pose
  ``X_CB(t_k) = c^-1(y)`` (Eq. 23);
* the target's pose in the world it implies, ``X_WB = X_WC(t_k) X_CB(t_k)``, with
  ``X_WC = X_WR X_RC`` from the carrier's pose at t_k;
* seen from the camera's pose now, ``X_CB(t) = X_WC(t)^-1 X_WB``, mapped back to an
  image, ``y(t) = c(X_CB(t))`` (Eqs. 3, 6, 7).

This is a Smith predictor in geometric form: it removes the hold and the latency
exactly when the target is still and the camera and its pose are exact (a test checks
``y(t)`` against the exact camera's), and otherwise carries the frame's own errors (its
noise, a wrong focal length or radius) forward unchanged. Scalar style on named
components (:mod:`geovs_drake.geometry.rigid`): any number type.
"""

from __future__ import annotations

from geovs_drake.geometry._ops import Ops
from geovs_drake.geometry.camera import image_of_pose, inverse_pose
from geovs_drake.geometry.rigid import apply, matmul, target_in_camera

__all__ = ["image_from_target", "predicted_image", "target_from_frame"]


def target_from_frame(
    y: tuple, rho: object, R_WR: tuple, p_WR: tuple, R_RC: tuple, p_RC: tuple, xp: Ops
) -> tuple[tuple, tuple]:
    """``(R_WB, p_WB)``: the target's pose in W that the frame ``y`` shows from the rig
    pose ``X_WR`` (the camera at ``X_RC`` on it), ``X_WB = X_WR X_RC c^-1(y)`` (Eq. 23)."""
    r1, r2, r3, d = inverse_pose(y, rho, xp)
    R_CB = (
        r1[0], r2[0], r3[0],
        r1[1], r2[1], r3[1],
        r1[2], r2[2], r3[2],
    )  # fmt: skip
    R_WC = matmul(R_WR, R_RC)
    p_WCo = apply(R_WR, p_RC)
    d_W = apply(R_WC, d)
    p_WB = tuple(p_WR[i] + p_WCo[i] + d_W[i] for i in range(3))
    return matmul(R_WC, R_CB), p_WB


def predicted_image(
    y: tuple,
    rho: object,
    R_WR_frame: tuple,
    p_WR_frame: tuple,
    R_WR_now: tuple,
    p_WR_now: tuple,
    R_RC: tuple,
    p_RC: tuple,
    xp: Ops,
) -> tuple:
    """The 13 components of ``y(t)``: the frame ``y`` taken from the rig pose
    ``X_WR_frame``, seen from ``X_WR_now`` (the module's three steps)."""
    R_WB, p_WB = target_from_frame(y, rho, R_WR_frame, p_WR_frame, R_RC, p_RC, xp)
    return image_from_target(R_WB, p_WB, rho, R_WR_now, p_WR_now, R_RC, p_RC, xp)


def image_from_target(
    R_WB: tuple,
    p_WB: tuple,
    rho: object,
    R_WR_now: tuple,
    p_WR_now: tuple,
    R_RC: tuple,
    p_RC: tuple,
    xp: Ops,
) -> tuple:
    """The 13 components of ``y(t)``: the target at ``X_WB`` seen from the rig pose
    ``X_WR_now``, ``c(X_WC^-1 X_WB)`` (Eqs. 3, 6, 7; the module's last step). A frame's
    ``X_WB`` (:func:`target_from_frame`) holds until the next frame, so a caller may keep
    it and call this alone at each evaluation: the same numbers as :func:`predicted_image`."""
    r2, r3, d = target_in_camera(R_WR_now, p_WR_now, R_RC, p_RC, R_WB, p_WB)
    return image_of_pose(r2, r3, d, rho, xp)
