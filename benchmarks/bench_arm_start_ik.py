"""The sweep's compiled IK (batch.arm_ik.StartSolver) against Drake's InverseKinematics.

N start poses of the arm sweep's sampler (seed 0, `bounded`), solved by both: the time a
pose, and the agreement: the same reached/unreachable decision, the same joints (to
1e-9 rad), where they differ whose IK score is higher, and the same start joints after
the branch (start_branch, which the sweep applies to both: whole turns chosen again).
Every compiled solution is checked by Drake's plant (the camera at the pose to 1e-9,
inside the limits).

    .venv/bin/python benchmarks/bench_arm_start_ik.py [--poses 500]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _record import Figure, record
from pydrake.math import RigidTransform

from geovs_drake.analysis.sweep.parts import _ArmStarts
from geovs_drake.analysis.sweep.starts import sample_starts
from geovs_drake.batch import loop_parameters
from geovs_drake.goal.arm import (
    Unreachable,
    _ik_score,
    chart_poses,
    solve_joints,
    start_branch,
)
from geovs_drake.goal.ik_choice import IK_SCORE_TIE
from geovs_drake.loop.resolved import exact_twin, free_twin
from geovs_drake.scenario import Arm, ScenarioConfig
from geovs_drake.systems.arm_model import CAMERA_FRAME, arm_plant

#: Joints that agree [rad], and the camera's pose error a solution may leave [m, rad].
SAME, POSE = 1e-9, 1e-9


def compare(model_name: str, n: int) -> tuple[dict, float, float]:
    """Both IKs on n sweep poses of the arm: the counts, and each one's seconds a pose."""
    config = ScenarioConfig(carrier=Arm(model=model_name))
    p = loop_parameters(exact_twin(free_twin(config)))
    X_BC, _ = sample_starts(config, n, 0, "bounded", 0, p)
    starts = _ArmStarts.of(config, p)
    model, solver = starts.model, starts.solver
    plant = arm_plant(model)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    X_WC = config.X_WB.GetAsMatrix4() @ X_BC
    solver(X_WC[:1, :3, :3], X_WC[:1, :3, 3])  # (compiled, loaded)
    t = time.perf_counter()
    q, ok = solver(X_WC[:, :3, :3], X_WC[:, :3, 3])
    compiled = (time.perf_counter() - t) / n
    t = time.perf_counter()
    drake = []
    for X in X_WC:
        try:
            drake.append(solve_joints(model, RigidTransform(X)))
        except Unreachable:
            drake.append(None)
    drake_time = (time.perf_counter() - t) / n
    ok_d = np.array([x is not None for x in drake])
    counts = dict.fromkeys(
        ("poses", "both", "compiled_only", "drake_only", "neither", "same_joints",
         "compiled_higher", "tied", "drake_higher", "same_start", "pose_or_limit_fail"),
        0,
    )  # fmt: skip
    counts["poses"] = n
    counts["worst_deficit"] = 0.0
    context, camera = plant.CreateDefaultContext(), plant.GetFrameByName(CAMERA_FRAME)
    goal = config.X_WB @ config.X_BC_goal
    for i in range(n):
        key = ("neither", "drake_only", "compiled_only", "both")[2 * ok[i] + ok_d[i]]
        counts[key] += 1
        if ok[i]:  # the compiled solution by Drake's plant
            plant.SetPositions(context, q[i])
            X = camera.CalcPoseInWorld(context).GetAsMatrix4()
            bad = np.max(np.abs(X - X_WC[i])) > POSE or np.any(q[i] < lower) or np.any(q[i] > upper)
            counts["pose_or_limit_fail"] += int(bad)
        if not (ok[i] and ok_d[i]):
            continue
        if np.max(np.abs(q[i] - drake[i])) < SAME:
            counts["same_joints"] += 1
        else:
            d = _ik_score(model, q[i], lower, upper) - _ik_score(model, drake[i], lower, upper)
            key = (
                "tied" if abs(d) <= IK_SCORE_TIE else "compiled_higher" if d > 0 else "drake_higher"
            )
            counts[key] += 1
            counts["worst_deficit"] = min(counts["worst_deficit"], d)
        X, path = (
            RigidTransform(X_WC[i]),
            chart_poses(config, starts.domain, RigidTransform(X_BC[i])),
        )
        a, b = (start_branch(model, x, X, goal, path, starts.follow) for x in (q[i], drake[i]))
        counts["same_start"] += int(np.max(np.abs(a - b)) < SAME)
    return counts, compiled, drake_time


def main() -> None:
    """Both arms; the record."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--poses", type=int, default=500)
    args = parser.parse_args()
    figures, notes = [], []
    for name, label in (("default", "UR5"), ("panda", "Panda")):
        counts, compiled, drake = compare(name, args.poses)
        print(label, counts, f"compiled {compiled * 1e3:.2f} ms, Drake {drake * 1e3:.1f} ms a pose")
        notes.append(f"{label}: {counts}")
        figures.append(
            Figure(f"{label}: the compiled IK of a sweep pose (13 seeds)", compiled * 1e3, "ms",
                   "Drake's InverseKinematics (solve_joints, 13 SNOPT solves)", drake * 1e3)
        )  # fmt: skip
    record(
        "bench_arm_start_ik",
        "The compiled IK of the sweep against Drake InverseKinematics",
        figures,
        "; ".join(notes),
    )


if __name__ == "__main__":
    main()
