"""A sweep's summary, merged from its parts: the client's memory does not grow with N.

Each task summarises its own rows (:meth:`SweepSummary.of_rows`) and the client
adds the summaries up (:meth:`SweepSummary.merge`): counts add, minima and
maxima combine, and the convergence times go into a fixed histogram of
:data:`TIME_BINS` bins on [0, duration]. A quantile read from it
(:meth:`SweepSummary.quantile`) is the midpoint of the bin that holds the
sample at rank ceil(q N) (numpy's ``inverted_cdf``), so it is within half a
bin, ``duration / (2 TIME_BINS)``, of the exact one: 0.5 ms for a 10-s sweep.
The maximum is kept exactly.

Each run's end is classified (:func:`run_ends`) and counted: converged; on the arm, a
run not converged whose joints have come to rest (:data:`STALL_SPEED`) has *stalled*,
at a spurious equilibrium of the barrier and the NF where the joint barrier is active
(``barrier_stall``: phi_q > 0), elsewhere otherwise (``stalled``), and one whose joints
still turn is ``moving``; the other statuses (joint limit, left D, ...) are their own.

The starts plot is drawn from the summary too: counts on a grid of distance
``|p_BC|`` (log bins over D's distance range) by the yaw of X_BC, for all starts,
those not converged and those that failed, and the :data:`SLOWEST` slowest
starts as points.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from geovs_drake.batch import STATUS_NAMES
from geovs_drake.scenario import ScenarioConfig

__all__ = [
    "ARM_STATUSES",
    "DISTANCE_BINS",
    "ENDS",
    "FAILED",
    "SLOWEST",
    "STALL_SPEED",
    "TIME_BINS",
    "YAW_BINS",
    "SweepSummary",
    "plot_summary",
    "run_ends",
]

#: Bins of the convergence-time histogram on [0, duration] (module docstring: the
#: quantiles' bound). 10^4 int64 counts: 80 kB a summary, whatever N.
TIME_BINS = 10_000
#: The slowest converged starts kept (time, distance, yaw) for the starts plot.
SLOWEST = 20
#: Grid of the starts plot: log-spaced distance bins, uniform yaw bins on [-pi, pi].
DISTANCE_BINS = 48
YAW_BINS = 48
#: Statuses that count as a failure: neither converged nor still on the way (on the arm
#: also its ``joint_limit``; an ``unreachable`` start never ran and is neither).
FAILED = ("left_domain", "lost_visibility", "non_finite")
#: The arm's own statuses (the Drake engine): a joint left its range, IK found no joints;
#: the first is a failure like FAILED's.
ARM_STATUSES = ("joint_limit", "unreachable")
_ARM_FAILED = ARM_STATUSES[:1]
#: A run not converged whose fastest joint turns slower than this at the end [rad/s] has
#: stalled (:func:`run_ends`). Measured on the UR5 under the NF (30 s runs, docs/arm.md
#: "The barrier's spurious equilibria"): the 44 runs held by the barrier ended below
#: 5e-7 rad/s, the 28 still on their way (1 to 6 mm off the goal) above 4e-3; the bound
#: sits between, a factor 40 from each. A run that nears its equilibrium slowly is still
#: ``moving`` at a short horizon: the count depends on the duration.
STALL_SPEED = 1e-4
#: The ends :func:`run_ends` adds to the statuses, in the order they are reported.
ENDS = ("converged", "barrier_stall", "stalled", "moving")
#: The layers of the starts grid.
_GRID_LAYERS = ("all", "not_converged", "failed")


def run_ends(columns: dict) -> np.ndarray:
    """How each run ended (module docstring), from its row's columns: its status, but a
    run not converged becomes ``barrier_stall`` (its joints at rest, slower than
    :data:`STALL_SPEED`, with the joint barrier active, ``final_joint_barrier`` > 0),
    ``stalled`` (at rest, the barrier inactive) or ``moving``; it stays
    ``not_converged`` where the joints' speed is unknown (NaN: no arm)."""
    status = np.asarray(columns["status"], dtype=object)
    speed = np.asarray(columns["final_joint_speed"], float)
    barrier = np.asarray(columns["final_joint_barrier"], float)
    end = status.copy()
    open_ = status == "not_converged"
    still = open_ & (speed < STALL_SPEED)  # NaN compares False: unknown stays open
    end[still & (barrier > 0)] = "barrier_stall"
    end[still & ~(barrier > 0)] = "stalled"
    end[open_ & (speed >= STALL_SPEED)] = "moving"
    return end


def distance_edges(config: ScenarioConfig) -> np.ndarray:
    """Log-spaced ``|p_BC|`` bin edges over D's distance range, rho / lam_max to
    rho / lam_min (lambda = rho / |p_CB|), widened by 10 % on both sides."""
    lo = 0.9 * config.radius / config.domain.lam_max
    hi = 1.1 * config.radius / config.domain.lam_min
    return np.geomspace(lo, hi, DISTANCE_BINS + 1)


def yaw_edges() -> np.ndarray:
    """Uniform bin edges of the yaw of X_BC on [-pi, pi]."""
    return np.linspace(-math.pi, math.pi, YAW_BINS + 1)


def _bin(values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Bin index of each value; values outside go to the first or last bin."""
    return np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)


@dataclass
class SweepSummary:
    """The mergeable summary of a set of sweep rows (module docstring)."""

    duration: float
    distance_edges: np.ndarray
    finished: int = 0
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(STATUS_NAMES, 0))
    #: Starts the guarantee covers (``initial_energy_ratio`` < 1), and those of them
    #: that failed, by status.
    covered: int = 0
    covered_failed: dict[str, int] = field(default_factory=lambda: dict.fromkeys(FAILED, 0))
    #: How the runs ended (:func:`run_ends`), by end: :data:`ENDS`, then the other
    #: statuses present.
    ends: dict[str, int] = field(default_factory=dict)
    min_margins: dict[str, float] = field(
        default_factory=lambda: dict.fromkeys(("fov", "lambda", "occlusion"), math.inf)
    )
    max_energy_ratio: float = -math.inf
    monotone: int = 0
    t_histogram: np.ndarray = field(default_factory=lambda: np.zeros(TIME_BINS, np.int64))
    t_max: float = -math.inf
    #: (t_converged, distance, yaw) of the slowest converged starts, slowest first.
    slowest: list[tuple[float, float, float]] = field(default_factory=list)
    #: Counts on the starts grid, (3, DISTANCE_BINS, YAW_BINS): all, not converged, failed.
    grid: np.ndarray = field(
        default_factory=lambda: np.zeros((3, DISTANCE_BINS, YAW_BINS), np.int64)
    )
    #: A hovering carrier's rows (those with a ``rotor_saturation_fraction``): how many,
    #: how many saturated at all, the sum of their saturated fractions, the peak tilt [deg].
    hover_rows: int = 0
    saturated: int = 0
    saturation_sum: float = 0.0
    max_tilt_deg: float = -math.inf

    @classmethod
    def empty(cls, config: ScenarioConfig, duration: float) -> SweepSummary:
        """The summary of no rows, for ``config`` over ``duration`` seconds."""
        return cls(duration=float(duration), distance_edges=distance_edges(config))

    @classmethod
    def of_rows(cls, config: ScenarioConfig, duration: float, columns: dict) -> SweepSummary:
        """The summary of one part's rows, given as columns (name -> array)."""
        s = cls.empty(config, duration)
        status = np.asarray(columns["status"], dtype=object)
        n = len(status)
        s.finished = n
        # The arm's statuses on the arm (joint_limit, unreachable), and any other present.
        arm = config.carrier.traits.joints
        names = [*STATUS_NAMES, *(ARM_STATUSES if arm else ())]
        for name in (*names, *sorted(set(status) - set(names))):
            s.counts[name] = int(np.sum(status == name))
        failed = (*FAILED, *_ARM_FAILED) if arm else FAILED
        end = np.asarray(columns["end"], dtype=object) if "end" in columns else run_ends(columns)
        for name in (*ENDS, *sorted(set(end) - set(ENDS))):
            s.ends[name] = int(np.sum(end == name))
        covered = np.asarray(columns["initial_energy_ratio"], float) < 1
        s.covered = int(np.sum(covered))
        for name in failed:
            s.covered_failed[name] = int(np.sum(covered & (status == name)))
        for key, column in (
            ("fov", "min_fov_margin"),
            ("lambda", "min_lambda_margin"),
            ("occlusion", "min_occlusion_margin"),
        ):
            v = np.asarray(columns[column], float)
            v = v[np.isfinite(v)]
            s.min_margins[key] = float(np.min(v)) if len(v) else math.inf
        ratio = np.asarray(columns["max_energy_ratio"], float)
        ratio = ratio[np.isfinite(ratio)]
        s.max_energy_ratio = float(np.max(ratio)) if len(ratio) else -math.inf
        s.monotone = int(np.sum(np.asarray(columns["monotone"], bool)))
        converged = status == "converged"
        t = np.asarray(columns["t_converged"], float)[converged]
        width = s.duration / TIME_BINS
        index = np.clip((t / width).astype(np.int64), 0, TIME_BINS - 1)
        s.t_histogram = np.bincount(index, minlength=TIME_BINS).astype(np.int64)
        s.t_max = float(np.max(t)) if len(t) else -math.inf
        x, y, z = (np.asarray(columns[k], float) for k in ("x", "y", "z"))
        distance = np.sqrt(x * x + y * y + z * z)
        yaw = np.asarray(columns["yaw"], float)
        order = np.argsort(-t, kind="stable")[:SLOWEST]
        s.slowest = [
            (float(t[i]), float(distance[converged][i]), float(yaw[converged][i])) for i in order
        ]
        finite = np.isfinite(distance) & np.isfinite(yaw)
        cells = _bin(distance[finite], s.distance_edges), _bin(yaw[finite], yaw_edges())
        masks = (
            np.ones(n, bool),
            status == "not_converged",
            np.isin(status, failed),
        )
        for layer, mask in enumerate(masks):
            np.add.at(s.grid[layer], (cells[0][mask[finite]], cells[1][mask[finite]]), 1)
        if "rotor_saturation_fraction" in columns:
            s._add_hover(columns)
        return s

    def _add_hover(self, columns: dict) -> None:
        """A hovering carrier's figures of its rows (the runs that ran: a start stopped
        at t = 0 has NaN)."""
        fraction = np.asarray(columns["rotor_saturation_fraction"], float)
        ran = np.isfinite(fraction)
        self.hover_rows = int(np.sum(ran))
        self.saturated = int(np.sum(fraction[ran] > 0))
        self.saturation_sum = float(np.sum(fraction[ran]))
        tilt = np.asarray(columns["max_tilt_deg"], float)
        tilt = tilt[np.isfinite(tilt)]
        self.max_tilt_deg = float(np.max(tilt)) if len(tilt) else -math.inf

    def merge(self, other: SweepSummary) -> None:
        """Add ``other`` (the same sweep's settings) into this summary."""
        if other.duration != self.duration or other.t_histogram.shape != self.t_histogram.shape:
            raise ValueError("summaries of different sweeps do not merge")
        self.finished += other.finished
        for name, count in other.counts.items():
            self.counts[name] = self.counts.get(name, 0) + count
        self.covered += other.covered
        for name, count in other.covered_failed.items():
            self.covered_failed[name] = self.covered_failed.get(name, 0) + count
        for name, count in other.ends.items():
            self.ends[name] = self.ends.get(name, 0) + count
        for key in self.min_margins:
            self.min_margins[key] = min(self.min_margins[key], other.min_margins[key])
        self.max_energy_ratio = max(self.max_energy_ratio, other.max_energy_ratio)
        self.monotone += other.monotone
        self.t_histogram += other.t_histogram
        self.t_max = max(self.t_max, other.t_max)
        self.slowest = heapq.nlargest(SLOWEST, self.slowest + other.slowest)
        self.grid += other.grid
        self.hover_rows += other.hover_rows
        self.saturated += other.saturated
        self.saturation_sum += other.saturation_sum
        self.max_tilt_deg = max(self.max_tilt_deg, other.max_tilt_deg)

    def quantile(self, q: float) -> float | None:
        """The q-quantile of the converged starts' times, within duration / (2 TIME_BINS)
        of numpy's ``inverted_cdf`` quantile (module docstring); None with none."""
        n = int(self.t_histogram.sum())
        if n == 0:
            return None
        rank = max(1, math.ceil(q * n))
        b = int(np.searchsorted(np.cumsum(self.t_histogram), rank))
        return (b + 0.5) * self.duration / TIME_BINS

    # ------------------------------------------------------------- JSON (parts' metadata)
    def to_json(self) -> dict:
        """A JSON-ready dict (the histogram sparse: [bin, count] pairs) that
        :meth:`from_json` reads back exactly."""
        nonzero = np.flatnonzero(self.t_histogram)
        cells = np.argwhere(self.grid)
        return {
            "duration": self.duration,
            "distance_edges": self.distance_edges.tolist(),
            "finished": self.finished,
            "counts": self.counts,
            "covered": self.covered,
            "covered_failed": self.covered_failed,
            "ends": self.ends,
            "min_margins": {k: _finite_or_none(v) for k, v in self.min_margins.items()},
            "max_energy_ratio": _finite_or_none(self.max_energy_ratio),
            "monotone": self.monotone,
            "t_histogram": [[int(b), int(self.t_histogram[b])] for b in nonzero],
            "t_max": _finite_or_none(self.t_max),
            "slowest": [list(item) for item in self.slowest],
            "grid": [[*map(int, c), int(self.grid[tuple(c)])] for c in cells],
            "hover": [
                self.hover_rows,
                self.saturated,
                self.saturation_sum,
                _finite_or_none(self.max_tilt_deg),
            ],
        }

    @classmethod
    def from_json(cls, data: dict) -> SweepSummary:
        """The summary that :meth:`to_json` wrote."""
        s = cls(duration=float(data["duration"]), distance_edges=np.array(data["distance_edges"]))
        s.finished = int(data["finished"])
        s.counts = {k: int(v) for k, v in data["counts"].items()}
        s.covered = int(data["covered"])
        s.covered_failed = {k: int(v) for k, v in data["covered_failed"].items()}
        s.ends = {k: int(v) for k, v in data.get("ends", {}).items()}  # none in older parts
        s.min_margins = {k: math.inf if v is None else v for k, v in data["min_margins"].items()}
        ratio = data["max_energy_ratio"]
        s.max_energy_ratio = -math.inf if ratio is None else ratio
        s.monotone = int(data["monotone"])
        for b, count in data["t_histogram"]:
            s.t_histogram[b] = count
        s.t_max = -math.inf if data["t_max"] is None else data["t_max"]
        s.slowest = [tuple(item) for item in data["slowest"]]
        for layer, i, j, count in data["grid"]:
            s.grid[layer, i, j] = count
        rows, saturated, total, tilt = data.get("hover", (0, 0, 0.0, None))  # none: older parts
        s.hover_rows, s.saturated, s.saturation_sum = int(rows), int(saturated), float(total)
        s.max_tilt_deg = -math.inf if tilt is None else float(tilt)
        return s

    def report(self) -> dict:
        """The figures a user reads (the CLI's ``summary.json`` entries about the rows):
        counts, convergence-time quantiles, worst margins, the guarantee's counts."""
        quantiles = {
            "median": self.quantile(0.5),
            "p90": self.quantile(0.9),
            "p99": self.quantile(0.99),
            "max": _finite_or_none(self.t_max),
        }
        return {
            "finished": self.finished,
            "counts": dict(self.counts),
            "ends": dict(self.ends),
            "t_converged_s": quantiles,
            "t_converged_resolution_s": self.duration / (2 * TIME_BINS),
            "worst_margins": {k: _finite_or_none(v) for k, v in self.min_margins.items()},
            "max_energy_ratio": _finite_or_none(self.max_energy_ratio),
            "monotone": self.monotone,
            "starts_below_energy_bound": self.covered,
            "guarantee": {"starts": self.covered, **self.covered_failed},
            **({"hover": self.hover_report()} if self.hover_rows else {}),
        }

    def hover_report(self) -> dict:
        """A hovering carrier's figures (``report()``'s ``hover``, only where its rows
        have them): the fractions of the finished starts converged, left D and with any
        rotor saturation, the mean saturated fraction of the logged samples over the runs,
        and the peak tilt [deg]."""
        n = max(self.finished, 1)
        return {
            "converged": self.counts.get("converged", 0) / n,
            "left_domain": self.counts.get("left_domain", 0) / n,
            "not_converged": self.counts.get("not_converged", 0) / n,
            "saturated": self.saturated / n,
            "mean_saturation_fraction": self.saturation_sum / max(self.hover_rows, 1),
            "max_tilt_deg": _finite_or_none(self.max_tilt_deg),
        }


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


#: The two figures' margins (fractions of the figure): room for the labels, the title and,
#: below the starts' axes, their legend.
_MARGINS_T = dict(left=0.13, right=0.97, bottom=0.13, top=0.92)
_MARGINS_STARTS = dict(left=0.12, right=0.97, bottom=0.2, top=0.93)


def plot_summary(summary: SweepSummary, plant: str, out_dir: str | Path) -> list[str]:
    """``t_converged.png`` and ``starts.png`` in ``out_dir`` from a merged summary;
    the file names written.

    ``starts.png`` shows the starts on a slice of D: distance ``|p_BC|`` against the yaw
    of X_BC, which at the goal's orientation is the roll about the optical axis (the
    hard direction: near pi the arrow points the wrong way, the NF's saddle). Cells
    with a start not converged or failed are marked, and the slowest starts circled.
    Each legend label counts its starts: a marker listed with none says "(0)".
    """
    from geovs_drake.plotting import pyplot

    plt = pyplot()
    out = Path(out_dir)
    s = summary
    converged = s.counts["converged"]

    # 50 display bins from the fine histogram: sums of whole fine bins.
    fig, ax = plt.subplots(figsize=(6, 4))
    coarse = s.t_histogram.reshape(50, -1).sum(axis=1)
    edges = np.linspace(0.0, s.duration, 51)
    ax.stairs(coarse, edges, fill=True)
    ax.set_xlabel("convergence time [s]")
    ax.set_ylabel("starts")
    ax.set_title(f"{converged} of {s.finished} starts converged ({plant})")
    # Fixed margins, not tight_layout: its text extents were two thirds of the drawing's
    # time (docs/performance.md, The sweep's start-up), and these labels do not change.
    fig.subplots_adjust(**_MARGINS_T)
    fig.savefig(out / "t_converged.png", dpi=120)
    plt.close(fig)

    d_edges, y_edges = s.distance_edges, yaw_edges()
    d_mid = np.sqrt(d_edges[:-1] * d_edges[1:])
    y_mid = 0.5 * (y_edges[:-1] + y_edges[1:])
    fig, ax = plt.subplots(figsize=(6.5, 5))
    counts = np.where(s.grid[0] > 0, s.grid[0], np.nan)
    ax.pcolormesh(d_edges, y_edges, counts.T, cmap="Greys", shading="flat")
    ax.scatter([], [], s=20, c="0.6", marker="s", label=f"start ({s.finished})")
    not_converged = np.argwhere(s.grid[1] > 0)
    ax.scatter(
        d_mid[not_converged[:, 0]],
        y_mid[not_converged[:, 1]],
        s=12,
        c="tab:orange",
        label=f"not converged ({s.counts['not_converged']})",
    )
    slowest = np.array(s.slowest).reshape(-1, 3)
    ax.scatter(
        slowest[:, 1],
        slowest[:, 2],
        s=30,
        facecolors="none",
        edgecolors="b",
        label=f"{len(slowest)} slowest",
    )
    failed = np.argwhere(s.grid[2] > 0)
    ax.scatter(
        d_mid[failed[:, 0]],
        y_mid[failed[:, 1]],
        s=30,
        c="r",
        marker="x",
        label=f"left D / failed ({sum(s.counts.get(k, 0) for k in (*FAILED, *_ARM_FAILED))})",
    )
    ax.set_xscale("log")
    ax.set_xlabel("distance |p_BC| [m]")
    ax.set_ylabel("yaw of X_BC (roll about the optical axis) [rad]")
    ax.set_title(f"{s.finished} starts ({plant}): cells with failed and slow starts marked")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=4, fontsize=8)
    fig.subplots_adjust(**_MARGINS_STARTS)
    fig.savefig(out / "starts.png", dpi=120)
    plt.close(fig)
    return ["t_converged.png", "starts.png"]
