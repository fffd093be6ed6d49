"""Closed-loop costs, each as a ratio against a baseline measured in this process.

* Real-time factor of the default dynamic scenario (simulated / wall seconds).
* Cost of one derivative evaluation of the dynamic diagram against the same
  math called bare (camera map, navigation differential, Eq. 45 wrench, frame
  shift) on the same state: the systems framework's overhead.
* Time of Drake's ``Linearize`` on the whole loop, in units of one float
  derivative evaluation of the diagram.

    .venv/bin/python benchmarks/bench_closed_loop.py
"""

from __future__ import annotations

import time
import timeit

import numpy as np
from pydrake.systems.framework import InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import Linearize

from geovs_drake.analysis.linearization import config_at_goal
from geovs_drake.camera import camera_map
from geovs_drake.diagrams import make_dynamic_servo_diagram
from geovs_drake.navigation import navigation_differential
from geovs_drake.scenario import ScenarioConfig
from geovs_drake.simulation import simulate
from geovs_drake.systems._common import (
    X_CB_matrix,
    camera_pose,
    camera_velocity,
    param_to_pose,
    pose_to_param,
)
from geovs_drake.systems.image_jacobian_force import servo_wrench


def best(fn, number: int, repeat: int = 5) -> float:
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def main() -> None:
    config = ScenarioConfig()
    result = simulate(config)
    print(
        f"real-time factor, default dynamic scenario: {result.sim_time_s / result.wall_time_s:.2f} "
        f"({result.sim_time_s:.0f} s simulated, {result.steps} steps, status {result.status})"
    )

    diagram = make_dynamic_servo_diagram(config, log=False)
    ctx = diagram.CreateDefaultContext()
    derivatives = diagram.AllocateTimeDerivatives()
    t = [0.0]

    def diagram_eval():
        t[0] += 1e-9  # invalidate every cache, as an integrator's new stage does
        ctx.SetTime(t[0])
        diagram.CalcTimeDerivatives(ctx, derivatives)

    x = ctx.get_continuous_state_vector().CopyToVector()
    X_RC, X_WB = pose_to_param(config.X_RC), pose_to_param(config.X_WB)
    goal, domain, gains = (
        config.goal_features(),
        config.domain.to_domain(),
        config.navigation.to_gains(),
    )
    damping = np.asarray(config.control.damping)
    plant = diagram.GetSubsystemByName("plant")
    pctx = plant.CreateDefaultContext()

    def bare_eval():
        R_WC, p_WC = camera_pose(x[:7], X_RC)
        y = camera_map(X_CB_matrix(R_WC, p_WC, *param_to_pose(X_WB)), config.radius).to_vector()
        _, dphi = navigation_differential(y, goal, domain, gains)
        F = servo_wrench(
            y, dphi, camera_velocity(x, X_RC), config.radius, config.control.potential_gain, damping
        )
        plant.SetPositionsAndVelocities(pctx, x)
        plant.EvalTimeDerivatives(pctx)  # the plant's own (C++) share of the work
        return F

    t_diag = best(diagram_eval, 200)
    t_bare = best(bare_eval, 200)
    print(f"derivative evaluation: diagram / bare math = {t_diag / t_bare:.2f}")

    goal_config = config_at_goal(config)
    lin_diagram = make_dynamic_servo_diagram(goal_config, log=False)
    lin_ctx = lin_diagram.CreateDefaultContext()
    start = time.perf_counter()
    for _ in range(5):
        Linearize(
            lin_diagram,
            lin_ctx,
            input_port_index=InputPortSelection.kNoInput,
            output_port_index=OutputPortSelection.kNoOutput,
        )
    t_lin = (time.perf_counter() - start) / 5
    print(f"Linearize of the whole loop = {t_lin / t_diag:.0f} float derivative evaluations")
    print(
        f"(context only: {t_diag * 1e3:.2f} ms per derivative, {t_bare * 1e3:.2f} ms bare, "
        f"{t_lin * 1e3:.0f} ms per Linearize)"
    )


if __name__ == "__main__":
    main()
