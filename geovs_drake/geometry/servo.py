"""The two servo laws, in scalar style on named components (any number type).

* the dynamic law of Eq. (45), ``F = k_p C(y)^T dphi - B (Omega, V)``;
* the kinematic law of Eqs. (18)-(19), ``(Omega, V) = k Tc^-1 dphi``.

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

__all__ = ["kinematic_velocity", "servo_wrench"]


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
