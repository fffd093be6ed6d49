"""simulate(config): run a servo loop with a safe-domain monitor and return its logs.

A straight line: resolve (once, :func:`~geovs_drake.loop.resolver`), build
(:func:`~geovs_drake.loop.assembly.assemble_loop`), run (Drake's Simulator under the
monitor), report (one :class:`~geovs_drake.simulation.result.SimulationResult`, made
once). What the scenario derives is read from the resolved scenario.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from pydrake.math import RigidTransform

from geovs_drake.geometry.joint_barrier import combine, joint_widths
from geovs_drake.goal.arm import (
    joint_barrier_values,
    joint_count,
    joint_limit_margins,
    self_motion_speeds,
    smallest_singular_values,
)
from geovs_drake.loop.assembly import Loop, assemble_loop
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.resolver import resolve
from geovs_drake.loop.targets import ESTIMATE_LOG_NAMES
from geovs_drake.planning import plan_for_scenario
from geovs_drake.scenario import ScenarioConfig
from geovs_drake.simulation.monitor import camera_signals, make_simulator
from geovs_drake.simulation.result import (
    MARGIN_NAMES,
    SADDLE_NOTE_ANGLE_RAD,
    ArmTrace,
    SimulationResult,
    TargetTrace,
    convergence_tolerance,
    energy_guarantee,
    energy_note,
    pose_error,
    run_warnings,
    saddle_note,
)
from geovs_drake.systems.arm_model import arm_plant

__all__ = ["StartOutsideDomain", "arm_trace", "check_start", "simulate"]


class StartOutsideDomain(ValueError):
    """The initial pose is not in the safe domain D (or not visible)."""


def check_start(config: ScenarioConfig | ResolvedScenario) -> None:
    """Raise StartOutsideDomain naming the first violated constraint of the start in the
    resolved D (a plain config is resolved first; its goal was checked there)."""
    _check_start(resolve(config))


def _check_start(resolved: ResolvedScenario) -> None:
    # Where the carrier changed the start (the quadrotor's level one), the line says so.
    changed = (
        "" if resolved.start_note is None else f" (the start as changed: {resolved.start_note})"
    )
    try:
        y0 = resolved.config.initial_features()
    except ValueError as e:
        raise StartOutsideDomain(f"start outside D: {e}{changed}") from e
    margins = resolved.domain.margins(y0)
    for name, value in zip(MARGIN_NAMES, margins, strict=True):
        if float(value) < 0:
            raise StartOutsideDomain(
                f"start outside D: {name} margin = {float(value):.4g} < 0{changed}"
            )


def arm_trace(loop: Loop, root, states: np.ndarray) -> ArmTrace:
    """The arm along the logged states: joint margins, sigma_min of J_C and, on the
    kinematic arm, its velocity scale (the diagram evaluated at each state)."""
    model = loop.carrier.arm
    nq = joint_count(model)
    q = states[:, :nq]
    scale = None
    if loop.diagram.HasSubsystemNamed("kinematic_arm"):
        arm = loop.diagram.GetSubsystemByName("kinematic_arm")
        context = root.Clone()
        scale = np.empty(len(states))
        for k, x in enumerate(states):
            context.SetContinuousState(x)
            scale[k] = arm.velocity_scale_output.Eval(arm.GetMyContextFromRoot(context))[0]
    # The barrier's width per joint, as ArmCamera has it (None: no barrier).
    carrier, plant = loop.resolved.config.carrier, arm_plant(model)
    widths = joint_widths(
        plant.GetPositionLowerLimits(),
        plant.GetPositionUpperLimits(),
        carrier.joint_barrier_width,
        carrier.joint_barrier_fraction,
    )
    # A redundant torque-driven arm: its state carries v, whose self-motion is shown.
    redundant = nq > 6 and states.shape[1] == 2 * nq
    return ArmTrace(
        joint_positions=q,
        joint_limit_margin=np.min(joint_limit_margins(model, q), axis=1),
        jacobian_singular_value=smallest_singular_values(model, q),
        velocity_scale=scale,
        joint_barrier=None if widths is None else joint_barrier_values(model, q, widths),
        self_motion_speed=self_motion_speeds(model, q, states[:, nq:]) if redundant else None,
    )


def _target_trace(loop: Loop, root) -> TargetTrace | None:
    """The estimator's logs where it runs (else None)."""
    diagram = loop.diagram
    if not diagram.HasSubsystemNamed(ESTIMATE_LOG_NAMES[0]):
        return None
    twist, covariance = (
        diagram.GetSubsystemByName(name).FindLog(root) for name in ESTIMATE_LOG_NAMES
    )
    times = twist.sample_times().copy()
    motion = diagram.GetSubsystemByName("target_motion")
    trace = TargetTrace(
        times=times,
        twist_estimate=twist.data().T.copy(),
        covariance_diagonal=covariance.data().T.copy(),
        twist=np.array([motion.xi_B(t) for t in times]).reshape(-1, 6),
    )
    return trace


def simulate(
    config: ScenarioConfig | ResolvedScenario | None = None,
    meshcat=None,
    progress: Callable[[float], None] | None = None,
    on_warning: Callable[[str], None] | None = None,
) -> SimulationResult:
    """Simulate the configured loop (``config.carrier``, ``config.plant``, ``config.sensor``,
    ``config.controller``) for ``config.duration``: resolve it once (a resolved scenario is
    taken as it is), build it, run it, report it.

    Raises StartOutsideDomain if the start is not in D. A run that leaves D
    stops early with ``status`` ``left_domain`` / ``lost_visibility``; a loop with
    a camera whose frame gives no y stops with ``feature_lost``. With a camera the
    logs (y, phi, margins, energy) are the true pose's; the controller acted on
    the measured y. The dynamic loop starts with the camera's body twist
    ``config.initial_velocity``; if its energy E0 is not below k_p, the message says that
    Appendix C's energy guarantee does not cover the start (see :func:`energy_note`).
    ``progress`` (default None: off), if given, is called with the simulated
    time after every accepted step, from the safe-domain monitor; e.g. a
    :class:`geovs_drake.progress.HorizonProgress`. It does not change the run.
    The logs are sampled at ``config.log_rate`` from the recorded steps (see
    :class:`SafeDomainMonitor`); ``wall_time_s`` times the integration alone.
    ``on_warning``, if given, is called with each warning line before the run starts
    (:func:`~geovs_drake.simulation.result.run_warnings`: the step limit's, the camera's,
    the effort limits'; the result keeps them too), so that a long run's user reads them
    while it runs. A plain config given with ``on_warning`` is resolved with the dynamic
    arm's effort check (``result.effort_fit``), which otherwise runs only where
    ``torque_limits: respect`` needs it (0.3-0.5 s: not in a sweep's every start).
    """
    resolved = resolve(config, effort=on_warning is not None)
    _check_start(resolved)
    loop = assemble_loop(resolved, meshcat=meshcat, log=False)
    for line in run_warnings(resolved):
        if on_warning is not None:
            on_warning(line)
    simulator, monitor = make_simulator(loop, record=True, on_step=progress)
    root = simulator.get_mutable_context()
    if meshcat is not None:
        loop.diagram.ForcedPublish(root)
    wall, failure = _advance(simulator, resolved.config.duration)
    return _report(loop, simulator, monitor, wall, failure)


def _advance(simulator, duration: float) -> tuple[float, str | None]:
    """Run to ``duration`` (or the monitor's stop); the integration's wall time [s] and
    Drake's line where its error control found no step it could accept (else None)."""
    # Initialize()'s monitor call may already stop the run (a law's feature point out
    # of view, or a camera whose first frame gives no y, at t = 0); AdvanceTo would
    # otherwise take one step regardless (on a held y of NaN).
    initial = simulator.Initialize()
    stopped = initial.reason() == initial.ReturnReason.kReachedTerminationCondition
    if not stopped:
        # The derivatives once at the start, so that every system on their path has
        # loaded its compiled kernels (numba's cache) before the timing: Initialize()
        # evaluates only what its events and the monitor read, and the first step
        # paid the rest (12 ms of a 10-s UR5 run's 107 ms). The first step evaluates
        # them again (Drake's integrator marks them out of date): the same values.
        simulator.get_system().EvalTimeDerivatives(simulator.get_context())
    start = time.perf_counter()
    failure = None
    try:
        if not stopped:
            simulator.AdvanceTo(duration)
    except RuntimeError as e:
        # Drake's error control found no step it could accept: the derivatives
        # grow without bound (a law's command near its singularity). The batch
        # engine calls the same event non_finite; the run ends here with that status.
        if "step smaller than minimum" not in str(e):
            raise
        failure = str(e).strip().splitlines()[0]
    return time.perf_counter() - start, failure


def _status(loop: Loop, root, monitor, failure: str | None, final_X_BC) -> tuple[str, str]:
    """The run's status and its message: the monitor's stop, Drake's failure, or the end
    judged against the convergence tolerances."""
    term_status, term_message = monitor.termination()
    if term_status:
        return term_status, term_message
    if failure is not None:
        return "non_finite", (
            f"no accurate step exists at t = {root.get_time():.4g}: the derivatives grow "
            f"without bound (Drake: {failure})"
        )
    dp, dr = pose_error(final_X_BC, loop.resolved.config.X_BC_goal)
    tol_p, tol_r = convergence_tolerance(loop.resolved)
    converged = dp <= tol_p and dr <= tol_r
    return "converged" if converged else "not_converged", (
        f"{'converged' if converged else 'did not converge'}: position error {dp:.3g} m, "
        f"rotation error {dr:.3g} rad after {root.get_time():.3g} s"
    )


def _energy(loop: Loop, states: np.ndarray, phi: np.ndarray, arm: ArmTrace | None):
    """E = kinetic + k_p phi along the run (Appendix C), where the NF's law drives a
    force-driven carrier with a plant: Drake's own kinetic energy of the free body (or
    of the arm, 1/2 v^T M(q) v), plus the potential (the joint barrier's, phi_total,
    where it is on); else None."""
    resolved = loop.resolved
    plant = loop.carrier.plant
    if plant is None or not loop.carrier.takes_wrench or not resolved.law.traits.navigation:
        return None
    pctx = plant.CreateDefaultContext()
    kinetic = np.empty(len(states))
    for k, x in enumerate(states):
        plant.SetPositionsAndVelocities(pctx, x)
        kinetic[k] = plant.CalcKineticEnergy(pctx)
    potential = phi if arm is None or arm.joint_barrier is None else combine(phi, arm.joint_barrier)
    return kinetic + resolved.config.control.potential_gain * potential


def _report(loop: Loop, simulator, monitor, wall: float, failure: str | None) -> SimulationResult:
    """The run as one :class:`SimulationResult`, its message with every note it needs."""
    resolved = loop.resolved
    config = resolved.config
    root = simulator.get_mutable_context()
    times, states = monitor.resample(config.log_rate)
    signals = camera_signals(loop, root, states, times)
    arm = arm_trace(loop, root, states) if loop.carrier.arm is not None else None
    x_final = root.get_continuous_state_vector().CopyToVector()
    final_X_BC = RigidTransform(loop.carrier.camera_poses(x_final, root.get_time())[0])
    status, message = _status(loop, root, monitor, failure, final_X_BC)
    energy = _energy(loop, states, signals["phi"], arm)
    moving = config.moving_target
    fields = dict(
        resolved=resolved,
        status=status,
        sim_time_s=root.get_time(),
        wall_time_s=wall,
        steps=simulator.get_num_steps_taken(),
        times=times,
        image_features=signals["image_features"],
        phi=signals["phi"],
        margins=signals["margins"],
        visibility=signals["visibility"],
        X_BC=loop.carrier.camera_poses(states, times),
        energy=energy,
        final_X_BC=final_X_BC,
        states=states,
        arm=arm,
        predicted_steady_error=resolved.predicted_lag if moving else None,
        target=_target_trace(loop, root) if moving else None,
        target_end_time=(
            loop.diagram.GetSubsystemByName("target_motion").end_time() if moving else None
        ),
        carrier_entries=(
            {}
            if loop.carrier.run_entries is None
            else loop.carrier.run_entries(root, states, times)
        ),
    )
    # The notes the message carries: the energy's where it does not cover the start
    # (the result's energy_guarantee), the planner's, the saddle's.
    if energy_guarantee(resolved, energy) is False:
        message += f" ({energy_note(float(energy[0]), config.control.potential_gain)})"
    if resolved.law.traits.plans:  # what the planner found (cached)
        message += f" (plan: {plan_for_scenario(config, resolved.law).message})"
    note = _saddle(resolved, status, signals["image_features"])
    if note is not None:
        message += f" ({note})"
    return SimulationResult(message=message, saddle_note=note, **fields)  # made once


def _saddle(resolved: ResolvedScenario, status: str, y: np.ndarray) -> str | None:
    """The saddle's note where the NF's start (or an unconverged end) is within
    :data:`SADDLE_NOTE_ANGLE_RAD` of its saddle; else None (another law has no saddle)."""
    if not resolved.law.traits.navigation:
        return None
    nf = resolved.nf
    angle = float(nf.angle_to_saddle(resolved.config.initial_features()))
    if status == "not_converged" and np.all(np.isfinite(y[-1])):
        angle = min(angle, float(nf.angle_to_saddle(y[-1])))
    return saddle_note(angle) if angle < SADDLE_NOTE_ANGLE_RAD else None
