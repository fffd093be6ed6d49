"""``geovs-drake linearize``: the loop's linear model at the goal or at a pose
(:func:`geovs_drake.analysis.linear.linearization.linearize`): its eigenvalues, damping ratios
and time constants, and whether it is stable; on request the studies built on it: gains
for a response (:mod:`~geovs_drake.analysis.linear.gain_design`), a camera's rate and latency
(:mod:`~geovs_drake.analysis.linear.latency`) and a sampled Lyapunov region
(:mod:`~geovs_drake.analysis.linear.region`)."""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np

from geovs_drake.cli._options import (
    EXIT_BAD_INPUT,
    EXIT_CONVERGED,
    add_command,
    add_config,
    add_field,
    add_json,
    add_plant,
    check_out,
    load_layers,
    numbers,
    pose_arg,
)

#: The files ``--out DIR`` writes: the JSON object ``--json`` prints, and the root locus
#: over k_p (the kinematic gain on the kinematic loop) with the loop's eigenvalues.
OUT_FILE = "linearize.json"
LOCUS_FILE = "root_locus.png"


def at_arg(text: str) -> str | dict[str, list[float]]:
    """``goal`` or a camera pose ``x,y,z,roll,pitch,yaw`` (X_BC, the target frame)."""
    return "goal" if text.strip().lower() == "goal" else pose_arg(text)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``linearize`` command."""
    p = add_command(
        sub,
        "linearize",
        "the loop's linear model at the goal or a pose: eigenvalues, damping, stability",
        "Linearise the closed loop (Drake's Linearize at the goal, "
        "FirstOrderTaylorApproximation at another pose, the camera at rest there) in "
        "minimal coordinates (the camera's displacement, then its twist for the dynamic "
        "loop) and print its eigenvalues, damping ratios and time constants and whether "
        "it is stable (every real part < 0). Away from the goal the model is the "
        "frozen-time one: an indication, not a proof. Exit code 0 when it ran, 2 for bad "
        "input (a pose outside D included).",
    )
    add_config(p)
    add_plant(p)
    add_field(
        p,
        "--carrier",
        ("carrier",),
        "free: the paper's free rig; arm: the camera on the arm shipped in the package "
        "(the dynamic arm at the goal, Drake's Linearize on its joints, and the camera "
        "study; the design and the regions are the free rig's); quadrotor: Drake's "
        "Linearize of its whole loop at hover, checked against finite differences",
        choices=("free", "arm", "quadrotor"),
    )
    p.add_argument(
        "--at",
        type=at_arg,
        default="goal",
        metavar="goal|x,y,z,roll,pitch,yaw",
        help="where: the goal, or a camera pose X_BC in the target frame [m, rad], at "
        "rest; write negative first values as --at=-0.1,... (default: goal)",
    )
    p.add_argument(
        "--settling-time",
        type=float,
        metavar="S",
        help="design the gains for the slowest mode to settle (2 %%) in S seconds: k_p and "
        "B (dynamic, with --damping-ratio) or k (kinematic); prints them and their cost "
        "(peak wrench or twist from the start, the energy bound k_p) (default: no design)",
    )
    p.add_argument(
        "--damping-ratio",
        type=float,
        metavar="ZETA",
        help="with --settling-time on the dynamic loop: no mode less damped than ZETA, in "
        "(0, 1) (default: 0.7 on the dynamic loop)",
    )
    p.add_argument(
        "--latency",
        type=int,
        metavar="FRAMES",
        help="predict the loop closed through a camera this many frames late (sampled at "
        "--camera-rate, held): spectral radius, latency margin, slowest stable rate "
        "(default: no camera study)",
    )
    p.add_argument(
        "--camera-rate",
        type=float,
        metavar="HZ",
        help="the camera's rate for --latency (default: the sensor's rate, or the default "
        "camera's 30 Hz with the exact sensor)",
    )
    p.add_argument(
        "--region",
        action="store_true",
        help="also sample the region of attraction of a quadratic Lyapunov function "
        "(200 rays; about 20 s on the dynamic loop): its level and its largest distance "
        "and roll from the goal",
    )
    p.add_argument(
        "--certify",
        action="store_true",
        help="also certify a level of that region's V by sum of squares (Drake's "
        "RegionOfAttraction on the loop's Taylor polynomial, degree 3 kinematic, 2 "
        "dynamic; implies --region; about 10 s on the kinematic loop, 4 to 9 minutes on "
        "the dynamic one)",
    )
    p.add_argument(
        "--sos-solver",
        default="scs",
        metavar="NAME",
        help="the SDP solver for --certify: scs, clarabel or csdp (all ship with the drake "
        "wheel; default: scs)",
    )
    add_json(p)
    p.add_argument(
        "--out",
        metavar="DIR",
        help=f"also write the JSON object to DIR/{OUT_FILE} and the root locus to "
        f"DIR/{LOCUS_FILE} (default: none)",
    )
    p.set_defaults(func=run)


def _on_arm(config) -> bool:
    return config.carrier.traits.joints


def _without_model(config) -> bool:
    # A carrier with no closed-form model at the goal (the quadrotor's cascade): asked
    # of its traits, not its type.
    return not config.carrier.traits.goal_model


def _loop_linearization(config, args):
    """Drake's Linearize of the whole loop at the goal, for a carrier with no model there;
    the studies that need one are one line's refusal."""
    from geovs_drake.analysis.linear.loop_study import linearize_loop_at_goal

    for flag, given in (
        ("--at", args.at != "goal"),
        ("--settling-time", args.settling_time is not None),
        ("--damping-ratio", args.damping_ratio is not None),
        ("--latency", args.latency is not None),
        ("--camera-rate", args.camera_rate is not None),
        ("--region", args.region),
        ("--certify", args.certify),
        ("--out", args.out is not None),
    ):
        if given:
            raise ValueError(
                f"{flag} needs a model at the goal, which carrier "
                f"{type(config.carrier).__name__} has not: linearize gives Drake's "
                "Linearize of its loop at the goal"
            )
    return linearize_loop_at_goal(config)


def _arm_linearization(config, args):
    """The dynamic arm at the goal (Drake's Linearize on its joints); what the command
    models on the free rig only is one line's refusal."""
    from geovs_drake.analysis.linear.arm_study import linearize_arm_at_goal

    free_rig_only = [
        flag
        for flag, given in (
            ("--at", args.at != "goal"),
            ("--settling-time", args.settling_time is not None),
            ("--damping-ratio", args.damping_ratio is not None),
            ("--region", args.region),
            ("--certify", args.certify),
            ("--out", args.out is not None),
        )
        if given
    ]
    if free_rig_only:
        raise ValueError(
            f"{free_rig_only[0]} is the free rig's study; on the arm linearize gives the "
            "goal's model and the camera study (--latency, --camera-rate)"
        )
    if not config.dynamic:
        raise ValueError(
            "linearize on the arm models the dynamic arm (joint torques); the kinematic "
            "arm's goal model is the kinematic body's in the camera's coordinates: "
            "--carrier free --plant kinematic"
        )
    return linearize_arm_at_goal(config)


def _design(config, args):
    """The gains ``--settling-time`` (and ``--damping-ratio``) ask for: a ``GainDesign``."""
    from geovs_drake.analysis.linear.gain_design import design_gains

    zeta = args.damping_ratio
    if zeta is None and config.dynamic:
        zeta = DEFAULT_DAMPING_RATIO
    return design_gains(config, args.settling_time, zeta)


def _camera(config, args, design) -> dict:
    """The camera study of the gains the command reports: the designed ones where it
    designs (the camera then damps with the designed B), else the scenario's; on the arm,
    the goal's closed form through J_C at the arm's own gains (``gain_scale``, auto
    chosen for this camera)."""
    from geovs_drake.analysis.linear.latency import camera_of, sampled_model
    from geovs_drake.goal.linear_model import check_camera
    from geovs_drake.scenario import PREDICTIONS, camera_like

    camera = camera_of(config)
    # With a predictor between frames the law reads the continuous loop's y at the goal.
    continuous = PREDICTIONS[camera.prediction].continuous
    rate = camera.rate if args.camera_rate is None else args.camera_rate
    check_camera(rate, args.latency)
    studied = config
    if config.carrier.traits.joints:
        from geovs_drake.goal.camera_fit import goal_sampled_model
        from geovs_drake.loop import resolve

        camera_config = copy.deepcopy(config)
        camera_config.sensor = camera_like(
            camera, type(camera), rate=rate, latency_frames=args.latency
        )
        resolved = resolve(camera_config)
        summary = goal_sampled_model(resolved, continuous=continuous).summary(rate, args.latency)
        return {
            "gains": "scenario",
            "gain_scale": resolved.gain_scale,
            "prediction": camera.prediction,
            **summary,
        }
    if design is not None:
        studied = copy.deepcopy(design.config)
        studied.sensor = camera_like(camera, type(camera), damping=list(studied.control.damping))
    model = sampled_model(studied)
    out = (model.continuous() if continuous else model).summary(rate, args.latency)
    return {
        "gains": "designed" if design is not None else "scenario",
        "prediction": camera.prediction,
        **out,
    }


def _region(config, certify: bool, solver: str) -> dict:
    from geovs_drake.analysis.linear.certified_region import certify_region
    from geovs_drake.analysis.linear.region import lyapunov_region

    r = lyapunov_region(config)
    out = r.summary()
    if certify:
        out["certified"] = certify_region(config, sampled=r, solver=solver).summary()
    return out


#: --settling-time's damping ratio on the dynamic loop when --damping-ratio is not given.
DEFAULT_DAMPING_RATIO = 0.7


def _studies_table(out: dict) -> list[str]:
    lines = []
    if "design" in out:
        d = out["design"]
        gains = (
            f"k_p = {d['potential_gain']:.5g} (the energy bound), B = {numbers(d['damping'])}; "
            f"peak torque {d['peak_torque_Nm']:.3g} N m, force {d['peak_force_N']:.3g} N"
            if "potential_gain" in d
            else f"k = {d['kinematic_gain']:.5g} 1/s; peak rate {d['peak_rate_rad_s']:.3g} rad/s, "
            f"speed {d['peak_speed_m_s']:.3g} m/s"
        )
        lines.append(
            f"designed: settling {d['achieved_settling_time']:.4g} s, least damping ratio "
            f"{d['achieved_damping_ratio']:.4g}: {gains} (from the start: {d['run_status']})"
        )
    if "camera" in out:
        c = out["camera"]
        margin = c["latency_margin_frames"]
        if margin is None:  # the search's end, or a loop stable at any latency: its reason
            latency = c["latency_margin_reason"]
        elif margin >= 0:
            latency = f"stable up to {margin} frames late"
        else:
            latency = "not stable at this rate even without latency"
        slowest = c["slowest_stable_rate_hz"]
        needs = (
            c["slowest_stable_rate_reason"]
            if slowest is None
            else f"slowest stable rate {slowest:.3g} Hz"
        )
        lines.append(
            f"camera at {c['rate']:g} Hz, {c['latency_frames']} frames late, with the "
            f"{c['gains']} gains"
            + (f" (the arm's gain_scale {c['gain_scale']:.3g})" if "gain_scale" in c else "")
            + f": spectral radius {c['spectral_radius']:.4g} "
            f"({'stable' if c['stable'] else 'not stable'}); {latency}; {needs}"
        )
    if "region" in out:
        r = out["region"]
        lines.append(
            f"Lyapunov region (sampled, {r['rays']} rays): level {r['level']:.3g}, largest "
            f"distance {r['largest_distance_m']:.3g} m and roll {r['largest_roll_rad']:.3g} rad "
            f"from the goal at rest (bounded where {r['failed_by']})"
        )
        if "certified" in r:
            c = r["certified"]
            lines.append(
                f"certified by SOS (degree-{c['degree']} Taylor polynomial, {c['solver']}, "
                f"{c['seconds']:.3g} s): level {c['level']:.3g}, largest distance "
                f"{c['largest_distance_m']:.3g} m and roll {c['largest_roll_rad']:.3g} rad; on the "
                f"nonlinear loop its boundary is in D with Vdot < 0: {c['nonlinear_check']}"
            )
    return lines


def _locus(config, lin, path: Path) -> None:
    from geovs_drake.analysis.linear.gain_design import root_locus
    from geovs_drake.plotting import plot_root_locus

    name = config.plant.gain_field  # the gain that scales the NF's loop on this plant
    own = float(getattr(config.control, name))
    gains = own * np.geomspace(0.1, 10.0, 41)
    plot_root_locus(
        gains,
        root_locus(config, gains, name),
        current=lin.eigenvalues,
        damping_ratio=DEFAULT_DAMPING_RATIO if config.dynamic else None,
        gain_label=config.plant.gain_symbol,
        path=path,
    )


def _table(lin, where: str) -> str:
    verdict = "stable" if lin.max_real_part < 0 else "not stable"
    continuum = set(lin.continuum)
    # A mode on a known continuum of equilibria (a redundant arm's self-motion) is 0 to
    # rounding: named, and left out of the verdict (spectrum.EigenvalueFacts).
    aside = (
        f"; {len(continuum)} mode{'s' if len(continuum) > 1 else ''} at 0 to rounding, not "
        f"counted: {lin.continuum_name}"
        if continuum
        else ""
    )
    lines = [
        f"{lin.plant} loop linearised at {where}: {verdict} "
        f"(largest real part {lin.max_real_part:.4g} 1/s{aside})"
        + ("" if lin.at_equilibrium else "; not an equilibrium: the frozen-time model"),
        f"  {'eigenvalue [1/s]':>26}  {'damping ratio':>13}  {'time constant [s]':>17}",
    ]
    rows = zip(lin.eigenvalues, lin.damping_ratios, lin.time_constants, strict=True)
    for k, (lam, zeta, tau) in enumerate(rows):
        facts = (
            f"  {'a continuum of equilibria':>32}"
            if k in continuum
            else f"  {zeta:>13.4g}  {tau:>17.4g}"
        )
        lines.append(f"  {lam.real:>12.5g} {lam.imag:+12.5g}j{facts}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Run ``linearize``; the exit code."""
    if args.out is not None:
        check_out(args.out)
    # As given, not resolved: the studies vary it and resolve it themselves (the arm's
    # gains are scaled once, by the loop they build).
    config = load_layers(args)
    if _without_model(config) and args.at == "goal":
        # Linearised at rest at the goal, the loop never reads the start: its checks (the
        # quadrotor with initial_attitude given refuses a start tilted too far) do not apply.
        config.initial = copy.deepcopy(config.goal)
    config.validate()
    from geovs_drake.analysis.linear.linearization import linearize, state_at
    from geovs_drake.scenario import PoseConfig
    from geovs_drake.simulation import StartOutsideDomain, check_start

    if args.at == "goal":
        where, state = "the goal", None
    else:
        text = ",".join(f"{v:g}" for v in args.at["xyz"] + args.at["rpy"])
        where = f"X_BC = ({text})"
        config.initial = PoseConfig(**args.at)
        try:
            check_start(config)  # D's margins at the pose, and the goal's
        except StartOutsideDomain as e:
            reason = str(e).removeprefix("start outside D: ")
            print(f"geovs-drake: --at {text} is outside D: {reason}", file=sys.stderr)
            return EXIT_BAD_INPUT
        state = state_at(config, config.X_BC_initial)
    if _without_model(config):
        try:
            lin = _loop_linearization(config, args)
        except ValueError as e:
            print(f"geovs-drake: {e}", file=sys.stderr)
            return EXIT_BAD_INPUT
    elif _on_arm(config):
        lin = _arm_linearization(config, args)
    else:
        lin = linearize(config, state)
    out = lin.summary()
    design = None
    # Every study runs before anything is written: bad input leaves no output behind.
    try:
        if args.settling_time is not None or args.damping_ratio is not None:
            if args.settling_time is None:
                raise ValueError("--damping-ratio needs --settling-time")
            design = _design(config, args)
            out["design"] = design.summary()
        if args.latency is not None or args.camera_rate is not None:
            args.latency = 0 if args.latency is None else args.latency
            out["camera"] = _camera(config, args, design)
        if args.certify:
            from geovs_drake.analysis.linear.certified_region import check_solver

            check_solver(args.sos_solver)
    except ValueError as e:
        print(f"geovs-drake: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.region or args.certify:
        out["region"] = _region(config, args.certify, args.sos_solver)
    if args.out is not None:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        _locus(config, lin, Path(args.out) / LOCUS_FILE)
        (Path(args.out) / OUT_FILE).write_text(json.dumps(out, indent=2) + "\n")
    if args.json:
        print(json.dumps(out))
    else:
        print("\n".join([_table(lin, where), *_studies_table(out)]))
    camera = out.get("camera")
    if camera is not None and camera["gains"] == "designed" and not camera["stable"]:
        # The design is for continuous feedback (Eq. 45); say where the camera breaks it.
        slowest = camera["slowest_stable_rate_hz"]
        print(
            f"geovs-drake: warning: the designed gains are not stable with a "
            f"{camera['rate']:g} Hz camera {camera['latency_frames']} frames late (spectral "
            f"radius {camera['spectral_radius']:.3g}): "
            + (
                camera["slowest_stable_rate_reason"]
                if slowest is None
                else f"they need at least {slowest:.3g} Hz, or a longer --settling-time"
            ),
            file=sys.stderr,
        )
    return EXIT_CONVERGED
