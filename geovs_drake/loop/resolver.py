"""``resolve(config)``: a scenario validated, and everything a run derives from it, once.

The one place where the values a run needs are worked out (the shape of Drake's
hardware_sim: load, validate, then build from what was resolved)::

    config.validate()                     D and the NF's gains, checked and kept
    the start                             the carrier's (the quadrotor's level one)
    y*, NF on D, its Hessian at y*        the goal (Eq. 33's phi and its chart Hessian)
    gain scale                            the arm's gain_scale (auto: fitted to the
                                          camera, then to the effort limits)
    goal model, camera fit, step limit    the loop at the goal (geovs_drake.goal)
    effort check, predicted lag           where asked, or where the fit needed it

Everything downstream (the loop's assembly, the simulator, the batch engine, the
studies, the hardware builders, the command line) reads the
:class:`~geovs_drake.loop.resolved.ResolvedScenario` and derives none of it again.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.goal.camera_fit import GAIN_MARGIN, CameraFit, camera_fit
from geovs_drake.goal.effort_fit import EffortFit, effort_fit
from geovs_drake.goal.linear_model import closed_form_refusal, navigation_hessian, tracking_lag
from geovs_drake.goal.step_limit import goal_A, step_limit
from geovs_drake.goal.target_reach import target_reach
from geovs_drake.loop.assembly import assemble_loop, refusal
from geovs_drake.loop.resolved import ResolvedScenario, exact_twin
from geovs_drake.scenario import AUTO, NOMINAL_GAIN_SCALES, PoseConfig, ScenarioConfig, damping_of
from geovs_drake.scenario.carriers import carrier_start

__all__ = ["resolve"]


def resolve(
    config: ScenarioConfig | ResolvedScenario | None = None, effort: bool = False
) -> ResolvedScenario:
    """Validate ``config`` (default: the default scenario) and resolve what follows from
    it (:class:`ResolvedScenario`), once; a resolved scenario passes through unchanged.

    The arm's ``gain_scale: auto`` is fitted here: the plant's
    :data:`~geovs_drake.scenario.NOMINAL_GAIN_SCALES`, at most the largest stable gain
    scale at the camera's rate and latency over
    :data:`~geovs_drake.goal.camera_fit.GAIN_MARGIN` (the nominal where no scale is
    stable, and the run's warning says so) and, with ``torque_limits: respect`` on the
    dynamic arm, at most the largest scale whose torques over the start's energy level
    set stay inside the effort limits. ``effort``: also check the dynamic arm's torques
    against its effort limits where the fit did not (``resolved.effort``; 0.3-0.5 s) and
    an arm's reach behind a moving target (``resolved.reach``; 0.2 s), only where someone
    reads them: the warning lines of the command line and of ``simulate(on_warning=)``."""
    if isinstance(config, ResolvedScenario):  # the record itself, not a variant's type
        return config
    config = ScenarioConfig() if config is None else config
    domain, gains = config.validate()
    # The start the carrier takes (the quadrotor's level one), derived here once: the
    # loop, the start's check in D and the run's errors all read this config's.
    started = carrier_start(config.carrier, config.X_WB, config.X_BC_initial)
    if started is not None:
        config = copy.deepcopy(config)
        config.initial = PoseConfig.from_rigid_transform(started[0])
    if config.simulator.integration_scheme is None:  # unset: the carrier's integrator
        config = copy.deepcopy(config)
        carrier = config.carrier.traits
        # The dynamic scheme under the NF's law only: there the step limit knows the
        # scheme's stability bound at the goal (its model), and RK5 takes a quarter to a
        # third of RK3's steps; under the other laws the limit is the cap, and RK5's
        # seven evaluations a step took 1.3-1.5x RK3's time (tests/test_loop.py's runs).
        dynamic = (
            config.plant.traits.dynamic
            and config.controller.traits.navigation
            and carrier.dynamic_integration_scheme
        )
        config.simulator.integration_scheme = (
            carrier.dynamic_integration_scheme if dynamic else carrier.integration_scheme
        )
    why = refusal(config)  # a part with no registry entry: one line, before anything
    if why is not None:
        raise ValueError(why)
    y_goal = config.goal_features()
    try:
        nf = NavigationFunction(domain, y_goal, gains)
    except ValueError as e:
        raise ValueError(f"goal invalid: {e}") from e
    base = ResolvedScenario(
        config=config,
        fitted_config=config,
        law=config.controller,
        believed_radius=config.believed_radius,
        damping=tuple(float(v) for v in damping_of(config)),
        y_goal=y_goal,
        domain=domain,
        gains=gains,
        nf=nf,
        hessian=navigation_hessian(nf, y_goal),
        start_note=None if started is None else started[1],
    )
    resolved, fit, checked = _fit_gains(base, effort)
    goal = goal_A(resolved)
    # A moving target against the arm's reach and speed: 0.2 s, so where a line reads it.
    moving_arm = config.carrier.traits.joints and config.moving_target
    return dataclasses.replace(
        resolved,
        goal=goal,
        camera_fit=fit,
        step_limit=step_limit(resolved.config, goal),
        effort=checked,
        predicted_lag=_predicted_lag(resolved),
        reach=target_reach(resolved.config) if effort and moving_arm else None,
    )


def _fit_gains(
    base: ResolvedScenario, effort: bool
) -> tuple[ResolvedScenario, CameraFit | None, EffortFit | None]:
    """The scenario at its gain scale (the arm's, ``auto`` fitted: :func:`resolve`), the
    camera fit there, and the effort check where asked or needed, each computed once (a
    fit moved to another scale is rebased, not searched again)."""
    config = base.config
    carrier = config.carrier
    if not carrier.traits.gain_scale:
        return base, camera_fit(base), None
    auto = carrier.gain_scale == AUTO
    scale = NOMINAL_GAIN_SCALES[type(config.plant)] if auto else float(carrier.gain_scale)
    resolved = _scaled(base, scale)
    fit = camera_fit(resolved)
    if auto and fit is not None and 0 < fit.margin < GAIN_MARGIN:
        chosen = fit.largest_stable_gain / GAIN_MARGIN
        fit, resolved = fit.rebased(chosen / scale), _scaled(base, chosen)
        scale = chosen
    respect = carrier.torque_limits == "respect"
    if not (carrier.traits.effort_limits and config.dynamic and (effort or respect)):
        return resolved, fit, None
    checked = effort_check(resolved)
    if auto and respect and 0 < checked.largest_scale < scale:
        chosen = checked.largest_scale
        fit = None if fit is None else fit.rebased(chosen / scale)
        resolved = _scaled(base, chosen)
        # At rest the level set does not depend on k_p, and the sampled estimate moves
        # to the new scale exactly; a start with joint velocity is checked again.
        moving = any(v != 0 for v in carrier.initial_joint_velocity)
        checked = effort_check(resolved) if moving else checked.at(chosen)
    return resolved, fit, checked


def _scaled(base: ResolvedScenario, scale: float) -> ResolvedScenario:
    """``base`` with the law's gains times ``scale`` (the arm's ``gain_scale``): a scaled
    copy of the config, so that every part of the loop, the energy bound included, reads
    one k_p and one B; the kinematic arm's one gain is k of Eq. (19)."""
    fitted = copy.deepcopy(base.config)
    fitted.carrier.gain_scale = scale
    config = copy.deepcopy(base.config)
    control = config.control
    if config.dynamic:
        control.potential_gain *= scale
        control.damping = [scale * v for v in control.damping]
        control.tracking_gains = [scale * v for v in control.tracking_gains]
        if config.sensor.traits.camera:  # a camera's loop damps with its own B
            config.sensor.damping = [scale * v for v in config.sensor.damping]
    else:
        control.kinematic_gain *= scale
    config.carrier.gain_scale = 1.0
    return dataclasses.replace(
        base,
        config=config,
        fitted_config=fitted,
        damping=tuple(float(v) for v in damping_of(config)),
        gain_scale=scale,
    )


def effort_check(resolved: ResolvedScenario) -> EffortFit:
    """The dynamic arm's torques over its start's energy level set against its effort
    limits (:func:`~geovs_drake.goal.effort_fit.effort_fit`, on this scenario's loop
    with the exact sensor: the law read at each configuration's own y)."""
    twin = dataclasses.replace(resolved, config=exact_twin(resolved.config))
    # Per process, by the scenario's repr (every field that decides the check): a
    # test session checks the same scenario many times, and a check builds a loop and
    # reads it at some 300 configurations (0.3-0.5 s).
    key = (repr(twin.config), twin.gain_scale)
    if key not in _EFFORT_CHECKS:
        _EFFORT_CHECKS[key] = effort_fit(assemble_loop(twin, log=False))
    return _EFFORT_CHECKS[key]


#: :func:`effort_check`'s results in this process, by the scenario's repr and gain scale.
_EFFORT_CHECKS: dict[tuple[str, float], EffortFit] = {}


def _predicted_lag(resolved: ResolvedScenario) -> float | None:
    """The position lag [m] the linearised loop predicts without feed-forward behind the
    scenario's constant-twist target (:func:`~geovs_drake.goal.linear_model.tracking_lag`),
    for the NF's law where the closed form models the loop; else None."""
    config = resolved.config
    if not (resolved.law.traits.navigation and config.target_motion.traits.constant_twist):
        return None  # a still target, a trajectory (no steady lag), another law
    if closed_form_refusal(config, "tracking lag") is not None:
        return None
    eps = tracking_lag(resolved, np.asarray(config.target_motion.twist))
    return float(np.linalg.norm(eps[3:]))
