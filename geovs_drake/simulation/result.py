"""A run's result: its logs, its summary in one line and as JSON, and the tolerances that
judge it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from pydrake.math import RigidTransform

from geovs_drake._json import json_ready
from geovs_drake.geometry.domain import DomainMargins
from geovs_drake.goal.linear_model import tracking_lag_range
from geovs_drake.scenario import PREDICTIONS, ScenarioConfig, radius_error_of, variant_name

if TYPE_CHECKING:  # named in annotations only: the batch engine's workers read the
    # tolerances here without the goal's models (an arm's MultibodyPlant) or the loop.
    from geovs_drake.goal.camera_fit import CameraFit
    from geovs_drake.goal.effort_fit import EffortFit
    from geovs_drake.goal.step_limit import StepLimit
    from geovs_drake.loop.resolved import ResolvedScenario

__all__ = [
    "CONVERGENCE_POSITION_M",
    "CONVERGENCE_ROTATION_RAD",
    "MARGIN_NAMES",
    "SADDLE_NOTE_ANGLE_RAD",
    "SimulationResult",
    "TargetTrace",
    "convergence_tolerance",
    "energy_exclusions",
    "energy_guarantee",
    "energy_note",
    "pose_error",
    "run_warnings",
    "saddle_note",
]

CONVERGENCE_POSITION_M = 1e-3
CONVERGENCE_ROTATION_RAD = 1e-3
#: A loop with a camera converges to what the camera resolves at the goal: within this
#: many pixels of lateral offset at the goal's distance, and this many pixel angles of
#: rotation (:func:`convergence_tolerance`).
CAMERA_TOLERANCE_PX = 2.0
CAMERA_ROTATION_TOLERANCE_PX = 5.0
MARGIN_NAMES = DomainMargins._fields


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


def energy_exclusions(resolved: ResolvedScenario) -> list[str]:
    """Why Appendix C's energy argument does not cover ``resolved``'s loop, one phrase
    each (empty where it does): behind a moving target, anything but the free rig with
    its known motion fed forward (the relative dynamics are then a still target's,
    docs/moving-target.md; behind an estimated or ignored motion, or on an arm
    simulated in the world, nothing bounds the energy the target's motion brings in);
    a law that reads a held frame (the argument needs continuous feedback; the
    sampled-data model at the goal, ``camera_fit``, is what is left); an arm whose
    torques over the energy level set pass its effort limits (the resolver's effort
    check, where it ran: MultibodyPlant clamps them, and the clamped torque does not do
    the work the argument counts on). The warning lines and the run's line say the same."""
    config = resolved.config
    out = []
    # A carrier that breaks the argument by what it is (the quadrotor's cascade) says so
    # in its traits.
    if config.carrier.traits.energy_exclusion:
        out.append(config.carrier.traits.energy_exclusion)
    if config.moving_target:
        if config.target_motion.feedforward != "known":
            out.append("behind a moving target it needs the known twist")
        elif not config.carrier.traits.rigid_body_goal:
            # The relative dynamics are a still target's for the rigid body of Appendix C.
            out.append("behind a moving target it covers the free rig only")
    # A camera's capability, not its variant: a sensor without a prediction (the exact
    # one) feeds the law continuously.
    prediction = getattr(config.sensor, "prediction", None)
    if prediction is not None and not PREDICTIONS[prediction].continuous:
        out.append(
            "the law reads a held frame (prediction: none), and the argument needs "
            "continuous feedback"
        )
    effort = resolved.effort
    if effort is not None and not effort.within:
        out.append(
            f"the arm's torques reach {effort.worst_ratio:.2g} times {effort.joint}'s "
            f"effort limit over E <= {effort.level:.3g} k_p, where MultibodyPlant "
            "clamps them"
        )
    return out


def energy_guarantee(resolved: ResolvedScenario, energy: np.ndarray | None) -> bool | None:
    """E0 < k_p: Appendix C's guarantee that phi < 1 throughout, for a run whose energy
    along it is ``energy`` (dynamic, under the NF); None where the run has no energy (a
    kinematic loop, another law) or the argument does not cover it
    (:func:`energy_exclusions`)."""
    if energy is None or energy_exclusions(resolved):
        return None
    return bool(energy[0] < resolved.config.control.potential_gain)


def convergence_tolerance(resolved: ResolvedScenario) -> tuple[float, float]:
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
    config = resolved.config
    if not config.sensor.traits.camera:
        return CONVERGENCE_POSITION_M, CONVERGENCE_ROTATION_RAD
    f = config.sensor.intrinsics(resolved.domain.fov_half_angle).fx
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


@dataclass(frozen=True)
class ArmTrace:
    """The arm along a run (carrier "arm"), at the logged times.

    ``joint_limit_margin``: the nearest joint's distance to its limit [rad], positive
    inside; ``jacobian_singular_value``: sigma_min of J_C; ``velocity_scale`` (the
    kinematic arm): the factor its joint velocities were scaled by to respect the
    velocity limits (1: not limited), else None; ``joint_barrier``: phi_q, the joints'
    barrier (the arm's ``joint_barrier_width`` > 0), else None; ``self_motion_speed``: the
    speed of a redundant arm's self-motion, the part of its joint velocity that leaves
    the camera still [rad/s] (the dynamic arm with more than 6 joints), else None.
    """

    joint_positions: np.ndarray
    joint_limit_margin: np.ndarray
    jacobian_singular_value: np.ndarray
    velocity_scale: np.ndarray | None = None
    joint_barrier: np.ndarray | None = None
    self_motion_speed: np.ndarray | None = None

    def summary(self) -> dict:
        """The JSON entries of the arm's run."""
        out = {
            "min_joint_limit_margin": float(np.min(self.joint_limit_margin)),
            "min_jacobian_singular_value": float(np.min(self.jacobian_singular_value)),
        }
        if self.velocity_scale is not None:
            out["joint_velocity_clipped"] = float(np.mean(self.velocity_scale < 1.0))
        if self.joint_barrier is not None:
            out["max_joint_barrier"] = float(np.max(self.joint_barrier))
        if self.self_motion_speed is not None:
            out["final_self_motion_speed"] = float(self.self_motion_speed[-1])
        return json_ready(out)


@dataclass(frozen=True)
class TargetTrace:
    """A moving target's estimator along a run (``target_motion`` with the ``estimated``
    feed-forward), at its own updates: ``times`` [s], ``twist_estimate`` (N, 6) and the
    filter's ``covariance_diagonal`` (N, 12, the pose's error then the twist's), against
    the true twist ``twist`` (N, 6) at those times."""

    times: np.ndarray
    twist_estimate: np.ndarray
    covariance_diagonal: np.ndarray
    twist: np.ndarray

    @property
    def estimation_error(self) -> np.ndarray:
        """``|xi_hat - xi_B|`` (N,), in the twist's mixed units (rad/s and m/s)."""
        return np.linalg.norm(self.twist_estimate - self.twist, axis=1)

    def summary(self) -> dict:
        """The JSON entries of the estimator's run."""
        return json_ready(
            {
                "final_twist_estimate": self.twist_estimate[-1],
                "final_twist_estimation_error": self.estimation_error[-1],
                "final_twist_std": np.sqrt(self.covariance_diagonal[-1, 6:]),
            }
        )


#: The share of a run, from its end, over which the steady tracking error is read.
STEADY_SHARE = 0.25


def run_warnings(resolved: ResolvedScenario) -> tuple[str, ...]:
    """The lines a run's user reads before it starts, from what the resolver found: the
    step limit's (a stiff loop, a step beyond the bound), the camera fit's (gains too
    close to instability), the effort check's (torques past a limit) and the carrier's
    changed start (the quadrotor's level one); none where each has nothing to say."""
    config = resolved.config
    lines = (
        resolved.step_limit.warning(config.simulator.integration_scheme),
        None if resolved.camera_fit is None else resolved.camera_fit.warning(),
        None if resolved.effort is None else resolved.effort.warning(),
        None if resolved.reach is None else resolved.reach.warning(),
        resolved.start_note,
    )
    return tuple(line for line in lines if line is not None)


@dataclass(frozen=True)
class SimulationResult:
    """A run's logs and summary, made once at the run's end. Arrays are sampled at
    ``config.log_rate``; what the resolver derived (the step limit, the camera fit, the
    effort check) is read from ``resolved``."""

    resolved: ResolvedScenario
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
    arm: ArmTrace | None = None  # carrier "arm": its joints along the run
    #: Drake's continuous states at ``times`` (for the linearisation along the run).
    states: np.ndarray | None = None
    #: A moving target: the lag the linearised loop predicts without feed-forward
    #: [m] (the resolver's for the NF, :func:`geovs_drake.goal.linear_model.tracking_lag`;
    #: None where no model covers the loop), and the estimator's trace (the ``estimated``
    #: feed-forward), else None.
    predicted_steady_error: float | None = None
    target: TargetTrace | None = None
    #: A moving target's end [s], where it stops (its trajectory's last knot; inf for a
    #: constant twist), as the run's TargetMotion had it; else None.
    target_end_time: float | None = None
    #: The carrier's own entries in :meth:`summary` (``CarrierParts.run_entries``: the
    #: quadrotor's rotor saturation and peak tilt); empty for the others.
    carrier_entries: dict = field(default_factory=dict)

    @property
    def config(self) -> ScenarioConfig:
        """The scenario run, as resolved (the arm's gains scaled)."""
        return self.resolved.config

    @property
    def step_limit(self) -> StepLimit:
        """The goal's fastest mode and the step limit run with (the resolver's)."""
        return self.resolved.step_limit

    @property
    def camera_fit(self) -> CameraFit | None:
        """The run's gains against its camera, for a camera loop a model covers."""
        return self.resolved.camera_fit

    @property
    def effort_fit(self) -> EffortFit | None:
        """The dynamic arm's torques over its energy level set against its effort limits
        (None where not checked: see :func:`~geovs_drake.loop.resolver`'s ``effort``)."""
        return self.resolved.effort

    @property
    def step_warning(self) -> str | None:
        """One line where the step limit puts the goal's fastest mode beyond the bound."""
        return self.step_limit.warning(self.config.simulator.integration_scheme)

    @property
    def camera_warning(self) -> str | None:
        """One line where the gains keep less than the camera's gain margin."""
        return None if self.camera_fit is None else self.camera_fit.warning()

    @property
    def effort_warning(self) -> str | None:
        """One line where the torques pass an effort limit."""
        return None if self.effort_fit is None else self.effort_fit.warning()

    @property
    def position_errors(self) -> np.ndarray:
        """``|p_BC - p_BC*|`` [m] at each logged time: the camera relative to the target,
        against the goal (a moving target's tracking error)."""
        return np.linalg.norm(self.X_BC[:, :3, 3] - self.config.X_BC_goal.translation(), axis=1)

    @property
    def steady_tracking_error(self) -> float:
        """The largest position error over the last :data:`STEADY_SHARE` of the run [m]."""
        start = self.times[-1] - STEADY_SHARE * (self.times[-1] - self.times[0])
        return float(np.max(self.position_errors[self.times >= start]))

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
    def energy_exclusions(self) -> list[str]:
        """Why Appendix C's energy argument does not cover this run's loop
        (:func:`energy_exclusions`)."""
        return energy_exclusions(self.resolved)

    @property
    def energy_applies(self) -> bool:
        """Whether Appendix C's energy argument covers this run's loop: no
        :attr:`energy_exclusions`."""
        return not self.energy_exclusions

    @property
    def energy_guarantee(self) -> bool | None:
        """E0 < k_p: Appendix C's guarantee that phi < 1 throughout (dynamic), else None
        (:func:`energy_guarantee`)."""
        return energy_guarantee(self.resolved, self.energy)

    @property
    def energy_guarantee_reason(self) -> str:
        """:attr:`energy_guarantee`'s reason, in the words the run's line uses: E0 against
        k_p where the argument covers the run, else why not."""
        if self.energy is None:
            return (
                "no energy guarantee: the kinematic loop has no energy"
                if not self.config.dynamic
                else "no energy guarantee: the law's energy is not the NF's, k_p phi"
            )
        if self.energy_applies:
            return energy_note(self.initial_energy, self.energy_bound)
        return f"no energy guarantee: {'; '.join(self.energy_exclusions)}"

    @property
    def final_errors(self) -> tuple[float, float]:
        """``(position [m], rotation [rad])`` errors of the final pose from the goal."""
        return pose_error(self.final_X_BC, self.config.X_BC_goal)

    @property
    def convergence_time(self) -> float:
        """The first logged time from which the pose error stays within the run's
        convergence tolerances (:func:`convergence_tolerance`, :attr:`converged`'s: a
        camera's are coarser) to the end; NaN unless the run converged."""
        if self.status != "converged":
            return math.nan
        tol_p, tol_r = convergence_tolerance(self.resolved)
        t_converged = math.nan
        for t, X in zip(self.times[::-1], self.X_BC[::-1], strict=True):
            dp, dr = pose_error(RigidTransform(X), self.config.X_BC_goal)
            if dp > tol_p or dr > tol_r:
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
        tol_p, tol_r = convergence_tolerance(self.resolved)
        return (
            not self.left_domain and self.status != "feature_lost" and dp <= tol_p and dr <= tol_r
        )

    def one_line(self) -> str:
        """The run in one line: status, final errors, minimum margins, timing."""
        s = self.summary()
        cam = self.config.sensor
        sensor = ""
        if cam.traits.camera:
            width, height = (int(v) for v in cam.resolution)
            sensor = f", {s['sensor']} camera {width}x{height} at {cam.rate:g} Hz"
        # The same verdict and reason as the JSON's (energy_guarantee_reason).
        energy = "" if self.energy is None else f" | {self.energy_guarantee_reason}"
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
        the NF, whose energy is not k_p phi; ``energy_guarantee`` is None too where the
        argument does not cover the run (:attr:`energy_exclusions`), and
        ``energy_guarantee_reason`` says why, as the run's line does. ``ibvs_depth`` is
        the IBVS depth estimate for the law ``ibvs``, else None."""
        dp, dr = self.final_errors
        tol_p, tol_r = convergence_tolerance(self.resolved)
        law = self.config.controller
        depth = law.traits.depth_label
        moving = self.config.moving_target
        out = {
            "plant": variant_name(self.config.plant),
            "carrier": variant_name(self.config.carrier),
            "controller": variant_name(law),
            "mount": "hand" if self.config.carrier.traits.camera_in_hand else "fixed",
            "ibvs_depth": getattr(law, depth) if depth else None,
            "sensor": variant_name(self.config.sensor),
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
            "energy_guarantee_reason": self.energy_guarantee_reason,
            "max_energy": None if self.energy is None else float(np.max(self.energy)),
            # A moving target's alone: behind a still one they would repeat the start's
            # error (issue 42).
            "steady_tracking_error_m": self.steady_tracking_error if moving else None,
            "max_tracking_error_m": float(np.max(self.position_errors)) if moving else None,
            "predicted_steady_error_m": self.predicted_steady_error,
            # How far that linear lag holds: measured for the NF's behind a constant twist
            # (issue 42; the variants by their registry names).
            # How far that linear lag holds: measured for the NF's behind a constant twist
            # (issue 42).
            "predicted_steady_error_range": (
                tracking_lag_range(self.config, self.config.target_motion.twist)
                if self.predicted_steady_error is not None
                and law.traits.navigation
                and self.config.target_motion.traits.constant_twist
                else None
            ),
        }
        out |= self._target_entries() | self._camera_entries() | self._effort_entries()
        out["radius_error"] = radius_error_of(self.config.sensor)
        out |= self.carrier_entries
        if self.arm is not None:
            out.update(self.arm.summary())
        out |= self._step_entries()
        return json_ready(out)

    def _target_entries(self) -> dict:
        """A moving target's entry: its kind, feed-forward, twist or end, estimator."""
        motion = self.config.target_motion
        if not self.config.moving_target:
            return {}
        entry = {"kind": type(motion).__name__, "feedforward": motion.feedforward}
        if motion.traits.constant_twist:
            entry["twist"] = [float(v) for v in motion.twist]
        else:  # a trajectory's knots: its end, where the target stops
            entry["end_time_s"] = self.target_end_time
        if self.target is not None:
            entry.update(self.target.summary())
        return {"target_motion": entry}

    def _camera_entries(self) -> dict:
        """A camera's entry: its settings and the sampled-data model's verdict at the goal."""
        cam = self.config.sensor
        if not cam.traits.camera:
            return {}
        entry = {
            "rate_hz": cam.rate,
            "resolution": [int(v) for v in cam.resolution],
            "pixel_noise_px": cam.pixel_noise,
            "focal_error": cam.focal_error,
            "latency_frames": int(cam.latency_frames),
            "prediction": cam.prediction,
        }
        fit = self.camera_fit
        if fit is not None:  # the sampled-data model at the goal (goal.camera_fit)
            entry["spectral_radius"] = fit.spectral_radius
            entry["largest_stable_gain"] = {
                "field": fit.gain_name,
                "value": fit.largest_stable_gain,  # inf (every scale searched): null
                "this_run": fit.gain_value,
            }
        return {"camera": entry}

    def _effort_entries(self) -> dict:
        """The torques over the energy level set against the effort limits, if checked."""
        effort = self.effort_fit
        if effort is None:
            return {}
        return {
            "effort": {
                "level": effort.level,
                "worst_ratio": effort.worst_ratio,
                "joint": effort.joint,
                "largest_gain_scale": effort.largest_scale,  # inf: null
                "this_run": effort.gain_scale,
                "samples": effort.samples,
            }
        }

    def _step_entries(self) -> dict:
        """What the integrator ran with, and why (the resolver's step limit)."""
        limit = self.step_limit
        if limit is None:
            return {}
        lam = limit.fastest_mode
        return {
            "max_step_size": limit.max_step_size,
            "max_step_automatic": limit.automatic,
            "fastest_mode": None if lam is None else [lam.real, lam.imag],
        }
