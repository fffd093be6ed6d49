"""The two servo laws, in scalar style on named components (any number type).

* the dynamic law of Eq. (45), ``F = k_p C(y)^T dphi - B (Omega, V)``;
* the kinematic law of Eqs. (18)-(19), ``(Omega, V) = k Tc^-1 dphi``;
* the path follower of Eq. (18), ``(Omega, V) = -Tc^-1 ydot_cmd`` with the
  commanded image velocity of :func:`~geovs_drake.geometry.image_path.tracking_rate`;
* the velocity-tracking wrench ``F = B (nu_cmd - nu)`` that runs any law which
  commands a body twist (the baselines, path following) on the dynamic plant.

The Drake systems run them through the generated kernels of
:mod:`geovs_drake.geometry.kernels`; this is their one source.
"""

from __future__ import annotations

from geovs_drake.geometry._ops import Ops
from geovs_drake.geometry.camera import (
    jacobian_inverse_times,
    jacobian_rows,
    jacobian_transpose_times,
)
from geovs_drake.geometry.image_path import tracking_rate

__all__ = ["kinematic_velocity", "path_following_velocity", "servo_wrench", "tracking_wrench"]


def servo_wrench(
    y: tuple,
    dphi: tuple,
    V_C: tuple,
    radius: object,
    potential_gain: object,
    damping: tuple,
    xp: Ops,
) -> tuple:
    """Eq. (45): ``F_C = k_p C(y)^T dphi - B (Omega, V)``, torque and force on the camera.

    Expressed in the camera frame C, about its origin Co: the pairing with
    the camera's body velocity ``(Omega, V)`` is the power. With
    ``(Omega, V) = -(omega, v)`` (Eq. 16),
    ``d/dt (k_p phi) = -(k_p C^T dphi) . (Omega, V)``, so the energy
    ``1/2 nu^T M nu + k_p phi`` decreases at the rate ``(Omega, V)^T B (Omega, V)``.
    ``damping`` is the diagonal of B (rotational first).
    """
    CT_dphi = jacobian_transpose_times(jacobian_rows(y, radius, xp), dphi)
    return tuple(potential_gain * f - b * v for f, b, v in zip(CT_dphi, damping, V_C, strict=True))


def kinematic_velocity(y: tuple, dphi: tuple, radius: object, gain: object, xp: Ops) -> tuple:
    """Eqs. (18)-(19) with ``ydot_d = -k grad phi``: ``(Omega, V) = k Tc^-1 dphi``.

    The sign: Eq. (18) has ``(Omega, V) = -Tc^-1 ydot_d`` because the camera's
    body velocity is minus the right-trivialised velocity of H (Eq. 16).
    Then ``ydot = C (omega, v) = -C (Omega, V) = -k grad phi``, exactly,
    since grad phi lies in the range of C.
    """
    return tuple(gain * u for u in jacobian_inverse_times(y, radius, dphi, xp))


def path_following_velocity(
    y: tuple, y_d: tuple, ydot_d: tuple, radius: object, gain: object, xp: Ops
) -> tuple:
    """Eq. (18): ``(Omega, V) = -Tc^-1 ydot_cmd``, following a planned image path y_d(t).

    ``ydot_d`` is the time derivative of the 13-vector y_d; ``ydot_cmd`` is
    :func:`~geovs_drake.geometry.image_path.tracking_rate` (``ydot_d`` carried
    to y, plus ``gain`` times the log-map error; ``gain = 0`` is Eq. 18 as
    written, open loop). The sign is that of :func:`kinematic_velocity`: the
    camera's body velocity is minus the right-trivialised velocity of H
    (Eq. 16), so on the kinematic plant ``ydot = -C (Omega, V) = ydot_cmd``
    exactly (ydot_cmd lies in the range of C: its s-part is orthogonal to s).
    ``radius`` is the controller's model of rho.
    """
    rate = tracking_rate(y, y_d, ydot_d, gain, xp)
    return tuple(-u for u in jacobian_inverse_times(y, radius, rate, xp))


def tracking_wrench(V_cmd: tuple, V_C: tuple, gains: tuple) -> tuple:
    """``F_C = B (nu_cmd - nu)``: the wrench on the camera that tracks a commanded twist.

    ``nu = (Omega, V)`` is the camera's body velocity in C (Eq. 16's sign) and
    ``gains`` the diagonal of B (rotational first) [N m s, N s/m]. On a free
    body of mass m it is a first-order lag ``m nudot = B (nu_cmd - nu)`` per
    axis (exactly so when C sits at the centre of mass, up to the gyroscopic
    term otherwise), with time constants m / B_i. It is the one actuation
    every twist-commanding law shares on the dynamic plant, so that a
    comparison between laws is a comparison of the laws.
    """
    return tuple(b * (c - v) for b, c, v in zip(gains, V_cmd, V_C, strict=True))
