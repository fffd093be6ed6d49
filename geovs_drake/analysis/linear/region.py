"""A region of attraction from the linearisation: a quadratic Lyapunov function, the
largest sublevel set on which it decreases along the nonlinear loop, found by sampling,
and the batch engine's check that every start inside converges.

The paper's guarantee is global on D for ``E0 < k_p`` (at rest: every pose of D, where
``phi < 1``). A linear certificate is local and smaller, but it is what a user of
Drake's linear tools reaches for. In the minimal coordinates centred at the goal,
``x = (g, dp, Omega, V)`` (:func:`~geovs_drake.analysis.linear.linearization.pose_error`'s
Gibbs vector and position offset, then the camera's body twist; the pose alone on
the kinematic body), ``A`` is the goal's minimal model (Drake's ``Linearize``) and
``P`` solves ``A^T P + P A = -Q`` (Drake's ``RealContinuousLyapunovEquation``,
``Q = I``). ``V(x) = x^T P x``.

``Vdot`` of the *nonlinear* loop is the central difference of V along the flow,
``(V(m(s + h f(s))) - V(m(s - h f(s)))) / 2h``, with ``f`` the batch engine's own
right-hand side on Drake's state s and ``m`` the map to x. Along random rays from
the goal, each ray's first level where ``Vdot >= 0`` or the state leaves D bounds
``rho``; the smallest over the rays, times :data:`LEVEL_MARGIN`, is the sampled
level. It is an estimate, not a proof: a sum-of-squares certificate (Drake's
``RegionOfAttraction``) on a Taylor expansion of the loop is not built yet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RealContinuousLyapunovEquation, RigidTransform, RotationMatrix

from geovs_drake._json import json_ready
from geovs_drake.analysis.linear.linearization import linearize, pose_error
from geovs_drake.batch.engine import _rhs, loop_parameters, run_batch
from geovs_drake.geometry._ops import MATH, NUMPY
from geovs_drake.geometry.camera import camera_map, visibility
from geovs_drake.geometry.domain import domain_margins
from geovs_drake.geometry.rigid import gibbs_quaternion, quaternion_to_rotation
from geovs_drake.loop.state import initial_body_states
from geovs_drake.scenario import ScenarioConfig, variant_name

__all__ = [
    "LEVEL_MARGIN",
    "LyapunovRegion",
    "lyapunov_region",
    "poses_in_domain",
    "sample_inside",
    "states_of",
]

#: The sampled level is the smallest failing level times this (the rays' grid is
#: 4 % apart in level, and a ray misses what lies between rays).
LEVEL_MARGIN = 0.9
#: The central difference's step along the flow [s].
_FLOW_STEP = 1e-6
#: The levels tried along each ray: V = s^2 for s on this geometric grid.
_SCALES = np.geomspace(1e-3, 1e1, 500)


def _gibbs_rotation(g: np.ndarray) -> np.ndarray:
    return np.array(quaternion_to_rotation(gibbs_quaternion(tuple(g), MATH), MATH)).reshape(3, 3)


def states_of(config: ScenarioConfig, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(X_BC (N, 4, 4), Drake states (N, n)) of minimal coordinates x (N, 6 or 12)
    centred at the goal: ``X_BC = X_BC* (Cay(g), dp)``, at the body twist x[6:12]."""
    x = np.atleast_2d(x)
    X_goal = config.X_BC_goal.GetAsMatrix4()
    X = np.repeat(X_goal[None], len(x), axis=0)
    for i, row in enumerate(x):
        X[i, 0:3, 0:3] = X_goal[0:3, 0:3] @ _gibbs_rotation(row[0:3])
        X[i, 0:3, 3] = X_goal[0:3, 3] + X_goal[0:3, 0:3] @ row[3:6]
    twists = x[:, 6:12] if x.shape[1] == 12 else None
    return X, initial_body_states(config, X, twists)


def _minimal(config: ScenarioConfig, s: np.ndarray) -> np.ndarray:
    """x of Drake states s (N, n): the inverse of :func:`states_of`."""
    dynamic = config.dynamic
    X_RC = config.X_RC if dynamic else RigidTransform()
    X_goal = config.X_WB @ config.X_BC_goal
    out = np.empty((len(s), 12 if dynamic else 6))
    for i, row in enumerate(s):
        out[i, 0:6] = pose_error(X_goal, row[0:7], X_RC)
        if dynamic:
            q = row[0:4] / np.linalg.norm(row[0:4])
            R_WR = RotationMatrix(Quaternion(q)).matrix()
            R_WC = R_WR @ X_RC.rotation().matrix()
            w_W, v_W = row[7:10], row[10:13]
            out[i, 6:9] = R_WC.T @ w_W
            out[i, 9:12] = R_WC.T @ (v_W + np.cross(w_W, R_WR @ X_RC.translation()))
    return out


def poses_in_domain(config: ScenarioConfig, X_BC: np.ndarray) -> np.ndarray:
    """Which camera poses X_BC (N, 4, 4) lie in the scenario's safe domain D (the target
    visible and every margin > 0), by the camera map and D's margins."""
    X_CB = np.linalg.inv(X_BC)
    inside = visibility(X_CB, config.radius) > 0
    if np.any(inside):
        y = camera_map(X_CB[inside], config.radius).components()
        margins = domain_margins(y, config.domain.to_domain().params, NUMPY)
        inside[inside] = np.all(np.stack([np.asarray(m) for m in margins]) > 0, axis=0)
    return inside


@dataclass
class LyapunovRegion:
    """The sampled region {x^T P x <= rho} (:func:`lyapunov_region`).

    Attributes:
        plant: the loop's plant.
        A: the goal's minimal model; P: the Lyapunov matrix (A^T P + P A = -I).
        rho: the sampled level (:data:`LEVEL_MARGIN` times the smallest failing one).
        rays: how many rays were sampled; failing_level: the smallest failing level;
        failed_by: why that ray failed (``"Vdot >= 0"`` or ``"leaves D"``).
    """

    plant: str
    A: np.ndarray
    P: np.ndarray
    rho: float
    rays: int
    failing_level: float
    failed_by: str

    def V(self, x: np.ndarray) -> np.ndarray:
        """x^T P x for rows of x."""
        x = np.atleast_2d(x)
        return np.einsum("ni,ij,nj->n", x, self.P, x)

    def largest_offset(self, coordinate: int) -> float:
        """The largest ``|x_i|`` in the region along one coordinate at rest (0-2: the
        rotation's Gibbs vector about C's x, y, z, ~ rad; 3-5: the position in C* [m])."""
        e = np.zeros(len(self.P))
        e[coordinate] = 1.0
        return math.sqrt(self.rho / float(e @ self.P @ e))

    def summary(self) -> dict:
        """The region as JSON values (``linearize --region --json``'s ``region``)."""
        return json_ready(
            {
                "level": self.rho,
                "rays": self.rays,
                "failed_by": self.failed_by,
                "largest_distance_m": self.largest_distance_m,
                "largest_roll_rad": self.largest_roll_rad,
            }
        )

    @property
    def largest_distance_m(self) -> float:
        """The largest position offset from the goal at rest, any direction [m]:
        ``sqrt(rho / lambda_max)`` of P's position block's Schur-free restriction
        (the rotation and the twist held at 0)."""
        return math.sqrt(self.rho / float(np.linalg.eigvalsh(self.P[3:6, 3:6]).max()))

    @property
    def largest_roll_rad(self) -> float:
        """The largest roll about the optical axis at rest [rad] (the Gibbs vector's
        z, ``2 atan(g_z / 2)``)."""
        return 2.0 * math.atan(self.largest_offset(2) / 2.0)


def _vdot(config: ScenarioConfig, P: np.ndarray, s: np.ndarray, p) -> np.ndarray:
    kinematic = not config.dynamic
    out = np.empty(len(s))
    for i, row in enumerate(s):
        f = np.zeros(len(row))
        _rhs(kinematic, np.ascontiguousarray(row), f, p.camera, p.navigation, p.controller, p.body)
        ends = _minimal(config, np.stack([row + _FLOW_STEP * f, row - _FLOW_STEP * f]))
        V = np.einsum("ni,ij,nj->n", ends, P, ends)
        out[i] = (V[0] - V[1]) / (2 * _FLOW_STEP)
    return out


def lyapunov_region(config: ScenarioConfig, rays: int = 200, seed: int = 0) -> LyapunovRegion:
    """The sampled :class:`LyapunovRegion` of ``config``'s loop (module docstring)."""
    lin = linearize(config)
    A = lin.A
    P = RealContinuousLyapunovEquation(A, np.eye(len(A)))
    P = 0.5 * (P + P.T)
    p = loop_parameters(config)
    rng = np.random.default_rng(seed)
    worst, why = math.inf, "none"
    for _ in range(rays):
        u = rng.normal(size=len(A))
        u /= math.sqrt(u @ P @ u)  # V(s u) = s^2
        x = _SCALES[:, None] * u[None]
        X_BC, s = states_of(config, x)
        inside = poses_in_domain(config, X_BC)
        bad = ~inside
        if np.any(inside):
            vdot = np.full(len(x), np.inf)
            vdot[inside] = _vdot(config, P, s[inside], p)
            bad |= ~(vdot < 0)
        if np.any(bad):
            k = int(np.argmax(bad))
            if _SCALES[k] ** 2 < worst:
                worst, why = float(_SCALES[k] ** 2), "leaves D" if not inside[k] else "Vdot >= 0"
    return LyapunovRegion(
        plant=variant_name(config.plant),
        A=A,
        P=P,
        rho=LEVEL_MARGIN * worst,
        rays=rays,
        failing_level=worst,
        failed_by=why,
    )


def sample_inside(region: LyapunovRegion, n: int, seed: int = 1) -> np.ndarray:
    """n minimal states uniform in the ellipsoid {x^T P x <= rho}."""
    rng = np.random.default_rng(seed)
    d = len(region.P)
    u = rng.normal(size=(n, d))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = rng.uniform(size=(n, 1)) ** (1.0 / d)
    L = np.linalg.cholesky(region.P / region.rho)  # x^T P x / rho = |L^T x|^2
    return np.linalg.solve(L.T, (r * u).T).T


def check_inside(config: ScenarioConfig, region: LyapunovRegion, n: int, seed: int = 1):
    """The batch engine from n starts inside the region: its :class:`BatchResult`."""
    x = sample_inside(region, n, seed)
    X_BC, _ = states_of(config, x)
    twists = x[:, 6:12] if config.dynamic else None
    return run_batch(config, X_BC, twists)
