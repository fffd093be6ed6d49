"""The arm in the batch engine: N starts of the arm's closed loop at once.

The right-hand side is :func:`~geovs_drake.batch.arm_rhs.arm_loop_rhs` (the arm's tree
kernels and the loop's, both plants, the effort limits clamped as MultibodyPlant clamps
them); the integrator is the free rig's (:mod:`.engine`): the pair of the loop's Drake
scheme's order (Dormand-Prince 5(4) on the dynamic arm's RK5, Bogacki-Shampine 3(2) on
the kinematic arm's RK3), error-controlled per start at ``config.simulator.accuracy``
under the Drake loop's step limit, a step that would leave D rejected, every accepted
state checked. The checks are the Drake loop's monitor's: the safe domain on the
camera's pose (``left_domain``, ``lost_visibility``, ``non_finite``) and the joints'
position limits, which neither plant enforces (``joint_limit``: a joint outside
``[lower, upper]`` at an accepted state). The monitor's second joint check, a run pinned
on a limit (500 steps within 25 ms), is not made: a start that pins runs on to its
horizon here, ``not_converged``.

The exact sensor or the pinhole camera (``sensor: !Pinhole``: its clock, latency,
prediction and noise, :mod:`.arm_sampled`); the rendered camera on the arm runs through
``simulate()`` or ``sweep --engine drake``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import partial

import numpy as np
from numba import njit

from geovs_drake.batch._checks import JOINT_LIMIT as _JOINT_LIMIT
from geovs_drake.batch._checks import joint_margin as _joint_margin
from geovs_drake.batch._checks import state_status as _state_status
from geovs_drake.batch._pairs import (
    RETRY,
    UNDERFLOW,
    error_norm,
    pair_for,
    solution,
    stage_point,
    step_control,
)
from geovs_drake.batch._threads import batch_kernel, over_starts
from geovs_drake.batch.arm_rhs import (
    SCRATCH_ROWS,
    ArmLoopParameters,
    arm_loop_rhs,
    effort_clamped,
)
from geovs_drake.batch.engine import DEFAULT_STEP, STATUS_NAMES, BatchResult
from geovs_drake.geometry import arm_kernels as _k
from geovs_drake.geometry import kernels

__all__ = ["ARM_STATUS_NAMES", "ArmBatchResult", "run_arm_batch", "warm_arm_engine"]

#: The arm's statuses: the free rig's, then ``joint_limit`` (code 5).
ARM_STATUS_NAMES = (*STATUS_NAMES, "joint_limit")
_pose_error = kernels.pose_error.compiled
_STATE, _POSE = 13, 7


@dataclass
class ArmBatchResult(BatchResult):
    """:class:`~geovs_drake.batch.BatchResult` of the arm, with its joints at the end
    (``final_states`` holds (q, v) or q), the least distance of any joint from its
    limits over the run [rad], and whether an actuator's torque was clamped at its
    effort limit at any accepted state (always False on the kinematic arm)."""

    min_joint_margin: np.ndarray | None = None
    torque_clamped: np.ndarray | None = None


@njit(cache=True, nogil=True, error_model="numpy")
def _rhs(dynamic, x, out, tree, p, scratch):
    """arm_loop_rhs on one start's scratch arrays."""
    parent, index, kind, frames, axis, inertia, joint, camera_body, X_BC, gravity = tree
    p_cam, p_nav, p_ctrl, p_arm, q_mid = p
    ws, J, M, L, A, L6, vec = scratch
    return arm_loop_rhs(
        dynamic, x, out, parent, index, kind, frames, axis, inertia, joint, camera_body,
        X_BC, gravity, p_cam, p_nav, p_ctrl, p_arm, q_mid, ws, J, M, L, A, L6, vec,
    )  # fmt: skip


@batch_kernel
def _integrate_arm(
    dynamic, X0, tree, p, ws_columns, k_p, p_err, h0, max_step, accuracy, t_end, tols, pair
):
    n, dim = X0.shape
    nv = tree[0].shape[0]
    joint = tree[6]
    status = np.ones(n, np.int64)
    t_stop = np.full(n, t_end)
    t_conv = np.full(n, np.nan)
    err_p = np.full(n, np.nan)
    err_r = np.full(n, np.nan)
    min_m = np.full((n, 4), np.inf)
    min_q = np.full(n, np.inf)
    clamped = np.zeros(n, np.bool_)
    L0 = np.full(n, np.nan)
    max_ratio = np.full(n, -np.inf)
    max_rise = np.zeros(n)
    steps = np.zeros(n, np.int64)
    final = X0.copy()
    adaptive = accuracy > 0
    A, B, E, exponent = pair
    stages = B.shape[0]
    for i in range(n):
        scratch = (
            np.zeros((nv, ws_columns)), np.zeros((6, nv)), np.zeros((nv, nv)),
            np.zeros((nv, nv)), np.zeros((6, 6)), np.zeros((6, 6)),
            np.zeros((SCRATCH_ROWS, max(nv, _STATE))),
        )  # fmt: skip
        vec = scratch[6]
        x = X0[i].copy()
        xs = np.empty(dim)
        x_new = np.empty(dim)
        K = np.empty((stages, dim))  # the step's stages (geovs_drake.batch._pairs)
        d = np.empty(dim)
        nu, margins, phi, kinetic = _rhs(dynamic, x, d, tree, p, scratch)
        pose = vec[2, 0:_POSE].copy()  # the camera's [q_WC, p_WC] at x
        t = 0.0
        h = h0
        inside_since = np.nan
        previous = 0.0
        while True:
            # The scratch holds the right-hand side at x (the start, or the step accepted).
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
            if steps[i] == 0:
                L0[i] = lyapunov
            else:
                max_rise[i] = max(max_rise[i], lyapunov - previous)
            previous = lyapunov
            max_ratio[i] = max(max_ratio[i], lyapunov / k_p)
            e = _pose_error(pose, p_err)
            err_p[i] = math.sqrt(e[0])
            err_r[i] = 2.0 * math.asin(min(1.0, math.sqrt(e[1] / 8.0)))
            if e[0] > tols[0] or e[1] > tols[1]:
                inside_since = np.nan
            elif math.isnan(inside_since):
                inside_since = t
            if t >= t_end:
                break
            for j in range(dim):
                K[0, j] = d[j]
            accepted = False
            while True:
                last = h >= t_end - t
                if last:
                    h = t_end - t
                h = min(h, max_step)
                for s in range(1, stages):
                    stage_point(A, s, x, h, K, xs)
                    _rhs(dynamic, xs, K[s], tree, p, scratch)
                solution(B, x, h, K, x_new)
                nu, margins, phi, kinetic = _rhs(dynamic, x_new, d, tree, p, scratch)
                grow = 1.0
                if adaptive:
                    outside = _state_status(x_new, nu, margins, phi) != 1
                    err = error_norm(E, x, h, K, d)
                    verdict, grow = step_control(err, accuracy, outside, h, exponent)
                    if verdict == RETRY:
                        h *= grow
                        continue
                    if verdict == UNDERFLOW:
                        break
                accepted = True
                t = t_end if last and h == t_end - t else t + h
                h *= grow
                break
            if not accepted:
                status[i] = 4
                t_stop[i] = t
                break
            for j in range(dim):
                x[j] = x_new[j]
            pose[:] = vec[2, 0:_POSE]
            steps[i] += 1
        final[i] = x
        if status[i] == 1 and not math.isnan(inside_since):
            status[i] = 0
            t_conv[i] = inside_since
    return (
        status, t_stop, t_conv, err_p, err_r, min_m, L0, max_ratio, max_rise, steps, final, min_q,
        clamped,
    )  # fmt: skip


def _exact_arm(*args) -> tuple:
    """:func:`_integrate_arm` with the exact sensor, X0's starts (its second argument) on
    threads (:func:`~geovs_drake.batch._threads.over_starts`)."""
    return over_starts(_integrate_arm, args, per_start=(1,))


def run_arm_batch(
    p: ArmLoopParameters,
    X_WC_goal: np.ndarray,
    q0: np.ndarray,
    v0: np.ndarray | None,
    duration: float,
    accuracy: float,
    tolerance: tuple[float, float],
    seeds: np.ndarray | None = None,
) -> ArmBatchResult:
    """Integrate the arm's loop ``p`` from the joints ``q0`` (N, nv) and velocities
    ``v0`` (dynamic only; zero if None) for ``duration`` [s], error-controlled at
    ``accuracy``; ``X_WC_goal`` (4x4) the camera's goal pose in W, ``tolerance`` the
    (position [m], rotation [rad]) within which a start counts as converged. With the
    pinhole (``p.sampled``), ``seeds`` are its noise seeds per start (N,), ``sensor.seed
    + i`` by default (:mod:`.arm_sampled`)."""
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be finite and > 0: duration = {duration}")
    if not (math.isfinite(accuracy) and 0 < accuracy < 1):
        raise ValueError(f"accuracy must be in (0, 1): accuracy = {accuracy}")
    q0 = np.atleast_2d(np.asarray(q0, dtype=float))
    n, nv = q0.shape
    X0 = q0.copy()
    if p.dynamic:
        v0 = np.zeros((n, nv)) if v0 is None else np.asarray(v0, dtype=float).reshape(n, nv)
        X0 = np.ascontiguousarray(np.hstack([q0, v0]))
    goal = np.asarray(X_WC_goal, dtype=float)
    p_err = np.concatenate([np.eye(3).ravel(), np.zeros(3), goal[:3, :3].ravel(), goal[:3, 3]])
    max_step = p.max_step_size
    tols = np.array([tolerance[0] ** 2, 8.0 * math.sin(0.5 * tolerance[1]) ** 2])
    names, integrate = ARM_STATUS_NAMES, _exact_arm
    if p.sampled is not None:  # the pinhole: the same arguments, its seeds and clock added
        names, integrate = (*ARM_STATUS_NAMES, "feature_lost"), partial(_sampled, p, seeds)
    out = integrate(
        p.dynamic, X0, p.tree.kernel_args(),
        (p.camera, p.navigation, p.controller, p.arm, p.q_mid), _k.WS_COLUMNS,
        float(p.potential_gain), p_err, float(min(DEFAULT_STEP, max_step)), float(max_step),
        float(accuracy), float(duration), tols, pair_for(p.scheme).kernel_args(),
    )  # fmt: skip
    status, t_stop, t_conv, err_p, err_r, min_m, L0, max_ratio, max_rise, steps, final = out[:11]
    return ArmBatchResult(
        plant=p.plant,
        step=math.nan,
        accuracy=float(accuracy),
        duration=float(duration),
        status_code=status,
        t_stop=t_stop,
        t_converged=t_conv,
        final_position_error_m=err_p,
        final_rotation_error_rad=err_r,
        min_margins=min_m,
        initial_lyapunov=L0,
        max_lyapunov_ratio=max_ratio,
        max_lyapunov_rise=max_rise,
        steps=steps,
        final_states=final,
        names=names,
        min_joint_margin=out[11],
        torque_clamped=out[12],
    )


def _sampled(
    p, seeds, dynamic, X0, tree, vectors, ws_columns, k_p, p_err, h0, max_step, accuracy,
    duration, tols, pair,
) -> tuple:  # fmt: skip
    """The pinhole's run (:func:`~geovs_drake.batch.arm_sampled.run_arm_sampled`) on
    :func:`_integrate_arm`'s arguments."""
    from geovs_drake.batch.arm_sampled import run_arm_sampled

    n = len(X0)
    seeds = p.sampled.seed + np.arange(n) if seeds is None else np.asarray(seeds)
    if seeds.shape != (n,):
        raise ValueError(f"seeds must have one entry per start ({n}): shape {seeds.shape}")
    settings = dict(
        h0=h0, max_step=max_step, accuracy=accuracy, duration=duration, tols=tols,
        p_err=p_err, ws_columns=ws_columns, seeds=seeds, pair=pair,
    )  # fmt: skip
    return run_arm_sampled(p, X0, settings, len(ARM_STATUS_NAMES))


def warm_arm_engine() -> None:
    """Compile the arm's integrator on both plants (the shipped UR5), with the exact
    sensor and the pinhole, into numba's on-disk cache (:mod:`geovs_drake.batch.warm`)."""
    from geovs_drake.batch.arm_rhs import arm_loop_parameters
    from geovs_drake.scenario import Arm, Dynamic, Exact, Kinematic, Pinhole, ScenarioConfig

    for plant, sensor in itertools.product((Dynamic(), Kinematic()), (Exact(), Pinhole())):
        p = arm_loop_parameters(ScenarioConfig(carrier=Arm(), plant=plant, sensor=sensor))
        run_arm_batch(p, np.eye(4), np.zeros((1, p.tree.nv)), None, 0.01, 1e-6, (1e-3, 1e-3))
