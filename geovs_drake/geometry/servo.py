"""The two servo laws, in scalar style on named components (any number type).

* the dynamic law of Eq. (45), ``F = k_p C(y)^T dphi - B (Omega, V)``;
* the kinematic law of Eqs. (18)-(19), ``(Omega, V) = k Tc^-1 dphi``;
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

__all__ = ["kinematic_velocity", "servo_wrench", "tracking_wrench"]


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
