"""The safe-domain monitor and the simulator it watches; the camera's signals along states.

The monitor reads the loop's parts (:class:`geovs_drake.loop.Loop`): the
carrier says which pose the camera reads from a state, the exact camera holds
the parameters of the kernel that checks it.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import EventStatus
from pydrake.trajectories import PiecewisePolynomial

from geovs_drake.geometry._ops import MATH, NUMPY
from geovs_drake.geometry.baselines import point_fov_margins, points_in_camera
from geovs_drake.geometry.features import FEATURE_FAILURES
from geovs_drake.geometry.kernels import (
    CAMERA_IMAGE,
    NAVIGATION,
    camera_image,
    for_scalar_type,
    navigation,
)
from geovs_drake.geometry.rigid import quaternion_to_rotation
from geovs_drake.goal.arm import joint_limit_margins, joint_names
from geovs_drake.loop.assembly import Loop
from geovs_drake.simulation.result import MARGIN_NAMES
from geovs_drake.systems._held_frames import waiting
from geovs_drake.systems.arm_model import arm_plant

__all__ = [
    "PIN_MARGIN_RAD",
    "PIN_SPAN_S",
    "PIN_STEPS",
    "FeaturePointCheck",
    "SafeDomainMonitor",
    "camera_signals",
    "feature_point_check",
    "make_simulator",
]

#: An arm's run pins on a joint limit where its last :data:`PIN_STEPS` accepted steps
#: span less than :data:`PIN_SPAN_S` of simulated time (the error control's steps have
#: collapsed) with a joint within :data:`PIN_MARGIN_RAD` of its limit: the monitor stops
#: it with status ``joint_limit``. Why: the kinematic Panda behind a target it could not
#: follow sat with its wrist (joint 6) 0.03-0.15 rad from its limit, where that wrist is
#: singular, and took 25 us steps (40,000 a simulated second) for 4 s before it left D:
#: 191 s of wall time for a 30 s run (issue 42). A run's steps are milliseconds; the
#: stiff arm of docs/arm.md, whose steps are 0.1 ms on RK3, has every joint a radian or
#: more from its limits.
PIN_STEPS = 500
PIN_SPAN_S = 0.025
PIN_MARGIN_RAD = 0.2

_camera_kernel = for_scalar_type(camera_image, float)
_NU, _MARGINS = CAMERA_IMAGE.nu, CAMERA_IMAGE.margins


class FeaturePointCheck:
    """Whether a law's feature points (point IBVS's four) are in the field of view.

    ``lost(x)`` takes the body pose the camera rides on (pose first: X_WR of the
    rig, X_WC of the kinematic body, or, for the fixed camera, X_BC with X_WB =
    X_RC = identity) and returns None while every point lies in the
    cone of half-angle theta about the optical axis (so in front of the camera),
    else one line naming the first point out and its angle.
    """

    def __init__(
        self,
        P_B: np.ndarray,
        X_WB: RigidTransform,
        X_RC: RigidTransform,
        fov_half_angle: float,
        names: tuple[str, ...] | None = None,
    ) -> None:
        self.P_B = np.asarray(P_B, dtype=float)
        self._R_WB = X_WB.rotation().matrix()
        self._p_WB = X_WB.translation()
        self._R_RC = X_RC.rotation().matrix()
        self._p_RC = X_RC.translation()
        self._theta = fov_half_angle
        self._cos = math.cos(fov_half_angle)
        self.names = names or tuple(f"point {i}" for i in range(len(self.P_B)))

    def points_in_camera(self, x: np.ndarray) -> np.ndarray:
        """The points in C (n, 3) for one state x."""
        q = np.asarray(x[0:4], dtype=float)
        R_WR = np.array(quaternion_to_rotation(tuple(q.tolist()), MATH)).reshape(3, 3)
        R_WC = R_WR @ self._R_RC
        p_WC = np.asarray(x[4:7], dtype=float) + R_WR @ self._p_RC
        # X_CB = X_WC^-1 X_WB.
        return points_in_camera(R_WC.T @ self._R_WB, R_WC.T @ (self._p_WB - p_WC), self.P_B)

    def margins(self, x: np.ndarray) -> np.ndarray:
        """``Z / |p| - cos(theta)`` per point (>= 0 in view)."""
        return point_fov_margins(self.points_in_camera(x), self._cos)

    def lost(self, x: np.ndarray) -> str | None:
        """None while every point is in view, else a line naming the first one out."""
        P_C = self.points_in_camera(x)
        margins = point_fov_margins(P_C, self._cos)
        if np.all(margins >= 0):
            return None
        i = int(np.argmin(margins))
        angle = math.degrees(math.acos(max(-1.0, min(1.0, margins[i] + self._cos))))
        where = "behind the camera" if P_C[i, 2] <= 0 else "outside the field of view"
        return (
            f"feature {self.names[i]} {where}: {angle:.4g} deg from the optical axis "
            f"> {math.degrees(self._theta):.4g} deg"
        )


def feature_point_check(loop: Loop) -> FeaturePointCheck | None:
    """The check of the law's feature points, if its system has any (point IBVS):
    its ``target_points_B`` in the diagram's default context, seen from the body
    the carrier moves (where the camera system sees the target and the camera)."""
    diagram = loop.diagram
    if not diagram.HasSubsystemNamed("controller"):
        return None
    law = diagram.GetSubsystemByName("controller")
    if not hasattr(law, "target_points_B"):
        return None
    P_B = law.target_points_B(law.CreateDefaultContext())
    names = getattr(law, "TARGET_POINT_NAMES", None)
    carrier = loop.carrier
    theta = loop.resolved.domain.fov_half_angle
    return FeaturePointCheck(P_B, carrier.X_WB, carrier.X_RC, theta, names)


class SafeDomainMonitor:
    """The simulator monitor: stops a run that leaves D, and records every step.

    Called by Drake after every accepted step (and at initialisation). It ends
    the run with ``ReachedTermination`` when the camera loses sight of the
    marked point (nu <= 0), leaves D (a margin < 0), or the state is not
    finite, so a run never continues into NaN; with a ``feature_points`` check
    (point IBVS), also when one of the law's points leaves the field-of-view
    cone (``lost_visibility``, naming the point). :meth:`termination` reports
    ``(status, message)`` of the last termination, if any. These read the true
    pose (the exact camera map), whatever sensor the loop uses. A loop with a
    camera (a ``feature_sensor`` subsystem) also stops with ``feature_lost``
    when the frame the controller acts on gave no y, naming why
    (:data:`~geovs_drake.geometry.features.FEATURE_FAILURES`).

    It also records ``(t, x)`` at every accepted step. That is how
    :func:`simulate` logs: interpolating the steps at the log rate afterwards
    costs one state copy per step, where Drake's periodic loggers would cut
    every integrator step at each sample time (about 50% more steps at the
    default 50 Hz) and evaluate every logged port there.

    ``on_step``, if given, is called with the time of every accepted step: how
    :func:`simulate` reports progress without cutting the integration into
    pieces (each ``AdvanceTo`` boundary would end a step early and change the run).
    """

    def __init__(
        self,
        loop: Loop,
        record: bool = True,
        feature_points: FeaturePointCheck | None = None,
        on_step: Callable[[float], None] | None = None,
    ) -> None:
        diagram = self._diagram = loop.diagram
        self._camera = loop.camera
        self._sensor = (
            diagram.GetSubsystemByName("feature_sensor")
            if diagram.HasSubsystemNamed("feature_sensor")
            else None
        )
        self._record = record
        # A camera's frames are where the law's y, hence the force, may jump: the log's
        # spline is cut there (resample).
        sensor = loop.resolved.config.sensor
        self._frame_clock = (
            (1.0 / sensor.rate, sensor.first_frame_time) if self._sensor is not None else None
        )
        self._feature_points = feature_points
        self._on_step = on_step
        self._reason: dict[str, str] = {}
        self._params_of: tuple = (None, None)
        self._pose_of_states = loop.carrier.loop_pose_of_states
        self._limit_check = loop.carrier.limit_check
        # An arm's joints (the head of its state) and the times of its last steps, for
        # the pinned check.
        self._arm = loop.carrier.arm
        # An arm's camera pose as its system computes it (the carrier's body_pose): the
        # arm systems keep their kinematics at the last state they saw, so evaluated here
        # at the step's end it is the one the next step's first derivative reads, and the
        # forward kinematics run once for both (pose_of_states would run them a second
        # time, on a plant of its own): 3-5% of a UR5 run's wall time. Only where the
        # arm's world is the loop's: behind a moving target (world_in_loop) body_pose is
        # carried into the target's frame by systems that keep nothing.
        carrier = loop.carrier
        self._pose_port = (
            carrier.body_pose if self._arm is not None and carrier.world_in_loop is None else None
        )
        self._pose_context: tuple = (None, None)
        self._recent: deque[float] = deque(maxlen=PIN_STEPS)
        self.times: list[float] = []
        self.states: list[np.ndarray] = []

    def termination(self) -> tuple[str, str]:
        """``(status, message)`` of the last termination, ``(, )`` if none."""
        return self._reason.get("status", ""), self._reason.get("message", "")

    def _stop(self, status: str, message: str) -> EventStatus:
        self._reason.update(status=status, message=message)
        return EventStatus.ReachedTermination(self._diagram, message)

    def __call__(self, root_context) -> EventStatus:
        # The diagram's only continuous state is the body's, pose first.
        x = root_context.get_continuous_state_vector().CopyToVector()
        if self._on_step is not None:
            self._on_step(root_context.get_time())
        if self._record:
            t = root_context.get_time()
            if self.times and t <= self.times[-1]:  # Initialize() and a first step at t = 0
                self.times.pop()
                self.states.pop()
            self.times.append(t)
            self.states.append(x)
        # One call of the camera's compiled kernel on the accepted state: nu and
        # the margins, without evaluating the diagram's ports (which would
        # rebuild their caches for this state, at several times the cost).
        if root_context is not self._params_of[0]:
            # A live read-only view of the camera's parameters in this context.
            camera_context = self._camera.GetMyContextFromRoot(root_context)
            self._params_of = (root_context, camera_context.get_numeric_parameter(0).get_value())
        if self._limit_check is not None:  # the carrier's own limits (an arm's joints)
            broken = self._limit_check(x)
            if broken is not None:
                return self._stop("joint_limit", f"{broken} at t = {root_context.get_time():.4g}")
        if self._arm is not None:
            pinned = self._pinned(x, root_context.get_time())
            if pinned is not None:
                return self._stop("joint_limit", pinned)
        # The pose the camera reads from this state (the carrier says which).
        pose = self._pose(root_context, x)
        out = _camera_kernel(pose, self._params_of[1])
        margins = out[_MARGINS]
        if out[_NU] > 0 and min(margins) > 0:
            if self._feature_points is not None:
                lost = self._feature_points.lost(pose)
                if lost is not None:
                    t = root_context.get_time()
                    return self._stop("lost_visibility", f"lost visibility: {lost} at t = {t:.4g}")
            return self._check_sensor(root_context)
        t = root_context.get_time()
        if not np.all(np.isfinite(x)):
            return self._stop("non_finite", f"non-finite state at t = {t:.4g}")
        nu = out[_NU]
        if not nu > 0:
            return self._stop(
                "lost_visibility", f"lost visibility: nu(H) = {nu:.4g} <= 0 at t = {t:.4g}"
            )
        if not all(math.isfinite(m) for m in margins):
            return self._stop("non_finite", f"non-finite domain margins at t = {t:.4g}")
        i = int(np.argmin(margins))
        if margins[i] < 0:
            return self._stop(
                "left_domain",
                f"left D: {MARGIN_NAMES[i]} margin = {margins[i]:.4g} < 0 at t = {t:.4g}",
            )
        return self._check_sensor(root_context)  # on the boundary of D, still in it

    def _pose(self, root_context, x: np.ndarray) -> tuple:
        """The pose the camera reads at the accepted state ``x`` (floats, ``[q, p]``)."""
        port = self._pose_port
        if port is None:
            return self._pose_of_states(x, MATH, root_context.get_time())
        if root_context is not self._pose_context[0]:
            self._pose_context = (
                root_context,
                port.get_system().GetMyContextFromRoot(root_context),
            )
        return tuple(port.Eval(self._pose_context[1]).tolist())

    def _pinned(self, x: np.ndarray, t: float) -> str | None:
        """A line where the arm pins on a joint limit (:data:`PIN_STEPS`), else None; the
        joints' margins are read only once the steps have collapsed."""
        self._recent.append(t)
        if len(self._recent) < PIN_STEPS or t - self._recent[0] >= PIN_SPAN_S:
            return None
        names = joint_names(arm_plant(self._arm))
        margins = joint_limit_margins(self._arm, x[: len(names)])
        i = int(np.argmin(margins))
        if margins[i] >= PIN_MARGIN_RAD:
            return None
        return (
            f"joint limit: pinned at {names[i]}'s limit ({margins[i]:.3g} rad from it) at "
            f"t = {t:.4g}: the last {PIN_STEPS} steps advanced {1e3 * (t - self._recent[0]):.3g} ms"
        )

    def _check_sensor(self, root_context) -> EventStatus:
        """``feature_lost`` if the held frame gave no y (a camera's loop), else go on."""
        if self._sensor is None:
            return EventStatus.Succeeded()
        status = self._sensor.feature_status_output.Eval(
            self._sensor.GetMyContextFromRoot(root_context)
        )
        if status[0] > 0 or waiting(status):  # a frame to act on, or the first to come
            return EventStatus.Succeeded()
        code, lost = int(status[1]), int(status[2])
        reason = FEATURE_FAILURES[code] if 0 < code < len(FEATURE_FAILURES) else f"code {code}"
        return self._stop(
            "feature_lost",
            f"feature lost at t = {root_context.get_time():.4g}: {reason} "
            f"({lost} frame{'s' if lost != 1 else ''} in a row)",
        )

    def resample(self, rate: float) -> tuple[np.ndarray, np.ndarray]:
        """``(times, states)`` at ``rate`` Hz from t = 0, plus the last step.

        A cubic spline with continuous second derivatives through the steps
        (Drake's ``PiecewisePolynomial``): its error is fourth order in the
        step, below the integrator's own at its accuracy setting. In a loop with
        a camera the spline is cut at each frame's read, a step boundary where
        the law's y and so the acceleration may jump: one spline across such a
        kink rings (a loop that waits 30 ms for its first frame, at rest until
        then, logged a velocity of 0.46 at t = 0.02 s). Quaternions are
        interpolated componentwise; every consumer normalises them.
        """
        T = np.asarray(self.times)
        X = np.asarray(self.states)
        end = T[-1]
        times = np.arange(0.0, end, 1.0 / rate)
        times = np.append(times[times < end - 1e-9], end)
        if len(T) < 2:
            return T, X
        out = np.empty((len(times), X.shape[1]))
        cuts = self._frame_reads(T)
        for lo, hi in zip(cuts[:-1], cuts[1:], strict=True):  # knots lo..hi, shared ends
            inside = (times >= T[lo]) & (times <= T[hi])
            out[inside] = _spline(T[lo : hi + 1], X[lo : hi + 1], times[inside])
        return times, out

    def _frame_reads(self, T: np.ndarray) -> list[int]:
        """Indices of the recorded steps that end at a frame's read, with the first and
        the last: where :meth:`resample` cuts its spline."""
        cuts = [0]
        if self._frame_clock is not None:
            period, offset = self._frame_clock
            k = (T - offset) / period
            on_read = (np.abs(k - np.round(k)) * period < _READ_TOLERANCE_S) & (k > -0.5)
            cuts += [int(i) for i in np.flatnonzero(on_read) if 0 < i < len(T) - 1]
        return cuts + [len(T) - 1]


#: How close [s] a step's end must be to a frame's read time to count as that read (the
#: simulator ends a step exactly at a discrete update; this only absorbs the rounding of
#: offset + k period).
_READ_TOLERANCE_S = 1e-9


def _spline(T: np.ndarray, X: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``X`` (rows at ``T``) at ``times``: a C2 cubic through three knots or more, a line
    through two."""
    if len(T) >= 3:
        spline = PiecewisePolynomial.CubicWithContinuousSecondDerivatives(T, X.T, False)
    else:
        spline = PiecewisePolynomial.FirstOrderHold(T, X.T)
    return spline.vector_values(times).T


def make_simulator(
    loop: Loop,
    record: bool = False,
    on_step: Callable[[float], None] | None = None,
    max_step_size: float | None = None,
) -> tuple[Simulator, SafeDomainMonitor]:
    """A Simulator of ``loop`` (:func:`~geovs_drake.loop.build_loop`) with its scenario's
    integrator and a :class:`SafeDomainMonitor` on its parts.

    ``record`` makes the monitor keep every accepted step (for logs); ``on_step``
    is called with each accepted step's time (progress); ``max_step_size``, if given,
    is the integrator's step limit, by default the one
    :func:`~geovs_drake.goal.step_limit.step_limit` decides for the scenario (the
    configured ``simulator.max_step_size`` is None where it is automatic).
    A law with feature points
    (point IBVS) gets them checked too (:func:`feature_point_check`). For the dynamic
    loop (a diagram with a ``plant``) the context starts in the carrier's start
    (:attr:`~geovs_drake.loop.carriers.CarrierParts.set_initial_state`): for the free
    rig its pose and the velocity that gives the camera ``config.initial_velocity``.
    """
    config = loop.resolved.config
    simulator = Simulator(loop.diagram)
    ApplySimulatorConfig(config.simulator.to_drake(), simulator)
    if max_step_size is None:  # decided in one place, by the resolver (goal.step_limit)
        max_step_size = loop.resolved.step_limit.max_step_size
    simulator.get_mutable_integrator().set_maximum_step_size(max_step_size)
    loop.carrier.set_initial_state(simulator.get_mutable_context())
    monitor = SafeDomainMonitor(
        loop,
        record=record,
        feature_points=feature_point_check(loop),
        on_step=on_step,
    )
    simulator.set_monitor(monitor)
    return simulator, monitor


def camera_signals(
    loop: Loop, root_context, states: np.ndarray, times: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """The camera's and the NF's outputs along a batch of states, in one call each.

    ``states`` is (N, n) in the diagram's continuous-state layout (a free body's
    13 or the kinematic body's 7, pose first), at the ``times`` (N,) (read where the
    target moves and the carrier stays in the world: an arm). The same generated kernels as
    the systems, on components of shape (N,), with the systems' parameters
    from ``root_context``. Returns ``image_features`` (N, 13), ``visibility``
    (N,), ``margins`` (N, 4) and ``phi`` (N,); where nu <= 0, y and phi are NaN
    and every margin reads nu, as on the systems' ports.
    """
    camera, nav = loop.camera, loop.navigation
    p_cam = camera.GetMyContextFromRoot(root_context).get_numeric_parameter(0).CopyToVector()
    p_nav = nav.navigation_parameters(nav.GetMyContextFromRoot(root_context))
    # The poses the camera reads from these states (the carrier says which).
    x = loop.carrier.loop_pose_of_states(np.atleast_2d(states), NUMPY, times)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = camera_image(x, p_cam)
        nu = np.asarray(out[_NU], dtype=float)
        visible = nu > 0
        y = np.where(visible, np.stack(np.broadcast_arrays(*out[CAMERA_IMAGE.y])), np.nan)
        margins = np.where(visible, np.stack(np.broadcast_arrays(*out[_MARGINS])), nu)
        phi = np.asarray(navigation(tuple(y), p_nav)[NAVIGATION.phi])
    return dict(image_features=y.T, visibility=nu, margins=margins.T, phi=phi)
