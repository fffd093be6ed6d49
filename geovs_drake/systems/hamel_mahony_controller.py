"""HamelMahonyController: Hamel & Mahony's image-based law for an underactuated body.

T. Hamel and R. Mahony, "Visual servoing of an under-actuated dynamic rigid-body system:
an image-based approach", IEEE Trans. Robotics and Automation 18(2), 2002: the anchor's
law for a quadrotor. Their image feature is the centroid of the target's image on the
unit sphere, ``q = sum_i p_i`` over unit directions p_i (Sec. III), whose kinematics
``qdot = -Omega x q - Q V`` have ``Q = sum_i pi_{p_i} / |P_i|`` positive definite
(``pi_p = I - p p^T``): the depths sit in Q only, and Q > 0 is all the law needs. Expressed
in the inertial frame (the attitude measured), ``qdot_W = -Q_W v``: the rotation drops out,
and ``delta_1 = q_W - q*_W`` with the storage ``1/2 |delta_1|^2`` is passive from v.

**The feature of this target.** The sphere of radius rho whose centre lies at distance d
along the unit direction s images as a cap of half-angle theta, sin theta = rho / d =
lambda (y's own lambda). The centroid of the cap's points, uniformly spread over it (the
continuum of Hamel & Mahony's sum, as a mean), is ``s (1 + cos theta) / 2``: the mean of
p . s over the cap is ``int_0^theta cos phi sin phi dphi / int_0^theta sin phi dphi =
(1 + cos theta) / 2``, the transverse parts cancel by symmetry. So ``q = s f`` with
``f = (1 + sqrt(1 - lambda^2)) / 2``, from the image alone (no depth, no radius); f grows
with d, so Q = f' s s^T + (f / d) pi_s is positive definite, as their sum's is.

**The law** (their backstepping, Sec. IV, in this package's world frame, z up):

1. ``delta_1 = q_W - q*_W``; the wanted velocity ``v = (k_1 / m) W delta_1``
   (``image_gain`` k_1 [N s]); W is a constant positive-definite metric on the image
   error (below), ``W = I`` in the paper.
2. ``delta_2 = m v / k_1 - W delta_1``; the thrust vector, the virtual input, is
   ``F = -k_1 k_2 delta_2 = k_1 k_2 W delta_1 - m k_2 v`` (``velocity_gain`` k_2 [1/s]),
   plus the weight. With ``S = 1/2 delta_1^T W delta_1 + 1/2 delta_2^T W^-1 delta_2``
   the cross terms in Q cancel (Q symmetric: the passivity-like structure), and
   ``Sdot = -(k_1/m) |W delta_1|_Q^2 - delta_2^T (k_2 W^-1 - (k_1/m) Q) delta_2``:
   negative where ``k_2 W^-1 > (k_1/m) Q``, their gain condition, here (at the goal,
   where W and Q share axes) ``k_2 > (k_1/m) f/d``: 1.0 1/s against k_2 = 4 by default.
3. The attitude and the torques: **simplified**. Hamel & Mahony carry the backstepping
   on through the thrust direction (delta_3) to the torque (delta_4); here the thrust
   vector F + m g e_z goes to the same Lee geometric attitude loop as the NF's cascade
   (:func:`~geovs_drake.systems.attitude_cascade.lee_wrench`, 60 rad/s against the law's
   2 rad/s), with its tilt limit, and to the same rotor allocation
   (:func:`~geovs_drake.systems.attitude_cascade.allocate`).
4. The heading (yaw), separately, as they do: the target's attitude in the world as the
   image shows it (the marked point and the arrow, Eq. 23's rotation, depth-free) turned
   back by the goal image's gives the attitude the body has at the goal; its heading is
   the one Lee's loop holds, and q*_W is the goal's centroid in that level frame.

**Why W.** The centroid is nearly blind to depth: ``f' d / f = lambda^2 / ((1 + cos
theta) cos theta)``, 1/48.5 at the default goal (lambda = 0.2), so with W = I the depth
converges 48.5 times slower than the lateral motion (time constant about 50 s: no run of
30 s converges to 1 mm). ``W = I + (w - 1) c c^T`` along the goal's direction c, ``w = 1
+ depth_balance ((1 + cos theta*) cos theta* / lambda*^2 - 1)`` from the goal image:
``depth_balance`` 1 makes depth as stiff as the lateral motion at the goal, 0 is the
paper's law. Being constant and positive definite, W keeps the Lyapunov function above.

Measured, not proved: v is the body's velocity (Hamel & Mahony assume V measured), taken
at the camera (v + omega x R p_RC); the attitude and the rate are the IMU's.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem_

from geovs_drake.geometry._ops import namespace
from geovs_drake.geometry.camera import inverse_pose
from geovs_drake.geometry.rigid import quaternion_to_rotation
from geovs_drake.systems._parameters import STATE_SIZE, image_usable
from geovs_drake.systems._template import template_system
from geovs_drake.systems.attitude_cascade import _DEFAULT_MIXER, allocate, lee_wrench

__all__ = [
    "HamelMahonyController",
    "HamelMahonyController_",
    "depth_weight",
    "spherical_centroid",
    "target_rotation",
]

_UP = np.array([0.0, 0.0, 1.0])


def spherical_centroid(y: np.ndarray) -> np.ndarray:
    """Hamel & Mahony's centroid of the sphere's image in C, ``s (1 + cos theta) / 2``
    with sin theta = lambda (the module's derivation): the mean unit direction over the
    cap the sphere covers on the image sphere."""
    lam, s = y[9], np.asarray(y[10:13])
    return s * (0.5 * (1.0 + (1.0 - lam * lam) ** 0.5))


def depth_weight(lam_goal: float, depth_balance: float) -> float:
    """w of the image metric W along the goal's direction: 1 + depth_balance ((1 + cos
    theta*) cos theta* / lambda*^2 - 1), the ratio (f/d) / f' of the centroid's lateral
    to its depth sensitivity at the goal (``lam_goal`` = sin theta*)."""
    c = math.sqrt(1.0 - lam_goal * lam_goal)
    return 1.0 + depth_balance * ((1.0 + c) * c / (lam_goal * lam_goal) - 1.0)


def target_rotation(y: np.ndarray) -> np.ndarray:
    """R_CB (3 x 3) from the image alone: the marked point and the arrow, Eq. (23)'s
    rotation (:func:`~geovs_drake.geometry.camera.inverse_pose`, whose rotation needs
    neither depth nor radius)."""
    r1, r2, r3, _ = inverse_pose(tuple(y), 1.0, namespace(y[0]))
    return np.column_stack([r1, r2, r3])


def _level_frame(heading: np.ndarray) -> np.ndarray:
    """The level rotation whose x axis is ``heading``'s horizontal part."""
    h = np.array([heading[0], heading[1], 0.0 * heading[0]])
    h = h / (h @ h) ** 0.5
    return np.column_stack([h, np.cross(_UP, h), _UP])


@template_system("HamelMahonyController_")
def HamelMahonyController_(T):
    class Impl(LeafSystem_[T]):
        """Hamel & Mahony's law: rotor thrusts from the sphere's spherical centroid.

        .. pydrake_system::

            name: HamelMahonyController
            input_ports:
            - image_features
            - body_state
            output_ports:
            - rotor_thrusts
            - saturated

        ``image_features`` is y of the camera on the level body
        (:class:`~geovs_drake.systems.LevelView`, whose frame C' is R_WC' = Rz(psi)
        R_RC; any frame would do, since the law reads y in W); ``body_state`` the
        quadrotor's 13-vector free-body state (its attitude, rate and velocity, the
        IMU's and the velocity Hamel & Mahony assume measured). ``rotor_thrusts`` (4)
        [N] and ``saturated`` as :class:`~geovs_drake.systems.AttitudeCascade`'s: the
        same attitude loop and allocation (module docstring, steps 3 and 4), from the
        thrust vector ``k_1 k_2 W (q_W - q*_W) - m k_2 v_C + m g e_z``. An image outside
        I gives NaN thrusts (the run's monitor stops it).

        Constructor numbers: ``goal`` y* (13), ``X_RC`` the camera on the body, the body
        (``mass`` [kg], ``inertia_diagonal`` [kg m^2], ``gravity`` [m/s^2],
        ``mixer_matrix``, ``max_thrust`` [N] per rotor), the attitude loop
        (``attitude_gains`` (k_R [1/s^2], k_Omega [1/s]), ``max_tilt`` [rad]) and the
        law's gains (``image_gain`` k_1 [N s], ``velocity_gain`` k_2 [1/s],
        ``depth_balance``).
        """

        def _construct(
            self,
            goal: np.ndarray,
            X_RC: RigidTransform | None = None,
            mass: float = 0.775,
            inertia_diagonal: tuple[float, float, float] = (0.0015, 0.0025, 0.0035),
            gravity: float = 9.81,
            attitude_gains: tuple[float, float] = (3600.0, 108.0),
            mixer_matrix: np.ndarray | None = None,
            max_thrust: float = 4.75,
            max_tilt: float = math.radians(10.0),
            image_gain: float = 0.4,
            velocity_gain: float = 4.0,
            depth_balance: float = 1.0,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            X_RC = RigidTransform() if X_RC is None else X_RC
            goal = np.asarray(goal, dtype=float)
            M = _DEFAULT_MIXER if mixer_matrix is None else np.asarray(mixer_matrix, dtype=float)
            for name, value in (
                ("image_gain", image_gain),
                ("velocity_gain", velocity_gain),
                ("max_thrust", max_thrust),
            ):
                if not (math.isfinite(value) and value > 0):
                    raise ValueError(f"{name} must be finite and > 0, got {value}")
            self._defaults = (
                goal,
                X_RC,
                mass,
                tuple(inertia_diagonal),
                gravity,
                tuple(attitude_gains),
                M,
                max_thrust,
                max_tilt,
                image_gain,
                velocity_gain,
                depth_balance,
            )
            self._R_RC = X_RC.rotation().matrix()
            self._p_RC = X_RC.translation()
            self._mass, self._weight = mass, mass * gravity
            self._J = np.asarray(inertia_diagonal, dtype=float)
            self._gains = tuple(float(k) for k in attitude_gains)
            self._M_inv = np.linalg.inv(M)
            self._max_thrust = float(max_thrust)
            self._tan_tilt = math.tan(max_tilt)
            self._k1, self._k2 = float(image_gain), float(velocity_gain)
            # What the goal image fixes: its centroid in C*, the target's rotation seen
            # from C* (to turn the target's seen attitude back to the goal's), and w.
            self._q_goal_C = spherical_centroid(goal)
            self._R_CB_goal = target_rotation(goal)
            self._w = depth_weight(float(goal[9]), depth_balance)
            self.image_features_input = self.DeclareVectorInputPort(name="image_features", size=13)
            self.body_state_input = self.DeclareVectorInputPort(name="body_state", size=STATE_SIZE)
            prerequisites = {self.all_input_ports_ticket()}
            self.rotor_thrusts_output = self.DeclareVectorOutputPort(
                name="rotor_thrusts",
                size=4,
                calc=self.CalcRotorThrusts,
                prerequisites_of_calc=prerequisites,
            )
            self.saturated_output = self.DeclareVectorOutputPort(
                name="saturated",
                size=1,
                calc=self.CalcSaturated,
                prerequisites_of_calc=prerequisites,
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def thrust_vector(self, x: np.ndarray, y: np.ndarray) -> tuple:
            """The thrust vector F + m g e_z [N] in W (step 2) and the heading (step 4)."""
            R = np.reshape(quaternion_to_rotation(tuple(x[0:4]), namespace(x[0])), (3, 3))
            R_WC = _level_frame(R[:, 0]) @ self._R_RC  # the level camera C' of y
            # Step 4: the body's attitude at the goal, as the image shows the target now.
            R_WR_goal = R_WC @ target_rotation(y) @ self._R_CB_goal.T @ self._R_RC.T
            R_level_goal = _level_frame(R_WR_goal[:, 0])
            q_goal = R_level_goal @ self._R_RC @ self._q_goal_C
            delta_1 = R_WC @ spherical_centroid(y) - q_goal
            c = q_goal / (q_goal @ q_goal) ** 0.5
            W_delta_1 = delta_1 + (self._w - 1.0) * (c @ delta_1) * c
            v_C = x[10:13] + np.cross(x[7:10], R @ self._p_RC)  # the camera's velocity
            F = self._k1 * self._k2 * W_delta_1 - self._mass * self._k2 * v_C
            return F + self._weight * _UP, R_level_goal[:, 0]

        def wanted_wrench(self, context) -> list | None:
            """(T, tau_x, tau_y, tau_z) before the allocation; None outside I."""
            y = self.image_features_input.Eval(context)
            if not image_usable(y):
                return None
            x = self.body_state_input.Eval(context)
            f_d, heading = self.thrust_vector(x, y)
            return lee_wrench(x, f_d, heading, self._J, self._gains, self._tan_tilt, self._weight)

        def CalcRotorThrusts(self, context, output) -> None:
            wrench = self.wanted_wrench(context)
            if wrench is None:
                output.SetFromVector([math.nan] * 4)
                return
            u, _ = allocate(wrench, self._M_inv, self._max_thrust)
            output.SetFromVector(u)

        def CalcSaturated(self, context, output) -> None:
            wrench = self.wanted_wrench(context)
            saturated = wrench is not None and allocate(wrench, self._M_inv, self._max_thrust)[1]
            output.SetFromVector([1.0 if saturated else 0.0])

    return Impl


HamelMahonyController = HamelMahonyController_[None]
