"""Closed-loop costs, each against baselines measured in this process.

Baselines, measured here and now (the machine is shared and noisy, so the
ratios are the figures to compare; microseconds are printed for context):

* ``numpy call``: one ``R @ v`` on 3-vectors, the unit the issue tracker uses
  ("numpy on 3-vectors costs about 1 us a call");
* ``framework floor``: the same dynamic diagram with every Python system's
  ``Calc`` replaced by a constant output: what Drake and pybind cost around
  our math, which no change to the math can remove.

Reported:

* bare derivative evaluation: the math alone on the default state (camera
  kernel, NF kernel, force kernel, and the plant's own forward dynamics);
* diagram derivative evaluation (``CalcTimeDerivatives``, every cache
  invalidated by a new state) and its ratio to bare;
* the real-time factor of both loops, on the default scenario, with the
  monitor and (a) ``simulate()``'s step recorder, (b) Drake's periodic
  ``LogVectorOutput`` loggers, (c) no logging; (d) a bare ``Simulator``
  with neither, at the scenario's integrator (the carrier's: RK5 on the dynamic loop,
  RK3 on the kinematic one; accuracy 1e-6, the step limit of
  ``simulation.step_limit``), whose ratio to (a) is what the monitor
  and the logging cost; and (e) Drake's default ``Simulator`` (``Simulator(diagram)``
  as constructed: RK3 at accuracy 1e-4, max step 0.1 s), neither, whose ratio
  to (d) is what the scenario's tighter accuracy costs;
* the time of Drake's ``Linearize`` of the whole dynamic loop.

    .venv/bin/python benchmarks/bench_closed_loop.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import time
import timeit

import numpy as np
from _record import Figure, record
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import Linearize

from geovs_drake.analysis.linear.linearization import config_at_goal
from geovs_drake.geometry import kernels
from geovs_drake.loop import build_loop, resolve
from geovs_drake.scenario import PLANT_VARIANTS, ScenarioConfig
from geovs_drake.simulation import make_simulator, simulate
from geovs_drake.systems import ImageJacobianForce_, NavigationController_, SphericalCamera_

#: The two Simulator baselines, as the performance page defines them.
BARE = "a bare Simulator at the scenario's integrator, no monitor, no loggers"
DRAKE_DEFAULT = "Drake's default Simulator, no monitor, no loggers"


def best(fn, number: int, repeat: int = 7) -> float:
    """Seconds per call: the best of ``repeat`` timings (the least disturbed)."""
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def derivative_timer(diagram):
    """A function evaluating the diagram's derivatives at a fresh state each call."""
    ctx = diagram.CreateDefaultContext()
    derivatives = diagram.AllocateTimeDerivatives()
    x0 = ctx.get_continuous_state_vector().CopyToVector()
    k = [0]

    def evaluate() -> None:
        k[0] += 1
        ctx.SetContinuousState(x0 + 1e-12 * (k[0] % 7))  # a new state: no cache hits
        diagram.CalcTimeDerivatives(ctx, derivatives)

    return evaluate, ctx


def bare_timer(diagram, ctx):
    """The same math called directly: kernels on the same state and parameters."""
    camera = diagram.GetSubsystemByName("spherical_camera")
    nav = diagram.GetSubsystemByName("navigation_controller")
    force = diagram.GetSubsystemByName("image_jacobian_force")
    plant = diagram.GetSubsystemByName("plant")
    p_cam = camera.GetMyContextFromRoot(ctx).get_numeric_parameter(0).CopyToVector()
    p_nav = nav.navigation_parameters(nav.GetMyContextFromRoot(ctx))
    p_force = force.GetMyContextFromRoot(ctx).get_numeric_parameter(0).CopyToVector()
    pctx = plant.CreateDefaultContext()
    x = ctx.get_continuous_state_vector().CopyToVector()
    u = plant.get_applied_generalized_force_input_port()

    def evaluate() -> None:
        cam = kernels.camera_image(x[0:7], p_cam)
        y = np.array(cam[1:14])
        dphi = np.array(kernels.navigation(y, p_nav)[1:8])
        force_out = kernels.servo_force(x, y, dphi, p_force)
        plant.SetPositionsAndVelocities(pctx, x)
        u.FixValue(pctx, np.array(force_out[6:12]))
        plant.EvalTimeDerivatives(pctx)  # the plant's own (C++) share of the work

    return evaluate


def framework_floor(config: ScenarioConfig) -> float:
    """Seconds per derivative evaluation with every Python Calc a constant."""
    saved = (
        SphericalCamera_[float].CalcImageFeatures,
        NavigationController_[float].CalcDifferential,
        ImageJacobianForce_[float].CalcGeneralizedForce,
    )
    y = [0.0, 0, 1, 0, 1, 0, -1, 0, 0, 0.2, 0, 0, 1]
    SphericalCamera_[float].CalcImageFeatures = lambda self, c, o: o.SetFromVector(
        y if self.body_pose_input.Eval(c) is not None else y
    )
    NavigationController_[float].CalcDifferential = lambda self, c, o: o.SetFromVector(
        [0.0] * 7 if self.image_features_input.Eval(c) is not None else []
    )
    ImageJacobianForce_[float].CalcGeneralizedForce = lambda self, c, o: o.SetFromVector(
        [0.0] * 6 if self.dphi_input.Eval(c) is not None else []
    )
    try:
        evaluate, _ = derivative_timer(build_loop(config, log=False).diagram)
        return best(evaluate, 2000)
    finally:
        (
            SphericalCamera_[float].CalcImageFeatures,
            NavigationController_[float].CalcDifferential,
            ImageJacobianForce_[float].CalcGeneralizedForce,
        ) = saved


def real_time_factors(config: ScenarioConfig, repeat: int) -> dict[str, float]:
    limit = resolve(config).step_limit.max_step_size
    out = {}
    out["simulate() (recorder)"] = max(
        (r := simulate(config)).sim_time_s / r.wall_time_s for _ in range(repeat)
    )
    for label, log, monitor, scenario_integrator in (
        ("Drake LogVectorOutput", True, True, True),
        ("monitor only", False, True, True),
        ("bare Simulator", False, False, True),
        ("Drake's default Simulator", False, False, False),
    ):
        rates = []
        for _ in range(repeat):
            loop = build_loop(config, log=log)
            diagram = loop.diagram
            if monitor:
                simulator, _ = make_simulator(loop)
            else:
                simulator = Simulator(diagram)
            if not monitor and scenario_integrator:
                ApplySimulatorConfig(config.simulator.to_drake(), simulator)
                # The step limit the other rows run with (simulation.step_limit).
                simulator.get_mutable_integrator().set_maximum_step_size(limit)
            simulator.Initialize()
            start = time.perf_counter()
            simulator.AdvanceTo(config.duration)
            rates.append(config.duration / (time.perf_counter() - start))
        out[label] = max(rates)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per real-time factor")
    args = parser.parse_args()
    config = ScenarioConfig()
    R, v = np.eye(3), np.ones(3)
    t_numpy = best(lambda: R @ v, 20000)
    t_floor = framework_floor(config)

    diagram = build_loop(config, log=False).diagram
    diagram_eval, ctx = derivative_timer(diagram)
    bare_eval = bare_timer(diagram, ctx)
    bare_eval()  # load the compiled kernels
    t_diag = best(diagram_eval, 2000)
    t_bare = best(bare_eval, 2000)
    print(f"baselines: numpy call {t_numpy * 1e6:.2f} us, framework floor {t_floor * 1e6:.1f} us")
    calls = "numpy calls"
    print(
        f"bare derivative evaluation:    {t_bare * 1e6:6.1f} us = {t_bare / t_numpy:5.1f} {calls}"
    )
    print(
        f"diagram derivative evaluation: {t_diag * 1e6:6.1f} us = {t_diag / t_numpy:5.1f} {calls};"
        f" diagram / bare = {t_diag / t_bare:.2f}; (diagram - floor) / bare = "
        f"{(t_diag - t_floor) / t_bare:.2f}"
    )

    figures = [
        Figure("bare derivative evaluation (kernels + plant)", t_bare * 1e6, "us",
               "a 3x3 numpy matrix-vector product", t_numpy * 1e6, target="<= 40 us"),
        Figure("diagram derivative evaluation (CalcTimeDerivatives)", t_diag * 1e6, "us",
               "the bare evaluation", t_bare * 1e6, target="<= 2x bare"),
        Figure("the framework's floor (an empty diagram of the same shape)", t_floor * 1e6, "us",
               "the bare evaluation", t_bare * 1e6),
    ]  # fmt: skip
    for controller in ("dynamic", "kinematic"):
        c = ScenarioConfig(plant=PLANT_VARIANTS[controller]())
        rates = real_time_factors(c, args.repeat)
        text = ", ".join(f"{k} {v:.0f}x" for k, v in rates.items())
        print(f"real-time factor, default {controller} scenario ({c.duration:.0f} s): {text}")
        cost = rates["bare Simulator"] / rates["simulate() (recorder)"] - 1
        print(f"  monitor + step recorder cost {cost:.0%} of a step")
        figures += [
            Figure(f"{controller} loop, simulate(), default scenario ({c.duration:.0f} s)",
                   rates["simulate() (recorder)"], "x real time", BARE,
                   rates["bare Simulator"], target=">= 50x" if controller == "dynamic" else ""),
            Figure(f"{controller} loop, {BARE}", rates["bare Simulator"], "x real time",
                   DRAKE_DEFAULT, rates["Drake's default Simulator"]),
        ]  # fmt: skip

    lin_diagram = build_loop(config_at_goal(config), log=False).diagram
    lin_ctx = lin_diagram.CreateDefaultContext()

    def linearize() -> None:
        Linearize(
            lin_diagram,
            lin_ctx,
            input_port_index=InputPortSelection.kNoInput,
            output_port_index=OutputPortSelection.kNoOutput,
        )

    linearize()
    t_lin = best(linearize, 5, repeat=3)
    print(
        f"Linearize of the whole dynamic loop: {t_lin * 1e3:.1f} ms "
        f"= {t_lin / t_diag:.0f} float derivative evaluations"
    )
    figures.append(Figure("Drake's Linearize of the whole dynamic loop", t_lin * 1e3, "ms",
                          "one diagram derivative evaluation", t_diag * 1e3))  # fmt: skip
    record("bench_closed_loop", "The closed loops: derivatives, real time, Linearize", figures)


if __name__ == "__main__":
    main()
