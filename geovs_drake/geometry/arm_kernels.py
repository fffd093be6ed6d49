"""The arm's rigid-body kernels, compiled by numba: one state at a time, float64.

All spatial quantities are Plücker vectors in the world frame W about W's origin
(Featherstone, *Rigid Body Dynamics Algorithms*, 2008, ch. 2): a motion ``[w; v_O]``,
a force ``[n_O; f]``, a body's spatial inertia about O as ``(m, h = m p_WBcm,
I_O)`` (13 numbers). In fixed coordinates a joint's motion subspace S_i, a subtree's
composite inertia and the recursions need no transform between bodies: sums and cross
products only. The tree's arrays come from :func:`geovs_drake.systems.arm_tree.arm_tree`
(its :meth:`~geovs_drake.systems.arm_tree.ArmTree.kernel_args`); the workspace ``ws``
(n x :data:`WS_COLUMNS`) from :meth:`~geovs_drake.systems.arm_tree.ArmTree.workspace`,
so the hot path allocates only its outputs.

* :func:`arm_forward`: X_WB of every body and each joint's S_i in W (into ``ws``);
* :func:`mass_matrix`: the composite-rigid-body algorithm, reflected rotor inertia on
  the diagonal (Drake's ``CalcMassMatrix``);
* :func:`inverse_dynamics`: recursive Newton-Euler at zero acceleration, C(q, v) v -
  tau_g(q) (Drake's ``CalcBiasTerm`` minus ``CalcGravityGeneralizedForces``);
* :func:`camera_pose` and :func:`camera_jacobian_W`: X_WC and J_C (the spatial-velocity
  Jacobian of frame C at Co, expressed in W: Drake's ``CalcJacobianSpatialVelocity``
  with ``JacobianWrtVariable.kV``);
* :func:`camera_terms`: what the Drake loop's ArmCamera reads at a state, in one pass
  (the camera's state, J_C expressed in C, tau_g), and :func:`camera_torque` its torque;
* :func:`cholesky_solve`, :func:`min_singular_value`: the small dense linear algebra
  (numba's ``np.linalg`` needs SciPy's LAPACK, which the package does not require).
"""

from __future__ import annotations

import math

from numba import njit

from geovs_drake.geometry.so3 import rotation_to_quaternion

__all__ = [
    "KIND_PRISMATIC",
    "KIND_REVOLUTE",
    "WS_COLUMNS",
    "arm_forward",
    "camera_jacobian_W",
    "camera_pose",
    "camera_terms",
    "camera_torque",
    "cholesky_factor",
    "cholesky_solve",
    "inverse_dynamics",
    "mass_matrix",
    "min_singular_value",
    "shifted_gram",
]

#: Joint kinds in the tree's ``kind`` array.
KIND_REVOLUTE, KIND_PRISMATIC = 0, 1
# The workspace's columns per body: R_WB (9, row-major), p_WB (3), S (6), then the
# recursions' V (6), A (6), f (6), the composite inertia (13) and a product (6).
_R, _P, _S, _V, _A, _F, _I, _X = 0, 9, 12, 18, 24, 30, 36, 49
#: The workspace's width (columns per body).
WS_COLUMNS = 55
#: Jacobi's sweeps at most, and its stop: the squared off-diagonal over the squared
#: diagonal (double precision's epsilon, squared).
_JACOBI_SWEEPS, _JACOBI_TOLERANCE = 30, 1e-32
_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}


# Small fixed-size algebra on tuples, which numba keeps in registers: the kernels
# allocate nothing per body (an array each costs more than the body's arithmetic).
@njit(**_JIT)
def _load9(a, i, o):
    return (a[i, o], a[i, o + 1], a[i, o + 2], a[i, o + 3], a[i, o + 4], a[i, o + 5],
            a[i, o + 6], a[i, o + 7], a[i, o + 8])  # fmt: skip


@njit(**_JIT)
def _load3(a, i, o):
    return (a[i, o], a[i, o + 1], a[i, o + 2])


@njit(**_JIT)
def _mat_mat(a, b):
    """a b for 3 x 3 row-major 9-tuples."""
    return (
        a[0] * b[0] + a[1] * b[3] + a[2] * b[6],
        a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
        a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
        a[3] * b[0] + a[4] * b[3] + a[5] * b[6],
        a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
        a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
        a[6] * b[0] + a[7] * b[3] + a[8] * b[6],
        a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
        a[6] * b[2] + a[7] * b[5] + a[8] * b[8],
    )


@njit(**_JIT)
def _mat_vec(a, v):
    """a v for a 3 x 3 row-major 9-tuple and a 3-tuple."""
    return (
        a[0] * v[0] + a[1] * v[1] + a[2] * v[2],
        a[3] * v[0] + a[4] * v[1] + a[5] * v[2],
        a[6] * v[0] + a[7] * v[1] + a[8] * v[2],
    )


@njit(**_JIT)
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(**_JIT)
def _joint_motion(kind, qi, ax, ay, az):
    """X_FM(q) of a revolute (Rodrigues' rotation by q about the unit axis) or prismatic
    (a shift by q along it) joint: (R_FM as a 9-tuple, the shift along the axis)."""
    if kind == KIND_REVOLUTE:
        sn, cs = math.sin(qi), math.cos(qi)
        t = 1.0 - cs
        R_FM = (
            cs + t * ax * ax, t * ax * ay - sn * az, t * ax * az + sn * ay,
            t * ax * ay + sn * az, cs + t * ay * ay, t * ay * az - sn * ax,
            t * ax * az - sn * ay, t * ay * az + sn * ax, cs + t * az * az,
        )  # fmt: skip
        return R_FM, 0.0
    return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0), qi


@njit(**_JIT)
def arm_forward(q, parent, index, kind, frames, axis, ws):
    """X_WB (``ws[i, 0:9]`` R_WB row-major, ``ws[i, 9:12]`` p_WB) of each moving body i
    and its joint's motion subspace S_i = [a_W; p_WM x a_W] (revolute) or [0; a_W]
    (prismatic) in ``ws[i, 12:18]``. X_WB = X_WP X_PF X_FM(q) X_MB, ``frames[i]`` =
    [R_PF (9), p_PF (3), R_MB (9), p_MB (3)]; X_FM a rotation about (a translation
    along) the axis, as Drake's RevoluteJoint (PrismaticJoint)."""
    for i in range(parent.shape[0]):
        p = parent[i]
        R_PF, p_PF = _load9(frames, i, 0), _load3(frames, i, 9)
        if p < 0:  # a root joint: its parent frame is the world's (the base's weld in X_PF)
            R_WF, p_WF = R_PF, p_PF
        else:
            R_WP, p_WP = _load9(ws, p, _R), _load3(ws, p, _P)
            R_WF = _mat_mat(R_WP, R_PF)
            Rp = _mat_vec(R_WP, p_PF)
            p_WF = (p_WP[0] + Rp[0], p_WP[1] + Rp[1], p_WP[2] + Rp[2])
        a = _load3(axis, i, 0)
        R_FM, shift = _joint_motion(kind[i], q[index[i, 0]], a[0], a[1], a[2])
        a_W = _mat_vec(R_WF, a)
        p_WM = (p_WF[0] + a_W[0] * shift, p_WF[1] + a_W[1] * shift, p_WF[2] + a_W[2] * shift)
        R_WM = _mat_mat(R_WF, R_FM)
        R_WB = _mat_mat(R_WM, _load9(frames, i, 12))
        Rp = _mat_vec(R_WM, _load3(frames, i, 21))
        for k in range(9):
            ws[i, _R + k] = R_WB[k]
        for k in range(3):
            ws[i, _P + k] = p_WM[k] + Rp[k]
        if kind[i] == KIND_REVOLUTE:
            m = _cross(p_WM, a_W)
            ws[i, _S], ws[i, _S + 1], ws[i, _S + 2] = a_W[0], a_W[1], a_W[2]
            ws[i, _S + 3], ws[i, _S + 4], ws[i, _S + 5] = m[0], m[1], m[2]
        else:
            ws[i, _S], ws[i, _S + 1], ws[i, _S + 2] = 0.0, 0.0, 0.0
            ws[i, _S + 3], ws[i, _S + 4], ws[i, _S + 5] = a_W[0], a_W[1], a_W[2]


@njit(**_JIT)
def _body_inertia_at_O(i, inertia, ws):
    """Body i's spatial inertia about W's origin in W into ``ws[i, _I:_I+13]`` as (m, h,
    I_O): from ``inertia[i]`` = [m, p_BoBcm_B (3), I_BBo_B (9)], I_O = R I_BBo R^T +
    m ([p]x^T [p]x + [p]x^T [c]x + [c]x^T [p]x), p = p_WB, c = R p_BoBcm (the
    parallel-axis theorem, shifted from Bo to O; Featherstone Eq. 2.63)."""
    m = inertia[i, 0]
    R = _load9(ws, i, _R)
    p = _load3(ws, i, _P)
    c = _mat_vec(R, _load3(inertia, i, 1))
    ws[i, _I] = m
    for r in range(3):
        ws[i, _I + 1 + r] = m * (p[r] + c[r])
    # R I_BBo R^T, then the shift: [x]x^T [y]x = (x . y) 1 - y x^T.
    RI = _mat_mat(R, _load9(inertia, i, 4))
    pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
    pc = p[0] * c[0] + p[1] * c[1] + p[2] * c[2]
    for r in range(3):
        for col in range(3):
            s = (
                RI[3 * r] * R[3 * col]
                + RI[3 * r + 1] * R[3 * col + 1]
                + RI[3 * r + 2] * R[3 * col + 2]
            )
            delta = pp + 2.0 * pc if r == col else 0.0
            shift = delta - p[r] * p[col] - c[r] * p[col] - p[r] * c[col]
            ws[i, _I + 4 + 3 * r + col] = s + m * shift


@njit(**_JIT)
def _inertia_times(ws, i, o_I, o_V, o_out):
    """ws[i, o_out:o_out+6] = I V for the spatial inertia (m, h, I_O) at ``ws[i, o_I:]``
    and the motion V = [w; v] at ``ws[i, o_V:]``: [I_O w + h x v; m v - h x w]."""
    m = ws[i, o_I]
    h = _load3(ws, i, o_I + 1)
    I_O = _load9(ws, i, o_I + 4)
    w, v = _load3(ws, i, o_V), _load3(ws, i, o_V + 3)
    Iw = _mat_vec(I_O, w)
    hv, hw = _cross(h, v), _cross(h, w)
    for r in range(3):
        ws[i, o_out + r] = Iw[r] + hv[r]
        ws[i, o_out + 3 + r] = m * v[r] - hw[r]


@njit(**_JIT)
def mass_matrix(parent, index, inertia, joint, ws, M):
    """M(q) (nv x nv, Drake's velocity order) into ``M`` by the composite-rigid-body
    algorithm (Featherstone Table 6.2) after :func:`arm_forward`: the composite inertia
    I^c_i of each subtree about O, M_ii = S_i^T I^c_i S_i plus the joint's reflected
    rotor inertia ``joint[i, 1]`` (as MultibodyPlant adds it), M_ij = S_j^T I^c_i S_i
    for each ancestor j of i."""
    n = parent.shape[0]
    for i in range(n):
        _body_inertia_at_O(i, inertia, ws)
    for i in range(n - 1, -1, -1):  # children first: I^c_i is whole when i is reached
        _inertia_times(ws, i, _I, _S, _X)  # F = I^c_i S_i
        vi = index[i, 1]
        s = 0.0
        for k in range(6):
            s += ws[i, _S + k] * ws[i, _X + k]
        M[vi, vi] = s + joint[i, 1]
        j = parent[i]
        while j >= 0:
            s = 0.0
            for k in range(6):
                s += ws[j, _S + k] * ws[i, _X + k]
            M[vi, index[j, 1]] = s
            M[index[j, 1], vi] = s
            j = parent[j]
        p = parent[i]
        if p >= 0:
            for k in range(13):
                ws[p, _I + k] += ws[i, _I + k]


@njit(**_JIT)
def inverse_dynamics(v, parent, index, inertia, gravity, ws, tau):
    """tau = C(q, v) v - tau_g(q) (nv, Drake's velocity order) by recursive Newton-Euler
    at zero acceleration (Featherstone Table 5.1, in fixed coordinates) after
    :func:`arm_forward`: V_i = V_p + S_i v_i, A_i = A_p + (V_i x S_i) v_i with the base's
    A_0 = -[0; g] (gravity as a fictitious acceleration), f_i = I_i A_i + V_i x* I_i V_i,
    tau_i = S_i^T f_i with each subtree's forces summed. ``gravity`` zero gives
    Drake's bias term alone; v zero gives -tau_g alone."""
    n = parent.shape[0]
    for i in range(n):
        _body_inertia_at_O(i, inertia, ws)
        p = parent[i]
        vi = v[index[i, 1]]
        for k in range(6):
            ws[i, _V + k] = (0.0 if p < 0 else ws[p, _V + k]) + ws[i, _S + k] * vi
        w, u = _load3(ws, i, _V), _load3(ws, i, _V + 3)
        s, t = _load3(ws, i, _S), _load3(ws, i, _S + 3)
        # V x S = [w x s; w x t + u x s] (the motion cross product).
        w_s, w_t, u_s = _cross(w, s), _cross(w, t), _cross(u, s)
        for k in range(3):
            if p < 0:
                ws[i, _A + k] = w_s[k] * vi
                ws[i, _A + 3 + k] = -gravity[k] + (w_t[k] + u_s[k]) * vi
            else:
                ws[i, _A + k] = ws[p, _A + k] + w_s[k] * vi
                ws[i, _A + 3 + k] = ws[p, _A + 3 + k] + (w_t[k] + u_s[k]) * vi
        _inertia_times(ws, i, _I, _A, _F)
        _inertia_times(ws, i, _I, _V, _X)
        # V x* (I V) = [w x n + u x f; w x f] for I V = [n; f] (the force cross product).
        nn, ff = _load3(ws, i, _X), _load3(ws, i, _X + 3)
        wn, uf, wf = _cross(w, nn), _cross(u, ff), _cross(w, ff)
        for k in range(3):
            ws[i, _F + k] += wn[k] + uf[k]
            ws[i, _F + 3 + k] += wf[k]
    for i in range(n - 1, -1, -1):
        s = 0.0
        for k in range(6):
            s += ws[i, _S + k] * ws[i, _F + k]
        tau[index[i, 1]] = s
        p = parent[i]
        if p >= 0:
            for k in range(6):
                ws[p, _F + k] += ws[i, _F + k]


@njit(**_JIT)
def camera_pose(camera_body, X_BC, ws, R_WC, p_WC):
    """X_WC = X_WB X_BC (R_WC 3 x 3, p_WC 3) after :func:`arm_forward`; ``X_BC`` = [R_BC
    (9, row-major), p_BC (3)] on the moving body ``camera_body``."""
    b = camera_body
    for r in range(3):
        s = ws[b, _P + r]
        for k in range(3):
            s += ws[b, _R + 3 * r + k] * X_BC[9 + k]
        p_WC[r] = s
        for c in range(3):
            s = 0.0
            for k in range(3):
                s += ws[b, _R + 3 * r + k] * X_BC[3 * k + c]
            R_WC[r, c] = s


@njit(**_JIT)
def camera_jacobian_W(camera_body, parent, index, p_WC, ws, J):
    """J_C (6 x nv) into ``J`` (zeroed first): the spatial velocity of frame C in W at
    Co, expressed in W, per joint velocity: [s; t + s x p_WC] for each joint on the
    chain from the world to the camera's body (S_i = [s; t] moves O; shifted to Co),
    zero for the others."""
    J[:, :] = 0.0
    j = camera_body
    while j >= 0:
        c = index[j, 1]
        s0, s1, s2 = ws[j, _S], ws[j, _S + 1], ws[j, _S + 2]
        J[0, c], J[1, c], J[2, c] = s0, s1, s2
        J[3, c] = ws[j, _S + 3] + s1 * p_WC[2] - s2 * p_WC[1]
        J[4, c] = ws[j, _S + 4] + s2 * p_WC[0] - s0 * p_WC[2]
        J[5, c] = ws[j, _S + 5] + s0 * p_WC[1] - s1 * p_WC[0]
        j = parent[j]


@njit(**_JIT)
def camera_terms(
    x, parent, index, kind, frames, axis, inertia, gravity, camera_body, X_BC, ws, R_WC, J_W,
    state, J_C, tau_g,
):  # fmt: skip
    """ArmCamera's terms at the arm's state ``x`` = (q, v), from one pass of
    :func:`arm_forward`: ``state`` (13) the camera's [q_WC (w >= 0), p_WC, w_WC_W,
    v_WCo_W] (Drake's ``CalcPose`` and ``CalcSpatialVelocity`` in W, the quaternion by
    :func:`~geovs_drake.geometry.so3.rotation_to_quaternion`), ``J_C`` (6 x nv) the
    spatial-velocity Jacobian at Co expressed in C (``CalcJacobianSpatialVelocity``,
    kV, expressed in C: blkdiag(R_CW, R_CW) J_W, so that J_C v = (Omega, V), the body
    twist of the paper's Eqs. (16)-(17)), and ``tau_g`` (nv) the gravity's generalized
    force (``CalcGravityGeneralizedForces``). ``R_WC`` (3 x 3) and ``J_W`` (6 x nv)
    are scratch, left holding R_WC and J_C in W."""
    n = parent.shape[0]
    arm_forward(x, parent, index, kind, frames, axis, ws)  # reads q = x[0:nq] by index
    p_WC = state[4:7]
    camera_pose(camera_body, X_BC, ws, R_WC, p_WC)
    rotation_to_quaternion(R_WC, state[0:4])
    camera_jacobian_W(camera_body, parent, index, p_WC, ws, J_W)
    for r in range(6):
        s = 0.0
        for c in range(n):
            s += J_W[r, c] * x[n + c]
        state[7 + r] = s
    for half in (0, 3):  # each 3-row block re-expressed in C: R_CW = R_WC^T
        for r in range(3):
            for c in range(n):
                J_C[half + r, c] = (
                    R_WC[0, r] * J_W[half, c]
                    + R_WC[1, r] * J_W[half + 1, c]
                    + R_WC[2, r] * J_W[half + 2, c]
                )
    # Newton-Euler at v = 0 gives -tau_g. tau_g serves as that zero v too: the forward
    # pass reads v before the backward pass writes tau.
    tau_g[:] = 0.0
    inverse_dynamics(tau_g, parent, index, inertia, gravity, ws, tau_g)
    for c in range(n):
        tau_g[c] = -tau_g[c]


@njit(**_JIT)
def camera_torque(J_C, F_C, tau_g, damping, x, tau):
    """ArmCamera's torque tau = J_C^T F_C - tau_g - B_q v (nv) into ``tau``, after
    :func:`camera_terms` at the arm's state ``x`` = (q, v) (nq = nv); ``damping``'s
    first nv entries are B_q per joint. The power J_C^T F_C . v is F_C . (Omega, V):
    the arm takes exactly the power the free rig would (Appendix C's energy)."""
    n = tau.shape[0]
    for c in range(n):
        s = -tau_g[c] - damping[c] * x[n + c]
        for r in range(6):
            s += J_C[r, c] * F_C[r]
        tau[c] = s


@njit(**_JIT)
def shifted_gram(J, shift, A):
    """``A = J J^T + shift I`` (m x m) for J (m x n): the damped least squares' matrix
    (``shift = lambda^2``), the singular zone's test (``-m^2``), the Gram matrix (0)."""
    rows = J.shape[0]
    for r in range(rows):
        for c in range(rows):
            s = shift if r == c else 0.0
            for k in range(J.shape[1]):
                s += J[r, k] * J[c, k]
            A[r, c] = s


@njit(**_JIT)
def cholesky_factor(A, L):
    """The lower Cholesky factor of a symmetric A (n x n) into ``L``: True, or False at
    the first pivot that is not positive (A is not positive definite; NaN included),
    ``L`` then filled only up to it."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / d
    return True


@njit(**_JIT)
def cholesky_solve(A, b, L, x):
    """x = A^-1 b for a symmetric positive definite A (n x n) by its Cholesky factor,
    written into the scratch ``L`` (n x n); NaN where A is not positive definite
    (the caller's state check stops the start)."""
    n = A.shape[0]
    if not cholesky_factor(A, L):
        for i in range(n):
            x[i] = math.nan
        return
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * x[k]
        x[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]


@njit(**_JIT)
def min_singular_value(J, G):
    """sigma_min of J (6 x n, n >= 6): the square root of the smallest eigenvalue of
    G = J J^T (6 x 6 scratch, overwritten) by cyclic Jacobi rotations (Golub and Van
    Loan, Algorithm 8.5.3), to the symmetric matrix's rounding."""
    m = J.shape[0]
    shifted_gram(J, 0.0, G)
    scale = 0.0
    for r in range(m):
        scale += G[r, r] * G[r, r]
    for _sweep in range(_JACOBI_SWEEPS):
        off = 0.0
        for r in range(m):
            for c in range(r + 1, m):
                off += G[r, c] * G[r, c]
        # Converged where what is left off the diagonal is below the rounding of its
        # largest entries (quadratic convergence: one sweep more than it takes).
        if off <= _JACOBI_TOLERANCE * scale:
            break
        for p in range(m - 1):
            for q in range(p + 1, m):
                if G[p, q] == 0.0:
                    continue
                tau = (G[q, q] - G[p, p]) / (2.0 * G[p, q])
                t = (1.0 if tau >= 0.0 else -1.0) / (abs(tau) + math.sqrt(1.0 + tau * tau))
                c = 1.0 / math.sqrt(1.0 + t * t)
                s = t * c
                for k in range(m):  # G <- J^T G J for the rotation J in (p, q)
                    gkp, gkq = G[k, p], G[k, q]
                    G[k, p], G[k, q] = c * gkp - s * gkq, s * gkp + c * gkq
                for k in range(m):
                    gpk, gqk = G[p, k], G[q, k]
                    G[p, k], G[q, k] = c * gpk - s * gqk, s * gpk + c * gqk
    smallest = G[0, 0]
    for r in range(1, m):
        smallest = min(smallest, G[r, r])
    return math.sqrt(max(smallest, 0.0))
