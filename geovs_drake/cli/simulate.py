"""``geovs-drake simulate``: one scenario, one line (or one JSON object) on stdout."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

from geovs_drake.cli._options import (
    EXIT_BAD_INPUT,
    PLANT_HELP,
    VALUE_AXES,
    add_axes,
    add_command,
    add_config,
    add_field,
    add_goal,
    add_json,
    add_latency_frames,
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
    FEEDFORWARD_MODES,
    IBVS_DEPTHS,
    PREDICTIONS,
    ScenarioConfig,
    Still,
    Trajectory,
    Twist,
    variant_layer,
    variant_name,
)

#: The flags that choose the target's motion (the field target_motion): one at most.
_TARGET_MOTION_FLAGS = VALUE_AXES["target_motion"]

#: ``--carrier``, ``--plant``, ``--sensor``, ``--controller`` (:func:`add_axes`): what
#: each axis is and what each of its variants does here; a variant not named here shows
#: its class's first sentence.
_AXIS_HELP: dict[str, tuple[str, dict[str, str]]] = {
    "carrier": (
        "what carries the camera",
        {
            "free": "the rigid body of Appendix C, eye-in-hand",
            "fixed": "the camera fixed in the world and the target sphere driven "
            "(eye-to-hand, G = H^-1 of Eq. 16)",
            "arm": "a robot arm, eye-in-hand: joint torques with --plant dynamic, joint "
            "velocities with kinematic",
        },
    ),
    "plant": ("how the carrier is driven", PLANT_HELP),
    "sensor": (
        "what the controller reads",
        {
            "exact": "y = c(H)",
            "pinhole": "a camera's measurement on exact image points, without rendering",
            "rendered": "Drake renders the target (RgbdSensor, VTK) and y is extracted "
            "from each frame",
        },
    ),
    "controller": (
        "the control law",
        {
            "nf": "the navigation function",
            "ibvs": "a baseline commanding the camera's twist, four image points",
            "pbvs": "a baseline commanding the camera's twist, the pose from c^-1(y)",
            "spherical": "a baseline commanding the camera's twist, sphere features",
            "path": "a planned image path followed (Eq. 18)",
            "hamel_mahony": "Hamel & Mahony's image-based law (2002), the quadrotor's "
            "rotors driven from the sphere's spherical centroid",
        },
    ),
}


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
    add_axes(p, _AXIS_HELP)
    _add_pose_flags(p)
    _add_target_flags(p)
    _add_law_flags(p)
    _add_arm_flags(p)
    _add_camera_flags(p)
    add_json(p)
    p.set_defaults(func=run, progress_delay_s=progress_delay_s)


def _add_pose_flags(p: argparse.ArgumentParser) -> None:
    """The start, the goal and the duration."""
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
    add_goal(p)
    add_field(p, "--duration", ("duration",), "simulated time [s]", type=float, metavar="T")


def _add_target_flags(p: argparse.ArgumentParser) -> None:
    """The moving target (issue 32): the axis target_motion, whose variants carry values
    (:data:`VALUE_AXES`), and what the loop feeds forward."""
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


def _add_law_flags(p: argparse.ArgumentParser) -> None:
    """The law's own fields: IBVS's depth, the path's duration and feedback (issue 12)."""
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


def _add_arm_flags(p: argparse.ArgumentParser) -> None:
    """The arm's own fields (issue 20), and ``--mount``, the carrier's earlier spelling."""
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
    # Deprecated, so out of --help: --carrier fixed|free says it as a file does.
    add_variant_flag(p, "--mount", _mount, argparse.SUPPRESS, choices=tuple(_MOUNT_SPELLING))


def _add_camera_flags(p: argparse.ArgumentParser) -> None:
    """The camera sensor's own fields (issue 13)."""
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
    add_latency_frames(p)


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
    if not config.moving_target:  # ScenarioConfig's own test, not the variant's type
        if mode == Twist().feedforward:
            return
        raise ValueError(
            f"{flag} applies to a moving target (--target-twist, --target-trajectory, or "
            "target_motion: !Twist or !Trajectory in the scenario); the target here is still"
        )
    config.target_motion = dataclasses.replace(config.target_motion, feedforward=mode)


#: ``--mount``'s values, and the carrier each is spelled as now.
_MOUNT_SPELLING = {"hand": "free (or arm)", "fixed": "fixed"}


def _mount(config: ScenarioConfig, flag: str, mount: str) -> None:
    """``--mount``, deprecated, on the carrier the layers chose: ``fixed`` makes a free rig
    the fixed camera (the same mass model, now the target's), ``hand`` the other way
    round; the arm carries its camera in its hand. It runs as it did, with a line on
    stderr pointing to ``--carrier``. The carriers by their names in AXES (not their
    types): the two rigid bodies share their fields."""
    carrier, name = config.carrier, variant_name(config.carrier)
    pointer = f"write --carrier {_MOUNT_SPELLING[mount]}"
    rigid = {"free": "fixed", "fixed": "free"}
    if mount == "fixed" and name not in rigid:
        raise ValueError(
            f"{flag} fixed needs the free body (--carrier free): the carrier here is "
            f"{type(carrier).__name__}, which carries the camera in its hand ({flag} is "
            f"deprecated: {pointer})"
        )
    wanted = "fixed" if mount == "fixed" else "free"
    if name in rigid and name != wanted:
        config.carrier = AXES["carrier"][wanted](carrier.mass, list(carrier.inertia_diagonal))
    print(f"geovs-drake: warning: {flag} {mount} is deprecated: {pointer}", file=sys.stderr)


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
