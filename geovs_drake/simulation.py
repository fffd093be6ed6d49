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

from geovs_drake.diagrams import make_dynamic_servo_diagram, make_kinematic_servo_diagram
from geovs_drake.domain import DomainMargins
from geovs_drake.navigation import NavigationFunction
from geovs_drake.scenario import ScenarioConfig

__all__ = [
    "CONVERGENCE_POSITION_M",
    "CONVERGENCE_ROTATION_RAD",
    "SimulationResult",
    "StartOutsideDomain",
    "camera_pose_in_target",
    "check_start",
    "make_simulator",
    "pose_error",
    "simulate",
]

CONVERGENCE_POSITION_M = 1e-3
CONVERGENCE_ROTATION_RAD = 1e-3
MARGIN_NAMES = DomainMargins._fields


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
        L = self.lyapunov
        return bool(len(L) < 2 or np.max(np.diff(L)) <= self.lyapunov_tolerance)

    @property
    def final_errors(self) -> tuple[float, float]:
        return pose_error(self.final_X_BC, self.config.X_BC_goal)

    @property
    def left_domain(self) -> bool:
        return self.status in ("left_domain", "lost_visibility")

    @property
    def converged(self) -> bool:
        dp, dr = self.final_errors
        return (
            not self.left_domain and dp <= CONVERGENCE_POSITION_M and dr <= CONVERGENCE_ROTATION_RAD
        )

    def summary(self) -> dict:
        dp, dr = self.final_errors
        out = {
            "controller": self.config.controller,
            "converged": self.converged,
            "status": self.status,
            "message": self.message,
            "final_position_error_m": dp,
            "final_rotation_error_rad": dr,
            "final_phi": float(self.phi[-1]),
            "min_fov_margin": float(np.min(self.margins[:, 0])),
            "min_lambda_margin": float(np.min(self.margins[:, 1:3])),
            "min_occlusion_margin": float(np.min(self.margins[:, 3])),
            "min_visibility": float(np.min(self.visibility)),
            "left_domain": self.left_domain,
            "lyapunov_monotone": self.lyapunov_monotone,
            "max_lyapunov_increase": float(np.max(np.diff(self.lyapunov), initial=0.0)),
            "sim_time_s": self.sim_time_s,
            "wall_time_s": self.wall_time_s,
            "steps": self.steps,
        }
        if self.energy is not None:
            out["max_energy"] = float(np.max(self.energy))
            out["initial_energy"] = float(self.energy[0])
        return out


def make_simulator(
    diagram: Diagram, config: ScenarioConfig
) -> tuple[Simulator, Callable[[], tuple[str, str]]]:
    """A Simulator with the config's integrator and a safe-domain monitor.

    The monitor runs after every step. It ends the run with
    ``ReachedTermination`` when the camera loses sight of the marked point
    (nu <= 0), leaves D (a margin < 0), or the state is not finite, so a
    run never continues into NaN. Returns the simulator and a function that
    reports ``(status, message)`` of the last termination, if any.
    """
    simulator = Simulator(diagram)
    ApplySimulatorConfig(config.simulator, simulator)
    camera = diagram.GetSubsystemByName("spherical_camera")
    reason: dict[str, str] = {}

    def monitor(root_context) -> EventStatus:
        x = root_context.get_continuous_state_vector().CopyToVector()
        if not np.all(np.isfinite(x)):
            reason.update(
                status="non_finite",
                message=f"non-finite state at t = {root_context.get_time():.4g}",
            )
            return EventStatus.ReachedTermination(diagram, reason["message"])
        ctx = camera.GetMyContextFromRoot(root_context)
        nu = float(camera.visibility_output.Eval(ctx)[0])
        if nu <= 0:
            reason.update(
                status="lost_visibility",
                message=(
                    f"lost visibility: nu(H) = {nu:.4g} <= 0 at t = {root_context.get_time():.4g}"
                ),
            )
            return EventStatus.ReachedTermination(diagram, reason["message"])
        margins = camera.domain_margins_output.Eval(ctx)
        i = int(np.argmin(margins))
        if margins[i] < 0:
            reason.update(
                status="left_domain",
                message=(
                    f"left D: {MARGIN_NAMES[i]} margin = {margins[i]:.4g} < 0 "
                    f"at t = {root_context.get_time():.4g}"
                ),
            )
            return EventStatus.ReachedTermination(diagram, reason["message"])
        return EventStatus.Succeeded()

    simulator.set_monitor(monitor)
    return simulator, lambda: (reason.get("status", ""), reason.get("message", ""))


def camera_pose_in_target(config: ScenarioConfig, x: np.ndarray, dynamic: bool) -> RigidTransform:
    """X_BC from a state whose first 7 entries are X_WR (dynamic) or X_WC (kinematic)."""
    q = np.asarray(x[0:4], dtype=float)
    X_W = RigidTransform(RotationMatrix(Quaternion(q / np.linalg.norm(q))), x[4:7])
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


def simulate(
    config: ScenarioConfig | None = None,
    meshcat=None,
    progress: Callable[[float], None] | None = None,
) -> SimulationResult:
    """Simulate the configured loop (``config.controller``) for ``config.duration``.

    Raises StartOutsideDomain if the start is not in D. A run that leaves D
    stops early with ``status`` ``left_domain`` / ``lost_visibility``.
    ``progress``, if given, is called with the simulated time as it advances.
    """
    config = config or ScenarioConfig()
    config.validate()
    check_start(config)
    dynamic = config.controller == "dynamic"
    diagram = (
        make_dynamic_servo_diagram(config, meshcat=meshcat)
        if dynamic
        else make_kinematic_servo_diagram(config)
    )
    simulator, termination = make_simulator(diagram, config)
    root = simulator.get_mutable_context()
    if meshcat is not None:
        diagram.ForcedPublish(root)
    status, message = "completed", ""
    start = time.perf_counter()
    simulator.Initialize()
    if progress is None:
        simulator.AdvanceTo(config.duration)
    else:
        chunk = config.duration / 100
        while root.get_time() < config.duration - 1e-12:
            sim_status = simulator.AdvanceTo(min(config.duration, root.get_time() + chunk))
            progress(root.get_time())
            if sim_status.reason() != sim_status.ReturnReason.kReachedBoundaryTime:
                break
    wall = time.perf_counter() - start
    term_status, term_message = termination()
    if term_status:
        status, message = term_status, term_message

    def log(name: str) -> np.ndarray:
        return diagram.GetSubsystemByName(name).FindLog(root)

    y_log = log("log_image_features")
    times = y_log.sample_times()
    pose_log = log("log_body_state" if dynamic else "log_body_pose").data()
    phi = log("log_phi").data()[0]
    energy = None
    if dynamic:
        plant = diagram.GetSubsystemByName("plant")
        pctx = plant.CreateDefaultContext()
        kinetic = np.empty(pose_log.shape[1])
        for k in range(pose_log.shape[1]):
            plant.SetPositionsAndVelocities(pctx, pose_log[:, k])
            kinetic[k] = plant.CalcKineticEnergy(pctx)
        energy = kinetic + config.control.potential_gain * phi
    x_final = root.get_continuous_state_vector().CopyToVector()
    final_X_BC = camera_pose_in_target(config, x_final, dynamic)
    if status == "completed":
        dp, dr = pose_error(final_X_BC, config.X_BC_goal)
        converged = dp <= CONVERGENCE_POSITION_M and dr <= CONVERGENCE_ROTATION_RAD
        status = "converged" if converged else "not_converged"
        message = (
            f"{'converged' if converged else 'did not converge'}: position error {dp:.3g} m, "
            f"rotation error {dr:.3g} rad after {root.get_time():.3g} s"
        )
    return SimulationResult(
        config=config,
        status=status,
        message=message,
        sim_time_s=root.get_time(),
        wall_time_s=wall,
        steps=simulator.get_num_steps_taken(),
        times=times,
        image_features=y_log.data().T,
        phi=phi,
        margins=log("log_margins").data().T,
        visibility=log("log_visibility").data()[0],
        X_BC=_poses_from_log(config, pose_log, dynamic),
        energy=energy,
        final_X_BC=final_X_BC,
    )
