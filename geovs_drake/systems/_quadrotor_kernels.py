"""The quadrotor systems' per-evaluation arithmetic as flat scalar kernels.

:class:`~geovs_drake.systems.AttitudeCascade` and :class:`~geovs_drake.systems.LevelView`
run in every derivative evaluation of the quadrotor's loop. Written with numpy's small
array calls (``np.cross``, ``column_stack``, 3 x 3 products) they cost about 150 us of
its 230 us per evaluation (``benchmarks/bench_quadrotor.py``): numpy's per-call overhead
on 3-vectors, not arithmetic. Here each is one function of scalars, written so that one
text serves every scalar type: numba compiles it for floats (``cache=True``, as the
generated kernels of :mod:`geovs_drake.geometry.kernels`), and the same Python runs for
AutoDiffXd (Drake's ``Linearize`` of the loop). Branches compare values, so a symbolic
Expression cannot run them (nor could the numpy forms they replace).

Parameter vectors (floats, built once by each system):

* ``cascade``: ``[m g, Jx, Jy, Jz, k_R, k_Omega, heading_W (3), max_thrust, b,
  tan(max_tilt), M^-1 (16, row-major), heading]`` (:data:`CASCADE_PARAMETERS` long;
  ``heading`` 0.0 for the goal's, 1.0 for the NF's: :data:`CASCADE_HEADINGS`);
* ``level_image`` and ``level_state``: ``[R_RC (9, row-major), p_RC (3)]``.
"""

from __future__ import annotations

from collections.abc import Callable

from geovs_drake.geometry.kernels import NUMBA

if NUMBA:
    # A helper that a compiled kernel calls, and plain Python where it is called from Python.
    from numba.extending import register_jitable as _helper
else:  # pragma: no cover - numba is a dependency

    def _helper(function: Callable) -> Callable:
        return function


__all__ = [
    "CASCADE_HEADINGS",
    "CASCADE_PARAMETERS",
    "allocation",
    "attitude_wrench",
    "cascade",
    "for_scalar_type",
    "level_image",
    "level_state",
]

#: The length of ``cascade``'s parameter vector.
CASCADE_PARAMETERS = 29

#: The cascade's headings (``Quadrotor.heading``) and their values in its vector's last
#: entry: ``goal``, Lee's loop turns the body to the goal's heading; ``nf``, the NF's
#: torque about z_B turns it and Lee's loop leaves the yaw alone.
CASCADE_HEADINGS: dict[str, float] = {"goal": 0.0, "nf": 1.0}


def cascade(x, w, p) -> tuple:
    """``(u0, u1, u2, u3, saturated, T, tau_x, tau_y, tau_z)``: the rotor thrusts [N] of
    :class:`~geovs_drake.systems.AttitudeCascade` for the 13-vector body state ``x`` and
    the NF's wrench ``w`` = (tau_W (3) [N m], f_W (3) [N]), the generalized force's
    order, the allocation's verdict (1.0 where it gave anything up, else 0.0) and the
    wanted wrench before the allocation (the thrust along z_B and the torque in B).
    ``p``: the module docstring's cascade vector; its ``heading`` entry 1.0 gives the
    yaw to the NF's torque (:func:`attitude_wrench`), 0.0 leaves tau_W unread."""
    # f_d = f_W - b v_W + m g e_z: the NF's force, the cascade's own damping, the weight.
    f0, f1, f2 = w[3] - p[10] * x[10], w[4] - p[10] * x[11], w[5] - p[10] * x[12] + p[0]
    thrust, tau0, tau1, tau2 = attitude_wrench(
        x, f0, f1, f2, p[6], p[7], p[8], p, p[28], w[0], w[1], w[2]
    )
    u0, u1, u2, u3, saturated = allocation(thrust, tau0, tau1, tau2, p[12:28], p[9])
    return u0, u1, u2, u3, saturated, thrust, tau0, tau1, tau2


@_helper
def attitude_wrench(x, f0, f1, f2, h0, h1, h2, p, nf_yaw, t0, t1, t2) -> tuple:
    """``(T, tau_x, tau_y, tau_z)``: the thrust along z_B [N] and Lee, Leok & McClamroch's
    torque in B [N m] that turn the body in state ``x`` to push along the thrust vector
    ``(f0, f1, f2)`` [N] in W (the weight included) with the heading ``(h0, h1, h2)``;
    ``p``: the cascade vector (its weight, inertia, gains and tilt limit). Shared by the
    cascade and the laws that drive the rotors themselves (Hamel & Mahony's).

    With ``nf_yaw`` 1.0 the heading is the body's own (its x axis: Lee's loop then turns
    z_B to z_d and leaves the yaw alone) and tau_z is the NF's torque ``(t0, t1, t2)``
    [N m] (in W) about z_B plus the gyroscopic term (Euler's equation about z_B, as
    Lee's law cancels it about all three); with 0.0 the torque is unread (zeros)."""
    weight, tan_tilt = p[0], p[11]
    # R_WB of the quaternion, normalised (the integrator's drifts off the unit sphere).
    n = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3]) ** 0.5
    w, a, b, c = x[0] / n, x[1] / n, x[2] / n, x[3] / n
    r00, r01, r02 = 1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b)
    r10, r11, r12 = 2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a)
    r20, r21, r22 = 2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b)
    # Omega = R^T w_W: the body's rate in its own frame.
    o0 = r00 * x[7] + r10 * x[8] + r20 * x[9]
    o1 = r01 * x[7] + r11 * x[8] + r21 * x[9]
    o2 = r02 * x[7] + r12 * x[8] + r22 * x[9]
    if nf_yaw > 0.5:
        # The NF turns the heading: x_d in the plane of z_d and the body's own x axis, so
        # that R_d differs from R by the turn of z_B to z_d (Lee's yaw error then vanishes
        # to first order; its torque about z_B is replaced below in any case).
        h0, h1, h2 = r00, r10, r20
    # f_d's upward part at least a tenth of the weight and its horizontal part at most
    # tan(max_tilt) times the upward: the attitude it asks within the tilt limit (far from
    # the goal the NF's force alone would lay the body on its side).
    up = f2 if f2 > 0.1 * weight else 0.0 * f2 + 0.1 * weight
    horizontal = (f0 * f0 + f1 * f1) ** 0.5
    if horizontal > tan_tilt * up:
        f0, f1 = f0 * (tan_tilt * up / horizontal), f1 * (tan_tilt * up / horizontal)
    f2 = up
    # R_d = [x_d, y_d, z_d]: z_d along f_d, y_d = z_d x heading normalised, x_d = y_d x z_d.
    m = (f0 * f0 + f1 * f1 + f2 * f2) ** 0.5
    z0, z1, z2 = f0 / m, f1 / m, f2 / m
    y0, y1, y2 = z1 * h2 - z2 * h1, z2 * h0 - z0 * h2, z0 * h1 - z1 * h0
    m = (y0 * y0 + y1 * y1 + y2 * y2) ** 0.5
    y0, y1, y2 = y0 / m, y1 / m, y2 / m
    x0, x1, x2 = y1 * z2 - y2 * z1, y2 * z0 - y0 * z2, y0 * z1 - y1 * z0
    # e_R = 1/2 vee(R_d^T R - R^T R_d) (Lee, Leok & McClamroch), entry by entry.
    e0 = 0.5 * ((z0 * r01 + z1 * r11 + z2 * r21) - (r02 * y0 + r12 * y1 + r22 * y2))
    e1 = 0.5 * ((x0 * r02 + x1 * r12 + x2 * r22) - (r00 * z0 + r10 * z1 + r20 * z2))
    e2 = 0.5 * ((y0 * r00 + y1 * r10 + y2 * r20) - (r01 * x0 + r11 * x1 + r21 * x2))
    # tau = J (-k_R e_R - k_Omega Omega) + Omega x J Omega.
    j0, j1, j2 = p[1] * o0, p[2] * o1, p[3] * o2
    tau0 = p[1] * (-p[4] * e0 - p[5] * o0) + (o1 * j2 - o2 * j1)
    tau1 = p[2] * (-p[4] * e1 - p[5] * o1) + (o2 * j0 - o0 * j2)
    if nf_yaw > 0.5:
        # The yaw is fully actuated (the rotors' drag): the NF's own torque drives it, as
        # Eq. 45's wrench drives the paper's free body, its component about z_B; the
        # gyroscopic term cancelled, so that J_z dOmega_z/dt = z_B . tau_NF (Lee's form).
        tau2 = (t0 * r02 + t1 * r12 + t2 * r22) + (o0 * j1 - o1 * j0)
    else:
        tau2 = p[3] * (-p[4] * e2 - p[5] * o2) + (o0 * j1 - o1 * j0)
    thrust = f0 * r02 + f1 * r12 + f2 * r22
    return thrust, tau0, tau1, tau2


@_helper
def allocation(thrust, tau_x, tau_y, tau_z, m, high) -> tuple:
    """``(u0, u1, u2, u3, saturated)``: rotor thrusts [N] for the wanted wrench (thrust
    [N], torques [N m]), ``m`` the mixer's inverse (16, row-major), each within [0,
    ``high``]: the thrust clamped to [0, 4 high], then the roll and pitch torques scaled
    down together, then the yaw torque (:func:`~geovs_drake.systems.allocate`)."""

    def largest_step(a0, a1, a2, a3, d0, d1, d2, d3):
        # The largest s in [0, 1] with a + s d within [0, high], for a within it.
        s = 1.0
        for a, d in ((a0, d0), (a1, d1), (a2, d2), (a3, d3)):
            if d > 0 and a + d > high:
                candidate = (high - a) / d
                if candidate < s:
                    s = candidate
            elif d < 0 and a + d < 0:
                candidate = -a / d
                if candidate < s:
                    s = candidate
        return s

    T = thrust
    saturated = 0.0
    if T < 0:
        T, saturated = 0.0 * T, 1.0
    elif T > 4 * high:
        T, saturated = 0.0 * T + 4 * high, 1.0
    b0, b1, b2, b3 = m[0] * T, m[4] * T, m[8] * T, m[12] * T
    d0 = m[1] * tau_x + m[2] * tau_y
    d1 = m[5] * tau_x + m[6] * tau_y
    d2 = m[9] * tau_x + m[10] * tau_y
    d3 = m[13] * tau_x + m[14] * tau_y
    r = largest_step(b0, b1, b2, b3, d0, d1, d2, d3)
    b0, b1, b2, b3 = b0 + r * d0, b1 + r * d1, b2 + r * d2, b3 + r * d3
    d0, d1, d2, d3 = m[3] * tau_z, m[7] * tau_z, m[11] * tau_z, m[15] * tau_z
    s = largest_step(b0, b1, b2, b3, d0, d1, d2, d3)
    if r < 1.0 or s < 1.0:
        saturated = 1.0
    return b0 + s * d0, b1 + s * d1, b2 + s * d2, b3 + s * d3, saturated


@_helper
def _level_turn(x, p) -> tuple:
    """``(R_WR (9), R_level (c, s))``: the body's rotation (row-major, its quaternion
    normalised) and its heading's cosine and sine (the level attitude Rz(psi))."""
    n = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3]) ** 0.5
    w, a, b, c = x[0] / n, x[1] / n, x[2] / n, x[3] / n
    R = (
        1 - 2 * (b * b + c * c),
        2 * (a * b - w * c),
        2 * (a * c + w * b),
        2 * (a * b + w * c),
        1 - 2 * (a * a + c * c),
        2 * (b * c - w * a),
        2 * (a * c - w * b),
        2 * (b * c + w * a),
        1 - 2 * (a * a + b * b),
    )
    m = (R[0] * R[0] + R[3] * R[3]) ** 0.5
    return R, R[0] / m, R[3] / m


def level_image(x, y, p) -> tuple:
    """:class:`~geovs_drake.systems.LevelView`'s image: y (13) with its vectors q1, q2,
    q3, s turned by R_C'C = R_RC^T Rz(psi)^T R_WR R_RC, lambda kept (NaN passes)."""
    R, c, s = _level_turn(x, p)
    # L = Rz(psi)^T R_WR, row by row.
    L = (
        c * R[0] + s * R[3],
        c * R[1] + s * R[4],
        c * R[2] + s * R[5],
        -s * R[0] + c * R[3],
        -s * R[1] + c * R[4],
        -s * R[2] + c * R[5],
        R[6],
        R[7],
        R[8],
    )
    # LR = L R_RC, then turn = R_RC^T LR.
    LR = (
        L[0] * p[0] + L[1] * p[3] + L[2] * p[6],
        L[0] * p[1] + L[1] * p[4] + L[2] * p[7],
        L[0] * p[2] + L[1] * p[5] + L[2] * p[8],
        L[3] * p[0] + L[4] * p[3] + L[5] * p[6],
        L[3] * p[1] + L[4] * p[4] + L[5] * p[7],
        L[3] * p[2] + L[4] * p[5] + L[5] * p[8],
        L[6] * p[0] + L[7] * p[3] + L[8] * p[6],
        L[6] * p[1] + L[7] * p[4] + L[8] * p[7],
        L[6] * p[2] + L[7] * p[5] + L[8] * p[8],
    )
    t = (
        p[0] * LR[0] + p[3] * LR[3] + p[6] * LR[6],
        p[0] * LR[1] + p[3] * LR[4] + p[6] * LR[7],
        p[0] * LR[2] + p[3] * LR[5] + p[6] * LR[8],
        p[1] * LR[0] + p[4] * LR[3] + p[7] * LR[6],
        p[1] * LR[1] + p[4] * LR[4] + p[7] * LR[7],
        p[1] * LR[2] + p[4] * LR[5] + p[7] * LR[8],
        p[2] * LR[0] + p[5] * LR[3] + p[8] * LR[6],
        p[2] * LR[1] + p[5] * LR[4] + p[8] * LR[7],
        p[2] * LR[2] + p[5] * LR[5] + p[8] * LR[8],
    )

    def turn(k):
        return (
            t[0] * y[k] + t[1] * y[k + 1] + t[2] * y[k + 2],
            t[3] * y[k] + t[4] * y[k + 1] + t[5] * y[k + 2],
            t[6] * y[k] + t[7] * y[k + 1] + t[8] * y[k + 2],
        )

    q1, q2, q3, s_ = turn(0), turn(3), turn(6), turn(10)
    return (*q1, *q2, *q3, y[9], *s_)


def level_state(x, p) -> tuple:
    """:class:`~geovs_drake.systems.LevelView`'s body state (13): the level quaternion
    (cos psi/2, 0, 0, sin psi/2), the origin ``p_WC - Rz(psi) p_RC``, the body's angular
    velocity, and the velocity ``v + omega x (R_WR - Rz(psi)) p_RC`` (C' moves with C)."""
    R, c, s = _level_turn(x, p)
    zero = 0.0 * c
    # (cos psi/2, 0, 0, sin psi/2) up to scale, from whichever form is far from 0.
    if c > -0.5:
        qw, qz = 1 + c, s
    else:
        qw, qz = s, 1 - c
    m = (qw * qw + qz * qz) ** 0.5
    # R p_RC and Rz(psi) p_RC.
    a0 = R[0] * p[9] + R[1] * p[10] + R[2] * p[11]
    a1 = R[3] * p[9] + R[4] * p[10] + R[5] * p[11]
    a2 = R[6] * p[9] + R[7] * p[10] + R[8] * p[11]
    l0, l1, l2 = c * p[9] - s * p[10], s * p[9] + c * p[10], zero + p[11]
    d0, d1, d2 = a0 - l0, a1 - l1, a2 - l2
    return (
        qw / m,
        zero,
        zero,
        qz / m,
        x[4] + a0 - l0,
        x[5] + a1 - l1,
        x[6] + a2 - l2,
        x[7],
        x[8],
        x[9],
        x[10] + (x[8] * d2 - x[9] * d1),
        x[11] + (x[9] * d0 - x[7] * d2),
        x[12] + (x[7] * d1 - x[8] * d0),
    )


def _compiled(function: Callable) -> Callable:
    """``function`` compiled by numba for float vectors (itself without numba)."""
    if not NUMBA:  # pragma: no cover - numba is a dependency
        return function
    from numba import njit

    return njit(cache=True, error_model="numpy", nogil=True)(function)


_COMPILED: dict[Callable, Callable] = {}


def for_scalar_type(function: Callable, T: type) -> Callable:
    """``function`` (one of this module's kernels) for a system of scalar type T: compiled
    for floats (once per process, loaded from numba's cache), the Python itself else."""
    if T is not float:
        return function
    if function not in _COMPILED:
        _COMPILED[function] = _compiled(function)
    return _COMPILED[function]
