"""simulate(config): run a servo loop with a safe-domain monitor and return its logs."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import Diagram, EventStatus
from pydrake.trajectories import PiecewisePolynomial

from geovs_drake.diagrams import fixed_camera_pose, initial_rig_state, make_servo_diagram
from geovs_drake.geometry._ops import MATH, NUMPY
from geovs_drake.geometry.baselines import point_fov_margins, points_in_camera
from geovs_drake.geometry.domain import DomainMargins
from geovs_drake.geometry.features import FEATURE_FAILURES
from geovs_drake.geometry.kernels import camera_image, for_scalar_type, navigation
from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.geometry.rigid import fixed_camera_relative_pose, quaternion_to_rotation
from geovs_drake.planning import plan_for_scenario
from geovs_drake.scenario import ScenarioConfig

__all__ = [
    "CONVERGENCE_POSITION_M",
    "CONVERGENCE_ROTATION_RAD",
    "FeaturePointCheck",
    "SafeDomainMonitor",
    "SimulationResult",
    "StartOutsideDomain",
    "camera_pose_in_target",
    "camera_signals",
    "check_start",
    "convergence_tolerance",
    "energy_note",
    "feature_point_check",
    "saddle_note",
    "make_simulator",
    "pose_error",
    "simulate",
]

CONVERGENCE_POSITION_M = 1e-3
CONVERGENCE_ROTATION_RAD = 1e-3
#: A loop with a camera converges to what the camera resolves at the goal: within this
#: many pixels of lateral offset at the goal's distance, and this many pixel angles of
#: rotation (:func:`convergence_tolerance`).
CAMERA_TOLERANCE_PX = 2.0
CAMERA_ROTATION_TOLERANCE_PX = 5.0
MARGIN_NAMES = DomainMargins._fields
_camera_kernel = for_scalar_type(camera_image, float)


class StartOutsideDomain(ValueError):
    """The initial pose is not in the safe domain D (or not visible)."""


def check_start(config: ScenarioConfig) -> None:
    """Raise StartOutsideDomain naming the first violated constraint."""
    try:
        y0 = config.initial_features()
    except ValueError as e:
        raise StartOutsideDomain(f"start outside D: {e}") from e
    margins = config.domain.to_domain().margins(y0)
    for name, value in zip(MARGIN_NAMES, margins, strict=True):
        if float(value) < 0:
            raise StartOutsideDomain(f"start outside D: {name} margin = {float(value):.4g} < 0")
    try:
        NavigationFunction(config.domain.to_domain(), config.goal_features())
    except ValueError as e:
        raise StartOutsideDomain(f"goal invalid: {e}") from e


#: A start or an unconverged end whose arrow is within this roll [rad] of the saddle's
#: gets :func:`saddle_note`.
SADDLE_NOTE_ANGLE_RAD = math.radians(3.0)


def saddle_note(angle: float) -> str:
    """Why a run near the navigation function's saddle may not converge, in words."""
    where = "at" if math.degrees(angle) < 0.01 else f"{math.degrees(angle):.2g} deg from"
    return (
        f"note: the arrow is {where} the navigation function's "
        "saddle (the goal with the arrow reversed); starts on the saddle's stable manifold, "
        "a measure-zero set, go to the saddle, not the goal: a small change of the roll "
        "converges"
    )


def energy_note(initial_energy: float, bound: float) -> str:
    """What the energy guarantee says about a dynamic run's start, in words.

    Appendix C: E = 1/2 nu^T M nu + k_p phi never increases and k_p phi <= E, so
    E0 < k_p keeps phi < 1 (phi = 1 exactly on the boundary of D) for all time.
    A start with E0 >= k_p may still converge, but nothing guarantees that.
    """
    covered = initial_energy < bound
    return (
        f"E0 = {initial_energy:.4g} {'<' if covered else '>='} k_p = {bound:.4g}: "
        f"the energy guarantee {'covers' if covered else 'does not cover'} this start"
    )


def convergence_tolerance(config: ScenarioConfig) -> tuple[float, float]:
    """``(position [m], rotation [rad])`` within which a run counts as converged.

    The exact sensor: 1 mm and 1 mrad. A camera cannot do better than it resolves:
    a pixel subtends ``1 / f`` rad, so the tolerances are ``CAMERA_TOLERANCE_PX``
    pixels of lateral offset at the goal's distance and
    ``CAMERA_ROTATION_TOLERANCE_PX`` pixel angles of rotation (at 320x240, 5.9 mm
    and 30 mrad; at 640x480 half that), never below the exact sensor's. Why so
    many pixel angles for rotation: the roll is read from the two marks, about
    8.5 px apart at 320x240 at the goal, so a tenth of a pixel on their
    centroids is 2 pixel angles of roll.
    """
    if config.camera.sensor == "exact":
        return CONVERGENCE_POSITION_M, CONVERGENCE_ROTATION_RAD
    f = config.camera.intrinsics(config.domain.to_domain().fov_half_angle).fx
    distance = float(np.linalg.norm(config.X_BC_goal.translation()))
    return (
        max(CONVERGENCE_POSITION_M, CAMERA_TOLERANCE_PX * distance / f),
        max(CONVERGENCE_ROTATION_RAD, CAMERA_ROTATION_TOLERANCE_PX / f),
    )


def pose_error(X_BC: RigidTransform, X_BC_goal: RigidTransform) -> tuple[float, float]:
    """(position error [m], rotation angle error [rad]) between two camera poses."""
    dp = float(np.linalg.norm(X_BC.translation() - X_BC_goal.translation()))
    R_err = X_BC_goal.rotation().inverse() @ X_BC.rotation()
    # Angle from the Frobenius distance to I (exact, and accurate near 0).
    d = np.linalg.norm(R_err.matrix() - np.eye(3)) / (2 * math.sqrt(2))
    return dp, 2 * math.asin(min(1.0, d))


@dataclass
class SimulationResult:
    """A run's logs and summary. Arrays are sampled at ``config.log_rate``."""

    config: ScenarioConfig
    status: str
    message: str
    sim_time_s: float
    wall_time_s: float
    steps: int
    times: np.ndarray
    image_features: np.ndarray
    phi: np.ndarray
    margins: np.ndarray
    visibility: np.ndarray
    X_BC: np.ndarray  # (N, 4, 4) camera poses in the target frame
    energy: np.ndarray | None = None
    final_X_BC: RigidTransform = field(default_factory=RigidTransform)
    saddle_note: str | None = None  # set when the start (or an unconverged end) is near the saddle

    @property
    def lyapunov(self) -> np.ndarray:
        """phi (kinematic) or the energy E (dynamic) along the run."""
        return self.energy if self.energy is not None else self.phi

    @property
    def lyapunov_tolerance(self) -> float:
        """Allowed per-sample increase: 10x the integrator's accuracy, relative to the
        initial value (the error control bounds the local error to that)."""
        return 10 * self.config.simulator.accuracy * max(1.0, float(abs(self.lyapunov[0])))

    @property
    def lyapunov_monotone(self) -> bool:
        """The Lyapunov function (energy, or phi on the kinematic loop) never rose by more
        than :attr:`lyapunov_tolerance` between two samples.
        """
        L = self.lyapunov
        return bool(len(L) < 2 or np.max(np.diff(L)) <= self.lyapunov_tolerance)

    @property
    def initial_energy(self) -> float | None:
        """E0 = 1/2 nu^T M nu + k_p phi(y0) (dynamic loop), else None."""
        return None if self.energy is None else float(self.energy[0])

    @property
    def energy_bound(self) -> float | None:
        """k_p, the level below which E0 keeps the loop in D (dynamic loop), else None."""
        return None if self.energy is None else float(self.config.control.potential_gain)

    @property
    def energy_guarantee(self) -> bool | None:
        """E0 < k_p: Appendix C's guarantee that phi < 1 throughout (dynamic), else None."""
        if self.energy is None:
            return None
        return bool(self.initial_energy < self.energy_bound)

    @property
    def final_errors(self) -> tuple[float, float]:
        """``(position [m], rotation [rad])`` errors of the final pose from the goal."""
        return pose_error(self.final_X_BC, self.config.X_BC_goal)

    @property
    def convergence_time(self) -> float:
        """The first logged time from which the pose error stays within the
        convergence tolerances to the end; NaN unless the run converged."""
        if self.status != "converged":
            return math.nan
        t_converged = math.nan
        for t, X in zip(self.times[::-1], self.X_BC[::-1], strict=True):
            dp, dr = pose_error(RigidTransform(X), self.config.X_BC_goal)
            if dp > CONVERGENCE_POSITION_M or dr > CONVERGENCE_ROTATION_RAD:
                break
            t_converged = float(t)
        return t_converged

    @property
    def left_domain(self) -> bool:
        """The run stopped because it left D or lost sight of the marked point."""
        return self.status in ("left_domain", "lost_visibility")

    @property
    def converged(self) -> bool:
        """Stayed in D and ended within :data:`CONVERGENCE_POSITION_M` and
        :data:`CONVERGENCE_ROTATION_RAD` of the goal.
        """
        dp, dr = self.final_errors
        tol_p, tol_r = convergence_tolerance(self.config)
        return (
            not self.left_domain and self.status != "feature_lost" and dp <= tol_p and dr <= tol_r
        )

    def one_line(self) -> str:
        """The run in one line: status, final errors, minimum margins, timing."""
        s = self.summary()
        cam = self.config.camera
        sensor = ""
        if cam.sensor != "exact":
            width, height = (int(v) for v in cam.resolution)
            sensor = f", {cam.sensor} camera {width}x{height} at {cam.rate:g} Hz"
        energy = ""
        if self.energy is not None:
            energy = f" | {energy_note(self.initial_energy, self.energy_bound)}"
        if self.saddle_note:
            energy += f" | {self.saddle_note}"
        law = s["controller"]
        if s["ibvs_depth"] is not None:
            law += f" ({s['ibvs_depth']} depth)"
        if self.status == "feature_lost":  # say which feature and why
            energy += f" | {self.message}"
        return (
            f"{law} on the {s['plant']} plant{sensor}"
            f"{', camera fixed' if s['mount'] == 'fixed' else ''}: {s['status']} | position error "
            f"{s['final_position_error_m']:.2e} m, rotation error "
            f"{s['final_rotation_error_rad']:.2e} rad | min margins: "
            f"fov {s['min_fov_margin']:.3g}, occlusion {s['min_occlusion_margin']:.3g}, "
            f"nu {s['min_visibility']:.3g} | Lyapunov monotone: {s['lyapunov_monotone']}"
            f"{energy} | "
            f"{s['sim_time_s']:.1f} s simulated in {s['wall_time_s']:.1f} s, {s['steps']} steps"
        )

    def summary(self) -> dict:
        """The run as JSON-ready values. The energy fields (``initial_energy``,
        ``energy_bound`` = k_p, ``energy_guarantee`` = E0 < k_p, ``max_energy``) are
        None for the kinematic loop, which has no energy, and for laws other than
        the NF, whose energy is not k_p phi. ``ibvs_depth`` is the IBVS depth
        estimate (``control.ibvs_depth``) for ``controller`` "ibvs", else None."""
        dp, dr = self.final_errors
        tol_p, tol_r = convergence_tolerance(self.config)
        out = {
            "plant": self.config.plant,
            "controller": self.config.controller,
            "mount": self.config.mount,
            "ibvs_depth": (
                self.config.control.ibvs_depth if self.config.controller == "ibvs" else None
            ),
            "sensor": self.config.camera.sensor,
            "converged": self.converged,
            "status": self.status,
            "message": self.message,
            "final_position_error_m": dp,
            "final_rotation_error_rad": dr,
            "tolerance_position_m": tol_p,
            "tolerance_rotation_rad": tol_r,
            "final_phi": float(self.phi[-1]),
            "min_fov_margin": float(np.min(self.margins[:, 0])),
            "min_lambda_margin": float(np.min(self.margins[:, 1:3])),
            "min_occlusion_margin": float(np.min(self.margins[:, 3])),
            "min_visibility": float(np.min(self.visibility)),
            "left_domain": self.left_domain,
            "lyapunov_monotone": self.lyapunov_monotone,
            "near_saddle": self.saddle_note is not None,
            "max_lyapunov_increase": float(np.max(np.diff(self.lyapunov), initial=0.0)),
            "sim_time_s": self.sim_time_s,
            "wall_time_s": self.wall_time_s,
            "steps": self.steps,
            "initial_energy": self.initial_energy,
            "energy_bound": self.energy_bound,
            "energy_guarantee": self.energy_guarantee,
            "max_energy": None if self.energy is None else float(np.max(self.energy)),
        }
        if self.config.camera.sensor != "exact":
            cam = self.config.camera
            out["camera"] = {
                "rate_hz": cam.rate,
                "resolution": [int(v) for v in cam.resolution],
                "pixel_noise_px": cam.pixel_noise,
                "focal_error": cam.focal_error,
                "latency_frames": int(cam.latency_frames),
            }
        out["radius_error"] = self.config.camera.radius_error
        return out


def _fixed_camera_of(diagram: Diagram) -> tuple[tuple, tuple] | None:
    """``(q_WC, p_WC)`` of a fixed-camera diagram's camera, or None (eye-in-hand).

    In the fixed-camera loop the body state is the target's; the camera system
    reads the relative pose the ``fixed_camera_mount`` forms from it.
    """
    if not diagram.HasSubsystemNamed("fixed_camera_mount"):
        return None
    mount = diagram.GetSubsystemByName("fixed_camera_mount")
    p = mount.CreateDefaultContext().get_numeric_parameter(0).CopyToVector()
    return tuple(p[12:16].tolist()), tuple(p[9:12].tolist())


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


def feature_point_check(diagram: Diagram, config: ScenarioConfig) -> FeaturePointCheck | None:
    """The check of the law's feature points, if its system has any (point IBVS):
    its ``target_points_B`` in the diagram's default context, seen from the body."""
    if not diagram.HasSubsystemNamed("controller"):
        return None
    law = diagram.GetSubsystemByName("controller")
    if not hasattr(law, "target_points_B"):
        return None
    P_B = law.target_points_B(law.CreateDefaultContext())
    names = getattr(law, "TARGET_POINT_NAMES", None)
    theta = config.domain.to_domain().fov_half_angle
    if diagram.HasSubsystemNamed("fixed_camera_mount"):  # the monitor passes X_BC
        return FeaturePointCheck(P_B, RigidTransform(), RigidTransform(), theta, names)
    X_RC = config.X_RC if diagram.HasSubsystemNamed("plant") else RigidTransform()
    return FeaturePointCheck(P_B, config.X_WB, X_RC, theta, names)


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
        diagram: Diagram,
        record: bool = True,
        feature_points: FeaturePointCheck | None = None,
        on_step: Callable[[float], None] | None = None,
    ) -> None:
        self._diagram = diagram
        self._camera = diagram.GetSubsystemByName("spherical_camera")
        self._sensor = (
            diagram.GetSubsystemByName("feature_sensor")
            if diagram.HasSubsystemNamed("feature_sensor")
            else None
        )
        self._record = record
        self._feature_points = feature_points
        self._on_step = on_step
        self._reason: dict[str, str] = {}
        self._params_of: tuple = (None, None)
        self._fixed_camera = _fixed_camera_of(diagram)
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
        pose = x[0:7]
        if self._fixed_camera is not None:  # the state is the target's: G = X_WB^-1 X_WC
            pose = fixed_camera_relative_pose(tuple(pose.tolist()), *self._fixed_camera, MATH)
        out = _camera_kernel(pose, self._params_of[1])
        if out[0] > 0 and out[14] > 0 and out[15] > 0 and out[16] > 0 and out[17] > 0:
            if self._feature_points is not None:
                lost = self._feature_points.lost(pose)
                if lost is not None:
                    t = root_context.get_time()
                    return self._stop("lost_visibility", f"lost visibility: {lost} at t = {t:.4g}")
            return self._check_sensor(root_context)
        t = root_context.get_time()
        if not np.all(np.isfinite(x)):
            return self._stop("non_finite", f"non-finite state at t = {t:.4g}")
        nu = out[0]
        if not nu > 0:
            return self._stop(
                "lost_visibility", f"lost visibility: nu(H) = {nu:.4g} <= 0 at t = {t:.4g}"
            )
        margins = out[14:18]
        if not all(math.isfinite(m) for m in margins):
            return self._stop("non_finite", f"non-finite domain margins at t = {t:.4g}")
        i = int(np.argmin(margins))
        if margins[i] < 0:
            return self._stop(
                "left_domain",
                f"left D: {MARGIN_NAMES[i]} margin = {margins[i]:.4g} < 0 at t = {t:.4g}",
            )
        return self._check_sensor(root_context)  # on the boundary of D, still in it

    def _check_sensor(self, root_context) -> EventStatus:
        """``feature_lost`` if the held frame gave no y (a camera's loop), else go on."""
        if self._sensor is None:
            return EventStatus.Succeeded()
        status = self._sensor.feature_status_output.Eval(
            self._sensor.GetMyContextFromRoot(root_context)
        )
        if status[0] > 0:
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
        step, below the integrator's own at its accuracy setting. Quaternions
        are interpolated componentwise; every consumer normalises them.
        """
        T = np.asarray(self.times)
        X = np.asarray(self.states).T
        end = T[-1]
        times = np.arange(0.0, end, 1.0 / rate)
        times = np.append(times[times < end - 1e-9], end)
        if len(T) >= 3:
            spline = PiecewisePolynomial.CubicWithContinuousSecondDerivatives(T, X, False)
        elif len(T) == 2:
            spline = PiecewisePolynomial.FirstOrderHold(T, X)
        else:
            return T, X.T
        return times, spline.vector_values(times).T


def make_simulator(
    diagram: Diagram,
    config: ScenarioConfig,
    record: bool = False,
    on_step: Callable[[float], None] | None = None,
) -> tuple[Simulator, SafeDomainMonitor]:
    """A Simulator with the config's integrator and a :class:`SafeDomainMonitor`.

    ``record`` makes the monitor keep every accepted step (for logs); ``on_step``
    is called with each accepted step's time (progress). A law with feature
    points (point IBVS) gets them checked too (:func:`feature_point_check`). For the
    dynamic loop (a diagram with a ``plant``) the context starts in
    :func:`geovs_drake.diagrams.initial_rig_state`: the rig's pose and the
    velocity that gives the camera ``config.initial_velocity``.
    """
    simulator = Simulator(diagram)
    ApplySimulatorConfig(config.simulator, simulator)
    if diagram.HasSubsystemNamed("plant"):
        plant = diagram.GetSubsystemByName("plant")
        plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
        plant.SetPositionsAndVelocities(plant_context, initial_rig_state(config))
    monitor = SafeDomainMonitor(
        diagram,
        record=record,
        feature_points=feature_point_check(diagram, config),
        on_step=on_step,
    )
    simulator.set_monitor(monitor)
    return simulator, monitor


def camera_pose_in_target(config: ScenarioConfig, x: np.ndarray, dynamic: bool) -> RigidTransform:
    """X_BC from a state whose first 7 entries are X_WR (dynamic) or X_WC (kinematic),
    or, for ``mount: fixed``, the target's X_WB (then X_BC = X_WB^-1 X_WC)."""
    q = np.asarray(x[0:4], dtype=float)
    X_W = RigidTransform(RotationMatrix(Quaternion(q / np.linalg.norm(q))), x[4:7])
    if config.mount == "fixed":
        return X_W.inverse() @ fixed_camera_pose(config)
    X_RC = config.X_RC if dynamic else RigidTransform()
    return config.X_WB.inverse() @ X_W @ X_RC


def _poses_from_log(config: ScenarioConfig, log: np.ndarray, dynamic: bool) -> np.ndarray:
    """X_BC (N, 4, 4) for each logged state column."""
    return np.stack(
        [
            camera_pose_in_target(config, log[:, k], dynamic).GetAsMatrix4()
            for k in range(log.shape[1])
        ]
    )


def camera_signals(diagram: Diagram, root_context, states: np.ndarray) -> dict[str, np.ndarray]:
    """The camera's and the NF's outputs along a batch of states, in one call each.

    ``states`` is (N, n) in the diagram's continuous-state layout (a free body's
    13 or the kinematic body's 7, pose first). The same generated kernels as
    the systems, on components of shape (N,), with the systems' parameters
    from ``root_context``. Returns ``image_features`` (N, 13), ``visibility``
    (N,), ``margins`` (N, 4) and ``phi`` (N,); where nu <= 0, y and phi are NaN
    and every margin reads nu, as on the systems' ports.
    """
    camera = diagram.GetSubsystemByName("spherical_camera")
    nav = diagram.GetSubsystemByName("navigation_controller")
    p_cam = camera.GetMyContextFromRoot(root_context).get_numeric_parameter(0).CopyToVector()
    p_nav = nav.navigation_parameters(nav.GetMyContextFromRoot(root_context))
    x = tuple(np.asarray(states, dtype=float)[:, :7].T)
    fixed = _fixed_camera_of(diagram)
    if fixed is not None:  # the target's states: the camera reads G = X_WB^-1 X_WC
        x = fixed_camera_relative_pose(x, *fixed, NUMPY)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = camera_image(x, p_cam)
        nu = np.asarray(out[0], dtype=float)
        visible = nu > 0
        y = np.where(visible, np.stack(np.broadcast_arrays(*out[1:14])), np.nan)
        margins = np.where(visible, np.stack(np.broadcast_arrays(*out[14:18])), nu)
        phi = np.asarray(navigation(tuple(y), p_nav)[8])
    return dict(image_features=y.T, visibility=nu, margins=margins.T, phi=phi)


def simulate(
    config: ScenarioConfig | None = None,
    meshcat=None,
    progress: Callable[[float], None] | None = None,
) -> SimulationResult:
    """Simulate the configured loop (``config.plant``, ``config.camera.sensor``) for
    ``config.duration``.

    Raises StartOutsideDomain if the start is not in D. A run that leaves D
    stops early with ``status`` ``left_domain`` / ``lost_visibility``; a loop with
    a camera whose frame gives no y stops with ``feature_lost``. With a camera the
    logs (y, phi, margins, energy) are the true pose's; the controller acted on
    the measured y. The
    dynamic loop starts with the camera's body twist ``config.initial_velocity``;
    if its energy E0 is not below k_p, the message says that Appendix C's energy
    guarantee does not cover the start (see :func:`energy_note`).
    ``progress`` (default None: off), if given, is called with the simulated
    time after every accepted step, from the safe-domain monitor; e.g. a
    :class:`geovs_drake.progress.HorizonProgress`. It does not change the run.
    The logs are sampled at ``config.log_rate`` from the recorded steps (see
    :class:`SafeDomainMonitor`); ``wall_time_s`` times the integration alone.
    """
    config = config or ScenarioConfig()
    config.validate()
    check_start(config)
    dynamic = config.plant == "dynamic"
    diagram = make_servo_diagram(config, meshcat=meshcat, log=False)
    simulator, monitor = make_simulator(diagram, config, record=True, on_step=progress)
    root = simulator.get_mutable_context()
    if meshcat is not None:
        diagram.ForcedPublish(root)
    status, message = "completed", ""
    # Initialize() also loads the compiled kernels: not part of the timing. Its
    # monitor call may already stop the run (a law's feature point out of view, or a
    # camera whose first frame gives no y, at t = 0); AdvanceTo would otherwise take
    # one step regardless (on a held y of NaN).
    initial = simulator.Initialize()
    stopped = initial.reason() == initial.ReturnReason.kReachedTerminationCondition
    start = time.perf_counter()
    failure = None
    try:
        if not stopped:
            simulator.AdvanceTo(config.duration)
    except RuntimeError as e:
        # Drake's error control found no step it could accept: the derivatives
        # grow without bound (a law's command near its singularity). The batch
        # engine calls the same event non_finite; the run ends here with that status.
        if "step smaller than minimum" not in str(e):
            raise
        failure = str(e).strip().splitlines()[0]
    wall = time.perf_counter() - start
    term_status, term_message = monitor.termination()
    if term_status:
        status, message = term_status, term_message
    elif failure is not None:
        status = "non_finite"
        message = (
            f"no accurate step exists at t = {root.get_time():.4g}: the derivatives grow "
            f"without bound (Drake: {failure})"
        )

    times, states = monitor.resample(config.log_rate)
    signals = camera_signals(diagram, root, states)
    energy = None
    nf_law = config.controller == "nf"
    if dynamic and nf_law:
        # Drake's own kinetic energy of the free body, plus the potential k_p phi.
        plant = diagram.GetSubsystemByName("plant")
        pctx = plant.CreateDefaultContext()
        kinetic = np.empty(len(states))
        for k, x in enumerate(states):
            plant.SetPositionsAndVelocities(pctx, x)
            kinetic[k] = plant.CalcKineticEnergy(pctx)
        energy = kinetic + config.control.potential_gain * signals["phi"]
    x_final = root.get_continuous_state_vector().CopyToVector()
    final_X_BC = camera_pose_in_target(config, x_final, dynamic)
    if status == "completed":
        dp, dr = pose_error(final_X_BC, config.X_BC_goal)
        tol_p, tol_r = convergence_tolerance(config)
        converged = dp <= tol_p and dr <= tol_r
        status = "converged" if converged else "not_converged"
        message = (
            f"{'converged' if converged else 'did not converge'}: position error {dp:.3g} m, "
            f"rotation error {dr:.3g} rad after {root.get_time():.3g} s"
        )
    result = SimulationResult(
        config=config,
        status=status,
        message=message,
        sim_time_s=root.get_time(),
        wall_time_s=wall,
        steps=simulator.get_num_steps_taken(),
        times=times,
        image_features=signals["image_features"],
        phi=signals["phi"],
        margins=signals["margins"],
        visibility=signals["visibility"],
        X_BC=_poses_from_log(config, states.T, dynamic),
        energy=energy,
        final_X_BC=final_X_BC,
    )
    if result.energy_guarantee is False:
        result.message += f" ({energy_note(result.initial_energy, result.energy_bound)})"
    if config.controller == "path":  # what the planner found (cached: the diagram's plan)
        result.message += f" (plan: {plan_for_scenario(config).message})"
    if not nf_law:  # the energy and the saddle belong to the NF's law
        return result
    nf = NavigationFunction(
        config.domain.to_domain(), config.goal_features(), config.navigation.to_gains()
    )
    angle = float(nf.angle_to_saddle(config.initial_features()))
    if status == "not_converged" and np.all(np.isfinite(result.image_features[-1])):
        angle = min(angle, float(nf.angle_to_saddle(result.image_features[-1])))
    if angle < SADDLE_NOTE_ANGLE_RAD:
        result.saddle_note = saddle_note(angle)
        result.message += f" ({result.saddle_note})"
    return result
