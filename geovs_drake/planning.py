"""Planning an image path y_d(t) in I from y(0) to y* (Sec. 4, the path Eq. 18 follows).

A plan is a path through knots ``y_0, ..., y_n`` of I, geodesic between
knots in the product structure of :mod:`geovs_drake.geometry.image_path`,
built from Drake's trajectory classes:

* Q: a ``PiecewiseQuaternionSlerp`` through the knots' Q (slerp is the
  SO(3) geodesic, ``exp(u hat(w)) Q_k``);
* lambda: a ``PiecewisePolynomial`` (first-order hold between knots);
* s: a great-circle arc between knots, traced as ``s(u) = R(u) s_0`` with
  R a ``PiecewiseQuaternionSlerp`` through rotations ``R_k`` that carry s_0
  to s_k, each the previous one followed by the minimal rotation from s_(k-1)
  to s_k (a polynomial cannot stay on the sphere; a slerp about the normal
  of the great circle does, exactly).

The path parameter u is the arc length in the product metric, and the
time law ``u = L h(t / T)`` with the quintic h of
:data:`~geovs_drake.geometry.image_path.QUINTIC_TIME_LAW` (zero velocity and
acceleration at both ends, duration T set by the user) is a
``PiecewisePolynomial`` too; Drake's ``PathParameterizedTrajectory``
composes them. The result is a 13-row trajectory ``[q1, q2, q3, lambda, s]``
with exact derivatives, which feeds a diagram through
``TrajectorySource(trajectory, output_derivative_order=1)``.

:func:`plan_path` first tries the geodesic from y(0) to y* (two knots) and
checks the whole timed path against the safe domain D on a dense grid. If
it leaves D, the plan says where (which margin, how far) and when; with a
navigation function it then falls back to a path along the NF's gradient
flow ``ydot = -grad phi`` (Eq. 19), which stays in D because phi decreases
along it and phi = 1 on the boundary of D, integrated in image space and
re-timed with the same time law.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix
from pydrake.polynomial import Polynomial
from pydrake.trajectories import (
    FunctionHandleTrajectory,
    PathParameterizedTrajectory,
    PiecewisePolynomial,
    PiecewiseQuaternionSlerp,
    Trajectory,
)

from geovs_drake.geometry._ops import NUMPY
from geovs_drake.geometry.camera import ImageFeatures, silhouette_margin, validate_features
from geovs_drake.geometry.domain import DomainMargins, SafeDomain, domain_margins
from geovs_drake.geometry.image_path import QUINTIC_TIME_LAW, exp_image, image_distance
from geovs_drake.geometry.navigation import NavigationFunction
from geovs_drake.scenario import PathFollowing, ScenarioConfig

__all__ = [
    "PathExit",
    "PathPlan",
    "PathPlanningError",
    "check_path",
    "gradient_flow_knots",
    "image_path_through",
    "path_margins",
    "plan_for_scenario",
    "plan_path",
    "time_law",
]

MARGIN_NAMES = DomainMargins._fields


class PathPlanningError(ValueError):
    """No path in D: the geodesic leaves D and there is no (working) fallback."""


# ------------------------------------------------------------------ the path in u
def _quaternion(R: np.ndarray) -> Quaternion:
    return RotationMatrix.ProjectToRotationMatrix(np.asarray(R, dtype=float)).ToQuaternion()


def _minimal_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation about a x b taking the unit a to b: ``c I + hat(v) + v v^T / (1 + c)``."""
    v, c = np.cross(a, b), float(a @ b)
    return c * np.eye(3) + _hat(v) + np.outer(v, v) / (1 + c)


def _hat(w: np.ndarray) -> np.ndarray:
    x, y, z = np.ravel(w).tolist()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def image_path_through(knots: ImageFeatures) -> tuple[Trajectory, float]:
    """The piecewise-geodesic path through ``knots`` (batch of n >= 2), parameterised
    by arc length u in [0, L]: ``(trajectory of the 13-vector y(u), L)``.

    Between knots the three factors move on their geodesics at constant speeds
    in proportion, so u is the arc length of the product metric (the embedded
    one of Eq. 12: the rotation angle, lambda, the angle on S^2).
    """
    Y = knots.to_vector()
    if Y.ndim != 2 or len(Y) < 2:
        raise ValueError(f"a path needs a batch of >= 2 knots, got shape {Y.shape}")
    steps = image_distance(knots[:-1], knots[1:])
    lengths = np.linalg.norm(steps, axis=-1)
    if np.any(lengths <= 0):
        k = int(np.argmin(lengths))
        raise ValueError(f"knots {k} and {k + 1} coincide: a path needs distinct knots")
    breaks = np.concatenate([[0.0], np.cumsum(lengths)]).tolist()
    Q = knots.Q
    s = np.asarray(knots.s, dtype=float)
    R_s = [np.eye(3)]
    for k in range(1, len(Y)):
        R_s.append(_minimal_rotation(s[k - 1], s[k]) @ R_s[-1])
    q_slerp = PiecewiseQuaternionSlerp(breaks, [_quaternion(Qk) for Qk in Q])
    s_slerp = PiecewiseQuaternionSlerp(breaks, [_quaternion(R) for R in R_s])
    lam = PiecewisePolynomial.FirstOrderHold(breaks, np.asarray(knots.lam, dtype=float)[None, :])
    s0 = s[0].copy()

    def value(u: float) -> np.ndarray:
        Qu = q_slerp.orientation(u).rotation()
        out = np.empty((13, 1))
        out[0:9, 0] = Qu.T.ravel()  # the columns q1, q2, q3
        out[9, 0] = lam.value(u)[0, 0]
        out[10:13, 0] = s_slerp.orientation(u).rotation() @ s0
        return out

    def derivative(u: float, order: int) -> np.ndarray:
        # Within a segment both slerps turn at constant angular velocity w
        # (right-trivialised, xi of Eq. 13): dQ/du = hat(w) Q, d2Q/du2 = hat(w)^2 Q.
        if order not in (1, 2):
            raise ValueError(f"the image path has derivatives of order 1 and 2, not {order}")
        Qu = q_slerp.orientation(u).rotation()
        W = _hat(q_slerp.angular_velocity(u))
        su = s_slerp.orientation(u).rotation() @ s0
        W_s = _hat(s_slerp.angular_velocity(u))
        dQ, ds = W @ Qu, W_s @ su
        if order == 2:
            dQ, ds = W @ dQ, W_s @ ds
        out = np.empty((13, 1))
        out[0:9, 0] = dQ.T.ravel()
        out[9, 0] = lam.EvalDerivative(u, 1)[0, 0] if order == 1 else 0.0
        out[10:13, 0] = ds
        return out

    path = FunctionHandleTrajectory(value, 13, 1, 0.0, breaks[-1])
    path.set_derivative(derivative)
    return path, breaks[-1]


def time_law(duration: float, length: float) -> PiecewisePolynomial:
    """``u(t) = L h(t / T)`` on [0, T] (:data:`QUINTIC_TIME_LAW`): from 0 to L, at rest at both
    ends."""
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"path duration must be finite and > 0 [s], got {duration}")
    coefficients = [length * a / duration**k for k, a in enumerate(QUINTIC_TIME_LAW)]
    return PiecewisePolynomial([np.array([[Polynomial(coefficients)]])], [0.0, duration])


# ------------------------------------------------------------------ checking against D
@dataclass(frozen=True)
class PathExit:
    """Where and when a timed path leaves D: the first sample outside, and the margin broken."""

    time: float
    margin: str  # the margin that goes negative first
    lam: float  # lambda there
    s_angle_deg: float  # the angle of s from the optical axis e3 there [deg]
    back_in_time: float | None  # the first later sample inside D again, if any
    worst_time: float  # where the path is deepest outside D ...
    worst_margin: str
    worst_value: float  # ... and that margin's value (< 0)

    def describe(self) -> str:
        """Where and when the path leaves D, in one sentence."""
        back = (
            f"back in D at t = {self.back_in_time:.3g} s"
            if self.back_in_time is not None
            else "and stays out to the end"
        )
        return (
            f"leaves D at t = {self.time:.3g} s through its {self.margin} face (lambda = "
            f"{self.lam:.3g}, s {self.s_angle_deg:.3g} deg off the axis), reaches "
            f"{self.worst_margin} margin {self.worst_value:.3g} at t = {self.worst_time:.3g} s, "
            f"{back}"
        )


def _sample_margins(domain: SafeDomain, Y: np.ndarray) -> np.ndarray:
    """(N, 4) margins of D; a sample outside I (the marked point beyond the limb)
    reads its silhouette margin q1.s - sqrt(1 - lambda^2) < 0 as its occlusion margin."""
    y = tuple(Y.T)
    with np.errstate(invalid="ignore", divide="ignore"):
        m = np.stack(np.broadcast_arrays(*domain_margins(y, domain.params, NUMPY)), axis=-1)
        limb = silhouette_margin(y)
    m[:, 3] = np.where(limb > 0, m[:, 3], limb)
    return np.where(np.isfinite(m), m, -np.inf)


def path_margins(trajectory: Trajectory, domain: SafeDomain, times: np.ndarray) -> np.ndarray:
    """The (N, 4) margins of D (``fov, lam_min, lam_max, occlusion``) along a timed path;
    a sample outside I reads its (negative) silhouette margin as its occlusion margin."""
    Y = trajectory.vector_values(np.asarray(times, dtype=float)).T
    return _sample_margins(domain, Y)


def check_path(
    trajectory: Trajectory, domain: SafeDomain, samples: int = 2001
) -> tuple[float, PathExit | None, np.ndarray]:
    """Sample the timed path densely: ``(smallest margin, first exit or None, times)``."""
    times = np.linspace(trajectory.start_time(), trajectory.end_time(), samples)
    Y = trajectory.vector_values(times).T
    margins = _sample_margins(domain, Y)
    worst = margins.min(axis=-1)
    outside = worst < 0
    if not np.any(outside):
        return float(worst.min()), None, times
    i = int(np.argmax(outside))
    later = np.flatnonzero(~outside[i:])
    k = int(np.argmin(worst))
    s = Y[i, 10:13]
    return (
        float(worst[k]),
        PathExit(
            time=float(times[i]),
            margin=MARGIN_NAMES[int(np.argmin(margins[i]))],
            lam=float(Y[i, 9]),
            s_angle_deg=math.degrees(math.atan2(math.hypot(s[0], s[1]), s[2])),
            back_in_time=float(times[i + later[0]]) if len(later) else None,
            worst_time=float(times[k]),
            worst_margin=MARGIN_NAMES[int(np.argmin(margins[k]))],
            worst_value=float(worst[k]),
        ),
        times,
    )


# ------------------------------------------------------------------ the fallback
def gradient_flow_knots(
    nf: NavigationFunction,
    start: ImageFeatures,
    step: float = 0.01,
    max_steps: int = 5000,
    reach: float = 0.03,
) -> ImageFeatures:
    """Knots along the gradient flow ``ydot = -grad phi`` (Eq. 19) from ``start`` to y*.

    Steps of arc length ``step`` along ``-grad phi / |grad phi|`` (the flow
    line, whatever its speed), by Heun's method and the exponential map of I
    (:func:`~geovs_drake.geometry.image_path.exp_image`); a step that would
    leave D is halved. Once within ``reach`` of y* (the product distance), the
    goal itself is the last knot. Raises PathPlanningError if the flow has not
    come that close after ``max_steps`` (a start on the saddle's stable
    manifold flows to the saddle).
    """
    goal = nf.goal
    # One image (not a batch of one): the NF's compiled kernel runs on floats.
    y = ImageFeatures(np.asarray(start.Q, float), float(start.lam), np.asarray(start.s, float))
    knots = [y.to_vector()]

    def direction(yy: ImageFeatures) -> np.ndarray:
        g = nf.differential(yy)
        return -g / np.linalg.norm(g)

    def inside(yy: ImageFeatures) -> bool:
        return 0 < yy.lam < 1 and bool(nf.domain.contains(yy))

    h = step
    for _ in range(max_steps):
        if np.linalg.norm(image_distance(y, goal)) < reach:
            break
        d1 = direction(y)
        mid = exp_image(y, h * d1)
        if inside(mid):
            cand = exp_image(y, 0.5 * h * (d1 + direction(mid)))
            if inside(cand):
                y = cand
                knots.append(y.to_vector())
                h = step
                continue
        h *= 0.5
        if h < 1e-9 * step:
            raise PathPlanningError("the gradient flow cannot take a step inside D")
    else:
        phi = float(nf.value(y))
        raise PathPlanningError(
            f"the gradient flow did not reach the goal in {max_steps} steps (phi = {phi:.3g}; "
            "a start near the saddle's stable manifold flows to the saddle)"
        )
    knots.append(goal.to_vector())
    return ImageFeatures.from_vector(np.array(knots))


# ------------------------------------------------------------------ the plan
@dataclass
class PathPlan:
    """A timed image path y_d(t) on [0, duration], and what the planner found.

    ``trajectory`` is the 13-row ``PathParameterizedTrajectory`` (its
    ``EvalDerivative(t, 1)`` is dy_d/dt); ``kind`` is "geodesic" or
    "gradient_flow"; ``geodesic`` is the timed geodesic from y(0) to y* (the
    trajectory itself when ``kind`` is "geodesic"), ``geodesic_exit`` where and
    when it left D (None if it did not); ``min_margin`` is the smallest margin
    of D along the returned path.
    """

    trajectory: Trajectory
    duration: float
    length: float
    kind: str
    knots: int
    min_margin: float
    geodesic: Trajectory
    geodesic_exit: PathExit | None
    message: str

    def desired(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(y_d, dy_d/dt)`` at ``times``, each (N, 13); held at y* after the end."""
        times = np.asarray(times, dtype=float)
        y = np.stack([self.trajectory.value(float(t))[:, 0] for t in times])
        tc = np.clip(times, 0.0, self.duration)
        ydot = np.stack([self.trajectory.EvalDerivative(float(t), 1)[:, 0] for t in tc])
        ydot[(times < 0) | (times > self.duration)] = 0.0
        return y, ydot


def plan_path(
    start: ImageFeatures,
    goal: ImageFeatures,
    domain: SafeDomain,
    duration: float,
    nf: NavigationFunction | None = None,
    samples: int = 2001,
) -> PathPlan:
    """Plan y_d(t) from ``start`` to ``goal`` in ``duration`` seconds, inside D.

    The geodesic first; if it leaves D and ``nf`` is given, the NF's gradient
    flow (:func:`gradient_flow_knots`), re-timed with the same time law. Raises
    PathPlanningError (a ValueError) saying where and when the geodesic leaves
    D if there is no fallback, or if the fallback too leaves D.
    """
    start, goal = validate_features(start), validate_features(goal)
    for name, y in (("start", start), ("goal", goal)):
        if not bool(domain.contains(y)):
            raise PathPlanningError(f"the {name} image is not in D")
    pair = ImageFeatures.from_vector(np.stack([start.to_vector(), goal.to_vector()]))
    if float(np.linalg.norm(image_distance(pair[0], pair[1]))) == 0.0:
        raise PathPlanningError("the start image is the goal: there is no path to plan")
    path, length = image_path_through(pair)
    trajectory = PathParameterizedTrajectory(path, time_law(duration, length))
    min_margin, exit_, _ = check_path(trajectory, domain, samples)
    if exit_ is None:
        return PathPlan(
            trajectory, duration, length, "geodesic", 2, min_margin, trajectory, None,
            f"the geodesic path stays in D (min margin {min_margin:.3g})",
        )  # fmt: skip
    said = f"the geodesic path {exit_.describe()}"
    if nf is None:
        raise PathPlanningError(said + "; no navigation function to fall back on")
    knots = gradient_flow_knots(nf, start)
    path, length = image_path_through(knots)
    geodesic = trajectory
    trajectory = PathParameterizedTrajectory(path, time_law(duration, length))
    min_margin, flow_exit, _ = check_path(trajectory, domain, max(samples, 20 * len(knots.lam)))
    if flow_exit is not None:
        raise PathPlanningError(f"{said}; the gradient-flow path {flow_exit.describe()} too")
    return PathPlan(
        trajectory, duration, length, "gradient_flow", len(knots.lam), min_margin, geodesic, exit_,
        f"{said}: following the NF's gradient flow instead ({len(knots.lam)} knots, "
        f"min margin {min_margin:.3g})",
    )  # fmt: skip


@functools.lru_cache(maxsize=16)
def _plan_cached(key: tuple) -> PathPlan:
    y0, goal, domain, gains, duration, fallback = key
    nf = NavigationFunction(domain, np.array(goal), gains) if fallback else None
    return plan_path(
        ImageFeatures.from_vector(np.array(y0)),
        ImageFeatures.from_vector(np.array(goal)),
        domain,
        duration,
        nf,
    )


def plan_for_scenario(config: ScenarioConfig, law: PathFollowing | None = None) -> PathPlan:
    """The plan of ``config``: from y(0) = c(X_BC(0)^-1) to y* in the path law's
    ``duration`` (``law``, default the scenario's law where it is a
    :class:`~geovs_drake.scenario.PathFollowing`, else the path law's defaults),
    falling back on the NF's gradient flow if its ``fallback``. Cached per
    (start, goal, domain, gains, duration, fallback): the diagram builder and
    ``simulate`` ask for the same plan."""
    law = config.controller if law is None else law
    if not law.traits.plans:  # another law: the path law's defaults
        law = PathFollowing()
    key = (
        tuple(config.initial_features().to_vector().tolist()),
        tuple(config.goal_features().to_vector().tolist()),
        config.domain.to_domain(),
        config.navigation.to_gains(),
        float(law.duration),
        bool(law.fallback),
    )
    return _plan_cached(key)
