"""The arm's start path by the compiled kernels: the joints carried along a camera path.

:func:`geovs_drake.goal.arm.goal_on_branch` carries a start's joints along the NF's
chart path to the goal (512 poses, three damped Newton steps each, then Newton to
rounding at the last) to choose the start's whole turns. Through MultibodyPlant's
context each step costs tens of microseconds of Python; here the whole path is one
numba call on :mod:`~geovs_drake.geometry.arm_kernels`' forward kinematics and J_C.

The steps are the same least-squares steps, written in W rather than in C: with
R~ = diag(R_WC, R_WC) orthogonal, ``J_C = R~^T J_W`` and the pose error ``e_C`` as a twist
in C, ``J_C^T (J_C J_C^T + d^2 I)^-1 e_C = J_W^T (J_W J_W^T + d^2 I)^-1 R~ e_C``, so
the kernel forms ``e_W = R~ e_C`` (the rotation error's axis-angle turned into W, the
translation error ``p* - p_WC``) and needs no change of frame of J. The last Newton
steps (d = 0) are the minimum-norm solution ``J^T (J J^T)^-1 e``, numpy's ``lstsq``
where J has full row rank. The results agree with the plant's path to rounding (the
joints at the end to about 1e-12 rad), and the branch chosen from them is the same
(``tests/test_arm_starts.py``).

:class:`StartSolver` is the sweep's IK of its starts on the same kernels (Drake's
``InverseKinematics``, 13 SNOPT solves a pose, cost 45 ms a start): all of a part's
poses in one call of :func:`solve_poses`, from the seeds of
:func:`~geovs_drake.goal.ik_choice.ik_seeds`, each by Levenberg-Marquardt (the damped
step above, its damping Sugihara's) with the joints kept in their limits (whole turns
where a joint's range spans one, else clipped), then Newton to rounding; the solution
kept by the score and tie rule of :mod:`geovs_drake.goal.ik_choice`, as Drake's IK keeps
its own. The two end on different solutions from some seeds (their ways differ), so
the starts are not Drake's to the bit: ``tests/test_arm_start_ik.py`` and docs/arm.md
give the agreement.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from geovs_drake.geometry import arm_kernels as _k
from geovs_drake.geometry.so3 import rotation_to_quaternion
from geovs_drake.systems.arm_model import ArmModel
from geovs_drake.systems.arm_tree import ArmTree, arm_tree

__all__ = [
    "IK_BIAS",
    "IK_ITERATIONS",
    "IK_REACHED",
    "IK_REFINE",
    "IK_STALL",
    "PathFollower",
    "StartSolver",
    "follow_path",
    "solve_poses",
    "warm_arm_ik",
    "warm_start_solver",
]

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
#: The compiled IK's Levenberg-Marquardt steps from a seed at most.
IK_ITERATIONS = 100
#: The bias of its damping, ``lambda = |e|^2 / 2 + bias`` [m^2, rad^2] (Sugihara 2011).
IK_BIAS = 1e-6
#: Its Newton steps to rounding after a seed converges (goal.arm's refinement's).
IK_REFINE = 4
#: Steps without the error falling by a tenth after which a seed is given up (measured
#: on 500 sweep poses of each arm: 0.56 ms a UR5 pose against 1.11 ms without, the same
#: poses reached, the same joints on 328 of 330).
IK_STALL = 20
#: The camera's pose error a compiled solution may leave [m] and [rad]: Newton's steps
#: bring one to rounding (1e-15), unless a joint limit stops them (a redundant arm's
#: solution pressed on a limit, 1e-7 off the pose: not a solution).
IK_REACHED = 1e-10


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
    rotation_to_quaternion(R_err, quat)  # w >= 0
    s = math.sqrt(quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3])
    angle = 2.0 * math.atan2(s, quat[0])
    scale = angle / s if s > 0.0 else 2.0  # (axis angle / |v|, its limit 2 at w = 1)
    for r in range(3):  # the axis-angle in W, and the translation error in W
        e[r] = scale * (R_WC[r, 0] * quat[1] + R_WC[r, 1] * quat[2] + R_WC[r, 2] * quat[3])
        e[3 + r] = p_t[r] - p_WC[r]
    dp = math.sqrt(e[3] * e[3] + e[4] * e[4] + e[5] * e[5])
    for r in range(6):  # J J^T + d^2 I, one triangle (the same sums, bit for bit)
        for c in range(r, 6):
            s = 0.0
            for k in range(J.shape[1]):
                s += J[r, k] * J[c, k]
            A[r, c] = A[c, r] = s + (damping * damping if r == c else 0.0)
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


@njit(**_JIT)
def _keep_in_limits(q, lower, upper, turns):
    """q into [lower, upper] in place: by whole turns where ``turns`` (a revolute joint
    whose range spans one: the same camera pose), else clipped."""
    for k in range(q.shape[0]):
        if turns[k] and q[k] > upper[k]:
            q[k] -= 2.0 * math.pi * math.ceil((q[k] - upper[k]) / (2.0 * math.pi))
        elif turns[k] and q[k] < lower[k]:
            q[k] += 2.0 * math.pi * math.ceil((lower[k] - q[k]) / (2.0 * math.pi))
        q[k] = min(max(q[k], lower[k]), upper[k])


@njit(**_JIT)
def _solve_seed(q, R_t, p_t, lower, upper, turns, iterations, bias, stall, tree, scratch):
    """Levenberg-Marquardt from q (in place) towards the camera pose (R_t, p_t), the
    joints clipped to [lower, upper] after each step; returns the last error (m, rad)."""
    damping = 1.0  # (the first step's: the seed's error is yet unknown)
    dp = dr = best = math.inf
    stalled = 0
    for _ in range(iterations):
        dp, dr = _newton_step(q, R_t, p_t, damping, tree, scratch)
        _keep_in_limits(q, lower, upper, turns)
        squared = dp * dp + dr * dr
        if squared < 1e-24:  # (the step just taken brought it to rounding)
            break
        # A seed whose error has not fallen by a tenth in IK_STALL steps is stuck (on a
        # limit, or at a pose out of reach): the next seed.
        if squared < 0.81 * best:
            best, stalled = squared, 0
        else:
            stalled += 1
            if stalled >= stall:
                break
        # Sugihara's damping (2011): lambda = E + bias with E = |e|^2 / 2, Gauss-Newton
        # near a solution, a bounded step far from one and near a singularity.
        damping = math.sqrt(0.5 * squared + bias)
    return dp, dr


@njit(**_JIT)
def solve_poses(
    R_t, p_t, seeds, lower, upper, turns, settings, tree, scratch, q, reached, margin, sigma
):
    """IK of each camera pose (R_t (n, 3, 3), p_t (n, 3)) from each seed (s, nv): q (n,
    s, nv) the joints reached, ``reached`` (n, s) where they meet the pose inside the
    limits, ``margin`` (n, s) their nearest limit's margin [rad] and ``sigma`` (n, s)
    sigma_min(J_C) there (that of J in W: the same singular values). ``settings``:
    [iterations, bias, stall, refine steps, the error [m, rad] below which they refine,
    the error a solution may leave]."""
    iterations, bias, stall, refine = (
        int(settings[0]),
        settings[1],
        int(settings[2]),
        int(settings[3]),
    )
    J, G = scratch[5], np.empty((6, 6))
    before = np.empty(seeds.shape[1])
    for i in range(R_t.shape[0]):
        for s in range(seeds.shape[0]):
            qs = q[i, s]
            qs[:] = seeds[s]
            reached[i, s] = False
            margin[i, s] = sigma[i, s] = math.nan
            dp, dr = _solve_seed(
                qs, R_t[i], p_t[i], lower, upper, turns, iterations, bias, stall, tree, scratch
            )
            if not (dp < settings[4] and dr < settings[4]):  # (NaN too) no solution here
                continue
            for _ in range(refine):  # Newton to rounding, as goal.arm's _refine, in limits
                _newton_step(qs, R_t[i], p_t[i], 0.0, tree, scratch)
                _keep_in_limits(qs, lower, upper, turns)
            before[:] = qs  # the error left, from a copy (a step moves q); J at qs
            dp, dr = _newton_step(before, R_t[i], p_t[i], 0.0, tree, scratch)
            m = math.inf
            for k in range(qs.shape[0]):
                m = min(m, qs[k] - lower[k], upper[k] - qs[k])
            margin[i, s] = m
            sigma[i, s] = _k.min_singular_value(J, G) if J.shape[1] >= 6 else 0.0
            reached[i, s] = dp < settings[5] and dr < settings[5] and m >= 0.0


class StartSolver:
    """The sweep's IK compiled: for many camera poses at once, each from
    :func:`~geovs_drake.goal.ik_choice.ik_seeds`' seeds (Levenberg-Marquardt in the
    joint limits, then Newton to rounding: :func:`solve_poses`), the solution kept by
    :func:`~geovs_drake.goal.ik_choice.ik_score` and
    :func:`~geovs_drake.goal.ik_choice.better_solution`, as Drake's
    :func:`~geovs_drake.goal.arm.solve_joints` keeps its own."""

    def __init__(self, model: ArmModel) -> None:
        """The solver of ``model``'s arm: its limits, seeds and kernels' arrays."""
        from geovs_drake.goal.ik_choice import ik_seeds
        from geovs_drake.systems.arm_model import arm_plant

        plant = arm_plant(model)
        self._lower = np.asarray(plant.GetPositionLowerLimits(), dtype=float)
        self._upper = np.asarray(plant.GetPositionUpperLimits(), dtype=float)
        self._seeds = ik_seeds(self._lower, self._upper)
        tree = arm_tree(model)
        self._follower = PathFollower(tree)
        # The revolute joints whose range spans a whole turn: wrapped, not clipped.
        revolute = np.zeros(len(self._lower), bool)
        revolute[tree.index[:, 0]] = tree.kind == _k.KIND_REVOLUTE
        self._turns = revolute & (self._upper - self._lower >= 2 * np.pi)

    def __call__(self, R_WC: np.ndarray, p_WC: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The joints (n, nq) that put the camera at each pose (R_WC (n, 3, 3), p_WC (n,
        3)), and whether each was reached (n,; its joints NaN where not)."""
        from geovs_drake.goal.arm import IK_POSITION_TOLERANCE
        from geovs_drake.goal.ik_choice import better_solution, ik_score

        R_WC = np.ascontiguousarray(R_WC, dtype=float).reshape(-1, 3, 3)
        p_WC = np.ascontiguousarray(p_WC, dtype=float).reshape(-1, 3)
        n, (s, nq) = len(R_WC), self._seeds.shape
        q, reached = np.empty((n, s, nq)), np.zeros((n, s), bool)
        margin, sigma = np.empty((n, s)), np.empty((n, s))
        settings = np.array(
            [IK_ITERATIONS, IK_BIAS, IK_STALL, IK_REFINE, IK_POSITION_TOLERANCE, IK_REACHED]
        )
        f = self._follower
        solve_poses(
            R_WC, p_WC, self._seeds, self._lower, self._upper, self._turns, settings, f._tree,
            f._scratch,
            q, reached, margin, sigma,
        )  # fmt: skip
        score = ik_score(margin, sigma)
        out = np.full((n, nq), np.nan)
        for i in range(n):
            best, best_score = None, -np.inf
            for k in np.flatnonzero(reached[i]):  # the seeds' order, as Drake's IK
                if better_solution(q[i, k], score[i, k], best, best_score):
                    best, best_score = q[i, k], score[i, k]
            if best is not None:
                out[i] = best
        return out, reached.any(axis=1)


def warm_arm_ik() -> None:
    """Compile :func:`follow_path` (the shipped UR5, a path of two poses) into numba's
    on-disk cache (:mod:`geovs_drake.batch.warm`)."""
    from geovs_drake.systems.arm_model import default_arm_model

    tree = arm_tree(default_arm_model())
    q = np.zeros(tree.nv)
    R_WC, p_WC = tree.camera_pose(q)
    path = (np.array([R_WC, R_WC]), np.array([p_WC, p_WC]))
    PathFollower(tree)(q, *path, 1e-3, 0.5, 1, 1, (1e-6, 1e-6))


def warm_start_solver() -> None:
    """Compile :func:`solve_poses` (the shipped UR5, one pose) into numba's on-disk cache
    (:mod:`geovs_drake.batch.warm`'s arm half)."""
    from geovs_drake.systems.arm_model import default_arm_model

    model = default_arm_model()
    R_WC, p_WC = arm_tree(model).camera_pose(np.zeros(6))
    StartSolver(model)(R_WC[None], p_WC[None])
