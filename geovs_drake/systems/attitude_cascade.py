"""AttitudeCascade: the NF's force on a quadrotor, through a thrust and an attitude.

A quadrotor has one thrust along its body's z axis and three torques; the NF's dynamic
law (Eq. 45) gives a wrench for a fully actuated body. The cascade keeps the wrench's
force, adds the weight, and asks the body to point its thrust along the sum; Lee, Leok &
McClamroch's geometric controller on SO(3) ("Geometric tracking control of a quadrotor
UAV on SE(3)", CDC 2010) turns it there, and the rotor allocation (the 4 x 4 mixer)
shares thrust and torques among the rotors within their limits.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import LeafSystem_

from geovs_drake.systems._parameters import STATE_SIZE
from geovs_drake.systems._quadrotor_kernels import (
    CASCADE_HEADINGS,
    allocation,
    attitude_wrench,
    cascade,
    for_scalar_type,
)
from geovs_drake.systems._template import template_system

__all__ = ["AttitudeCascade", "AttitudeCascade_", "allocate", "lee_wrench", "mixer"]


def mixer(positions: np.ndarray, moment_ratios: np.ndarray) -> np.ndarray:
    """The 4 x 4 matrix M with ``(T, tau_x, tau_y, tau_z) = M u`` for rotor thrusts u
    [N] along the body's z at ``positions`` (4, 3) [m] in the body frame, each with a
    drag moment ``moment_ratios[i] u_i`` about z (Drake's ``PropellerInfo``): the
    thrust's sum, the moments r_i x (0, 0, u_i) about the centre of mass, and the drag."""
    positions = np.asarray(positions, dtype=float)
    M = np.empty((4, len(positions)))
    M[0] = 1.0
    M[1] = positions[:, 1]  # (r x e_z)_x = r_y
    M[2] = -positions[:, 0]  # (r x e_z)_y = -r_x
    M[3] = np.asarray(moment_ratios, dtype=float)
    return M


def allocate(wrench: list, M_inv: np.ndarray, max_thrust: float) -> tuple[list, bool]:
    """Rotor thrusts for a wanted ``wrench`` = (T, tau_x, tau_y, tau_z) [N, N m], each
    within [0, ``max_thrust``], giving up authority in a fixed order: the thrust is
    clamped to [0, 4 max_thrust]; then the roll and pitch torques are scaled down
    together until the rotors fit; then the yaw torque (the weakest axis, through the
    rotors' drag, and the one the servo needs least to stay in the air). Returns the
    thrusts and whether anything was given up (saturated). The cascade's kernel runs the
    same function (:mod:`geovs_drake.systems._quadrotor_kernels`)."""
    T, tau_x, tau_y, tau_z = wrench
    *u, saturated = allocation(T, tau_x, tau_y, tau_z, tuple(np.ravel(M_inv)), max_thrust)
    return u, bool(saturated > 0)


def lee_wrench(
    x: np.ndarray,
    f_d: np.ndarray,
    heading: np.ndarray,
    inertia: np.ndarray,
    gains: tuple[float, float],
    tan_tilt: float,
    weight: float,
) -> list:
    """(T, tau_x, tau_y, tau_z) before the allocation, for a body in the free-body state
    ``x`` (13) that should push along the thrust vector ``f_d`` [N] (in W, the weight
    included): ``f_d`` tilt-limited (``tan_tilt``, the ``weight`` m g [N]), R_d with z_d
    along it and x_d in the plane of ``heading`` and z_d, and Lee, Leok & McClamroch's
    torque with ``gains`` = (k_R, k_Omega) per unit of ``inertia`` (the principal diagonal
    [kg m^2]); the thrust is ``f_d . z_B``. The cascade's own kernel
    (:mod:`geovs_drake.systems._quadrotor_kernels`, ``attitude_wrench``), for the laws that
    drive the rotors themselves (Hamel & Mahony's)."""
    p = (weight, *inertia, *gains, 0.0, 0.0, 0.0, 0.0, 0.0, tan_tilt)
    h0, h1, h2 = heading[0], heading[1], heading[2]
    return list(attitude_wrench(x, f_d[0], f_d[1], f_d[2], h0, h1, h2, p, 0.0, 0.0, 0.0, 0.0))


_ARM, _MOMENT_RATIO = 0.15, 0.0245
_DEFAULT_MIXER = mixer(
    [[_ARM, 0, 0], [0, _ARM, 0], [-_ARM, 0, 0], [0, -_ARM, 0]],
    [_MOMENT_RATIO, -_MOMENT_RATIO, _MOMENT_RATIO, -_MOMENT_RATIO],
)


@template_system("AttitudeCascade_")
def AttitudeCascade_(T):
    class Impl(LeafSystem_[T]):
        """A quadrotor's rotor thrusts from the NF's wrench (the attitude cascade).

        .. pydrake_system::

            name: AttitudeCascade
            input_ports:
            - generalized_force
            - body_state
            - feedforward_twist
            - feedforward_acceleration
            output_ports:
            - rotor_thrusts
            - saturated

        ``generalized_force`` is the NF's wrench in the plant's convention,
        ``[tau_Ro_W, f_W]`` (:class:`ImageJacobianForce`); its force f_W plus the
        weight m g and the cascade's own damping of the body's velocity gives the wanted
        thrust vector ``f_d = f_W - b v_W + m g e_z`` (b = ``velocity_damping`` [N s/m]:
        the thrust's direction lags the NF's force by the attitude loop, and the NF's
        own B on the translation alone leaves the lateral mode unstable at hover), its
        tilt limited to ``max_tilt`` [rad] (and its upward part to at least a tenth of
        the weight). ``body_state``
        is the quadrotor's 13-vector free-body state. The thrust is ``f_d . z_B``; the
        wanted attitude R_d has its z axis along f_d and its x axis in the plane of
        ``heading_W`` (the goal's body x axis, level) and z_d; the torque is Lee, Leok &
        McClamroch's, ``J (-k_R e_R - k_Omega Omega) + Omega x J Omega`` with ``e_R =
        1/2 vee(R_d^T R - R^T R_d)``, per unit of inertia, the wanted rate taken as zero
        (f_d moves at the NF's pace against the attitude's 60 rad/s).
        ``rotor_thrusts`` (4) [N] are the allocation's (:func:`allocate`: the mixer's
        inverse, then saturation to [0, max_thrust], yaw given up first);
        ``saturated`` is 1 where the allocation gave anything up, else 0. With ``heading``
        ``goal`` the NF's torque is not used: three torques go to the attitude, and the
        heading is the goal's. With ``nf`` the yaw is the NF's: x_d lies in the plane of
        z_d and the body's own x axis (Lee's loop turns z_B only), and the torque about
        z_B is the NF's torque's component about z_B (``generalized_force``'s tau_Ro_W,
        about the level view's body origin: the centre of mass with the body level, off
        it by the tilt times the length of p_RC, 1 cm at 10 deg, forward mount) plus the
        gyroscopic term ``(Omega x J Omega)_z`` that Lee's law cancels: the yaw obeys
        ``J_z dOmega_z/dt = z_B . tau_NF``, the paper's free body (Eq. 45's wrench
        applied) about the one axis the rotors actuate fully.

        Behind a moving target (translating: the goal's heading is held) the thrust
        vector follows the target's motion as the loop believes it, as the free rig's
        law's feed-forward does (:class:`~geovs_drake.systems.TargetRelativeWrench`):
        ``f_d = f_W - b (v_W - v_ff) + m a_ff + m g e_z``. ``feedforward_twist`` is the
        believed target twist carried to the body R, ``Ad_{X_RB} xi_hat`` (6, in R, as
        :class:`~geovs_drake.systems.TargetFrame` gives it): v_ff = R_WR times its
        linear part, the velocity the body needs to move with the target (the cascade's
        damping acts on the velocity relative to it). ``feedforward_acceleration`` is
        the believed twist's rate in the target's frame B (6): a_ff = R_WB times its
        linear part (the target's ``target_rotation`` R_WB held), the acceleration the
        thrust adds so that the body keeps pace (Newton's law, m a_ff). Either input
        left unconnected (a still target) reads zero. Both enter the kernel as a force
        added to the NF's, ``b v_ff + m a_ff``.

        The numbers are constructor arguments (the body's mass model, the gains, the
        mixer, the target's rotation), fixed for the loop's life.
        """

        def _construct(
            self,
            mass: float = 0.775,
            inertia_diagonal: tuple[float, float, float] = (0.0015, 0.0025, 0.0035),
            gravity: float = 9.81,
            attitude_gains: tuple[float, float] = (3600.0, 108.0),
            heading_W: tuple[float, float, float] = (1.0, 0.0, 0.0),
            mixer_matrix: np.ndarray | None = None,
            max_thrust: float = 4.75,
            velocity_damping: float = 4.0,
            max_tilt: float = math.radians(10.0),
            target_rotation: np.ndarray | None = None,
            heading: str = "goal",
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            # The default: Drake's quadrotor example's rotors, a + of arm 0.15 m with
            # moment ratios +-0.0245 m (the Quadrotor carrier's defaults).
            M = _DEFAULT_MIXER if mixer_matrix is None else np.asarray(mixer_matrix, dtype=float)
            if M.shape != (4, 4) or abs(np.linalg.det(M)) < 1e-12:
                raise ValueError(f"the mixer must be an invertible 4 x 4 matrix, got {M}")
            heading_vector = np.asarray(heading_W, dtype=float)
            if heading not in CASCADE_HEADINGS:
                raise ValueError(
                    f"heading must be one of {', '.join(CASCADE_HEADINGS)}, got {heading!r}"
                )
            if not (math.isfinite(max_thrust) and max_thrust > 0):
                raise ValueError(f"max_thrust must be finite and > 0 [N], got {max_thrust}")
            self._defaults = (
                mass,
                tuple(inertia_diagonal),
                gravity,
                tuple(attitude_gains),
                tuple(heading_vector),
                M,
                max_thrust,
                velocity_damping,
                max_tilt,
                target_rotation,
                heading,
            )
            # The feed-forward's numbers (a moving target's): b, m and R_WB of a
            # translating target, the believed acceleration's frame.
            self._damping, self._mass = float(velocity_damping), float(mass)
            self._R_WT = np.eye(3) if target_rotation is None else np.asarray(target_rotation)
            # The kernel's parameters (_quadrotor_kernels: the cascade's vector), floats for
            # the compiled path and a tuple of Python floats for AutoDiffXd's.
            p = np.array(
                [
                    mass * gravity,
                    *inertia_diagonal,
                    *(float(k) for k in attitude_gains),
                    *heading_vector,
                    max_thrust,
                    velocity_damping,
                    math.tan(max_tilt),
                    *np.linalg.inv(M).ravel(),
                    CASCADE_HEADINGS[heading],
                ],
                dtype=float,
            )
            self._p = p if T is float else tuple(p.tolist())
            self._cascade = for_scalar_type(cascade, T)
            self.generalized_force_input = self.DeclareVectorInputPort(
                name="generalized_force", size=6
            )
            self.body_state_input = self.DeclareVectorInputPort(name="body_state", size=STATE_SIZE)
            self.feedforward_twist_input = self.DeclareVectorInputPort(
                name="feedforward_twist", size=6
            )
            self.feedforward_acceleration_input = self.DeclareVectorInputPort(
                name="feedforward_acceleration", size=6
            )
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

        def _kernel(self, context) -> tuple:
            """The kernel's ``(u (4), saturated, T, tau (3))`` at this context."""
            x = self.body_state_input.Eval(context)
            wrench = self.generalized_force_input.Eval(context)
            feedforward = self._feedforward(context, x)
            if feedforward is not None:  # a moving target's, added to the force f_W
                wrench = np.concatenate([wrench[0:3], wrench[3:6] + feedforward])
            return self._cascade(x, wrench, self._p)

        def _feedforward(self, context, x: np.ndarray) -> np.ndarray | None:
            """``b v_ff + m a_ff`` (3, in W) of a moving target's believed motion (the
            class docstring): f_d's feed-forward, added to the NF's force; None where
            neither input is connected (a still target: the kernel's path as it was)."""
            twist, rate = self.feedforward_twist_input, self.feedforward_acceleration_input
            out = None
            if rate.HasValue(context):
                out = self._mass * (self._R_WT @ rate.Eval(context)[3:6])
            if not twist.HasValue(context):
                return out
            w, a, b, c = x[0:4] / (x[0:4] @ x[0:4]) ** 0.5
            # R_WR of the body's quaternion: v_ff = R_WR (Ad_{X_RB} xi_hat)'s linear part.
            R = np.array(
                [
                    [1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b)],
                    [2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a)],
                    [2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b)],
                ]
            )
            velocity = self._damping * (R @ twist.Eval(context)[3:6])
            return velocity if out is None else out + velocity

        def wanted_wrench(self, context) -> list:
            """(T, tau_x, tau_y, tau_z) before the allocation: the thrust along z_B and
            the torque in the body frame."""
            return list(self._kernel(context)[5:9])

        def CalcRotorThrusts(self, context, output) -> None:
            output.SetFromVector(self._kernel(context)[0:4])

        def CalcSaturated(self, context, output) -> None:
            output.SetFromVector(self._kernel(context)[4:5])

    return Impl


AttitudeCascade = AttitudeCascade_[None]
