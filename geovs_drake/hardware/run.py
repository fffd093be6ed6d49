"""Running a station or a controller: the setup from a station file and layers, the
simulator, and the summary each prints (``geovs-drake station`` / ``controller``)."""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import DiagramBuilder, EventStatus

from geovs_drake._json import json_ready
from geovs_drake.hardware.config import (
    HardwareConfig,
    check_lcm_url,
    load_hardware,
    split_station_file,
)
from geovs_drake.hardware.controller import Controller, build_controller
from geovs_drake.hardware.link import LATENCY_BIN_MS, LINK_FIELDS, STOP_REASONS
from geovs_drake.hardware.station import Station, build_station
from geovs_drake.loop import ResolvedScenario, resolve
from geovs_drake.scenario import ScenarioConfig, load_scenario
from geovs_drake.simulation.result import convergence_tolerance, pose_error

__all__ = [
    "CONTROLLER_SUCCESS",
    "LOOP_TIME_EDGES_MS",
    "SETTLED_JOINT_SPEED",
    "TRACE_PERIOD_S",
    "Lockstep",
    "Setup",
    "controller_status",
    "default_station_file",
    "load_setup",
    "lockstep",
    "open_lcm",
    "run_controller",
    "run_station",
]


#: The joint speed [rad/s] below which a held arm counts as stopped (the station's
#: ``hold_settle_time_s``).
SETTLED_JOINT_SPEED = 0.01
#: The controller's statuses that end a run well (exit 0): it ran its duration, or the
#: station stopped after it had converged (:func:`controller_status`).
CONTROLLER_SUCCESS = ("completed", "station_stopped")
#: The controller's ``loop_time_histogram``: the upper edges [ms] of its bins of the
#: wall time between two simulator steps (the last bin: the rest). The status period
#: is 1 ms; the command timeout 100 ms.
LOOP_TIME_EDGES_MS = (1.5, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)
#: The period [s] of the station's ``position_error_trace_m``.
TRACE_PERIOD_S = 1.0
#: Slack on a count of periods in a float time.
_ROUNDING = 1e-9


def default_station_file() -> Path:
    """The shipped station file, ``geovs_drake/scenarios/panda_lcm.yaml``."""
    from geovs_drake import scenarios

    return scenarios.path("panda_lcm")


@dataclass
class Setup:
    """A station's or a controller's scenario (resolved once) and hardware config."""

    resolved: ResolvedScenario
    hardware: HardwareConfig


@dataclass
class Lockstep:
    """A station and a controller in one Diagram on one bus, simulated together: their
    clocks are one (tests, profiles, the measurements of docs/hardware.md)."""

    station: Station
    controller: Controller
    simulator: Simulator

    @property
    def root(self):
        """The simulator's root context."""
        return self.simulator.get_mutable_context()


def lockstep(setup: Setup, lcm: DrakeLcm | None = None) -> Lockstep:
    """``build_station`` and ``build_controller`` of ``setup`` on ``lcm`` (default: a fresh
    ``memq://`` bus, in this process), both diagrams in one Simulator, the station's
    start set and the simulator initialised."""
    lcm = DrakeLcm("memq://") if lcm is None else lcm
    station = build_station(setup.resolved, setup.hardware, lcm)
    controller = build_controller(setup.resolved, setup.hardware, lcm)
    builder = DiagramBuilder()
    builder.AddSystem(station.diagram)
    builder.AddSystem(controller.diagram)
    simulator = Simulator(builder.Build())
    station.set_initial_state(simulator.get_mutable_context())
    simulator.Initialize()
    return Lockstep(station, controller, simulator)


def load_setup(
    path: str | Path | None,
    layers: Sequence[tuple[str, Any]] = (),
    hardware_changes: Mapping[str, Any] | None = None,
    adjust: Callable[[ScenarioConfig], None] | None = None,
) -> Setup:
    """The station file at ``path`` (default :func:`default_station_file`), its scenario
    with ``layers`` over it (:func:`~geovs_drake.scenario.load_scenario`'s overrides)
    and its ``hardware`` section with ``hardware_changes`` set; ``adjust`` then changes
    the loaded scenario in place (the command line's variant flags); validated and
    resolved once. ValueError in one line for bad input."""
    path = default_station_file() if path is None else Path(path)
    scenario, section = split_station_file(path)
    config = load_scenario(overrides=[(str(path), scenario), *layers])
    if adjust is not None:
        adjust(config)
    hardware = load_hardware({**section, **(hardware_changes or {})}, f"{path}: hardware")
    return Setup(resolve(config), hardware)


def _simulator(diagram, setup: Setup, root_setter=None) -> Simulator:
    simulator = Simulator(diagram)
    hardware = setup.hardware
    # Status and commands at 1 kHz cut every step there anyway.
    ApplySimulatorConfig(
        setup.resolved.config.simulator.to_drake(1.0 / hardware.status_rate), simulator
    )
    simulator.set_target_realtime_rate(hardware.real_time_rate)
    if root_setter is not None:
        root_setter(simulator.get_mutable_context())
    return simulator


def _run_until(
    simulator: Simulator, monitor: Callable[[Any], EventStatus], duration: float
) -> float:
    """``simulator`` advanced to ``duration`` under ``monitor`` (which may end it
    earlier); the wall time it took [s], for the real-time rate."""
    simulator.set_monitor(monitor)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(duration)
    return time.perf_counter() - start


def run_station(station: Station, duration: float) -> dict:
    """Run the station for ``duration`` [s] (less if commands are lost: then until the
    arm has been held ``hold_time``); its ground truth as a dict: ``status``
    (``converged``, ``not_converged`` or ``command_lost``), ``final_position_error_m``,
    ``final_rotation_error_rad``, ``commands_received``, ``command_timeouts``,
    ``commands_refused`` (not of the station's mode),
    ``final_joint_speed`` [rad/s], ``sim_time_s``; the link: ``first_command_s`` and
    ``last_command_s`` (when the first and last new command came, NaN before one),
    ``statuses_published``, ``frames_published``; the hold: ``lost_time_s`` (when
    the gate latched ``command_lost``, NaN if never), ``hold_start_joint_speed``
    [rad/s] and ``hold_settle_time_s`` (the first time after ``lost_time_s`` at which
    the joint speed was below :data:`SETTLED_JOINT_SPEED`; NaN if never); the pacing:
    ``wall_time_s`` and ``realtime_rate`` (the simulator's actual rate); and
    ``position_error_trace_m``, the camera's distance from the goal every
    :data:`TRACE_PERIOD_S` from 0."""
    setup = Setup(station.resolved, station.hardware)
    simulator = _simulator(station.diagram, setup, station.set_initial_state)
    gate = station.gate
    hold = station.hardware.hold_time
    nq = station.plant.num_positions()
    first_command, hold_watch = [math.nan], {"start": math.nan, "settled": math.nan}
    goal = station.resolved.config.X_BC_goal
    trace: list[float] = []

    def monitor(root) -> EventStatus:
        context = gate.GetMyContextFromRoot(root)
        if root.get_time() >= len(trace) * TRACE_PERIOD_S - _ROUNDING:
            trace.append(pose_error(station.X_BC(root), goal)[0])
        if math.isnan(first_command[0]) and gate.started(context):
            first_command[0] = gate.last_command_time(context)
        if gate.lost(context):
            t = root.get_time()
            if math.isnan(hold_watch["settled"]):
                speed = float(np.linalg.norm(station.arm_state(root)[nq:]))
                if math.isnan(hold_watch["start"]):
                    hold_watch["start"] = speed
                if speed < SETTLED_JOINT_SPEED:
                    hold_watch["settled"] = t
            if t >= gate.lost_time(context) + hold:
                return EventStatus.ReachedTermination(gate, "command_lost")
        return EventStatus.Succeeded()

    wall = _run_until(simulator, monitor, duration)
    root = simulator.get_context()
    context = gate.GetMyContextFromRoot(root)
    config = station.resolved.config
    dp, dr = pose_error(station.X_BC(root), config.X_BC_goal)
    tol_p, tol_r = convergence_tolerance(station.resolved)
    if gate.lost(context):
        status = "command_lost"
    else:
        status = "converged" if dp <= tol_p and dr <= tol_r else "not_converged"
    t_end = root.get_time()
    hardware = station.hardware
    frames = math.floor((t_end - station.frame_offset) / station.frame_period + _ROUNDING) + 1
    if hardware.drop_every_frame > 0:
        frames -= frames // hardware.drop_every_frame
    # As every result's summary: JSON's values (a time that never came is null, not NaN).
    return json_ready(
        {
            "status": status,
            "final_position_error_m": dp,
            "final_rotation_error_rad": dr,
            "commands_received": gate.commands_received(context),
            "command_timeouts": gate.command_timeouts(context),
            "commands_refused": gate.commands_refused(context),
            "final_joint_speed": float(np.linalg.norm(station.arm_state(root)[nq:])),
            "sim_time_s": t_end,
            "first_command_s": first_command[0],
            "last_command_s": gate.last_command_time(context)
            if gate.started(context)
            else math.nan,
            "statuses_published": math.floor(t_end * hardware.status_rate + _ROUNDING) + 1,
            "frames_published": max(frames, 0),
            "lost_time_s": gate.lost_time(context),
            "hold_start_joint_speed": hold_watch["start"],
            "hold_settle_time_s": hold_watch["settled"],
            "wall_time_s": wall,
            "realtime_rate": simulator.get_actual_realtime_rate(),
            "position_error_trace_m": trace,
        }
    )


#: The controller's stop reason that, with its own estimate converged, is the station's
#: end and not a loss (``station_stopped``).
_NO_STATUS_REASON = STOP_REASONS[1]


def controller_status(controller: Controller, root) -> str:
    """How the controller's run ended: ``completed`` (it commanded to its duration),
    ``station_stopped`` (the statuses stopped after its own estimate of the camera's
    pose error, :meth:`~.controller.Controller.estimated_pose_error`, was within the
    scenario's convergence tolerance: the station, or the robot, ended a run that had
    converged) or ``stopped`` (any other stop: statuses lost mid-servo, a frame
    timeout, the target lost)."""
    publisher = controller.publisher
    context = publisher.GetMyContextFromRoot(root)
    if not publisher.stopped(context):
        return "completed"
    if publisher.stop_reason(context) == _NO_STATUS_REASON:
        dp, dr = controller.estimated_pose_error(root)
        tol_p, tol_r = convergence_tolerance(controller.resolved)
        if dp <= tol_p and dr <= tol_r:  # NaN (no frame) compares False: stopped
            return "station_stopped"
    return "stopped"


def run_controller(controller: Controller, duration: float) -> dict:
    """Run the controller for ``duration`` [s] or until it stops commanding; a dict:
    ``status`` (:func:`controller_status`: ``completed``, ``station_stopped`` or
    ``stopped``), ``stop_reason``, ``statuses_received``,
    ``max_status_gap_s`` (the longest time between two new statuses, its own clock),
    ``frames_received``, ``frames_dropped``, ``commands_sent``, ``final_image_error``
    (``|y - y*|``), ``estimated_position_error_m`` and
    ``estimated_rotation_error_rad`` (its own estimates, from the frames),
    ``latency_histogram`` (frames by the latency from their capture to the first
    command from them, ``latency_bin_ms`` bins from 0, the last one the rest),
    ``sim_time_s``, ``wall_time_s`` and ``realtime_rate``; its loop's wall time from
    one simulator step to the next: ``loop_time_histogram`` (counts in the bins whose
    upper edges are ``loop_time_edges_ms``, the last bin the rest) and
    ``max_loop_time_s``. ValueError when its first
    frame's image cannot be inverted (it never commanded)."""
    setup = Setup(controller.resolved, controller.hardware)
    controller.warm_up()
    simulator = _simulator(controller.diagram, setup)
    publisher = controller.publisher
    # The loop's wall time, step to step, counted in place (no allocation in the loop).
    edges = np.array(LOOP_TIME_EDGES_MS) * 1e-3
    loop_counts = np.zeros(len(edges) + 1, dtype=np.int64)
    last = [math.nan, 0.0]  # the last step's wall clock, the longest step

    def monitor(root) -> EventStatus:
        now = time.perf_counter()
        step = now - last[0]
        if step == step:  # not the first (NaN)
            loop_counts[int(np.searchsorted(edges, step))] += 1
            last[1] = max(last[1], step)
        last[0] = now
        if publisher.stopped(publisher.GetMyContextFromRoot(root)):
            return EventStatus.ReachedTermination(publisher, "stopped")
        return EventStatus.Succeeded()

    # Everything built so far is kept out of the garbage collector's scans: a full
    # collection of the diagram's objects mid-run is a pause of milliseconds.
    gc.collect()
    gc.freeze()
    try:
        wall = _run_until(simulator, monitor, duration)
    finally:  # a caller's later garbage (a test session's) is collected again
        gc.unfreeze()
    root = simulator.get_context()
    context = publisher.GetMyContextFromRoot(root)
    reason = publisher.stop_reason(context)
    if publisher.stopped(context) and publisher.commands_sent(context) == 0 and "invert" in reason:
        _, y = controller.tracker.held_frame(controller.tracker.GetMyContextFromRoot(root))
        raise ValueError(
            f"controller: refuses to start a command: {reason}: first y = {y.tolist()}"
        )
    link = controller.tracker.link_output.Eval(controller.tracker.GetMyContextFromRoot(root))
    image_error, _ = controller.image_error(root)
    position_error, rotation_error = controller.estimated_pose_error(root)
    return json_ready(
        {
            "status": controller_status(controller, root),
            "stop_reason": reason,
            "statuses_received": int(link[0]),
            "frames_received": int(link[1]),
            "frames_dropped": int(link[2]),
            "max_status_gap_s": float(link[LINK_FIELDS.index("max_status_gap")]),
            "commands_sent": publisher.commands_sent(context),
            "final_image_error": image_error,
            "estimated_position_error_m": position_error,
            "estimated_rotation_error_rad": rotation_error,
            "latency_bin_ms": LATENCY_BIN_MS,
            "latency_histogram": publisher.latency_histogram(context),
            "sim_time_s": root.get_time(),
            "wall_time_s": wall,
            "realtime_rate": simulator.get_actual_realtime_rate(),
            "loop_time_edges_ms": list(LOOP_TIME_EDGES_MS),
            "loop_time_histogram": loop_counts.tolist(),
            "max_loop_time_s": last[1],
        }
    )


def open_lcm(url: str) -> DrakeLcm:
    """The bus at ``url`` (checked first: DrakeLcm takes a bad URL without raising)."""
    check_lcm_url(url)
    return DrakeLcm(url)
