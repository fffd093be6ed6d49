"""Robustness of the loop closed through a camera: pixel noise, focal-length error, radius
error and latency.

Each case runs the dynamic loop from the same random starts in D (images uniform
in D's chart, at rest, :func:`~geovs_drake.analysis.sweep.sample_starts`) with one
error set (:data:`LEVELS`), through Drake's Simulator with the
:class:`~geovs_drake.systems.PinholeFeatureSensor` by default: the extractor's
measurement (30 Hz, held, the same fit) on exactly projected image points, so the
error under study is the only one. Why not the batch engine: it integrates the
exact, continuous y with error control, and a camera's y is a held sample that
changes at frame times (and noise drawn per frame): that needs the integrator
stopped at every frame, which :func:`~geovs_drake.simulation.simulate` does for
free. A few cases go through the rendered loop (``sensor="rendered"``) to confirm.

Per run: the status, whether it **settled** (stayed in D, every frame gave y, and
over the last second the camera moved less than the camera's convergence
tolerance, :func:`~geovs_drake.simulation.convergence_tolerance`: it came to rest
at *an* equilibrium), whether that is the goal (status ``converged``) and the
final pose error.

Two predictions to compare with:

* :func:`predicted_equilibrium`: where the noise-free measurement equals the goal
  image y*, along the line from the sphere's centre through the goal. A focal
  error scales every measured angle's tangent; a radius error leaves the
  measurement alone (y is scale-free) but moves the goal image, y* = c(X_CB*)
  computed with the believed rho, so ``lambda* = rho_believed / |d*|`` and the loop
  stops where ``rho_true / |d| = lambda*``: ``|d| = |d*| rho_true / rho_believed``.
* :func:`sampled_spectral_radius`: the loop linearised at that equilibrium
  (:func:`potential_stiffness`, the measured y's own stiffness) with the
  potential force sampled every frame, held, and delayed by the latency, the
  damping continuous; Drake's ``DiscreteTimeApproximation`` gives the
  zero-order-hold discretisation. Below 1 the sampled loop is locally stable.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from geovs_drake.analysis._pool import map_scenarios
from geovs_drake.analysis.linear.linearization import rig_spatial_inertia
from geovs_drake.analysis.studies.robustness_levels import LEVELS, NOMINAL, SHRINK
from geovs_drake.geometry.camera import camera_map, camera_map_inverse, image_jacobian
from geovs_drake.geometry.features import FEATURE_FAILURES, TargetMarks, pinhole_measurement
from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.geometry.so3 import so3_exp
from geovs_drake.goal.linear_model import SampledModel
from geovs_drake.sampling import random_features_in_domain
from geovs_drake.scenario import (
    PREDICTIONS,
    SENSOR_VARIANTS,
    CameraModel,
    Pinhole,
    PoseConfig,
    ScenarioConfig,
    camera_like,
    variant_name,
)
from geovs_drake.simulation import (
    StartOutsideDomain,
    convergence_tolerance,
    pose_error,
    simulate,
)

__all__ = [
    "LEVELS",
    "SOFT_GAINS",
    "RobustnessRow",
    "case_config",
    "plot_robustness",
    "potential_stiffness",
    "predicted_equilibrium",
    "robustness_study",
    "robustness_sweep",
    "sampled_spectral_radius",
    "soft_gains",
    "summarize_robustness",
]

#: Over this final stretch [s] a settled run moves less than the camera's tolerance.
SETTLE_WINDOW_S = 1.0
#: Gains that tolerate 3 frames of latency at 30 Hz (:func:`sampled_spectral_radius`
#: 0.990 against 1.27 with the default camera gains), found on a grid of potential gain
#: x rotational x translational damping: ``(k_p, sensor.damping)``. A quarter of the
#: stiffness: the loop's slowest mode has a time constant of about 3.3 s instead of 0.7 s.
SOFT_GAINS = (1.0, [1.0, 1.0, 1.0, 2.0, 2.0, 2.0])


def soft_gains(config: ScenarioConfig) -> ScenarioConfig:
    """``config`` with :data:`SOFT_GAINS`."""
    c = copy.deepcopy(config)
    kind = type(c.sensor) if c.sensor.traits.camera else Pinhole
    c.control.potential_gain = SOFT_GAINS[0]
    c.sensor = camera_like(c.sensor, kind, damping=list(SOFT_GAINS[1]))
    return c


def case_config(
    config: ScenarioConfig, parameter: str | None, level: float, sensor: str = "pinhole"
) -> ScenarioConfig:
    """``config`` with a camera (``sensor``, a camera's name in
    :data:`~geovs_drake.scenario.SENSOR_VARIANTS`, its fields the config's sensor's) and one
    setting changed: ``sensor.<parameter> = level`` (``None``: the nominal case)."""
    kind = SENSOR_VARIANTS.get(sensor)
    if kind is None or not issubclass(kind, CameraModel):
        raise ValueError(f"sensor must be pinhole or rendered, got {sensor!r}")
    c = copy.deepcopy(config)
    c.sensor = camera_like(c.sensor, kind)
    if parameter is not None:
        if parameter not in LEVELS:
            raise ValueError(f"parameter must be one of {', '.join(LEVELS)}, got {parameter!r}")
        setattr(c.sensor, parameter, int(level) if parameter == "latency_frames" else level)
    c.validate()
    return c


def _measured(config: ScenarioConfig, X_BC: RigidTransform) -> np.ndarray:
    """The noise-free y the loop's sensor gives at camera pose X_BC (the exact c(H) for the
    exact sensor)."""
    X_CB = X_BC.inverse().GetAsMatrix4()
    camera = config.sensor
    if not camera.traits.camera:
        return camera_map(X_CB, config.radius).to_vector()
    theta = config.domain.to_domain().fov_half_angle
    y, code = pinhole_measurement(
        X_CB,
        config.radius,
        TargetMarks(),
        camera.intrinsics(theta),
        camera.believed_intrinsics(theta),
    )
    if y is None:
        raise ValueError(f"no measurement at this pose: {FEATURE_FAILURES[code]}")
    return np.asarray(y)


def potential_stiffness(
    config: ScenarioConfig, X_BC: RigidTransform | None = None, h: float = 1e-6
) -> np.ndarray:
    """K = -dF/d eps (6x6) at camera pose X_BC (default: the goal), at rest.

    F = k_p C(y; rho_believed)^T dphi(y) is the servo wrench of Eq. (45) without
    damping, y the noise-free measurement (:func:`_measured`), and the pose is
    perturbed on the right in the camera's frame, ``X_BC exp(eps)``, eps =
    (rotation, translation): the coordinates of
    :func:`~geovs_drake.analysis.linear.linearization.closed_form_A`, whose K it equals for
    the exact sensor (a test checks). Central differences: the measurement is a fit,
    not a formula to differentiate. With calibration errors this is where they
    enter the loop's stiffness: a focal error scales every measured angle, a
    radius error the force's translational part (C's velocity columns scale as
    1/rho, Eq. 14).
    """
    X_BC = X_BC or config.X_BC_goal
    nf = NavigationFunction(
        config.domain.to_domain(), config.goal_features(), config.navigation.to_gains()
    )

    def force(eps: np.ndarray) -> np.ndarray:
        X = X_BC @ RigidTransform(RotationMatrix(so3_exp(eps[:3])), eps[3:])
        y = _measured(config, X)
        dphi = nf.differential(y, extend=True)
        return config.control.potential_gain * image_jacobian(y, config.believed_radius).T @ dphi

    K = np.zeros((6, 6))
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        K[:, i] = -(force(e) - force(-e)) / (2 * h)
    return K


def sampled_spectral_radius(config: ScenarioConfig) -> float:
    """The spectral radius of the sampled, delayed loop linearised at its equilibrium.

    The equilibrium is :func:`predicted_equilibrium`'s pose; there the potential's
    stiffness K is :func:`potential_stiffness` (calibration errors included) and
    M is the rig's inertia. State ``z_k = (x_k, ..., x_{k-L})`` of the 12 minimal
    coordinates (eps, nu) at frame k; between frames ``xdot = A_d x + A_p
    x_{k-L}``, ``A_d = [[0, I], [0, -M^-1 B]]`` (kinematics and the damping
    ``config.damping``, continuous) and ``A_p = [[0, 0], [-M^-1 K, 0]]`` (the
    potential, sampled and held). :class:`~geovs_drake.goal.linear_model.SampledModel`
    discretises it (Drake's ``DiscreteTimeApproximation``, a zero-order hold) and adds
    the delay. Below 1: locally stable. With a continuous ``sensor.prediction``
    (odometry: the held frame moved by the rig's motion, exact at the equilibrium) the
    potential joins the continuous part (:meth:`SampledModel.continuous`).
    """
    M = rig_spatial_inertia(config)
    equilibrium = predicted_equilibrium(config)
    K = potential_stiffness(config, equilibrium["pose"])
    A_d = np.zeros((12, 12))
    A_d[:6, 6:] = np.eye(6)
    A_d[6:, 6:] = -np.linalg.solve(M, np.diag(config.damping))
    # The held potential force: A_p = B_n C_xi = [[0, 0], [-M^-1 K, 0]].
    B_n = np.vstack([np.zeros((6, 6)), np.linalg.inv(M)])
    C_xi = np.hstack([-K, np.zeros((6, 6))])
    model = SampledModel(A_c=A_d, B_n=B_n, C_xi=C_xi)
    if PREDICTIONS[config.sensor.prediction].continuous:
        model = model.continuous()
    return model.spectral_radius(config.sensor.rate, config.sensor.model_latency_frames)


def predicted_equilibrium(config: ScenarioConfig) -> dict:
    """Where the loop comes to rest with a calibration error, without simulating.

    Along the line from the sphere's centre through the goal camera position,
    the distance z where the noise-free measurement (:func:`_measured`: true
    intrinsics projecting, believed ones lifting) gives the goal's lambda*
    (computed with the believed radius), by bisection. Returns ``distance`` [m],
    ``position_error`` [m] (``|z - |p*||``), ``pose`` (the camera pose X_BC there)
    and ``residual``, the largest difference between the whole measured y there
    and y*: 0 means the goal image is reached exactly at that pose (so it is for
    the default goal, on the marked point's axis, where these errors move only
    the distance).
    """
    goal = config.X_BC_goal
    p_goal = goal.translation()
    r_goal = float(np.linalg.norm(p_goal))
    y_goal = config.goal_features().to_vector()

    def pose(z: float) -> RigidTransform:
        return RigidTransform(goal.rotation(), p_goal * (z / r_goal))

    d = config.domain
    lo, hi = config.radius / d.lam_max, config.radius / d.lam_min
    lam_star = y_goal[9]
    for _ in range(60):  # lambda falls with distance
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _measured(config, pose(mid))[9] > lam_star else (lo, mid)
    z = 0.5 * (lo + hi)
    return {
        "distance": z,
        "position_error": abs(z - r_goal),
        "pose": pose(z),
        "residual": float(np.max(np.abs(_measured(config, pose(z)) - y_goal))),
    }


@dataclass
class RobustnessRow:
    """One run: the case, the start, and what happened."""

    parameter: str
    level: float
    start: int
    sensor: str
    gains: str  # "default" or "soft" (SOFT_GAINS)
    status: str
    settled: bool
    converged: bool
    position_error_m: float
    rotation_error_rad: float
    final_motion_m: float  # how far the camera moved over the last SETTLE_WINDOW_S
    final_motion_rad: float
    wall_time_s: float


def _final_motion(result) -> tuple[float, float]:
    """The largest position and rotation change over the last SETTLE_WINDOW_S [m, rad]."""
    t = result.times
    window = result.X_BC[t >= t[-1] - SETTLE_WINDOW_S]
    last = RigidTransform(window[-1])
    errors = np.array([pose_error(RigidTransform(X), last) for X in window])
    return float(errors[:, 0].max()), float(errors[:, 1].max())


def _run_one(
    config: ScenarioConfig, parameter: str, level: float, start: int, gains: str
) -> RobustnessRow:
    """One run of one case from one start."""
    try:
        result = simulate(config)
    except StartOutsideDomain as e:  # a start is in D by construction: say so if not
        raise RuntimeError(f"start {start}: {e}") from e
    moved = _final_motion(result)
    tol = convergence_tolerance(result.resolved)
    stayed = result.status in ("converged", "not_converged")
    settled = stayed and result.sim_time_s >= config.duration - 1e-9
    settled = settled and moved[0] <= tol[0] and moved[1] <= tol[1]
    dp, dr = result.final_errors
    return RobustnessRow(
        parameter=parameter,
        level=float(level),
        start=int(start),
        sensor=variant_name(config.sensor),
        gains=gains,
        status=result.status,
        settled=bool(settled),
        converged=result.status == "converged",
        position_error_m=dp,
        rotation_error_rad=dr,
        final_motion_m=moved[0],
        final_motion_rad=moved[1],
        wall_time_s=result.wall_time_s,
    )


def sample_poses(config: ScenarioConfig, n: int, seed: int, shrink: float) -> np.ndarray:
    """n camera poses X_BC (n, 4, 4) at rest, images uniform in ``shrink`` of D's chart."""
    y = random_features_in_domain(np.random.default_rng(seed), n, config.domain.to_domain(), shrink)
    return np.linalg.inv(camera_map_inverse(y, config.radius))


def robustness_sweep(
    config: ScenarioConfig | None = None,
    starts: int = 20,
    duration: float = 10.0,
    seed: int = 0,
    shrink: float = SHRINK,
    sensor: str = "pinhole",
    levels: dict[str, Sequence[float]] | None = None,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    gains: str = "default",
) -> list[RobustnessRow]:
    """Run every (parameter, level) of ``levels`` (default :data:`LEVELS`) from ``starts``
    random starts in D for ``duration`` seconds; return one row per run.

    ``gains``: ``"default"`` runs ``config``'s gains, ``"soft"`` :data:`SOFT_GAINS`.
    Starts: :func:`sample_poses` (``shrink`` of D's chart, from ``seed``). The nominal
    level of every parameter (:data:`NOMINAL`) is the same run: it runs once and its
    rows are repeated under each parameter. Start k draws its pixel noise from seed k.
    ``workers`` > 1 runs the cases in that many processes.
    """
    base = copy.deepcopy(config or ScenarioConfig())
    if gains == "soft":
        base = soft_gains(base)
    elif gains != "default":
        raise ValueError(f"gains must be 'default' or 'soft', got {gains!r}")
    base.duration = duration
    levels = LEVELS if levels is None else levels
    X_BC = sample_poses(base, starts, seed, shrink)
    tasks, keys = [], {}
    for parameter, values in levels.items():
        for level in values:
            nominal = level == NOMINAL[parameter]
            key = ("nominal", 0.0) if nominal else (parameter, float(level))
            if key in keys:
                continue
            keys[key] = len(tasks)
            for k in range(starts):
                c = case_config(base, None if nominal else parameter, level, sensor)
                c.initial = PoseConfig.from_rigid_transform(RigidTransform(X_BC[k]))
                c.sensor.seed = k
                tasks.append((c, key[0], key[1], k, gains))
    rows: list[RobustnessRow] = []
    for row in map_scenarios(_run_one, tasks, workers):
        rows.append(row)
        if progress:
            progress(len(rows), len(tasks))
    out = []
    for parameter, values in levels.items():
        for level in values:
            if level == NOMINAL[parameter]:
                out += [
                    RobustnessRow(**{**asdict(r), "parameter": parameter, "level": float(level)})
                    for r in rows
                    if r.parameter == "nominal"
                ]
            else:
                out += [r for r in rows if r.parameter == parameter and r.level == float(level)]
    return out


def summarize_robustness(
    rows: Sequence[RobustnessRow], config: ScenarioConfig | None = None
) -> list[dict]:
    """One line per (gains, parameter, level): runs, how many stayed in D with every
    frame usable to the end (``stayed``), settled, and converged (at the goal within
    the camera's tolerance), the statuses, the final pose error over the runs that
    stayed (median, max; NaN if none) and the predictions (equilibrium offset for the
    calibration errors, spectral radius of the sampled loop)."""
    config = config or ScenarioConfig()
    bases = {"default": config, "soft": soft_gains(config)}
    order = {p: i for i, p in enumerate(LEVELS)}
    cases = sorted(
        {(r.gains, r.parameter, r.level) for r in rows},
        key=lambda k: (k[0] != "default", order.get(k[1], 99), k[2]),
    )
    table = []
    for gains, parameter, level in cases:
        group = [r for r in rows if (r.gains, r.parameter, r.level) == (gains, parameter, level)]
        # Final errors of the runs that stayed in D to the end (a run that stopped has
        # only a pose where it stopped).
        stayed = [r for r in group if r.status in ("converged", "not_converged")]
        dp = np.array([r.position_error_m for r in stayed] or [np.nan])
        dr = np.array([r.rotation_error_rad for r in stayed] or [np.nan])
        statuses: dict[str, int] = {}
        for r in group:
            statuses[r.status] = statuses.get(r.status, 0) + 1
        nominal = level == NOMINAL[parameter]
        c = case_config(bases[gains], None if nominal else parameter, level, group[0].sensor)
        line = {
            "gains": gains,
            "parameter": parameter,
            "level": level,
            "sensor": group[0].sensor,
            "runs": len(group),
            "stayed": len(stayed),
            "settled": sum(r.settled for r in group),
            "converged": sum(r.converged for r in group),
            "statuses": statuses,
            "position_error_median_m": float(np.median(dp)),
            "position_error_max_m": float(np.max(dp)),
            "rotation_error_median_rad": float(np.median(dr)),
            "rotation_error_max_rad": float(np.max(dr)),
            "spectral_radius": sampled_spectral_radius(c),
        }
        if parameter in ("focal_error", "radius_error"):
            line["predicted_position_error_m"] = predicted_equilibrium(c)["position_error"]
        table.append(line)
    return table


def plot_robustness(table: Sequence[dict], path: str | Path | None = None):
    """The shares that stayed in D, settled and reached the goal, and the final position
    error of the runs in D, against each error's level."""
    from geovs_drake.plotting import pyplot

    plt = pyplot()
    columns = []
    for t in table:
        if (t["gains"], t["parameter"]) not in columns:
            columns.append((t["gains"], t["parameter"]))
    units = {
        "pixel_noise": "sigma [px]",
        "focal_error": "focal error (believed / true - 1)",
        "radius_error": "radius error (believed / true - 1)",
        "latency_frames": "latency [frames of 1/30 s]",
        "rate": "camera rate [Hz]",
    }
    fig, axes = plt.subplots(2, len(columns), figsize=(3.6 * len(columns), 6.4))
    axes = np.asarray(axes).reshape(2, len(columns))
    for j, (gains, parameter) in enumerate(columns):
        lines = [t for t in table if (t["gains"], t["parameter"]) == (gains, parameter)]
        x = [t["level"] for t in lines]
        ax = axes[0, j]
        ax.plot(x, [t["stayed"] / t["runs"] for t in lines], "^-", label="stayed in D")
        ax.plot(x, [t["settled"] / t["runs"] for t in lines], "o-", label="settled")
        ax.plot(x, [t["converged"] / t["runs"] for t in lines], "s--", label="at the goal")
        title = parameter if gains == "default" else f"{parameter}, soft gains"
        ax.set(ylim=(-0.05, 1.05), title=title, ylabel="share of starts")
        ax.legend(fontsize=7)
        ax = axes[1, j]
        ax.semilogy(x, [t["position_error_median_m"] for t in lines], "o-", label="median")
        ax.semilogy(x, [t["position_error_max_m"] for t in lines], "v:", label="max")
        predicted = [t.get("predicted_position_error_m") for t in lines]
        if any(p is not None for p in predicted):
            ax.semilogy(x, [max(p, 1e-6) for p in predicted], "k+", ms=10, label="predicted offset")
        ax.set(xlabel=units[parameter], ylabel="final position error [m], runs in D")
        ax.legend(fontsize=7)
        pad = 0.08 * (max(x) - min(x) or 1.0)
        for a in axes[:, j]:
            a.grid(alpha=0.3)
            a.set_xlim(min(x) - pad, max(x) + pad)  # the same levels, data or not
    fig.suptitle("The loop through a camera (30 Hz, 320x240): one error at a time")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def robustness_study(
    config: ScenarioConfig | None = None,
    out_dir: str | Path = "results/robustness",
    starts: int = 20,
    duration: float = 10.0,
    seed: int = 0,
    shrink: float = SHRINK,
    sensor: str = "pinhole",
    only: str | None = None,
    soft_duration: float = 20.0,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> list[dict]:
    """Every sweep of :data:`LEVELS` but the camera rate (``only``: that one alone), and
    latency again with :data:`SOFT_GAINS` for ``soft_duration`` seconds (0: not);
    write ``out_dir``/rows.json, table.json and robustness.png once every run is done;
    return the table (:func:`summarize_robustness`)."""
    if only is not None:
        levels = {only: LEVELS[only]}
    else:  # the errors; the camera rate is its own study (only="rate")
        levels = {k: v for k, v in LEVELS.items() if k != "rate"}
    common = dict(starts=starts, seed=seed, shrink=shrink, sensor=sensor, workers=workers)
    rows = robustness_sweep(config, duration=duration, levels=levels, progress=progress, **common)
    if "latency_frames" in levels and soft_duration > 0:
        rows += robustness_sweep(
            config,
            duration=soft_duration,
            levels={"latency_frames": levels["latency_frames"]},
            progress=progress,
            gains="soft",
            **common,
        )
    table = summarize_robustness(rows, config)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "rows.json").write_text(json.dumps([asdict(r) for r in rows], indent=1) + "\n")
    (out / "table.json").write_text(json.dumps(table, indent=1) + "\n")
    plot_robustness(table, out / "robustness.png")
    return table
