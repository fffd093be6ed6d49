"""The batch engine's sampled camera: the pinhole at its rate, as the Drake loop runs it.

The Drake loop's pinhole sensor (:func:`geovs_drake.loop.sensors.add_pinhole_sensor`)
measures once per frame and holds; this module runs the same clock on N starts:

* frames are read at ``offset + k period`` (and at t = 0 where the offset is 0; the
  offset is the first capture, ``capture_offset``), each start's integration stopping
  at every read, where Drake's periodic event stops its integrator;
* a read measures the start's pose with
  :func:`~geovs_drake.geometry.features.pinhole_measurement` (the exact limb and marks
  through the true intrinsics, pixel noise, lifted by the believed ones, the same fit),
  keeps a line of ``latency_frames + 1`` frames and hands the oldest on, a failed
  frame keeping the last good y and counting the frames lost
  (:mod:`geovs_drake.systems._held_frames`); past ``max_lost_frames`` the start stops
  ``feature_lost``;
* between reads the law reads the held frame (``prediction: none``) or the held frame
  moved by the rig's motion since (``odometry``: the Smith predictor of
  :class:`~geovs_drake.systems.FramePredictor`, the same formula generated into
  :mod:`geovs_drake.batch._generated.predicted`), and the goal image before the first
  frame (:class:`~geovs_drake.systems.FrameWait`);
* the safe domain, the Lyapunov function and the pose error are the exact camera's,
  as the Drake loop's monitor reads them.

**Noise, per start.** Start i's frame k draws its pixel noise from
``default_rng([seeds[i], k])``, the pinhole sensor's own rule with ``seed = seeds[i]``:
so start i is the Drake loop's run with ``sensor.seed = seeds[i]``, reproducible, and
different starts draw different noise (``seeds`` default: ``sensor.seed + i``).

A camera whose frames arrive after their capture (``output_delay > 0``) is not run here
(its capture pose would need a second stop per frame): :func:`camera_parameters`
refuses it in one line, and such a loop runs through ``simulate()``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from geovs_drake.batch._checks import state_status as _state_status
from geovs_drake.batch._generated.predicted import predicted_image
from geovs_drake.batch._pairs import (
    RETRY,
    UNDERFLOW,
    error_norm,
    pair_for,
    solution,
    stage_point,
    step_control,
    step_to_frame,
)
from geovs_drake.batch._threads import batch_kernel, over_starts
from geovs_drake.geometry import kernels
from geovs_drake.geometry.kernels import CAMERA_IMAGE, FREE_BODY, NAVIGATION, SERVO_FORCE

if TYPE_CHECKING:
    from geovs_drake.loop.resolved import ResolvedScenario

__all__ = [
    "FEATURE_LOST",
    "SampledCamera",
    "camera_parameters",
    "frame_clock",
    "run_sampled",
]

#: The status code of a start whose held frame gave no y (after ``STATUS_NAMES``).
FEATURE_LOST = 5

_camera = kernels.camera_image.compiled
_navigation = kernels.navigation.compiled
_force = kernels.servo_force.compiled
_free_body = kernels.free_body.compiled
_kinematic_velocity = kernels.kinematic_velocity.compiled
_kinematic_body = kernels.kinematic_body.compiled
_pose_error = kernels.pose_error.compiled
_predicted = njit(cache=True, error_model="numpy", nogil=True)(predicted_image)

_NU = CAMERA_IMAGE.nu
_Y0, _Y1 = CAMERA_IMAGE.y.start, CAMERA_IMAGE.y.stop
_M0, _M1 = CAMERA_IMAGE.margins.start, CAMERA_IMAGE.margins.stop
_D0, _D1 = NAVIGATION.dphi.start, NAVIGATION.dphi.stop
_PHI = NAVIGATION.phi
_F0, _F1 = SERVO_FORCE.generalized.start, SERVO_FORCE.generalized.stop
_KINETIC = FREE_BODY.kinetic_energy
_POSE, _FREE_STATE, _KINEMATIC_STATE = 7, 13, 7
_Y_SIZE = 13


@dataclass(frozen=True)
class SampledCamera:
    """The pinhole camera's clock, line and measurement, read from a loop's diagram."""

    period: float  # [s] between frames
    offset: float  # [s] the first frame's read (0: a frame at t = 0)
    latency_frames: int
    max_lost_frames: int
    predict: bool  # odometry prediction between frames (else the held frame)
    pixel_noise: float  # [px] per axis
    seed: int
    sensor: np.ndarray  # PinholeFeatureSensor's parameter vector
    size: tuple[int, int]  # the image's width and height [px]
    predictor: np.ndarray  # [believed radius, R_RC (9), p_RC (3)]
    y_goal: np.ndarray  # what the law reads before the first frame


def camera_parameters(
    resolved: ResolvedScenario, diagram, root, camera_offset: np.ndarray
) -> SampledCamera:
    """The pinhole sensor ``feature_sensor`` of ``diagram`` (its parameters in the
    context ``root``), ``resolved``'s camera clock and the camera on the rig
    (``camera_offset``: ``[R_RC, p_RC]``, the exact camera's); ValueError for a camera
    whose frames arrive after their capture (module docstring)."""
    cam = resolved.config.sensor
    if cam.output_delay > 0:
        raise ValueError(
            f"the batch engine reads a frame when it is taken: sensor.output_delay = "
            f"{cam.output_delay} > 0 runs through simulate() or sweep --engine drake"
        )
    sensor = diagram.GetSubsystemByName("feature_sensor")
    values = sensor.GetMyContextFromRoot(root).get_numeric_parameter(0).CopyToVector()
    intrinsics = cam.intrinsics(resolved.domain.fov_half_angle)
    predictor = np.concatenate([[resolved.believed_radius], camera_offset])
    return SampledCamera(
        period=1.0 / cam.rate,
        offset=float(cam.first_frame_time),
        latency_frames=int(cam.latency_frames),
        max_lost_frames=int(cam.max_lost_frames),
        predict=cam.prediction == "odometry",
        pixel_noise=float(cam.pixel_noise),
        seed=int(cam.seed),
        sensor=np.asarray(values, dtype=float),
        size=(int(intrinsics.width), int(intrinsics.height)),
        predictor=np.asarray(predictor, dtype=float),
        y_goal=np.asarray(resolved.y_goal, dtype=float),
    )


def _measure(cam: SampledCamera, pose: np.ndarray, seed: int, frame: int) -> tuple:
    """One frame of the pinhole sensor at the rig pose ``[q, p]``: ``(y | None, code)``,
    as :class:`~geovs_drake.systems.PinholeFeatureSensor` measures it."""
    from geovs_drake.geometry._ops import MATH
    from geovs_drake.geometry.features import TargetMarks, pinhole_measurement
    from geovs_drake.geometry.pinhole import PinholeIntrinsics
    from geovs_drake.geometry.rigid import cross, quaternion_to_rotation, target_in_camera

    p = cam.sensor.tolist()
    x = pose.tolist()
    R_WR = quaternion_to_rotation(x[0:4], MATH)
    r2, r3, d = target_in_camera(R_WR, x[4:7], p[13:22], p[22:25], p[1:10], p[10:13])
    X_CB = np.eye(4)
    X_CB[:3, :3] = np.column_stack([cross(r2, r3), r2, r3])
    X_CB[:3, 3] = d
    noise = np.random.default_rng([seed, frame]) if cam.pixel_noise > 0 else None
    defaults = TargetMarks()
    marks = TargetMarks(defaults.mark_radius, p[33], defaults.arrow_mark_radius)
    return pinhole_measurement(
        X_CB,
        p[0],
        marks,
        PinholeIntrinsics(*cam.size, *p[25:29]),
        PinholeIntrinsics(*cam.size, *p[29:33]),
        noise,
        cam.pixel_noise,
    )


@njit(cache=True, error_model="numpy", nogil=True)
def _law_rhs(kinematic, x, y_held, then, predict, out, p_cam, p_nav, p_ctrl, p_body, p_pred):
    """The loop's xdot into ``out`` with the law on the held (or predicted) frame;
    returns the exact camera's output at x and the kinetic energy."""
    cam = _camera(x[0:_POSE], p_cam)
    y = y_held.copy()
    if predict:
        moved = _predicted(y_held, then, x[0:_POSE], p_pred)
        for j in range(_Y_SIZE):
            y[j] = moved[j]
    nav = _navigation(y, p_nav)
    if kinematic:
        xdot = _kinematic_body(x, _kinematic_velocity(y, nav[_D0:_D1], p_ctrl))
        for j in range(_KINEMATIC_STATE):
            out[j] = xdot[j]
        return cam, 0.0
    force = _force(x, y, nav[_D0:_D1], p_ctrl)
    body = _free_body(x, force[_F0:_F1], p_body)
    for j in range(_FREE_STATE):
        out[j] = body[j]
    return cam, body[_KINETIC]


#: :func:`_advance`'s arguments over the starts (:func:`~._threads.over_starts` splits
#: them): X, H, Y, THEN, PRED and the records from status to err_r.
_ADVANCE_PER_START = (1, 2, 5, 6, 7, *range(8, 19))


@batch_kernel
def _advance(
    kinematic,
    X,
    H,
    t0,
    t1,
    Y,
    THEN,
    PRED,
    status,
    t_stop,
    steps,
    min_m,
    L0,
    max_ratio,
    max_rise,
    prev_L,
    inside,
    err_p,
    err_r,
    p_cam,
    p_nav,
    p_ctrl,
    p_body,
    p_err,
    p_pred,
    k_p,
    max_step,
    accuracy,
    tol_p2,
    tol_r2,
    pair,
):
    """Every running start (status 1) from t0 to t1, the law on its frame ``Y[i]``
    (moved from the rig pose ``THEN[i]`` where ``PRED[i]``): the engine's step of the
    pair of the loop's scheme's order (:func:`geovs_drake.batch.engine._integrate`), its
    state checks and records, the next step size kept in ``H``."""
    n, dim = X.shape
    adaptive = accuracy > 0
    A, B, E, exponent = pair
    stages = B.shape[0]
    for i in range(n):
        if status[i] != 1:
            continue
        x = X[i].copy()
        y, then, pred = Y[i], THEN[i], PRED[i]
        xs = np.empty(dim)
        x_new = np.empty(dim)
        K = np.empty((stages, dim))  # the step's stages (geovs_drake.batch._pairs)
        d = np.empty(dim)
        cam, kinetic = _law_rhs(
            kinematic, x, y, then, pred, d, p_cam, p_nav, p_ctrl, p_body, p_pred
        )
        t = t0
        h = H[i]
        while True:
            margins = cam[_M0:_M1]
            phi = _navigation(cam[_Y0:_Y1], p_nav)[_PHI]  # the exact image's, as the monitor
            status[i] = _state_status(x, cam[_NU], margins, phi)
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
            e = _pose_error(x[0:_POSE], p_err)
            err_p[i] = math.sqrt(e[0])
            err_r[i] = 2.0 * math.asin(min(1.0, math.sqrt(e[1] / 8.0)))
            if e[0] > tol_p2 or e[1] > tol_r2:
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
                    _law_rhs(
                        kinematic, xs, y, then, pred, K[s], p_cam, p_nav, p_ctrl, p_body, p_pred
                    )
                solution(B, x, hh, K, x_new)
                cam, kinetic = _law_rhs(
                    kinematic, x_new, y, then, pred, d, p_cam, p_nav, p_ctrl, p_body, p_pred
                )
                grow = 1.0
                if adaptive:
                    phi_new = _navigation(cam[_Y0:_Y1], p_nav)[_PHI]
                    outside = _state_status(x_new, cam[_NU], cam[_M0:_M1], phi_new) != 1
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
            steps[i] += 1
        X[i] = x
        H[i] = h


class _Frames:
    """Each start's latency line of frames ``[y, has_y, code, lost]`` and of the rig
    poses they were taken from, oldest first (:mod:`geovs_drake.systems._held_frames`,
    :class:`~geovs_drake.systems.FramePredictor`)."""

    def __init__(self, cam: SampledCamera, n: int) -> None:
        line = cam.latency_frames + 1
        self.y = np.full((n, line, _Y_SIZE), np.nan)
        self.has_y = np.zeros((n, line), bool)
        self.code = np.zeros((n, line), np.int64)
        self.lost = np.zeros((n, line), np.int64)
        self.pose = np.zeros((n, line, _POSE))

    def read(self, i: int, y, code: int, pose: np.ndarray, first: bool) -> None:
        """Start i's frame: shift the line (``first``: fill it, the frame at t = 0)."""
        prev = (self.y[i, -1], self.has_y[i, -1], self.code[i, -1], self.lost[i, -1])
        if first:
            prev = (np.full(_Y_SIZE, np.nan), False, 0, 0)
        if y is None:  # keep the last good y; one more frame lost
            entry = (prev[0], prev[1], code, prev[3] + 1)
        else:
            entry = (np.asarray(y, dtype=float), True, 0, 0)
        for name, value in zip(("y", "has_y", "code", "lost", "pose"), (*entry, pose), strict=True):
            a = getattr(self, name)
            if first:
                a[i] = value
            else:
                a[i, :-1] = a[i, 1:]
                a[i, -1] = value


def _read_frame(
    cam, frames, poses, seeds, t, k, first, Y, THEN, PRED, status, t_stop, lost
) -> None:
    """Every running start's frame k at time t, taken from its pose ``poses[i]`` (``[q,
    p]``), and what its law reads until the next; ``lost``: the feature-lost status code."""
    for i in np.flatnonzero(status == 1):
        pose = poses[i].copy()
        y, code = _measure(cam, pose, int(seeds[i]), k)
        frames.read(i, y, int(code), pose, first)
        has_y, lost_frames, code0 = frames.has_y[i, 0], frames.lost[i, 0], frames.code[i, 0]
        if has_y and lost_frames <= cam.max_lost_frames:
            Y[i], THEN[i], PRED[i] = frames.y[i, 0], frames.pose[i, 0], cam.predict
        elif not has_y and code0 == 0 and lost_frames == 0:  # waiting for the first frame
            Y[i], PRED[i] = cam.y_goal, False
        else:
            status[i], t_stop[i] = lost, t


def frame_clock(
    cam: SampledCamera,
    poses: Callable[[], np.ndarray],
    advance: Callable[..., None],
    status: np.ndarray,
    t_stop: np.ndarray,
    run: dict,
    lost: int = FEATURE_LOST,
) -> None:
    """The camera's clock over N starts (module docstring): frames read at ``offset + k
    period`` from the poses ``poses()`` returns ((N, 7) ``[q, p]``, the pinhole's body:
    the rig, or the arm's camera), and ``advance(t0, t1, Y, THEN, PRED)`` integrating
    every running start (``status`` 1) from t0 to t1, the law on ``Y[i]`` (moved from
    ``THEN[i]`` where ``PRED[i]``). A start whose frames stay lost gets status ``lost``
    (its time into ``t_stop``). ``run``: ``duration`` and ``seeds`` (N,), the noise's."""
    n = len(status)
    seeds, duration = run["seeds"], run["duration"]
    Y = np.tile(cam.y_goal, (n, 1))
    THEN = np.array(poses(), dtype=float)
    PRED = np.zeros(n, bool)
    frames = _Frames(cam, n)
    t, k = 0.0, 0
    if cam.offset == 0:  # the frame at t = 0 fills the line (an initialization event)
        _read_frame(cam, frames, THEN, seeds, 0.0, 0, True, Y, THEN, PRED, status, t_stop, lost)
        k = 1
    while True:
        t_next = min(cam.offset + k * cam.period, duration)
        advance(t, t_next, Y, THEN, PRED)
        t = t_next
        if t >= duration or not np.any(status == 1):
            break
        _read_frame(cam, frames, poses(), seeds, t, k, False, Y, THEN, PRED, status, t_stop, lost)
        k += 1


def run_sampled(kinematic: bool, X0: np.ndarray, p, cam: SampledCamera, run: dict) -> tuple:
    """Integrate from the states ``X0`` with the sampled camera ``cam`` (module
    docstring); ``p`` the :class:`~geovs_drake.batch.LoopParameters`, ``run`` the
    integration's settings (h0, max_step, accuracy, duration, tol_p2, tol_r2, seeds).
    Returns the engine's tuple of per-start arrays."""
    n, _ = X0.shape
    X = X0.copy()
    H = np.full(n, run["h0"])
    status = np.ones(n, np.int64)
    t_stop = np.full(n, run["duration"])
    steps = np.zeros(n, np.int64)
    min_m = np.full((n, 4), np.inf)
    L0, prev_L, inside = np.full(n, np.nan), np.zeros(n), np.full(n, np.nan)
    max_ratio, max_rise = np.full(n, -np.inf), np.zeros(n)
    err_p, err_r = np.full(n, np.nan), np.full(n, np.nan)

    def advance(t0, t1, Y, THEN, PRED) -> None:
        args = (
            kinematic, X, H, t0, t1, Y, THEN, PRED, status, t_stop, steps, min_m, L0,
            max_ratio, max_rise, prev_L, inside, err_p, err_r, p.camera, p.navigation,
            p.controller, p.body, p.pose_error, cam.predictor, float(p.potential_gain),
            run["max_step"], run["accuracy"], run["tol_p2"], run["tol_r2"],
            pair_for(p.scheme).kernel_args(),
        )  # fmt: skip
        over_starts(_advance, args, _ADVANCE_PER_START)

    frame_clock(cam, lambda: X[:, :_POSE], advance, status, t_stop, run)
    t_conv = np.full(n, np.nan)
    converged = (status == 1) & ~np.isnan(inside)
    status[converged], t_conv[converged] = 0, inside[converged]
    return status, t_stop, t_conv, err_p, err_r, min_m, L0, max_ratio, max_rise, steps, X
