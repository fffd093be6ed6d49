"""The arm with the pinhole camera in the batch engine: the free rig's camera clock on the
arm's loop.

The Drake loop puts the pinhole sensor
(:func:`geovs_drake.loop.sensors.add_pinhole_sensor`) on the arm's camera pose
(``ArmCamera``'s or ``KinematicArm``'s, X_RC = I) and, with ``prediction: odometry``, a
:class:`~geovs_drake.systems.FramePredictor` on the same pose: the arm's own odometry,
the camera pose from the joints. This module runs that on N starts with the sampled
camera's clock, line, noise and refusals of :mod:`.sampled`
(:func:`~geovs_drake.batch.sampled.frame_clock`: frames at the camera's rate and capture
offset, each start's integration stopping at every frame, latency in frames, pixel noise
from ``default_rng([seeds[i], k])``), measuring each frame at the camera pose the joints
give, and between frames the arm's right-hand side with the law on the held (or
predicted) frame (:func:`~geovs_drake.batch.arm_rhs.arm_loop_rhs_held`). The integrator,
its checks and records are :mod:`.arm_engine`'s (the pair of the loop's scheme's order
per start, a step that would leave D rejected, the joint limits checked at each accepted
state); the safe domain, the energy and the pose error are the exact camera's at the
state, as the Drake loop's monitor reads them. A start whose frames stay lost stops
``feature_lost``."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from geovs_drake.batch._checks import JOINT_LIMIT as _JOINT_LIMIT
from geovs_drake.batch._checks import joint_margin as _joint_margin
from geovs_drake.batch._checks import state_status as _state_status
from geovs_drake.batch._pairs import (
    RETRY,
    UNDERFLOW,
    error_norm,
    solution,
    stage_point,
    step_control,
    step_to_frame,
)
from geovs_drake.batch._threads import batch_kernel, over_starts
from geovs_drake.batch.arm_rhs import (
    SCRATCH_ROWS,
    ArmLoopParameters,
    arm_loop_rhs,
    arm_loop_rhs_held,
    effort_clamped,
)
from geovs_drake.batch.sampled import frame_clock
from geovs_drake.geometry import kernels

__all__ = ["run_arm_sampled"]

_pose_error = kernels.pose_error.compiled
_STATE, _POSE = 13, 7
_ROW_STATE = 2  # the camera state's row of the scratch ``vec`` (arm_rhs)


@njit(cache=True, nogil=True, error_model="numpy")
def _scratch(nv, ws_columns):
    """One start's scratch arrays for the arm's right-hand side."""
    return (
        np.zeros((nv, ws_columns)), np.zeros((6, nv)), np.zeros((nv, nv)), np.zeros((nv, nv)),
        np.zeros((6, 6)), np.zeros((6, 6)), np.zeros((SCRATCH_ROWS, max(nv, _STATE))),
    )  # fmt: skip


@njit(cache=True, nogil=True, error_model="numpy")
def _rhs(dynamic, x, out, y, then, predict, p_pred, tree, p, scratch):
    """arm_loop_rhs_held on one start's scratch arrays."""
    parent, index, kind, frames, axis, inertia, joint, camera_body, X_BC, gravity = tree
    p_cam, p_nav, p_ctrl, p_arm, q_mid = p
    ws, J, M, L, A, L6, vec = scratch
    return arm_loop_rhs_held(
        dynamic, x, out, y, then, predict, p_pred, parent, index, kind, frames, axis,
        inertia, joint, camera_body, X_BC, gravity, p_cam, p_nav, p_ctrl, p_arm, q_mid, ws,
        J, M, L, A, L6, vec,
    )  # fmt: skip


# Not parallel: one right-hand side a start, once a run (microseconds), where a parallel
# kernel costs about 4 s of compiling on a fresh checkout.
@njit(cache=True, nogil=True, error_model="numpy")
def _camera_poses(dynamic, X, tree, p, ws_columns):
    """Each start's camera pose ``[q_WC, p_WC]`` (N, 7) at its joints: what the pinhole
    measures its first frame from."""
    n, dim = X.shape
    poses = np.empty((n, _POSE))
    parent, index, kind, frames, axis, inertia, joint, camera_body, X_BC, gravity = tree
    p_cam, p_nav, p_ctrl, p_arm, q_mid = p
    for i in range(n):
        ws, J, M, L, A, L6, vec = _scratch(parent.shape[0], ws_columns)
        arm_loop_rhs(
            dynamic, X[i].copy(), np.empty(dim), parent, index, kind, frames, axis, inertia,
            joint, camera_body, X_BC, gravity, p_cam, p_nav, p_ctrl, p_arm, q_mid, ws, J, M, L,
            A, L6, vec,
        )  # fmt: skip
        poses[i] = vec[_ROW_STATE, 0:_POSE]
    return poses


#: :func:`_advance_arm`'s arguments over the starts (:func:`~._threads.over_starts`
#: splits them): X, H, POSES, Y, THEN, PRED, the records ``rec`` and min_m.
_ADVANCE_PER_START = (1, 2, 3, 6, 7, 8, 9, 10)


@batch_kernel
def _advance_arm(
    dynamic, X, H, POSES, t0, t1, Y, THEN, PRED, rec, min_m, tree, p, ws_columns, settings
):
    """Every running start (``rec[0]``, status, 1) from t0 to t1, the law on its frame
    ``Y[i]`` (moved from the camera pose ``THEN[i]`` where ``PRED[i]``): the arm engine's
    step, checks and records (``rec``: status, t_stop, steps, L0, prev_L, max_ratio,
    max_rise, inside, err_p, err_r, min_q, clamped), the next step size kept in ``H`` and the
    camera pose at the last state in ``POSES`` (the next frame's)."""
    status, t_stop, steps, L0, prev_L, max_ratio, max_rise, inside, err_p, err_r, min_q = rec[:11]
    clamped = rec[11]
    p_pred, p_err, tols, k_p, max_step, accuracy, pair = settings
    A, B, E, exponent = pair
    stages = B.shape[0]
    n, dim = X.shape
    nv = tree[0].shape[0]
    joint = tree[6]
    adaptive = accuracy > 0
    for i in range(n):
        if status[i] != 1:
            continue
        scratch = _scratch(nv, ws_columns)
        vec = scratch[6]
        x = X[i].copy()
        y, then, pred = Y[i], THEN[i], PRED[i]
        xs, x_new = np.empty(dim), np.empty(dim)
        K, d = np.empty((stages, dim)), np.empty(dim)  # the stages (geovs_drake.batch._pairs)
        nu, margins, phi, kinetic = _rhs(dynamic, x, d, y, then, pred, p_pred, tree, p, scratch)
        pose = vec[_ROW_STATE, 0:_POSE].copy()
        t = t0
        h = H[i]
        while True:
            # The scratch holds the right-hand side at x (the frame's first state, or the
            # step accepted), as the exact sensor's engine reads it.
            if dynamic and not clamped[i]:
                clamped[i] = effort_clamped(x, joint, vec)
            status[i] = _state_status(x, nu, margins, phi)
            q_margin = _joint_margin(x, joint)
            if status[i] == 1 and q_margin < 0:
                status[i] = _JOINT_LIMIT
            min_q[i] = min(min_q[i], q_margin)
            if status[i] == 2:
                for j in range(4):
                    min_m[i, j] = min(min_m[i, j], margins[j])
            if status[i] != 1:
                t_stop[i] = t
                break
            for j in range(4):
                min_m[i, j] = min(min_m[i, j], margins[j])
            lyapunov = kinetic + k_p * phi
            if steps[i] == 0 and math.isnan(L0[i]):
                L0[i] = lyapunov
            else:
                max_rise[i] = max(max_rise[i], lyapunov - prev_L[i])
            prev_L[i] = lyapunov
            max_ratio[i] = max(max_ratio[i], lyapunov / k_p)
            e = _pose_error(pose, p_err)
            err_p[i] = math.sqrt(e[0])
            err_r[i] = 2.0 * math.asin(min(1.0, math.sqrt(e[1] / 8.0)))
            if e[0] > tols[0] or e[1] > tols[1]:
                inside[i] = np.nan
            elif math.isnan(inside[i]):
                inside[i] = t
            if t >= t1:
                break
            for j in range(dim):
                K[0, j] = d[j]
            accepted = False
            while True:
                h_try = min(h, max_step)
                last = h_try >= t1 - t
                hh = t1 - t if last else h_try
                for s in range(1, stages):
                    stage_point(A, s, x, hh, K, xs)
                    _rhs(dynamic, xs, K[s], y, then, pred, p_pred, tree, p, scratch)
                solution(B, x, hh, K, x_new)
                nu, margins, phi, kinetic = _rhs(
                    dynamic, x_new, d, y, then, pred, p_pred, tree, p, scratch
                )
                grow = 1.0
                if adaptive:
                    outside = _state_status(x_new, nu, margins, phi) != 1
                    err = error_norm(E, x, hh, K, d)
                    verdict, grow = step_control(err, accuracy, outside, hh, exponent)
                    if verdict == RETRY:
                        h = hh * grow
                        continue
                    if verdict == UNDERFLOW:
                        break
                accepted = True
                t, h = step_to_frame(t, t1, hh, h_try, grow, last)
                break
            if not accepted:
                status[i] = 4
                t_stop[i] = t
                break
            for j in range(dim):
                x[j] = x_new[j]
            pose[:] = vec[_ROW_STATE, 0:_POSE]
            steps[i] += 1
        X[i] = x
        H[i] = h
        POSES[i] = pose


def run_arm_sampled(p: ArmLoopParameters, X0: np.ndarray, settings: dict, lost: int) -> tuple:
    """Integrate the arm's loop ``p`` (``p.sampled`` set) from the states ``X0`` (N, the
    plant's layout) through its pinhole camera (module docstring). ``settings``: h0,
    max_step, accuracy, duration, tols (squared position and chord errors), p_err (the
    pose error's parameters), ws_columns, seeds (N,); ``lost``: the status code of
    ``feature_lost``. Returns the arm engine's tuple of per-start arrays."""
    cam = p.sampled
    n, _ = X0.shape
    X = np.ascontiguousarray(X0, dtype=float).copy()
    H = np.full(n, settings["h0"])
    status = np.ones(n, np.int64)
    t_stop = np.full(n, settings["duration"])
    steps = np.zeros(n, np.int64)
    L0, prev_L, inside = np.full(n, np.nan), np.zeros(n), np.full(n, np.nan)
    max_ratio, max_rise = np.full(n, -np.inf), np.zeros(n)
    err_p, err_r = np.full(n, np.nan), np.full(n, np.nan)
    min_m, min_q = np.full((n, 4), np.inf), np.full(n, np.inf)
    clamped = np.zeros(n, np.bool_)
    rec = (
        status, t_stop, steps, L0, prev_L, max_ratio, max_rise, inside, err_p, err_r, min_q,
        clamped,
    )  # fmt: skip
    tree = p.tree.kernel_args()
    vectors = (p.camera, p.navigation, p.controller, p.arm, p.q_mid)
    columns = settings["ws_columns"]
    step = (
        cam.predictor, settings["p_err"], settings["tols"], float(p.potential_gain),
        float(settings["max_step"]), float(settings["accuracy"]), settings["pair"],
    )  # fmt: skip

    # The camera poses at t = 0, then each interval's last (the running starts' only:
    # frame_clock reads no other).
    POSES = _camera_poses(p.dynamic, X, tree, vectors, columns)

    def advance(t0, t1, Y, THEN, PRED) -> None:
        args = (
            p.dynamic, X, H, POSES, float(t0), float(t1), Y, THEN, PRED, rec, min_m, tree,
            vectors, columns, step,
        )  # fmt: skip
        over_starts(_advance_arm, args, _ADVANCE_PER_START)

    frame_clock(cam, lambda: POSES, advance, status, t_stop, settings, lost)
    t_conv = np.full(n, np.nan)
    converged = (status == 1) & ~np.isnan(inside)
    status[converged], t_conv[converged] = 0, inside[converged]
    return (
        status, t_stop, t_conv, err_p, err_r, min_m, L0, max_ratio, max_rise, steps, X, min_q,
        clamped,
    )  # fmt: skip
