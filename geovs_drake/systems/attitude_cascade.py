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
from geovs_drake.systems._template import template_system

__all__ = ["AttitudeCascade", "AttitudeCascade_", "allocate", "mixer"]

#: The world's up, along which the weight is compensated.
_UP = np.array([0.0, 0.0, 1.0])


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


def _largest_step(u0: list, du: list, high: float) -> object:
    """The largest s in [0, 1] with ``u0 + s du`` within [0, high], for u0 within it."""
    s = 1.0
    for a, d in zip(u0, du, strict=True):
        if d > 0 and a + d > high:
            candidate = (high - a) / d
        elif d < 0 and a + d < 0:
            candidate = -a / d
        else:
            continue
        if candidate < s:
            s = candidate
    return s


def allocate(wrench: list, M_inv: np.ndarray, max_thrust: float) -> tuple[list, bool]:
    """Rotor thrusts for a wanted ``wrench`` = (T, tau_x, tau_y, tau_z) [N, N m], each
    within [0, ``max_thrust``], giving up authority in a fixed order: the thrust is
    clamped to [0, 4 max_thrust]; then the roll and pitch torques are scaled down
    together until the rotors fit; then the yaw torque (the weakest axis, through the
    rotors' drag, and the one the servo needs least to stay in the air). Returns the
    thrusts and whether anything was given up (saturated)."""
    T, tau_x, tau_y, tau_z = wrench
    saturated = False
    if T < 0:
        T, saturated = 0.0 * T, True
    elif T > 4 * max_thrust:
        T, saturated = 0.0 * T + 4 * max_thrust, True
    base = [M_inv[i, 0] * T for i in range(4)]
    tilt = [M_inv[i, 1] * tau_x + M_inv[i, 2] * tau_y for i in range(4)]
    r = _largest_step(base, tilt, max_thrust)
    u1 = [b + r * d for b, d in zip(base, tilt, strict=True)]
    yaw = [M_inv[i, 3] * tau_z for i in range(4)]
    s = _largest_step(u1, yaw, max_thrust)
    saturated = saturated or r < 1.0 or s < 1.0
    return [a + s * d for a, d in zip(u1, yaw, strict=True)], saturated


def _rotation(q: np.ndarray) -> np.ndarray:
    """R_WB (3 x 3) of a quaternion (w, x, y, z), normalised first (the integrator's
    quaternion drifts off the unit sphere between steps; MultibodyPlant normalises too)."""
    n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) ** 0.5
    w, x, y, z = (c / n for c in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _tilt_limited(f: np.ndarray, tan_tilt: float, weight: float) -> np.ndarray:
    """``f`` with its upward part at least a tenth of the weight and its horizontal part
    at most ``tan_tilt`` times the upward: the attitude it asks for within the tilt limit
    (far from the goal the NF's force alone would ask the body to lie on its side)."""
    up = f[2] if f[2] > 0.1 * weight else 0.0 * f[2] + 0.1 * weight
    horizontal = (f[0] * f[0] + f[1] * f[1]) ** 0.5
    scale = 1.0
    if horizontal > tan_tilt * up:
        scale = tan_tilt * up / horizontal
    return np.array([f[0] * scale, f[1] * scale, up])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / (v @ v) ** 0.5


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
        ``saturated`` is 1 where the allocation gave anything up, else 0. The NF's torque
        is not used: three torques go to the attitude, and the heading is the goal's.

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
        left unconnected (a still target) reads zero.

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
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            # The default: Drake's quadrotor example's rotors, a + of arm 0.15 m with
            # moment ratios +-0.0245 m (the Quadrotor carrier's defaults).
            M = _DEFAULT_MIXER if mixer_matrix is None else np.asarray(mixer_matrix, dtype=float)
            if M.shape != (4, 4) or abs(np.linalg.det(M)) < 1e-12:
                raise ValueError(f"the mixer must be an invertible 4 x 4 matrix, got {M}")
            heading = np.asarray(heading_W, dtype=float)
            if not (math.isfinite(max_thrust) and max_thrust > 0):
                raise ValueError(f"max_thrust must be finite and > 0 [N], got {max_thrust}")
            self._defaults = (
                mass,
                tuple(inertia_diagonal),
                gravity,
                tuple(attitude_gains),
                tuple(heading),
                M,
                max_thrust,
                velocity_damping,
                max_tilt,
                target_rotation,
            )
            # R_WB of a translating target: the believed acceleration's frame.
            self._R_WT = np.eye(3) if target_rotation is None else np.asarray(target_rotation)
            self._weight = mass * gravity * _UP
            self._mass = float(mass)
            self._J = np.asarray(inertia_diagonal, dtype=float)
            self._k_R, self._k_Omega = (float(k) for k in attitude_gains)
            self._heading = heading
            self._M_inv = np.linalg.inv(M)
            self._max_thrust = float(max_thrust)
            self._damping = float(velocity_damping)
            self._tan_tilt = math.tan(max_tilt)
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

        def wanted_wrench(self, context) -> list:
            """(T, tau_x, tau_y, tau_z) before the allocation: the thrust along z_B and
            the torque in the body frame."""
            x = self.body_state_input.Eval(context)
            force = self.generalized_force_input.Eval(context)
            R = _rotation(x[0:4])
            Omega = R.T @ x[7:10]  # the body's rate in its own frame
            f_d = _tilt_limited(
                force[3:6]
                - self._damping * x[10:13]
                + self._weight
                + self._feedforward(context, R),
                self._tan_tilt,
                self._weight[2],
            )
            z_d = _unit(f_d)
            y_d = _unit(np.cross(z_d, self._heading))
            R_d = np.column_stack([np.cross(y_d, z_d), y_d, z_d])
            E = R_d.T @ R - R.T @ R_d
            e_R = 0.5 * np.array([E[2, 1], E[0, 2], E[1, 0]])
            J_Omega = self._J * Omega
            tau = self._J * (-self._k_R * e_R - self._k_Omega * Omega) + np.cross(Omega, J_Omega)
            return [f_d @ R[:, 2], *tau]

        def _feedforward(self, context, R: np.ndarray) -> np.ndarray:
            """``b v_ff + m a_ff`` (3, in W) of a moving target's believed motion (the
            class docstring), zero where the inputs are unconnected (a still target)."""
            out = np.zeros(3)
            if self.feedforward_twist_input.HasValue(context):
                out = out + self._damping * (R @ self.feedforward_twist_input.Eval(context)[3:6])
            if self.feedforward_acceleration_input.HasValue(context):
                rate = self.feedforward_acceleration_input.Eval(context)[3:6]
                out = out + self._mass * (self._R_WT @ rate)
            return out

        def CalcRotorThrusts(self, context, output) -> None:
            u, _ = allocate(self.wanted_wrench(context), self._M_inv, self._max_thrust)
            output.SetFromVector(u)

        def CalcSaturated(self, context, output) -> None:
            _, saturated = allocate(self.wanted_wrench(context), self._M_inv, self._max_thrust)
            output.SetFromVector([1.0 if saturated else 0.0])

    return Impl


AttitudeCascade = AttitudeCascade_[None]
