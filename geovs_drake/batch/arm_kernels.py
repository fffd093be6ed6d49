"""The arm's rigid-body kernels, compiled by numba: one state at a time, float64.

All spatial quantities are Plücker vectors in the world frame W about W's origin
(Featherstone, *Rigid Body Dynamics Algorithms*, 2008, ch. 2): a motion ``[w; v_O]``,
a force ``[n_O; f]``, a body's spatial inertia about O as ``(m, h = m p_WBcm,
I_O)`` (13 numbers). In fixed coordinates a joint's motion subspace S_i, a subtree's
composite inertia and the recursions need no transform between bodies: sums and cross
products only. The tree's arrays come from :func:`geovs_drake.batch.arm_tree.arm_tree`
(its :meth:`~geovs_drake.batch.arm_tree.ArmTree.kernel_args`); the workspace ``ws``
(n x :data:`WS_COLUMNS`) from :meth:`~geovs_drake.batch.arm_tree.ArmTree.workspace`,
so the hot path allocates only its outputs.

* :func:`arm_forward`: X_WB of every body and each joint's S_i in W (into ``ws``);
* :func:`mass_matrix`: the composite-rigid-body algorithm, reflected rotor inertia on
  the diagonal (Drake's ``CalcMassMatrix``);
* :func:`inverse_dynamics`: recursive Newton-Euler at zero acceleration, C(q, v) v -
  tau_g(q) (Drake's ``CalcBiasTerm`` minus ``CalcGravityGeneralizedForces``);
* :func:`camera_pose` and :func:`camera_jacobian_W`: X_WC and J_C (the spatial-velocity
  Jacobian of frame C at Co, expressed in W: Drake's ``CalcJacobianSpatialVelocity``
  with ``JacobianWrtVariable.kV``);
* :func:`cholesky_solve`, :func:`min_singular_value`: the small dense linear algebra
  (numba's ``np.linalg`` needs SciPy's LAPACK, which the package does not require).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "KIND_PRISMATIC",
    "KIND_REVOLUTE",
    "WS_COLUMNS",
    "arm_forward",
    "camera_jacobian_W",
    "camera_pose",
    "cholesky_solve",
    "inverse_dynamics",
    "mass_matrix",
    "min_singular_value",
    "rotation_to_quaternion",
]

#: Joint kinds in the tree's ``kind`` array.
KIND_REVOLUTE, KIND_PRISMATIC = 0, 1
# The workspace's columns per body: R_WB (9, row-major), p_WB (3), S (6), then the
# recursions' V (6), A (6), f (6) and the composite inertia (13).
_R, _P, _S, _V, _A, _F, _I = 0, 9, 12, 18, 24, 30, 36
#: The workspace's width (columns per body).
WS_COLUMNS = 49
#: Jacobi's sweeps at most, and its stop: the squared off-diagonal over the squared
#: diagonal (double precision's epsilon, squared).
_JACOBI_SWEEPS, _JACOBI_TOLERANCE = 30, 1e-32
_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}


@njit(**_JIT)
def arm_forward(q, parent, index, kind, frames, axis, ws):
    """X_WB (``ws[i, 0:9]`` R_WB row-major, ``ws[i, 9:12]`` p_WB) of each moving body i
    and its joint's motion subspace S_i = [a_W; p_WM x a_W] (revolute) or [0; a_W]
    (prismatic) in ``ws[i, 12:18]``. X_WB = X_WP X_PF X_FM(q) X_MB, ``frames[i]`` =
    [R_PF (9), p_PF (3), R_MB (9), p_MB (3)]; X_FM a rotation about (a translation
    along) the axis, as Drake's RevoluteJoint (PrismaticJoint)."""
    n = parent.shape[0]
    R_FM = np.empty(9)
    for i in range(n):
        p = parent[i]
        qi = q[index[i, 0]]
        ax, ay, az = axis[i, 0], axis[i, 1], axis[i, 2]
        # R_WF = R_WP R_PF, p_WF = p_WP + R_WP p_PF (the world for a root joint).
        R_WF = np.empty(9)
        p_WF = np.empty(3)
        for r in range(3):
            for c in range(3):
                if p < 0:
                    R_WF[3 * r + c] = frames[i, 3 * r + c]
                else:
                    s = 0.0
                    for k in range(3):
                        s += ws[p, _R + 3 * r + k] * frames[i, 3 * k + c]
                    R_WF[3 * r + c] = s
            if p < 0:
                p_WF[r] = frames[i, 9 + r]
            else:
                s = ws[p, _P + r]
                for k in range(3):
                    s += ws[p, _R + 3 * r + k] * frames[i, 9 + k]
                p_WF[r] = s
        # X_FM: Rodrigues' rotation by q about the unit axis, or a shift by q along it.
        if kind[i] == KIND_REVOLUTE:
            sn, cs = math.sin(qi), math.cos(qi)
            t = 1.0 - cs
            R_FM[0], R_FM[1], R_FM[2] = (
                cs + t * ax * ax,
                t * ax * ay - sn * az,
                t * ax * az + sn * ay,
            )
            R_FM[3], R_FM[4], R_FM[5] = (
                t * ax * ay + sn * az,
                cs + t * ay * ay,
                t * ay * az - sn * ax,
            )
            R_FM[6], R_FM[7], R_FM[8] = (
                t * ax * az - sn * ay,
                t * ay * az + sn * ax,
                cs + t * az * az,
            )
            shift = 0.0
        else:
            for k in range(9):
                R_FM[k] = 1.0 if k % 4 == 0 else 0.0
            shift = qi
        # p_WM = p_WF + R_WF a q (prismatic); R_WM = R_WF R_FM; a_W = R_WF a.
        a_W = np.empty(3)
        p_WM = np.empty(3)
        R_WM = np.empty(9)
        for r in range(3):
            a_W[r] = R_WF[3 * r] * ax + R_WF[3 * r + 1] * ay + R_WF[3 * r + 2] * az
            p_WM[r] = p_WF[r] + a_W[r] * shift
            for c in range(3):
                s = 0.0
                for k in range(3):
                    s += R_WF[3 * r + k] * R_FM[3 * k + c]
                R_WM[3 * r + c] = s
        for r in range(3):
            s = p_WM[r]
            for k in range(3):
                s += R_WM[3 * r + k] * frames[i, 21 + k]
            ws[i, _P + r] = s
            for c in range(3):
                s = 0.0
                for k in range(3):
                    s += R_WM[3 * r + k] * frames[i, 12 + 3 * k + c]
                ws[i, _R + 3 * r + c] = s
        if kind[i] == KIND_REVOLUTE:
            ws[i, _S], ws[i, _S + 1], ws[i, _S + 2] = a_W[0], a_W[1], a_W[2]
            ws[i, _S + 3] = p_WM[1] * a_W[2] - p_WM[2] * a_W[1]
            ws[i, _S + 4] = p_WM[2] * a_W[0] - p_WM[0] * a_W[2]
            ws[i, _S + 5] = p_WM[0] * a_W[1] - p_WM[1] * a_W[0]
        else:
            ws[i, _S], ws[i, _S + 1], ws[i, _S + 2] = 0.0, 0.0, 0.0
            ws[i, _S + 3], ws[i, _S + 4], ws[i, _S + 5] = a_W[0], a_W[1], a_W[2]


@njit(**_JIT)
def _body_inertia_at_O(i, inertia, ws, out, o):
    """Body i's spatial inertia about W's origin in W into ``out[o:o+13]`` as (m, h,
    I_O): from ``inertia[i]`` = [m, p_BoBcm_B (3), I_BBo_B (9)], I_O = R I_BBo R^T +
    m ([p_WB]x^T [p_WB]x + [p_WB]x^T [R c]x + [R c]x^T [p_WB]x) (the parallel-axis
    theorem, shifted from Bo to O; Featherstone Eq. 2.63)."""
    m = inertia[i, 0]
    c_W = np.empty(3)
    for r in range(3):
        c_W[r] = (
            ws[i, _R + 3 * r] * inertia[i, 1]
            + ws[i, _R + 3 * r + 1] * inertia[i, 2]
            + ws[i, _R + 3 * r + 2] * inertia[i, 3]
        )
    p = ws[i, _P : _P + 3]
    out[o] = m
    for r in range(3):
        out[o + 1 + r] = m * (p[r] + c_W[r])
    # R I_BBo R^T.
    for r in range(3):
        for c in range(3):
            s = 0.0
            for k in range(3):
                t = 0.0
                for l in range(3):
                    t += inertia[i, 4 + 3 * k + l] * ws[i, _R + 3 * c + l]
                s += ws[i, _R + 3 * r + k] * t
            # [x]x^T [y]x = (x . y) 1 - y x^T, summed symmetrically for (p, c) and (c, p).
            pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
            pc = p[0] * c_W[0] + p[1] * c_W[1] + p[2] * c_W[2]
            delta = 1.0 if r == c else 0.0
            shift = (pp + 2.0 * pc) * delta - p[r] * p[c] - c_W[r] * p[c] - p[r] * c_W[c]
            out[o + 4 + 3 * r + c] = s + m * shift


@njit(**_JIT)
def _inertia_times(I, o, V, out):
    """out = I V for the spatial inertia (m, h, I_O) at ``I[o:o+13]`` and the motion
    V = [w; v]: [I_O w + h x v; m v - h x w]."""
    m = I[o]
    h0, h1, h2 = I[o + 1], I[o + 2], I[o + 3]
    w0, w1, w2, v0, v1, v2 = V[0], V[1], V[2], V[3], V[4], V[5]
    for r in range(3):
        out[r] = I[o + 4 + 3 * r] * w0 + I[o + 5 + 3 * r] * w1 + I[o + 6 + 3 * r] * w2
    out[0] += h1 * v2 - h2 * v1
    out[1] += h2 * v0 - h0 * v2
    out[2] += h0 * v1 - h1 * v0
    out[3] = m * v0 - (h1 * w2 - h2 * w1)
    out[4] = m * v1 - (h2 * w0 - h0 * w2)
    out[5] = m * v2 - (h0 * w1 - h1 * w0)


@njit(**_JIT)
def mass_matrix(parent, index, inertia, joint, ws, M):
    """M(q) (nv x nv, Drake's velocity order) into ``M`` by the composite-rigid-body
    algorithm (Featherstone Table 6.2) after :func:`arm_forward`: the composite inertia
    I^c_i of each subtree about O, M_ii = S_i^T I^c_i S_i plus the joint's reflected
    rotor inertia ``joint[i, 1]`` (as MultibodyPlant adds it), M_ij = S_j^T I^c_i S_i
    for each ancestor j of i."""
    n = parent.shape[0]
    for i in range(n):
        _body_inertia_at_O(i, inertia, ws, ws[i], _I)
    F = np.empty(6)
    for i in range(n - 1, -1, -1):
        _inertia_times(ws[i], _I, ws[i, _S : _S + 6], F)
        vi = index[i, 1]
        s = 0.0
        for k in range(6):
            s += ws[i, _S + k] * F[k]
        M[vi, vi] = s + joint[i, 1]
        j = parent[i]
        while j >= 0:
            s = 0.0
            for k in range(6):
                s += ws[j, _S + k] * F[k]
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
    IV = np.empty(6)
    for i in range(n):
        _body_inertia_at_O(i, inertia, ws, ws[i], _I)
        p = parent[i]
        vi = v[index[i, 1]]
        for k in range(6):
            base_V = 0.0 if p < 0 else ws[p, _V + k]
            ws[i, _V + k] = base_V + ws[i, _S + k] * vi
        w0, w1, w2 = ws[i, _V], ws[i, _V + 1], ws[i, _V + 2]
        u0, u1, u2 = ws[i, _V + 3], ws[i, _V + 4], ws[i, _V + 5]
        s0, s1, s2 = ws[i, _S], ws[i, _S + 1], ws[i, _S + 2]
        t0, t1, t2 = ws[i, _S + 3], ws[i, _S + 4], ws[i, _S + 5]
        # V x S = [w x s; w x t + u x s] (the motion cross product).
        cross = (
            w1 * s2 - w2 * s1,
            w2 * s0 - w0 * s2,
            w0 * s1 - w1 * s0,
            w1 * t2 - w2 * t1 + u1 * s2 - u2 * s1,
            w2 * t0 - w0 * t2 + u2 * s0 - u0 * s2,
            w0 * t1 - w1 * t0 + u0 * s1 - u1 * s0,
        )
        for k in range(6):
            if p < 0:
                base_A = 0.0 if k < 3 else -gravity[k - 3]
            else:
                base_A = ws[p, _A + k]
            ws[i, _A + k] = base_A + cross[k] * vi
        _inertia_times(ws[i], _I, ws[i, _A : _A + 6], ws[i, _F : _F + 6])
        _inertia_times(ws[i], _I, ws[i, _V : _V + 6], IV)
        # V x* (I V) = [w x n + u x f; w x f] for I V = [n; f] (the force cross product).
        n0, n1, n2, f0, f1, f2 = IV[0], IV[1], IV[2], IV[3], IV[4], IV[5]
        ws[i, _F] += w1 * n2 - w2 * n1 + u1 * f2 - u2 * f1
        ws[i, _F + 1] += w2 * n0 - w0 * n2 + u2 * f0 - u0 * f2
        ws[i, _F + 2] += w0 * n1 - w1 * n0 + u0 * f1 - u1 * f0
        ws[i, _F + 3] += w1 * f2 - w2 * f1
        ws[i, _F + 4] += w2 * f0 - w0 * f2
        ws[i, _F + 5] += w0 * f1 - w1 * f0
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
def rotation_to_quaternion(R, out):
    """The unit quaternion [w, x, y, z] of R (3 x 3) into ``out``, w >= 0, by the branch
    on the largest of the trace and the diagonal (Shepperd's method, as Drake's
    ``RotationMatrix::ToQuaternion``)."""
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    if trace >= R[0, 0] and trace >= R[1, 1] and trace >= R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + trace)
        w, x, y, z = (
            0.25 * s,
            (R[2, 1] - R[1, 2]) / s,
            (R[0, 2] - R[2, 0]) / s,
            (R[1, 0] - R[0, 1]) / s,
        )
    elif R[0, 0] >= R[1, 1] and R[0, 0] >= R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        w, x, y, z = (
            (R[2, 1] - R[1, 2]) / s,
            0.25 * s,
            (R[0, 1] + R[1, 0]) / s,
            (R[0, 2] + R[2, 0]) / s,
        )
    elif R[1, 1] >= R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        w, x, y, z = (
            (R[0, 2] - R[2, 0]) / s,
            (R[0, 1] + R[1, 0]) / s,
            0.25 * s,
            (R[1, 2] + R[2, 1]) / s,
        )
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        w, x, y, z = (
            (R[1, 0] - R[0, 1]) / s,
            (R[0, 2] + R[2, 0]) / s,
            (R[1, 2] + R[2, 1]) / s,
            0.25 * s,
        )
    sign = -1.0 if w < 0.0 else 1.0
    norm = sign / math.sqrt(w * w + x * x + y * y + z * z)
    out[0], out[1], out[2], out[3] = w * norm, x * norm, y * norm, z * norm


@njit(**_JIT)
def cholesky_solve(A, b, L, x):
    """x = A^-1 b for a symmetric positive definite A (n x n) by its Cholesky factor,
    written into the scratch ``L`` (n x n); NaN where A is not positive definite
    (the caller's state check stops the start)."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        d = math.sqrt(s) if s > 0.0 else math.nan
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
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
    for r in range(m):
        for c in range(m):
            s = 0.0
            for k in range(J.shape[1]):
                s += J[r, k] * J[c, k]
            G[r, c] = s
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
