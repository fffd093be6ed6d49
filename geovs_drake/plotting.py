"""Matplotlib figures: navigation-function slices and closed-loop runs.

matplotlib is imported lazily (it is an optional dependency, the
``notebooks`` extra), with the non-interactive Agg backend when no display
backend has been chosen.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from geovs_drake.navigation import (
    ModelCoordinates,
    NavigationFunction,
    features_from_model,
    model_coordinates,
)

__all__ = ["plot_navigation_slices"]


def _pyplot():
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
    plt = _pyplot()
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
    ax.legend()
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
    fig.colorbar(cs, ax=ax)
    ax.plot([float(nf.goal.lam)] * 2, [0, 180], "w*", ms=10)
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
    fig.colorbar(cs, ax=ax)
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
