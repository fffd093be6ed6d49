"""``geovs-drake simulate``: one scenario, one line (or one JSON object) on stdout."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

from geovs_drake.cli._options import (
    EXIT_BAD_INPUT,
    add_command,
    add_config,
    add_field,
    add_json,
    add_plant,
    add_variant_field,
    add_variant_flag,
    exit_code_of,
    field_default,
    gain_scale_arg,
    joints_arg,
    load_resolved,
    numbers,
    pose_arg,
    resolution_arg,
    twist_arg,
)
from geovs_drake.progress import HorizonProgress
from geovs_drake.scenario import (
    AXES,
    CONTROLLERS,
    FEEDFORWARD_MODES,
    IBVS_DEPTHS,
    PREDICTIONS,
    FixedCamera,
    FreeRig,
    ScenarioConfig,
    Still,
    Trajectory,
    Twist,
    variant_layer,
)

#: The flags that choose the target's motion (the field target_motion): one at most.
_TARGET_MOTION_FLAGS = ("--target-twist", "--target-trajectory")


def add_parser(sub: argparse._SubParsersAction, progress_delay_s: float) -> None:
    """The ``simulate`` command; a run longer than ``progress_delay_s`` [s wall] shows
    its progress on stderr."""
    p = add_command(
        sub,
        "simulate",
        "simulate a scenario and print a one-line result",
        "Simulate a scenario and print its result on stdout: one line, or one JSON object "
        f"with --json. A run that takes longer than {progress_delay_s:g} s of wall time "
        "shows its progress on stderr.",
    )
    add_config(p)
    add_plant(p)
    add_field(
        p,
        "--controller",
        ("controller",),
        "the control law: nf (the navigation function), or a baseline commanding the "
        "camera's twist: ibvs (four points), pbvs (pose from c^-1(y)), spherical (sphere "
        "features)",
        choices=CONTROLLERS,
    )
    add_variant_field(
        p,
        "--ibvs-depth",
        "controller",
        ("ibvs",),
        "depth",
        "the depth estimate: true (the current interaction matrix with the true depths, "
        "from c^-1(y)), desired (the matrix at the goal) or mean (their mean)",
        choices=IBVS_DEPTHS,
    )
    add_field(
        p,
        "--initial",
        ("initial",),
        "initial camera pose X_BC in the target frame [m, rad]; "
        "write negative first values as --initial=-0.2,...",
        type=pose_arg,
        metavar="x,y,z,roll,pitch,yaw",
    )
    add_field(
        p,
        "--initial-velocity",
        ("initial_velocity",),
        "initial body twist (Omega, V) of the camera in its frame C [rad/s, m/s], "
        "G^-1 dG/dt for G = X_BC (dynamic loop only); "
        "write negative first values as --initial-velocity=-0.1,...",
        shown="at rest " + numbers(field_default(("initial_velocity",))),
        type=twist_arg,
        metavar="wx,wy,wz,vx,vy,vz",
    )
    add_field(
        p,
        "--goal",
        ("goal",),
        "goal camera pose X_BC* in the target frame [m, rad]",
        type=pose_arg,
        metavar="x,y,z,roll,pitch,yaw",
    )
    add_field(p, "--duration", ("duration",), "simulated time [s]", type=float, metavar="T")
    # The moving target (issue 32).
    add_field(
        p,
        "--target-twist",
        ("target_motion",),
        "the target moves with this constant body twist (omega, v) in its own frame B "
        "[rad/s, m/s], angular part first, from its pose (a helix about the screw axis), "
        "or still; the goal stays X_BC*, relative to the target; "
        "write negative first values as --target-twist=-0.1,...",
        shown="still",
        type=_target_twist,
        metavar="wx,wy,wz,vx,vy,vz|still",
    )
    add_field(
        p,
        "--target-trajectory",
        ("target_motion",),
        "the target moves along the trajectory of poses in this CSV file, one row per knot "
        "t, qw, qx, qy, qz, x, y, z [s, unit quaternion, m]: its displacement X_B0B(t) "
        "from its pose, the identity at t = 0 (target_motion: !Trajectory {file: FILE}), "
        "or still; not with --target-twist",
        shown="still",
        type=_target_trajectory,
        metavar="FILE|still",
    )
    add_variant_flag(
        p,
        "--feedforward",
        _feedforward,
        "with a moving target: what the loop adds for its motion: "
        + "; ".join(f"{name}: {text}" for name, text in FEEDFORWARD_MODES.items())
        + f" (default: the config's, else {Twist().feedforward})",
        choices=tuple(FEEDFORWARD_MODES),
    )
    # The arm (issue 20).
    add_field(
        p,
        "--carrier",
        ("carrier",),
        "what carries the camera: free (the rigid body of Appendix C) or arm (a robot arm, "
        "eye-in-hand: joint torques with --plant dynamic, joint velocities with kinematic)",
        choices=("free", "arm"),
    )
    add_variant_field(
        p,
        "--arm",
        "carrier",
        ("arm",),
        "model",
        "default (the UR5-like arm shipped in the package), panda (the "
        '7-axis Franka Panda of example-robot-data: pip install "geovs-drake[panda]") or '
        "the path of a URDF or SDFormat file (with the carrier's end_effector_frame in the "
        "scenario)",
        metavar="default|panda|PATH",
    )
    add_variant_field(
        p,
        "--initial-joints",
        "carrier",
        ("arm",),
        "initial_joints",
        "the arm's initial joint positions [rad], in place of "
        "--initial solved by inverse kinematics (none: solve it)",
        shown="none",
        type=joints_arg,
        metavar="q1,q2,...",
    )
    add_variant_field(
        p,
        "--initial-joint-velocity",
        "carrier",
        ("arm",),
        "initial_joint_velocity",
        "with --plant dynamic: the arm's initial joint velocities [rad/s] "
        "(in place of --initial-velocity)",
        shown="at rest none",
        type=joints_arg,
        metavar="v1,v2,...",
    )
    add_variant_field(
        p,
        "--joint-barrier",
        "carrier",
        ("arm",),
        "joint_barrier_width",
        "with --plant dynamic (the NF): the width [rad] of the barrier that "
        "puts the joint limits inside the energy guarantee, phi_total = 1 - (1 - phi)(1 - "
        "phi_q) (0: off)",
        type=float,
        metavar="RAD",
    )
    add_variant_field(
        p,
        "--gain-scale",
        "carrier",
        ("arm",),
        "gain_scale",
        "with --plant dynamic: the factor on the law's gains (k_p, B, the velocity "
        "tracking); auto: 10, at most what the camera's rate and latency carry with a gain "
        "margin of 2",
        type=gain_scale_arg,
        metavar="SCALE",
    )
    # Path following (--controller path) and the fixed camera (--mount): issue 12.
    add_variant_flag(
        p,
        "--mount",
        _mount,
        "hand: the camera rides on the driven body (eye-in-hand, carrier !FreeRig or "
        "!Arm); fixed: the camera is fixed in the world and the target sphere is driven "
        "(eye-to-hand, G = H^-1 of Eq. 16: carrier !FixedCamera) (default: the config's, "
        "else hand)",
        choices=("hand", "fixed"),
    )
    add_variant_field(
        p,
        "--path-duration",
        "controller",
        ("path",),
        "duration",
        "the planned image path's duration [s]",
        type=float,
        metavar="T",
    )
    add_variant_field(
        p,
        "--path-feedback",
        "controller",
        ("path",),
        "feedback_gain",
        "the gain k [1/s] of the log-map feedback added to the feed-forward of Eq. (18); "
        "0 is Eq. (18) as written, open loop",
        type=float,
        metavar="GAIN",
    )
    # The camera (issue 13).
    add_field(
        p,
        "--sensor",
        ("sensor",),
        "exact: the controller reads y = c(H); rendered: Drake renders the target "
        "(RgbdSensor, VTK) and y is extracted from each frame; pinhole: that measurement "
        "on exact image points, without rendering (eye-in-hand, either plant, for the last two)",
        choices=tuple(AXES["sensor"]),
    )
    add_variant_field(
        p,
        "--camera-rate",
        "sensor",
        ("pinhole", "rendered"),
        "rate",
        "frames per second of the camera",
        type=float,
        metavar="HZ",
        positive="Hz",
    )
    add_variant_field(
        p,
        "--prediction",
        "sensor",
        ("pinhole", "rendered"),
        "prediction",
        "what the law sees between frames: "
        + "; ".join(f"{name}: {p.description}" for name, p in PREDICTIONS.items()),
        choices=tuple(PREDICTIONS),
    )
    add_variant_field(
        p,
        "--resolution",
        "sensor",
        ("pinhole", "rendered"),
        "resolution",
        "image size [px]; the focal length makes the inscribed cone the field of view",
        shown="x".join(str(v) for v in AXES["sensor"]["pinhole"]().resolution),
        type=resolution_arg,
        metavar="WxH",
    )
    add_json(p)
    p.set_defaults(func=run, progress_delay_s=progress_delay_s)


def _target_twist(text: str) -> dict:
    """``--target-twist``: 6 numbers, as the layer of a :class:`Twist` target motion, or
    ``still`` (the default, :class:`Still`)."""
    if _still(text):
        return variant_layer(Still)
    return variant_layer(Twist, twist=twist_arg(text))


def _target_trajectory(path: str) -> dict:
    """``--target-trajectory``: the layer of a :class:`Trajectory` read from the CSV file
    ``path`` (read and checked with the scenario; it replaces inline ``poses`` a lower
    layer gave), or ``still`` (the default, :class:`Still`)."""
    if _still(path):
        return variant_layer(Still)
    return variant_layer(Trajectory, file=path, poses=None)


def _still(text: str) -> bool:
    """Whether a target-motion flag's value is ``still``, the still target (the default
    its help shows, which given back is the default scenario)."""
    return text.strip().lower() == "still"


def _check_one_target_motion(args: argparse.Namespace) -> None:
    """ValueError (one line) where both flags of :data:`_TARGET_MOTION_FLAGS` are given:
    each sets the whole target motion, and the later would quietly drop the other."""
    given = {flag for flag, _ in args.layers or [] if flag in _TARGET_MOTION_FLAGS}
    if len(given) > 1:
        raise ValueError(
            f"{' and '.join(_TARGET_MOTION_FLAGS)} both set the target's motion "
            "(target_motion): give one"
        )


def _feedforward(config: ScenarioConfig, flag: str, mode: str) -> None:
    """``--feedforward`` on the moving target the layers chose. On a still target there is
    nothing to feed forward: the default mode leaves it as it is (as any flag given its
    default does), another is one line."""
    if not isinstance(config.target_motion, Twist | Trajectory):
        if mode == Twist().feedforward:
            return
        raise ValueError(
            f"{flag} applies to a moving target (--target-twist, --target-trajectory, or "
            "target_motion: !Twist or !Trajectory in the scenario); the target here is still"
        )
    config.target_motion = dataclasses.replace(config.target_motion, feedforward=mode)


def _mount(config: ScenarioConfig, flag: str, mount: str) -> None:
    """``--mount`` on the carrier the layers chose: ``fixed`` makes a free rig the fixed
    camera (the same mass model, now the target's), ``hand`` the other way round; the
    arm carries its camera in its hand."""
    carrier = config.carrier
    if mount == "fixed" and isinstance(carrier, FreeRig):
        config.carrier = FixedCamera(carrier.mass, list(carrier.inertia_diagonal))
    elif mount == "hand" and isinstance(carrier, FixedCamera):
        config.carrier = FreeRig(carrier.mass, list(carrier.inertia_diagonal))
    elif mount == "fixed" and not isinstance(carrier, FixedCamera):
        raise ValueError(
            f"{flag} fixed needs the free body (--carrier free): the carrier here is "
            f"{type(carrier).__name__}, which carries the camera in its hand"
        )


def simulate(resolved, progress=None):
    """:func:`geovs_drake.simulation.simulate`, imported when a run starts: the command
    line's start (``--help``, ``--version``, bad input) stays free of the loop's imports."""
    from geovs_drake.simulation import simulate as run_loop

    def warn(line: str) -> None:  # before the run: a long run's user reads it meanwhile
        print(f"geovs-drake: warning: {line}", file=sys.stderr, flush=True)

    return run_loop(resolved, progress=progress, on_warning=warn)


def _start_outside_domain() -> type[Exception]:
    from geovs_drake.simulation import StartOutsideDomain

    return StartOutsideDomain


def run(args: argparse.Namespace) -> int:
    """Run ``simulate``; the exit code."""
    _check_one_target_motion(args)
    resolved = load_resolved(args, effort=True)  # once, with the effort check it warns from
    progress = HorizonProgress(
        resolved.config.duration, "geovs-drake simulate", delay_s=args.progress_delay_s
    )
    try:
        result = simulate(resolved, progress=progress)
    except _start_outside_domain() as e:
        print(f"geovs-drake: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    finally:
        progress.close()
    if result.predicted_steady_error is None and resolved.config.moving_target:
        # A baseline's lag: Drake's Linearize of its loop (the NF's is simulate()'s own).
        from geovs_drake.analysis.linear.tracking_lag import predicted_tracking_lag

        lag = predicted_tracking_lag(resolved)
        result = dataclasses.replace(result, predicted_steady_error=lag)
    if args.json:
        print(json.dumps(result.summary()))
    else:
        print(result.one_line())
    return exit_code_of(result.status)
