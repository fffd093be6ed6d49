"""Matplotlib figures: navigation-function slices and closed-loop runs.

matplotlib is imported lazily (it is an optional dependency, the
``notebooks`` extra), with the non-interactive Agg backend when no display
backend has been chosen.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from geovs_drake.geometry.navigation import (
    ModelCoordinates,
    NavigationFunction,
    features_from_model,
    model_coordinates,
)

__all__ = [
    "plot_camera_frames",
    "plot_image_view",
    "plot_navigation_slices",
    "pyplot",
    "plot_run",
    "plot_root_locus",
    "plot_sensor_comparison",
    "write_block_diagram",
]


def pyplot():
    """matplotlib's pyplot on a non-interactive backend (Agg) unless a notebook's inline one
    is active: the one place the package picks a backend."""
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _slice(nf: NavigationFunction, m0: ModelCoordinates, field: str, values: np.ndarray):
    n = len(values)
    m = ModelCoordinates(
        np.full(n, float(m0.u)),
        np.tile(np.asarray(m0.w_fov, float), (n, 1)),
        np.tile(np.asarray(m0.w_occ, float), (n, 1)),
        np.tile(np.asarray(m0.circle, float), (n, 1)),
    )
    if field == "u":
        m = m._replace(u=values)
    elif field == "circle":
        a0 = np.arctan2(m0.circle[1], m0.circle[0])
        m = m._replace(circle=np.stack([np.cos(a0 + values), np.sin(a0 + values)], -1))
    else:
        w = np.zeros((n, 2))
        w[:, 0] = values
        m = m._replace(**{field: w})
    y = features_from_model(m, nf.domain)
    return y, nf.value(y)


def plot_navigation_slices(nf: NavigationFunction, path: str | Path | None = None):
    """phi along one-parameter slices through y*, one per factor of D, plus a 2-D slice.

    Each slice moves one model coordinate from the goal to both faces of D
    (or once around the circle) and plots phi against the physical quantity.
    Returns the figure; saves a PNG when ``path`` is given.
    """
    plt = pyplot()
    m0 = model_coordinates(nf.goal, nf.domain)
    t = np.linspace(-0.999999, 0.999999, 801)
    fig, axes = plt.subplots(2, 3, figsize=(13, 7.5))
    ax = axes[0, 0]
    y, phi = _slice(nf, m0, "u", t)
    ax.plot(y.lam, phi)
    ax.axvline(float(nf.goal.lam), ls=":", c="k")
    ax.set(xlabel="lambda = rho / |d|", ylabel="phi", title="distance (lambda) slice")
    ax = axes[0, 1]
    y, phi = _slice(nf, m0, "w_fov", t)
    ax.plot(np.degrees(np.arctan2(y.s[:, 0], y.s[:, 2])), phi)
    ax.set(xlabel="angle of s from e3 in the x-z plane [deg]", title="field-of-view slice")
    ax = axes[0, 2]
    y, phi = _slice(nf, m0, "w_occ", t)
    ang = np.degrees(np.arccos(np.clip(np.sum(y.q1 * y.s, -1), -1, 1))) * np.sign(t)
    ax.plot(ang, phi)
    ax.set(xlabel="signed angle between q1 and s [deg]", title="occlusion slice")
    ax = axes[1, 0]
    a = np.linspace(-np.pi, np.pi, 721)
    y, phi = _slice(nf, m0, "circle", a)
    ax.plot(np.degrees(a), phi)
    ax.axhline(nf.gains.circle_weight, ls=":", c="r", label="saddle value c_w")
    # Named beside the line, between the curve's arms (a legend box this wide covered
    # the line or the curve wherever it went).
    ax.text(
        0.0, nf.gains.circle_weight - 0.03, "saddle value c_w", color="r", ha="center", va="top"
    )
    ax.set(xlabel="roll of q2 about q1 from the goal [deg]", ylabel="phi", title="circle slice")
    # 2-D: lambda against roll, through the goal and the saddle.
    ax = axes[1, 1]
    uu, aa = np.meshgrid(np.linspace(-0.999, 0.999, 161), np.linspace(-np.pi, np.pi, 181))
    n = uu.size
    a0 = np.arctan2(m0.circle[1], m0.circle[0])
    m = ModelCoordinates(
        uu.ravel(),
        np.tile(np.asarray(m0.w_fov, float), (n, 1)),
        np.tile(np.asarray(m0.w_occ, float), (n, 1)),
        np.stack([np.cos(a0 + aa.ravel()), np.sin(a0 + aa.ravel())], -1),
    )
    y = features_from_model(m, nf.domain)
    phi = nf.value(y).reshape(uu.shape)
    cs = ax.contourf(y.lam.reshape(uu.shape), np.degrees(aa), phi, levels=np.linspace(0, 1, 21))
    fig.colorbar(cs, ax=ax, label="phi")
    # The goal (roll 0) and the saddle (roll 180 deg, on the plot's edge: not clipped).
    ax.plot([float(nf.goal.lam)] * 2, [0, 180], "w*", ms=10, clip_on=False, zorder=5)
    ax.set(xlabel="lambda", ylabel="roll [deg]", title="phi over (lambda, roll): min and saddle")
    # 2-D: the two discs' x coordinates.
    ax = axes[1, 2]
    g1, g2 = np.meshgrid(np.linspace(-0.999, 0.999, 161), np.linspace(-0.999, 0.999, 161))
    n = g1.size
    m = ModelCoordinates(
        np.full(n, float(m0.u)),
        np.stack([g1.ravel(), np.zeros(n)], -1),
        np.stack([g2.ravel(), np.zeros(n)], -1),
        np.tile(np.asarray(m0.circle, float), (n, 1)),
    )
    y = features_from_model(m, nf.domain)
    phi = nf.value(y).reshape(g1.shape)
    cs = ax.contourf(g1, g2, phi, levels=np.linspace(0, 1, 21))
    fig.colorbar(cs, ax=ax, label="phi")
    ax.set(xlabel="FOV disc coordinate w_fov,x", ylabel="occlusion disc coordinate w_occ,x")
    ax.set_title("phi over the two discs")
    for a in axes[0]:
        a.set_ylim(-0.02, 1.02)
        a.grid(alpha=0.3)
    axes[1, 0].grid(alpha=0.3)
    fig.suptitle("Navigation function phi on D: slices through the goal y*")
    fig.tight_layout()
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110)
    return fig


def _gnomonic(u: np.ndarray) -> np.ndarray:
    """Image-plane coordinates (u_x / u_z, u_y / u_z) of unit directions (N, 3)."""
    return u[..., :2] / u[..., 2:3]


def _silhouette(s: np.ndarray, lam: float, n: int = 200) -> np.ndarray:
    """Directions on the silhouette circle: angle arcsin(lambda) about s."""
    a = np.cross(s, [1.0, 0, 0] if abs(s[0]) < 0.9 else [0, 1.0, 0])
    m1 = a / np.linalg.norm(a)
    m2 = np.cross(s, m1)
    t = np.linspace(0, 2 * np.pi, n)
    g = np.arcsin(lam)
    return np.cos(g) * s + np.sin(g) * (np.cos(t)[:, None] * m1 + np.sin(t)[:, None] * m2)


def plot_image_view(result, path: str | Path | None = None, snapshots: int = 8):
    """What the camera sees: silhouettes, q1 and the q2 arrow over time (gnomonic view)."""
    plt = pyplot()
    from geovs_drake.geometry.camera import ImageFeatures

    y = ImageFeatures.from_vector(result.image_features)
    goal = result.config.goal_features()
    theta = np.radians(result.config.domain.fov_half_angle_deg)
    fig, ax = plt.subplots(figsize=(9, 7))
    a = np.linspace(0, 2 * np.pi, 400)
    ax.plot(
        np.tan(theta) * np.cos(a), np.tan(theta) * np.sin(a), "k-", lw=1.5, label="FOV boundary"
    )
    cmap = plt.get_cmap("viridis")
    idx = np.unique(np.geomspace(1, len(y.lam), snapshots).astype(int) - 1)
    for k, i in enumerate(idx):
        c = cmap(k / max(1, len(idx) - 1))
        sil = _gnomonic(_silhouette(y.s[i], float(y.lam[i])))
        ax.plot(sil[:, 0], sil[:, 1], color=c, lw=1.2, label=f"t = {result.times[i]:.3g} s")
        q1 = _gnomonic(y.q1[i][None])[0]
        tip = _gnomonic((y.q1[i] + 0.04 * y.q2[i])[None])[0]
        ax.annotate("", tip, q1, arrowprops=dict(arrowstyle="->", color=c, lw=1.5))
        ax.plot(*q1, "o", color=c, ms=4)
    q1_path = _gnomonic(y.q1)
    ax.plot(q1_path[:, 0], q1_path[:, 1], ":", color="tab:red", lw=1, label="q1 path")
    sil = _gnomonic(_silhouette(goal.s, float(goal.lam)))
    ax.plot(sil[:, 0], sil[:, 1], "r--", lw=1.5, label="goal silhouette")
    ax.set_aspect("equal")
    lim = 1.1 * np.tan(theta)
    ax.set(xlim=(-lim, lim), ylim=(-lim, lim), xlabel="u_x / u_z", ylabel="u_y / u_z")
    ax.set_title("Image (gnomonic projection): silhouette, q1 and the q2 arrow")
    # Beside the image, not on it: inside, it hid a stretch of the FOV boundary.
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def plot_run(result, path: str | Path | None = None):
    """phi and the energy, every domain margin, and the pose error over time."""
    plt = pyplot()
    from pydrake.math import RigidTransform

    from geovs_drake.geometry.domain import DomainMargins
    from geovs_drake.simulation import pose_error

    t = result.times
    fig, axes = plt.subplots(3, 1, figsize=(9, 10), sharex=True)
    ax = axes[0]
    ax.plot(t, result.phi, label="phi")
    if result.energy is not None:
        ax.plot(t, result.energy, label="E = 1/2 nu^T M nu + k_p phi")
    plant = result.summary()["plant"]
    ax.set(ylabel="Lyapunov", yscale="log", title=f"{plant} loop: {result.message}")
    ax.legend()
    ax = axes[1]
    for k, name in enumerate(DomainMargins._fields):
        ax.plot(t, result.margins[:, k], label=f"{name} margin")
    # Margins are positive inside D; a log axis shows the small occlusion margin
    # (a fraction of the cap width ~ lambda^2 / 2) beside the others.
    ax.set(ylabel="margin (> 0 inside D)", yscale="log", title="safe-domain margins")
    ax.legend(fontsize=8)
    ax = axes[2]
    goal = result.config.X_BC_goal
    err = np.array([pose_error(RigidTransform(X), goal) for X in result.X_BC])
    ax.semilogy(t, err[:, 0], label="position error [m]")
    ax.semilogy(t, err[:, 1], label="rotation error [rad]")
    ax.axhline(1e-3, color="k", ls=":", lw=0.8, label="1 mm / 1 mrad")
    ax.set(xlabel="t [s]", ylabel="pose error", title="pose error")
    ax.legend()
    for a in axes:
        a.grid(alpha=0.3)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def plot_sensor_comparison(runs: dict, path: str | Path | None = None):
    """The pose error of runs from the same start with different sensors (label -> result),
    with each run's convergence tolerance."""
    plt = pyplot()
    from pydrake.math import RigidTransform

    from geovs_drake.simulation import convergence_tolerance, pose_error

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharex=True)
    for k, (label, result) in enumerate(runs.items()):
        colour = f"C{k}"
        goal = result.config.X_BC_goal
        err = np.array([pose_error(RigidTransform(X), goal) for X in result.X_BC])
        tol = convergence_tolerance(result.resolved)
        for j, (ax, unit) in enumerate(zip(axes, ("m", "rad"), strict=True)):
            ax.semilogy(result.times, err[:, j], color=colour, label=f"{label}: {result.status}")
            ax.axhline(tol[j], color=colour, ls=":", lw=0.9, label=f"{label}: tolerance {unit}")
    axes[0].set(xlabel="t [s]", ylabel="position error [m]", title="position error")
    axes[1].set(xlabel="t [s]", ylabel="rotation error [rad]", title="rotation error")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("The same start and gains: the exact y = c(H) against y from rendered frames")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def plot_camera_frames(frames, features, intrinsics, times, path: str | Path | None = None):
    """Rendered frames (N, H, W, 4) with what the extractor read from each (features: (N, 13)
    rows or None): the fitted silhouette, the marked point q1 and the q2 arrow."""
    plt = pyplot()
    n = len(frames)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.6))
    for ax, frame, y, t in zip(np.atleast_1d(axes), frames, features, times, strict=True):
        ax.imshow(frame[..., :3], interpolation="nearest")
        if y is not None:
            y = np.asarray(y)
            sil = intrinsics.ray_to_pixel(_silhouette(y[10:13], float(y[9])))
            ax.plot(sil[:, 0], sil[:, 1], "y-", lw=1, label="fitted silhouette")
            q1 = intrinsics.ray_to_pixel(y[0:3])
            tip = intrinsics.ray_to_pixel(y[0:3] + 0.25 * y[9] * y[3:6])
            ax.annotate("", tip, q1, arrowprops=dict(arrowstyle="->", color="yellow", lw=1.5))
            ax.plot(*q1, "+", color="yellow", ms=8, label="q1, q2")
            ax.legend(loc="lower left", fontsize=7)
        ax.set_title(f"t = {t:.2f} s" + ("" if y is not None else ": no features"))
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle("What the rendered camera sees, and what the extractor reads")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def write_block_diagram(
    diagram,
    path_stem: str | Path,
    max_depth: int = 1,
    options: dict[str, str] | None = None,
    rankdir: str = "LR",
) -> list[Path]:
    """Graphviz SVG and PNG of a Diagram via ``dot``; [] with a message if dot is missing.

    ``options``: Drake's Graphviz options (e.g. ``{"plant/split": "I/O"}``, a subsystem's
    inputs and outputs drawn as two nodes); ``rankdir``: ``LR`` (Drake's, left to right)
    or ``TB``, top to bottom, for a loop of many systems, which left to right is several
    times wider than tall and unreadable at a page's width (notebook 05's arm)."""
    import shutil
    import subprocess

    dot = shutil.which("dot")
    if dot is None:
        print(
            "geovs-drake: skipping the block diagram: Graphviz's 'dot' is not installed "
            "(Debian: apt-get install graphviz)",
            file=sys.stderr,
        )
        return []
    source = diagram.GetGraphvizString(max_depth=max_depth, options=options or {})
    if rankdir != "LR":
        source = source.replace("rankdir=LR", f"rankdir={rankdir}", 1)
    out = []
    for fmt in ("svg", "png"):
        target = Path(f"{path_stem}.{fmt}")
        subprocess.run([dot, f"-T{fmt}", "-o", str(target)], input=source, text=True, check=True)
        out.append(target)
    return out


def plot_basin_map(basin, path: str | Path) -> None:
    """Convergence time over the roll x distance slice; failed starts marked by status."""
    import matplotlib.pyplot as plt

    r = basin.result
    t = basin.grid(np.where(r.status_code == 0, r.t_converged, np.nan))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    mesh = ax.pcolormesh(basin.distances, np.degrees(basin.rolls), t, shading="nearest")
    fig.colorbar(mesh, ax=ax, label="time to 1 mm / 1 mrad [s]")
    status = basin.grid(r.status_code)
    for code, marker in ((1, "x"), (2, "s"), (3, "v"), (4, "o")):
        rows, cols = np.nonzero(status == code)
        if len(rows):
            ax.scatter(
                basin.distances[cols],
                np.degrees(basin.rolls[rows]),
                marker=marker,
                s=12,
                color="red",
                label=f"{r.names[code]} ({len(rows)})",
            )
    ax.set(
        xlabel="distance to the marked point [m]",
        ylabel="roll about the optical axis [deg]",
        title=f"basin map, {r.plant} loop: {int(np.sum(r.status_code == 0))}/{r.status_code.size} "
        f"converged in {r.duration:g} s",
    )
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_root_locus(
    gains: np.ndarray,
    locus: np.ndarray,
    current: np.ndarray | None = None,
    damping_ratio: float | None = None,
    gain_label: str = "k_p",
    path: str | Path | None = None,
):
    """The eigenvalues (rows of ``locus``, one per gain) in the complex plane, coloured by
    the gain; ``current`` (the loop's own eigenvalues) as crosses; the lines of constant
    ``damping_ratio`` (``Re = -zeta |lambda|``) dashed. Returns the figure (closed after
    saving when ``path`` is given)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 5))
    colours = np.repeat(np.log10(np.asarray(gains, dtype=float))[:, None], locus.shape[1], axis=1)
    points = ax.scatter(locus.real.ravel(), locus.imag.ravel(), c=colours.ravel(), s=8)
    fig.colorbar(points, ax=ax, label=f"log10 {gain_label}")
    if current is not None:
        ax.scatter(current.real, current.imag, marker="x", color="black", s=50, label="the loop")
    if damping_ratio is not None:
        r = np.abs(locus).max()
        angle = np.arccos(damping_ratio)
        for sign in (1, -1):
            ax.plot(
                [0, -r * np.cos(angle)],
                [0, sign * r * np.sin(angle)],
                "--",
                color="grey",
                label=f"damping ratio {damping_ratio:g}" if sign == 1 else None,
            )
    ax.axvline(0, color="black", lw=0.5)
    ax.set(xlabel="Re [1/s]", ylabel="Im [1/s]", title=f"root locus over {gain_label}")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig
