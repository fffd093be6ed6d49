"""The arm's start path by the compiled kernels: the joints carried along a camera path.

:func:`geovs_drake.goal.arm.goal_on_branch` carries a start's joints along the NF's
chart path to the goal (512 poses, three damped Newton steps each, then Newton to
rounding at the last) to choose the start's whole turns. Through MultibodyPlant's
context each step costs tens of microseconds of Python; here the whole path is one
numba call on :mod:`~geovs_drake.batch.arm_kernels`' forward kinematics and J_C.

The steps are the same least-squares steps, written in W rather than in C: with
R~ = diag(R_WC, R_WC) orthogonal, ``J_C = R~^T J_W`` and the pose error ``e_C`` as a twist
in C, ``J_C^T (J_C J_C^T + d^2 I)^-1 e_C = J_W^T (J_W J_W^T + d^2 I)^-1 R~ e_C``, so
the kernel forms ``e_W = R~ e_C`` (the rotation error's axis-angle turned into W, the
translation error ``p* - p_WC``) and needs no change of frame of J. The last Newton
steps (d = 0) are the minimum-norm solution ``J^T (J J^T)^-1 e``, numpy's ``lstsq``
where J has full row rank. The results agree with the plant's path to rounding (the
joints at the end to about 1e-12 rad), and the branch chosen from them is the same
(``tests/test_arm_starts.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from geovs_drake.batch import arm_kernels as _k
from geovs_drake.batch.arm_tree import ArmTree, arm_tree

__all__ = ["PathFollower", "follow_path", "warm_arm_ik"]

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}


@njit(**_JIT)
def _newton_step(q, R_t, p_t, damping, tree, scratch):
    """One least-squares step of q towards the camera pose (R_t, p_t) in place; returns
    the pose error before the step (position [m], rotation [rad])."""
    parent, index, kind, frames, axis, camera_body, X_BC, ws = tree
    R_WC, p_WC, R_err, quat, e, J, A, L, y = scratch
    _k.arm_forward(q, parent, index, kind, frames, axis, ws)
    _k.camera_pose(camera_body, X_BC, ws, R_WC, p_WC)
    _k.camera_jacobian_W(camera_body, parent, index, p_WC, ws, J)
    for r in range(3):  # R_err = R_WC^T R_t: the error X_WC^-1 X* in C
        for c in range(3):
            s = 0.0
            for k in range(3):
                s += R_WC[k, r] * R_t[k, c]
            R_err[r, c] = s
    _k.rotation_to_quaternion(R_err, quat)  # w >= 0
    s = math.sqrt(quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3])
    angle = 2.0 * math.atan2(s, quat[0])
    scale = angle / s if s > 0.0 else 2.0  # (axis angle / |v|, its limit 2 at w = 1)
    for r in range(3):  # the axis-angle in W, and the translation error in W
        e[r] = scale * (R_WC[r, 0] * quat[1] + R_WC[r, 1] * quat[2] + R_WC[r, 2] * quat[3])
        e[3 + r] = p_t[r] - p_WC[r]
    dp = math.sqrt(e[3] * e[3] + e[4] * e[4] + e[5] * e[5])
    for r in range(6):
        for c in range(6):
            s = 0.0
            for k in range(J.shape[1]):
                s += J[r, k] * J[c, k]
            A[r, c] = s + (damping * damping if r == c else 0.0)
    _k.cholesky_solve(A, e, L, y)
    for k in range(J.shape[1]):
        s = 0.0
        for r in range(6):
            s += J[r, k] * y[r]
        q[k] += s
    return dp, angle


@njit(**_JIT)
def follow_path(q, R_path, p_path, damping, jump, steps, refine, tolerance, tree, scratch):
    """Carry q (nv, in place) along the camera poses (R_path (n, 3, 3), p_path (n, 3),
    the camera at q at the first): ``steps`` damped steps per pose, ``refine`` undamped
    ones at the last. False where a joint moves more than ``jump`` [rad] over one pose
    (a singularity) or the last pose is missed by ``tolerance`` (m and rad)."""
    before = np.empty(q.shape[0])
    for i in range(1, R_path.shape[0]):
        before[:] = q
        for _ in range(steps):
            _newton_step(q, R_path[i], p_path[i], damping, tree, scratch)
        moved = 0.0
        for k in range(q.shape[0]):
            moved = max(moved, abs(q[k] - before[k]))
        if not moved <= jump:  # (NaN too)
            return False
    last = R_path.shape[0] - 1
    for _ in range(refine):
        _newton_step(q, R_path[last], p_path[last], 0.0, tree, scratch)
    # The error left, from a copy (a step moves q).
    before[:] = q
    dp, dr = _newton_step(before, R_path[last], p_path[last], 0.0, tree, scratch)
    return dp < tolerance[0] and dr < tolerance[1]


class PathFollower:
    """:func:`follow_path` for one arm, its workspace allocated once: the ``follow``
    argument of :func:`geovs_drake.goal.arm.goal_on_branch` (and
    :func:`~geovs_drake.goal.arm.start_branch`)."""

    def __init__(self, tree: ArmTree) -> None:
        nv = tree.nv
        self._tree = (
            tree.parent, tree.index, tree.kind, tree.frames, tree.axis, tree.camera_body,
            tree.X_BC, tree.workspace(),
        )  # fmt: skip
        self._scratch = (
            np.empty((3, 3)), np.empty(3), np.empty((3, 3)), np.empty(4), np.empty(6),
            np.empty((6, nv)), np.empty((6, 6)), np.empty((6, 6)), np.empty(6),
        )  # fmt: skip

    def __call__(
        self,
        q: np.ndarray,
        R_path: np.ndarray,
        p_path: np.ndarray,
        damping: float,
        jump: float,
        steps: int,
        refine: int,
        tolerance: tuple[float, float],
    ) -> np.ndarray | None:
        """The joints at the path's last pose carried from q, or None (:func:`follow_path`)."""
        q = np.array(q, dtype=float)
        R_path = np.ascontiguousarray(R_path, dtype=float)
        p_path = np.ascontiguousarray(p_path, dtype=float)
        ok = follow_path(
            q, R_path, p_path, float(damping), float(jump), int(steps), int(refine),
            np.asarray(tolerance, dtype=float), self._tree, self._scratch,
        )  # fmt: skip
        return q if ok else None


def warm_arm_ik() -> None:
    """Compile :func:`follow_path` (the shipped UR5, a path of two poses) into numba's
    on-disk cache (:mod:`geovs_drake.batch.warm`)."""
    from geovs_drake.systems.arm_model import default_arm_model

    tree = arm_tree(default_arm_model())
    q = np.zeros(tree.nv)
    R_WC, p_WC = tree.camera_pose(q)
    path = (np.array([R_WC, R_WC]), np.array([p_WC, p_WC]))
    PathFollower(tree)(q, *path, 1e-3, 0.5, 1, 1, (1e-6, 1e-6))
