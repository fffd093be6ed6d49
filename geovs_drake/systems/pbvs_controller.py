"""PbvsController: position-based servoing on c^-1(y), straight line in Cartesian space."""

from __future__ import annotations

from geovs_drake.geometry.baselines import pbvs_velocity
from geovs_drake.systems._goal_image_law import goal_image_law_class
from geovs_drake.systems._template import template_system

__all__ = ["PbvsController", "PbvsController_"]

_DOC = """Position-based visual servoing with the pose from the paper's inverse map.

.. pydrake_system::

    name: PbvsController
    input_ports:
    - image_features
    output_ports:
    - camera_velocity

The current and desired poses are ``c^-1(y)`` and ``c^-1(y*)`` (Eq. 23),
so ``s = (c*t_c, theta u)``: the camera's origin in the desired camera
frame and the angle-axis of ``c*R_c``. The law is Chaumette &
Hutchinson's (*Visual servo control I*, 2006, Sec. IV) variant whose
camera origin moves on a straight line: ``v = -lambda c*R_c^T c*t_c``,
``omega = -lambda theta u``
(:func:`~geovs_drake.geometry.baselines.pbvs_velocity`), output as
``(Omega, V)`` in C (Eq. 16's sign).

An image outside I gives NaN. One numeric parameter vector ``[y* (13),
rho, lambda]``: the goal image, the radius [m], the gain [1/s].

Behind a moving target its tracking term (Chaumette & Hutchinson 2007, Part II:
``-L_e^-1 de/dt``) is the target's twist carried to C, ``Ad_{X_CB} xi``: the law
inverts its features' interaction matrix exactly (``L_theta_u^-1 theta u = theta u``),
so the loop's adapter, which adds ``Ad_{X_CB} xi_hat`` to every law's twist
(:mod:`geovs_drake.loop.targets`), gives PBVS its whole feed-forward; it has no input
of its own for it.
"""


@template_system("PbvsController_")
def PbvsController_(T):
    return goal_image_law_class(T, pbvs_velocity, _DOC)


PbvsController = PbvsController_[None]
