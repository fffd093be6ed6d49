"""``geovs-drake place-base``: where to stand an arm's base so that its goal sits well
inside the arm's workspace (:func:`geovs_drake.goal.arm.place_base`)."""

from __future__ import annotations

import argparse
import dataclasses
import json

from geovs_drake.cli._options import (
    EXIT_CONVERGED,
    add_command,
    add_config,
    add_goal,
    add_json,
    add_variant_flag,
    load_layers,
)
from geovs_drake.scenario import CARRIER_VARIANTS, ScenarioConfig, variant_name


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``place-base`` command."""
    p = add_command(
        sub,
        "place-base",
        "print an arm base pose that puts the goal well inside the arm's workspace",
        "For the scenario's arm (carrier: !Arm, its model, end_effector_frame and "
        "camera_offset; its base_pose is ignored), print the base pose that puts the goal "
        "camera pose X_WB X_BC* where the arm is farthest from its joint limits and its "
        "singularities, upright and looking away from the base, checked by inverse "
        "kinematics; with the line to paste into a scenario (carrier.base_pose). Exit code "
        "0 when placed, 2 for bad input or a goal no base reaches.",
    )
    add_config(p)
    add_variant_flag(
        p,
        "--arm",
        _arm,
        "the arm: default (the UR5-like arm shipped in the package), panda, or the path of "
        "a URDF or SDFormat file (with the carrier's end_effector_frame in the scenario) "
        "(default: the config's arm)",
        metavar="default|panda|PATH",
    )
    add_goal(p)
    add_json(p)
    p.set_defaults(func=run)


def _arm(config: ScenarioConfig, flag: str, model: str) -> None:
    """``--arm``: the scenario's arm with this model, or that arm in place of another
    carrier (the command places nothing else). By the registry's name, not the type."""
    if variant_name(config.carrier) != "arm":
        config.carrier = CARRIER_VARIANTS["arm"]()
    config.carrier = dataclasses.replace(config.carrier, model=model)


def run(args: argparse.Namespace) -> int:
    """Run ``place-base``; the exit code."""
    config = load_layers(args)
    # The registry's name of the carrier, not its type (the variants' checks live in
    # geovs_drake.scenario): the command places an arm's base and nothing else.
    if variant_name(config.carrier) != "arm":
        raise ValueError(
            "place-base places an arm's base: the carrier here is "
            f"{variant_name(config.carrier)} (give --arm, or carrier: !Arm {{...}} in "
            "--config or --scenario-text)"
        )
    config.validate()
    # Here, not at the top: the command line starts without the loop's modules.
    from geovs_drake.goal.arm import place_base

    placed = place_base(config)
    # (+ 0.0: an upright base's rpy without a -0)
    xyz, rpy = placed.xyz_rpy[:3], [v + 0.0 for v in placed.xyz_rpy[3:]]
    numbers = (", ".join(f"{v:.4f}" for v in xyz), ", ".join(f"{v:g}" for v in rpy))
    pose = "{{xyz: [{}], rpy: [{}]}}".format(*numbers)
    if args.json:
        print(
            json.dumps(
                {
                    "base_pose": {"xyz": list(xyz), "rpy": list(rpy)},
                    "goal_camera_pose_xyz": [float(v) for v in placed.X_WC.translation()],
                    "goal_joints": [float(v) for v in placed.q],
                    "min_joint_limit_margin": placed.joint_margin,
                    "min_jacobian_singular_value": placed.singular_value,
                }
            )
        )
        return EXIT_CONVERGED
    goal = ", ".join(f"{round(v, 6) + 0.0:g}" for v in placed.X_WC.translation())
    print(
        f"base_pose: {pose}\n"
        f"# the goal camera at ({goal}) m in W: IK's joints {placed.joint_margin:.3g} rad "
        f"from their nearest limit, sigma_min(J_C) {placed.singular_value:.3g}"
    )
    return EXIT_CONVERGED
