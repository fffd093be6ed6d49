"""simulate(config): run a servo loop with a safe-domain monitor and return its logs."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from pydrake.math import RigidTransform

from geovs_drake.geometry.joint_barrier import combine, joint_widths
from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.goal.arm import (
    joint_barrier_values,
    joint_count,
    joint_limit_margins,
    self_motion_speeds,
    smallest_singular_values,
)
from geovs_drake.goal.camera_fit import camera_fit
from geovs_drake.goal.linear_model import closed_form_refusal, tracking_lag
from geovs_drake.goal.step_limit import step_limit
from geovs_drake.goal.target_reach import target_reach_warning
from geovs_drake.loop.build import Loop, build_loop, effort_check, fit_gains
from geovs_drake.loop.targets import ESTIMATE_LOG_NAMES
from geovs_drake.planning import plan_for_scenario
from geovs_drake.scenario import (
    Nf,
    PathFollowing,
    ResolvedScenario,
    ScenarioConfig,
    Twist,
    resolve,
)
from geovs_drake.simulation.monitor import camera_signals, make_simulator
from geovs_drake.simulation.result import (
    MARGIN_NAMES,
    SADDLE_NOTE_ANGLE_RAD,
    ArmTrace,
    SimulationResult,
    TargetTrace,
    convergence_tolerance,
    energy_note,
    pose_error,
    saddle_note,
)
from geovs_drake.systems.arm_model import arm_plant

__all__ = ["StartOutsideDomain", "arm_trace", "check_start", "predicted_lag", "simulate"]


class StartOutsideDomain(ValueError):
    """The initial pose is not in the safe domain D (or not visible)."""


def check_start(config: ScenarioConfig | ResolvedScenario) -> None:
    """Raise StartOutsideDomain naming the first violated constraint."""
    if isinstance(config, ResolvedScenario):
        config = config.config
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


def predicted_lag(resolved: ResolvedScenario) -> float | None:
    """The position lag [m] the linearised loop predicts without feed-forward behind the
    scenario's moving target (:func:`~geovs_drake.goal.linear_model.tracking_lag`), or None
    where the closed form does not model the loop (a carrier other than the free rig, a
    law other than the NF) or the target stands still."""
    config = resolved.config
    if not isinstance(config.target_motion, Twist) or not isinstance(resolved.law, Nf):
        return None  # a still target, a trajectory (no steady lag), another law
    if closed_form_refusal(config, "tracking lag") is not None:
        return None
    eps = tracking_lag(config, np.asarray(config.target_motion.twist), resolved.damping)
    return float(np.linalg.norm(eps[3:]))


def _target_trace(loop: Loop, root) -> tuple[float | None, TargetTrace | None]:
    """The predicted lag, and the estimator's logs where it runs (else None)."""
    diagram, resolved = loop.diagram, loop.resolved
    if not diagram.HasSubsystemNamed(ESTIMATE_LOG_NAMES[0]):
        return predicted_lag(resolved), None
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
    return predicted_lag(resolved), trace


def simulate(
    config: ScenarioConfig | ResolvedScenario | None = None,
    meshcat=None,
    progress: Callable[[float], None] | None = None,
    on_warning: Callable[[str], None] | None = None,
) -> SimulationResult:
    """Simulate the configured loop (``config.carrier``, ``config.plant``, ``config.sensor``,
    ``config.controller``) for
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
    ``on_warning``, if given, is called with each warning line before the run starts
    (the step limit's, the camera's, the effort limits', a moving target's reach on an arm;
    the result keeps the first three), so
    that a long run's user reads them while it runs. The dynamic arm's effort check
    (:func:`~geovs_drake.loop.build.effort_check`, ``result.effort_fit``) runs where it
    is read: with ``on_warning`` or ``torque_limits: respect``; else it is None.
    """
    if not isinstance(config, ResolvedScenario):  # the arm's gain_scale: auto, chosen once
        config = fit_gains(ScenarioConfig() if config is None else config)
    resolved = resolve(config)  # the builder trusts it
    config = resolved.config
    check_start(config)
    loop = build_loop(resolved, meshcat=meshcat, log=False)
    diagram = loop.diagram
    limit = step_limit(resolved)
    fit = camera_fit(resolved)  # the gains against the camera, before the run (issue 31)
    # And against the arm's effort limits, where someone reads it: the command line (a
    # warning line) or torque_limits: respect (then fit_gains has checked it already, and
    # this is its cached result). Not in a sweep's every start: 0.3-0.5 s each.
    effort = (
        effort_check(resolved)
        if on_warning is not None or getattr(config.carrier, "torque_limits", "") == "respect"
        else None
    )
    warnings = (
        limit.warning(config.simulator.integration_scheme),
        None if fit is None else fit.warning(),
        None if effort is None else effort.warning(),
    )
    for line in warnings:
        if line is not None and on_warning is not None:
            on_warning(line)
    # A moving target against the arm's reach and speed (issue 42): a line, not a field.
    reach = target_reach_warning(config) if on_warning is not None else None
    if reach is not None:
        on_warning(reach)
    simulator, monitor = make_simulator(
        loop,
        record=True,
        on_step=progress,
        max_step_size=limit.max_step_size,
    )
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
    signals = camera_signals(loop, root, states, times)
    energy = None
    arm = arm_trace(loop, root, states) if loop.carrier.arm is not None else None
    nf_law = isinstance(resolved.law, Nf)
    if loop.carrier.plant is not None and loop.carrier.takes_wrench and nf_law:
        # Drake's own kinetic energy of the free body (or of the arm, 1/2 v^T M(q) v),
        # plus the potential k_p phi.
        plant = loop.carrier.plant
        pctx = plant.CreateDefaultContext()
        kinetic = np.empty(len(states))
        for k, x in enumerate(states):
            plant.SetPositionsAndVelocities(pctx, x)
            kinetic[k] = plant.CalcKineticEnergy(pctx)
        potential = signals["phi"]
        if arm is not None and arm.joint_barrier is not None:  # the barrier: phi_total
            potential = combine(potential, arm.joint_barrier)
        energy = kinetic + config.control.potential_gain * potential
    x_final = root.get_continuous_state_vector().CopyToVector()
    final_X_BC = RigidTransform(loop.carrier.camera_poses(x_final, root.get_time())[0])
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
        X_BC=loop.carrier.camera_poses(states, times),
        energy=energy,
        final_X_BC=final_X_BC,
        states=states,
        arm=arm,
    )
    result.step_limit = limit
    if config.moving_target:
        result.predicted_steady_error, result.target = _target_trace(loop, root)
        result.target_end_time = loop.diagram.GetSubsystemByName("target_motion").end_time()
    # Each check's one warning line, None where it has nothing to say.
    result.step_warning, result.camera_warning, result.effort_warning = warnings
    result.camera_fit = fit
    result.effort_fit = effort
    if result.energy_guarantee is False:
        result.message += f" ({energy_note(result.initial_energy, result.energy_bound)})"
    if isinstance(resolved.law, PathFollowing):  # what the planner found (cached)
        result.message += f" (plan: {plan_for_scenario(config, resolved.law).message})"
    if not nf_law:  # the energy and the saddle belong to the NF's law
        return result
    nf = NavigationFunction(resolved.domain, resolved.y_goal, resolved.gains)
    angle = float(nf.angle_to_saddle(config.initial_features()))
    if status == "not_converged" and np.all(np.isfinite(result.image_features[-1])):
        angle = min(angle, float(nf.angle_to_saddle(result.image_features[-1])))
    if angle < SADDLE_NOTE_ANGLE_RAD:
        result.saddle_note = saddle_note(angle)
        result.message += f" ({result.saddle_note})"
    return result
