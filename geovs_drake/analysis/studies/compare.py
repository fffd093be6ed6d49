"""``geovs-drake compare``: every control law on every scenario of a suite, in one table.

The laws (:data:`COMPARED_LAWS`) are the navigation function and the baselines of
:mod:`geovs_drake.geometry.baselines` (point IBVS with each depth estimate,
PBVS, sphere features). Each runs through :func:`geovs_drake.simulation.simulate`
in the same plant, with the same monitor: a run stops when it leaves D, when
the marked point turns away, or (point IBVS) when one of its four points
leaves the field-of-view cone; Drake's error control failing ends it as
``non_finite``. A row per (scenario, law):

* ``status``, ``t_converged_s`` (the first logged time from which the pose
  error stays within 1 mm and 1 mrad; empty unless converged);
* ``path_length_m``: the camera's path, summed over the logged samples;
* ``max_axis_angle_deg``: the largest angle between the optical axis and the
  direction of the target's centre along the run;
* the minimum margins of D (``fov``, ``lambda``, ``occlusion``), of the
  visibility nu, and of the four IBVS points' field-of-view cone
  (``Z / |p| - cos theta``, computed for every law);
* ``features_in_view``: the law's own features never left the field of view
  (point IBVS: its four points; the others: the silhouette and the marked
  point, i.e. the fov margin and nu).

On a carrier whose rotors a law may drive (its traits' ``rotors``: the quadrotor) the
laws are :data:`ROTOR_LAWS`, the NF through its attitude cascade and Hamel & Mahony's law,
the suite by default the quadrotor's (``quadrotor_suite.yaml``), and the rows add
:data:`ROTOR_FIELDS`, the peak tilt and the rotors' saturation.

A scenario whose target moves (``SuiteScenario.target_motion``, issue 32) adds the
columns :data:`TRACKING_FIELDS` to its rows, and the tables show them only where a
suite has such a scenario: a suite of still targets writes the tables it always did.

The laws run in worker processes (Python systems hold the GIL).
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from geovs_drake.analysis._pool import map_scenarios
from geovs_drake.geometry.baselines import (
    DEFAULT_SQUARE_SIDE,
    TARGET_POINT_NAMES,
    point_fov_margins,
    points_in_camera,
    target_points,
)
from geovs_drake.scenario import (
    PLANT_VARIANTS,
    Dynamic,
    HamelMahony,
    Ibvs,
    LawConfig,
    Nf,
    Pbvs,
    PlantConfig,
    ScenarioConfig,
    Spherical,
    SuiteConfig,
    default_suite_path,
    load_suite,
    variant_name,
)
from geovs_drake.simulation import simulate

__all__ = [
    "COMPARED_LAWS",
    "ROTOR_FIELDS",
    "ROTOR_LAWS",
    "ROW_FIELDS",
    "TRACKING_FIELDS",
    "CompareResult",
    "Run",
    "compare",
    "compared_laws",
    "default_suite",
    "law_label",
    "plot_compare",
    "row_fields",
    "run_case",
    "run_compare",
    "status_matrix",
    "suite_cases",
    "summarize",
    "write_tables",
]

#: The laws compared: the NF, point IBVS with each depth estimate, PBVS and the
#: sphere features.
COMPARED_LAWS: tuple[LawConfig, ...] = (
    Nf(),
    Ibvs("true"),
    Ibvs("desired"),
    Ibvs("mean"),
    Pbvs(),
    Spherical(),
)

#: The laws compared on a carrier whose rotors a law may drive: the NF (through the
#: carrier's attitude cascade) and Hamel & Mahony's law (docs/quadrotor.md).
ROTOR_LAWS: tuple[LawConfig, ...] = (Nf(), HamelMahony())

ROW_FIELDS = (
    "scenario",
    "law",
    "plant",
    "status",
    "t_converged_s",
    "path_length_m",
    "max_axis_angle_deg",
    "min_fov_margin",
    "min_lambda_margin",
    "min_occlusion_margin",
    "min_visibility",
    "min_point_fov_margin",
    "features_in_view",
    "final_position_error_m",
    "final_rotation_error_rad",
    "sim_time_s",
    "wall_time_s",
    "message",
)


#: The columns a moving target's rows add (:mod:`geovs_drake.loop.targets`): the largest
#: position error of the camera relative to the target over the run's last quarter [m].
TRACKING_FIELDS = ("steady_tracking_error_m",)


#: The columns a carrier with rotors adds (its run's JSON entries): the peak tilt [deg] and
#: the share of logged samples at which the rotor allocation gave anything up.
ROTOR_FIELDS = ("max_tilt_deg", "rotor_saturation_fraction")


def row_fields(rows: Sequence[dict]) -> tuple[str, ...]:
    """The table's columns: :data:`ROW_FIELDS`, :data:`TRACKING_FIELDS` where a row has
    them (a moving target's) and :data:`ROTOR_FIELDS` where a row has them (rotors')."""
    fields = ROW_FIELDS
    if any(TRACKING_FIELDS[0] in r for r in rows):
        fields += TRACKING_FIELDS
    if any(ROTOR_FIELDS[0] in r for r in rows):
        fields += ROTOR_FIELDS
    return fields


def compared_laws(base: ScenarioConfig | None = None) -> tuple[LawConfig, ...]:
    """The laws compared on ``base``'s carrier: :data:`ROTOR_LAWS` where a law may drive
    its rotors (its traits' ``rotors``), else :data:`COMPARED_LAWS`."""
    carrier = base.carrier if base is not None else ScenarioConfig().carrier
    return ROTOR_LAWS if carrier.traits.rotors else COMPARED_LAWS


def default_suite(base: ScenarioConfig | None = None) -> Path:
    """The suite compared on ``base``'s carrier when none is given: the quadrotor's
    (``quadrotor_suite.yaml``, the starts of docs/quadrotor.md) where a law may drive its
    rotors, else the package's ``suite.yaml``."""
    carrier = base.carrier if base is not None else ScenarioConfig().carrier
    if carrier.traits.rotors:
        return default_suite_path().with_name("quadrotor_suite.yaml")
    return default_suite_path()


def law_label(law: LawConfig) -> str:
    """``nf``, ``ibvs-true``, ``ibvs-desired``, ``ibvs-mean``, ``pbvs``, ``spherical``."""
    name = variant_name(law)
    depth = law.traits.depth_label
    return f"{name}-{getattr(law, depth)}" if depth else name


@dataclass
class Run:
    """One (scenario, law) run: its row and the trajectories the figures draw.

    ``positions`` is the camera's origin in B (N, 3); ``directions`` maps
    ``"centre"``, ``"b"`` and each IBVS point's name to its unit direction in
    C (N, 3), the image sphere's view of it.
    """

    row: dict
    times: np.ndarray
    positions: np.ndarray
    directions: dict[str, np.ndarray]


@dataclass
class CompareResult:
    """Every law's run on every scenario of ``suite``, on the plant named ``plant``."""

    suite: SuiteConfig
    plant: str
    runs: list[Run] = field(default_factory=list)
    wall_time_s: float = 0.0
    #: The laws compared (:func:`compared_laws`).
    laws: tuple[LawConfig, ...] = COMPARED_LAWS

    @property
    def rows(self) -> list[dict]:
        """One table row per run (the columns of table.csv)."""
        return [r.row for r in self.runs]


def suite_cases(
    suite: SuiteConfig,
    plant: PlantConfig | None = None,
    duration: float | None = None,
    base: ScenarioConfig | None = None,
) -> list[tuple[str, str, ScenarioConfig]]:
    """``(scenario, law, config)`` for every scenario and law, in table order, on
    ``plant`` (default: ``base``'s); the laws are :func:`compared_laws`."""
    if plant is not None and type(plant) not in PLANT_VARIANTS.values():
        raise ValueError(f"plant must be Dynamic() or Kinematic(), got {plant!r}")
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be finite and > 0 [s]: duration = {duration}")
    cases = []
    for scenario in suite.scenarios:
        for law in compared_laws(base):
            config = copy.deepcopy(base) if base is not None else ScenarioConfig()
            config.controller = copy.deepcopy(law)
            if plant is not None:
                config.plant = copy.deepcopy(plant)
            config.initial = scenario.initial()
            if scenario.moving_target:  # a still entry keeps the base's target
                config.target_motion = copy.deepcopy(scenario.target_motion)
            config.initial_velocity = [0.0] * 6
            config.duration = suite.duration if duration is None else duration
            config.validate()
            cases.append((scenario.name, law_label(law), config))
    return cases


def _directions(P_C: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return P_C / np.linalg.norm(P_C, axis=-1, keepdims=True)


def run_case(scenario: str, law: str, config: ScenarioConfig) -> Run:
    """Simulate one (scenario, law) and measure its row (see the module)."""
    result = simulate(config)
    summary = result.summary()
    X_BC = result.X_BC
    R_CB = np.swapaxes(X_BC[:, :3, :3], 1, 2)
    p_CB = -np.einsum("nij,nj->ni", R_CB, X_BC[:, :3, 3])
    centre = _directions(p_CB)
    axis_angle = np.degrees(np.arccos(np.clip(centre[:, 2], -1.0, 1.0)))
    P_B = target_points(config.radius, DEFAULT_SQUARE_SIDE * config.radius)
    cos_theta = math.cos(config.domain.to_domain().fov_half_angle)
    points = np.stack([points_in_camera(R, p, P_B) for R, p in zip(R_CB, p_CB, strict=True)])
    point_margin = float(np.min([point_fov_margins(P, cos_theta) for P in points]))
    b = points[:, 0, :]  # the first IBVS point is the marked point b
    if config.controller.traits.feature_points:
        in_view = point_margin >= 0
    else:
        in_view = summary["min_fov_margin"] >= 0 and summary["min_visibility"] > 0
    row = {
        "scenario": scenario,
        "law": law,
        "plant": variant_name(config.plant),
        "status": result.status,
        "t_converged_s": result.convergence_time,
        "path_length_m": float(np.sum(np.linalg.norm(np.diff(X_BC[:, :3, 3], axis=0), axis=1))),
        "max_axis_angle_deg": float(np.nanmax(axis_angle)),
        "min_fov_margin": summary["min_fov_margin"],
        "min_lambda_margin": summary["min_lambda_margin"],
        "min_occlusion_margin": summary["min_occlusion_margin"],
        "min_visibility": summary["min_visibility"],
        "min_point_fov_margin": point_margin,
        "features_in_view": bool(in_view),
        "final_position_error_m": summary["final_position_error_m"],
        "final_rotation_error_rad": summary["final_rotation_error_rad"],
        "sim_time_s": result.sim_time_s,
        "wall_time_s": result.wall_time_s,
        "message": result.message,
    }
    if config.moving_target:
        row["steady_tracking_error_m"] = result.steady_tracking_error
    for name in ROTOR_FIELDS:  # a carrier with rotors reports them (its run entries)
        if name in summary:
            row[name] = summary[name]
    directions = {"centre": centre, "b": _directions(b)}
    for k, name in enumerate(TARGET_POINT_NAMES):
        directions[name] = _directions(points[:, k, :])
    return Run(row, result.times, X_BC[:, :3, 3].copy(), directions)


def _run_case(config: ScenarioConfig, scenario: str, law: str) -> Run:
    return run_case(scenario, law, config)


def still_entries_for(suite: SuiteConfig, base: ScenarioConfig | None) -> SuiteConfig:
    """``suite`` for ``base``'s carrier: all of it on the free rig; only its still-target
    entries elsewhere: the fixed camera cannot run a moving target
    (:meth:`ScenarioConfig.validate` says why), and the moving entry's target (a 0.25 m
    circle at 0.2 rad/s about the free rig's goal) is not one an arm's workspace holds
    (an arm tracks the slow circle of docs/moving-target.md), nor one a carrier that
    follows translating targets only takes (the quadrotor: its traits'
    ``turning_target``), so that the shipped suite's moving entry does not refuse or
    spoil the whole comparison there."""
    carrier = base.carrier if base is not None else ScenarioConfig().carrier
    traits = carrier.traits
    # No workspace to leave, and the suite's moving entry (a circle) turns.
    if traits.moving_target and traits.turning_target and not traits.joints:
        return suite
    kept = [entry for entry in suite.scenarios if not entry.moving_target]
    conundrum = suite.conundrum if suite.conundrum in {e.name for e in kept} else ""
    return dataclasses.replace(suite, scenarios=kept, conundrum=conundrum)


def run_compare(
    suite: SuiteConfig,
    plant: PlantConfig | None = None,
    workers: int = 2,
    duration: float | None = None,
    base: ScenarioConfig | None = None,
    on_run: Callable[[Run], None] | None = None,
) -> CompareResult:
    """Every law of :func:`compared_laws` on every scenario of ``suite`` on ``plant``
    (default: ``base``'s).

    ``workers`` processes (1: in this process; more use multiprocessing's
    spawn, so a script that calls this needs the ``if __name__ == "__main__":``
    guard); ``duration`` overrides the
    suite's; ``base`` is the scenario the starts are put into (default: the
    default scenario). ``on_run`` is called with each finished run. The runs
    come back in table order whatever the workers do.
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    suite.validate()
    suite = still_entries_for(suite, base)
    cases = suite_cases(suite, plant, duration, base)
    start = time.perf_counter()
    runs: list[Run | None] = [None] * len(cases)
    tasks = [(config, name, law) for name, law, config in cases]
    for i, run in enumerate(map_scenarios(_run_case, tasks, workers)):
        runs[i] = run
        if on_run:
            on_run(run)
    name = variant_name(cases[0][2].plant) if cases else variant_name(plant or Dynamic())
    laws = compared_laws(base)
    return CompareResult(suite, name, list(runs), time.perf_counter() - start, laws)


# --------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------
def _cell(value: object, digits: int = 3) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if math.isnan(value):
            return ""
        return f"{value:.{digits}g}"
    return str(value)


#: The markdown table's columns: (heading, row field, significant digits).
_MD_COLUMNS = (
    ("scenario", "scenario", 0),
    ("law", "law", 0),
    ("status", "status", 0),
    ("t conv. [s]", "t_converged_s", 3),
    ("path [m]", "path_length_m", 3),
    ("max axis angle [deg]", "max_axis_angle_deg", 3),
    ("min fov", "min_fov_margin", 2),
    ("min lambda", "min_lambda_margin", 2),
    ("min occl.", "min_occlusion_margin", 2),
    ("min points fov", "min_point_fov_margin", 2),
    ("features in view", "features_in_view", 0),
)
#: The columns a moving target adds to the markdown table (:data:`TRACKING_FIELDS`).
_MD_TRACKING_COLUMNS = (("steady tracking error [m]", "steady_tracking_error_m", 3),)
#: The columns a carrier with rotors adds to the markdown table (:data:`ROTOR_FIELDS`).
_MD_ROTOR_COLUMNS = (
    ("peak tilt [deg]", "max_tilt_deg", 3),
    ("saturated", "rotor_saturation_fraction", 2),
)


def markdown_table(rows: Sequence[dict]) -> str:
    """The rows as a GitHub markdown table (the columns of :data:`_MD_COLUMNS`, and a
    moving target's where a row has them; a still target's row leaves them empty)."""
    fields = row_fields(rows)
    columns = _MD_COLUMNS + (_MD_TRACKING_COLUMNS if TRACKING_FIELDS[0] in fields else ())
    columns += _MD_ROTOR_COLUMNS if ROTOR_FIELDS[0] in fields else ()
    lines = [
        "| " + " | ".join(h for h, _, _ in columns) + " |",
        "|" + "---|" * len(columns),
    ]
    for row in rows:
        cells = [_cell(row.get(key, ""), digits or 3) for _, key, digits in columns]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def status_matrix(rows: Sequence[dict]) -> str:
    """Scenarios x laws as a markdown table: the time to converge, or how the run ended
    (``left D (face, t)`` naming the margin that went negative, ``lost view (t)``,
    ``not converged``, ``non_finite (t)``)."""
    laws = list(dict.fromkeys(r["law"] for r in rows))
    scenarios = list(dict.fromkeys(r["scenario"] for r in rows))
    cells = {}
    for r in rows:
        status, t = r["status"], r["sim_time_s"]
        if status == "converged":
            text = f"{r['t_converged_s']:.1f} s"
        elif status == "left_domain" and "margin" in r["message"]:
            face = r["message"].split(":", 1)[1].split("margin")[0].strip()
            text = f"left D ({face}, {t:.2f} s)"
        elif status == "lost_visibility":
            text = f"lost view ({t:.2f} s)"
        elif status == "not_converged":
            text = "not converged"
        else:
            text = f"{status} ({t:.2g} s)"
        cells[r["scenario"], r["law"]] = text
    lines = ["| scenario | " + " | ".join(laws) + " |", "|---|" + "---|" * len(laws)]
    for name in scenarios:
        lines.append(f"| {name} | " + " | ".join(cells.get((name, law), "") for law in laws) + " |")
    return "\n".join(lines) + "\n"


def write_tables(result: CompareResult, out_dir: str | Path) -> tuple[Path, Path]:
    """``DIR/table.md`` (:func:`status_matrix`, the table, then the message of each run
    that did not converge) and ``DIR/table.csv`` (every field of :func:`row_fields`)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md = out / "table.md"
    notes = [
        f"* {r['scenario']}, {r['law']}: {r['message']}"
        for r in result.rows
        if r["status"] not in ("converged",)
    ]
    md.write_text(
        f"# geovs-drake compare: {result.plant} plant, {len(result.suite.scenarios)} scenarios "
        f"x {len(result.laws)} laws, {result.suite.duration:g} s each\n\n"
        + "Time to converge, or how the run ended:\n\n"
        + status_matrix(result.rows)
        + "\nEvery run:\n\n"
        + markdown_table(result.rows)
        + ("\nRuns that did not converge:\n\n" + "\n".join(notes) + "\n" if notes else "")
    )
    path = out / "table.csv"
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=row_fields(result.rows), restval="")
        writer.writeheader()
        for row in result.rows:
            writer.writerow({k: ("" if _is_nan(v) else v) for k, v in row.items()})
    return md, path


def _is_nan(value: object) -> bool:
    return isinstance(value, float) and math.isnan(value)


# --------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------
#: Colour and line style per image-sphere trajectory.
_IMAGE_STYLES = {
    "centre": ("k", "-"),
    "b": ("C3", "-"),
    TARGET_POINT_NAMES[1]: ("C0", "--"),
    TARGET_POINT_NAMES[2]: ("C2", "--"),
    TARGET_POINT_NAMES[3]: ("C1", "--"),
}


def plot_compare(result: CompareResult, out_dir: str | Path) -> list[Path]:
    """``image_sphere_<conundrum>.png``: per law, the image-sphere trajectories of the
    target's centre, the marked point and the four IBVS points on the conundrum
    scenario (orthographic view of the unit sphere along the optical axis, the
    field-of-view circle drawn); ``camera_paths.png``: per scenario, the camera's
    3-D path in B for every law."""
    from geovs_drake.plotting import pyplot

    plt = pyplot()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    laws = [law_label(law) for law in result.laws]
    colours = {law: plt.get_cmap("tab10")(i) for i, law in enumerate(laws)}
    theta = None
    conundrum = result.suite.conundrum or result.suite.scenarios[0].name
    runs = [r for r in result.runs if r.row["scenario"] == conundrum]
    if runs:
        fig, axes = plt.subplots(
            2, math.ceil(len(runs) / 2), figsize=(4 * math.ceil(len(runs) / 2), 8)
        )
        theta = math.radians(ScenarioConfig().domain.fov_half_angle_deg)
        for ax, run in zip(np.ravel(axes), runs, strict=False):
            circle = np.linspace(0, 2 * math.pi, 200)
            ax.plot(
                math.sin(theta) * np.cos(circle), math.sin(theta) * np.sin(circle), "k:", lw=0.8
            )
            for name, d in run.directions.items():
                colour, ls = _IMAGE_STYLES.get(name, ("0.5", "--"))
                ax.plot(d[:, 0], d[:, 1], color=colour, ls=ls, lw=1.2, label=name)
                ax.plot(d[0, 0], d[0, 1], "o", color=colour, ms=4)
                ax.plot(d[-1, 0], d[-1, 1], "x", color=colour, ms=6)
            ax.set_title(f"{run.row['law']}: {run.row['status']}", fontsize=10)
            ax.set_aspect("equal")
            lim = 1.15 * math.sin(theta)
            ax.set_xlim(-lim, lim)
            ax.set_ylim(-lim, lim)
            ax.set_xlabel("x of the direction in C")
            ax.set_ylabel("y of the direction in C")
        np.ravel(axes)[0].legend(fontsize=7, loc="lower left")
        fig.suptitle(
            f"{conundrum} ({result.plant} plant): image-sphere trajectories, o start, x end; "
            "dotted: the field of view"
        )
        fig.tight_layout()
        path = out / f"image_sphere_{conundrum}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    names = [s.name for s in result.suite.scenarios]
    cols = min(4, len(names))
    rows = math.ceil(len(names) / cols)
    fig = plt.figure(figsize=(4.5 * cols, 4.2 * rows))
    for i, name in enumerate(names):
        ax = fig.add_subplot(rows, cols, i + 1, projection="3d")
        for run in result.runs:
            if run.row["scenario"] != name:
                continue
            p = run.positions
            ax.plot(p[:, 0], p[:, 1], p[:, 2], color=colours[run.row["law"]], label=run.row["law"])
            ax.plot([p[-1, 0]], [p[-1, 1]], [p[-1, 2]], "x", color=colours[run.row["law"]])
        u, v = np.meshgrid(np.linspace(0, 2 * math.pi, 16), np.linspace(0, math.pi, 9))
        rho = ScenarioConfig().radius
        ax.plot_wireframe(
            rho * np.cos(u) * np.sin(v),
            rho * np.sin(u) * np.sin(v),
            rho * np.cos(v),
            lw=0.3,
            color="0.6",
        )
        # Equal scales on the three axes, so that the sphere is round.
        points = np.concatenate(
            [r.positions for r in result.runs if r.row["scenario"] == name] + [np.eye(3) * rho]
        )
        centre = (points.max(axis=0) + points.min(axis=0)) / 2
        half = max(float(np.max(points.max(axis=0) - points.min(axis=0))) / 2, rho)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("x_B [m]")
        ax.set_ylabel("y_B [m]")
        ax.set_zlabel("z_B [m]")
        if i == 0:
            ax.legend(fontsize=7)
    fig.suptitle(f"camera paths in the target frame B ({result.plant} plant); x: end")
    fig.tight_layout()
    path = out / "camera_paths.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path)
    return written


def summarize(result: CompareResult, files: Sequence[Path] = ()) -> dict:
    """The comparison as JSON-ready values: counts per status, per law the scenarios
    it converged on, the rows, the files written."""
    counts: dict[str, int] = {}
    converged: dict[str, list[str]] = {law_label(law): [] for law in result.laws}
    for row in result.rows:
        counts[row["status"]] = counts.get(row["status"], 0) + 1
        if row["status"] == "converged":
            converged[row["law"]].append(row["scenario"])
    rows = [{k: (None if _is_nan(v) else v) for k, v in row.items()} for row in result.rows]
    return {
        "plant": result.plant,
        "scenarios": [s.name for s in result.suite.scenarios],
        "laws": list(converged),
        "duration": result.suite.duration,
        "counts": counts,
        "converged": converged,
        "wall_time_s": result.wall_time_s,
        "files": [str(f) for f in files],
        "rows": rows,
    }


def compare(
    suite_path: str | Path | None = None,
    plant: PlantConfig | None = None,
    out_dir: str | Path = "results/compare",
    workers: int = 2,
    duration: float | None = None,
    on_run: Callable[[Run], None] | None = None,
    base: ScenarioConfig | None = None,
) -> tuple[CompareResult, list[Path]]:
    """The whole command: load the suite, run it, write the tables and the figures.

    ``base``: the scenario the starts are put into, as in :func:`run_compare`;
    ``suite_path`` None: :func:`default_suite` for its carrier.

    Returns the result and the files written; figures are skipped (not an
    error) when matplotlib is not installed.
    """
    suite = load_suite(default_suite(base) if suite_path is None else suite_path)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a directory")
    result = run_compare(suite, plant, workers, duration, base=base, on_run=on_run)
    written = list(write_tables(result, out))
    try:
        written += plot_compare(result, out)
    except ImportError:
        pass
    return result, written
