"""SphericalFeatureController: decoupled sphere features (p = s / lambda, theta u)."""

from __future__ import annotations

from geovs_drake.geometry.baselines import spherical_velocity
from geovs_drake.systems._goal_image_law import goal_image_law_class
from geovs_drake.systems._template import template_system

__all__ = ["SphericalFeatureController", "SphericalFeatureController_"]

_DOC = """Visual servoing on decoupled features of the marked sphere.

.. pydrake_system::

    name: SphericalFeatureController
    input_ports:
    - image_features
    output_ports:
    - camera_velocity

After Tatsambon Fomena & Chaumette, *Improvements on visual servoing
from spherical targets using a spherical projection model* (IEEE
T-RO 25(4), 2009): ``s = (p, theta u)`` with ``p = s / lambda``, the
sphere's centre over its radius read from the image (their feature
for a sphere, with interaction ``[-(1 / rho) I, [p]x]``), and theta u
of the target's rotation ``c*R_c`` from ``c^-1(y)``, ``c^-1(y*)``
(Eq. 23). The rotational part is our derivation for the arrow, not a
transcription of the paper's (whose text we could not retrieve); see
:mod:`geovs_drake.geometry.baselines`. The interaction matrix is block
triangular, and ``(v, omega) = -lambda L^-1 (p - p*, theta u)`` is, in
closed form, ``omega = -lambda theta u``, ``v = rho (lambda (p - p*) +
p x omega)`` (:func:`~geovs_drake.geometry.baselines.spherical_velocity`):
the centre moves on a straight line in the camera frame. Output as
``(Omega, V)`` in C (Eq. 16's sign).

An image outside I gives NaN. One numeric parameter vector ``[y* (13),
rho, lambda]``: the goal image, the radius [m], the gain [1/s].
"""


@template_system("SphericalFeatureController_")
def SphericalFeatureController_(T):
    return goal_image_law_class(T, spherical_velocity, _DOC)


SphericalFeatureController = SphericalFeatureController_[None]
