"""The region of attraction certified by sum of squares: Drake's ``RegionOfAttraction``
on the Taylor expansion of the closed loop in minimal coordinates.

:mod:`~geovs_drake.analysis.linear.region` finds, by sampling, the largest level of the
linearisation's Lyapunov function ``V = x^T P x`` on which the nonlinear loop's Vdot
is negative. This module certifies a level with a proof, for a polynomial model:

1. **The loop in minimal coordinates** (:func:`minimal_field`): ``x = (g, dp, Omega,
   V)`` centred at the goal (the Gibbs vector and the position offset of the camera from
   X_WC*, then its body twist; the pose alone on the kinematic body), with the pose's
   kinematics written exactly, ``gdot = (I + [g]/2 + g g^T / 4) Omega`` and ``dp_dot =
   R(g) V``, and the twist's derivative from the same generated kernels the Drake
   systems and the batch engine run (camera map, NF, Eq. 45's wrench, the free rig).
2. **Its Taylor expansion** (:func:`taylor_field`): the kernels evaluated on truncated
   Taylor jets (:mod:`geovs_drake.geometry.taylor`), so the coefficients are exact to
   rounding, in the scaled coordinates ``x = T w`` with ``T = sqrt(rho_s) L^-T``
   (``P = L L^T``, rho_s the sampled level): V becomes ``rho_s |w|^2`` and the region
   the unit ball, which the SDP solvers need (unscaled, P spans 5 decades and SCS
   stalls, Clarabel takes 20 GB).
3. **The certificate** (:func:`certify_region`): the polynomial vector field as a
   ``SymbolicVectorSystem``, handed to Drake's ``RegionOfAttraction`` with the
   candidate ``|w|^2``; Drake searches the largest level on which Vdot < 0 by the
   S-procedure (one SDP, SCS by default: it ships with the wheel and is the one that
   solves the dynamic loop's 12-variable program in a few GB).

**What the truncation leaves out.** The certificate is a proof for the degree-d Taylor
polynomial, not for the loop: the remainder, ``O(|x|^(d+1))``, is not bounded, and neither
is the safe domain D (the polynomial does not know where the camera map ends). So the
certified level is then checked against the nonlinear loop, as the sampled level is:
its ellipsoid's boundary must lie in D with the nonlinear Vdot < 0 there
(:attr:`CertifiedRegion.nonlinear_check`), and starts sampled inside must converge in
the batch engine (``tests/test_certified_region.py``; 10^4 starts in the slow test).
Here the degree-3 certificate falls just inside the sampled level, so the remainder
does not matter at this size; a degree-2 model (Vdot odd) certifies less.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import pydrake.symbolic as sym
from pydrake.math import RigidTransform
from pydrake.solvers import ClarabelSolver, CsdpSolver, ScsSolver
from pydrake.systems.analysis import RegionOfAttraction, RegionOfAttractionOptions
from pydrake.systems.primitives import SymbolicVectorSystem

from geovs_drake._json import json_ready
from geovs_drake.analysis.linear.region import (
    LyapunovRegion,
    _vdot,
    lyapunov_region,
    poses_in_domain,
    states_of,
)
from geovs_drake.batch.engine import LoopParameters, loop_parameters
from geovs_drake.geometry import kernels
from geovs_drake.geometry._ops import NUMPY
from geovs_drake.geometry.kernels import CAMERA_IMAGE, FREE_BODY, NAVIGATION, SERVO_FORCE
from geovs_drake.geometry.rigid import (
    apply,
    cross,
    gibbs_quaternion,
    matmul,
    quaternion_multiply,
    quaternion_to_rotation,
    rig_velocity,
)
from geovs_drake.geometry.taylor import monomials, variables
from geovs_drake.scenario import Dynamic, Kinematic, ScenarioConfig, variant_name

__all__ = [
    "DEFAULT_DEGREE",
    "SOLVERS",
    "CertifiedRegion",
    "TaylorField",
    "certify_region",
    "check_solver",
    "minimal_field",
    "taylor_field",
]

#: The Taylor degree by plant. Degree 3 keeps Vdot even (degree 4), which the
#: S-procedure needs to certify more than the odd degree-2 model does; on the dynamic
#: loop's 12 variables Drake's degree-3 program (SCS) had grown past 14 GB after 225 s
#: and was stopped, so the dynamic default is 2 (213 s, 0.7 GB).
DEFAULT_DEGREE = {Kinematic: 3, Dynamic: 2}
#: The SDP solvers that ship with the drake wheel, by name (one registry; the CLI's
#: choices). SCS is the default (module docstring).
SOLVERS = {"scs": ScsSolver.id(), "clarabel": ClarabelSolver.id(), "csdp": CsdpSolver.id()}
#: The equilibrium's residual f(0) (rounding of the kernels at the goal) that is dropped
#: before Drake's ``RegionOfAttraction``, which requires ``|f(0)| <= 1e-14``; larger is a bug.
_EQUILIBRIUM_TOLERANCE = 1e-9
#: Points on the certified ellipsoid's boundary checked against the nonlinear loop.
_BOUNDARY_POINTS = 200


def _hat(v) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]], dtype=object)


def minimal_field(config: ScenarioConfig, x, p: LoopParameters | None = None) -> np.ndarray:
    """xdot of the closed loop in minimal coordinates x (6 kinematic, 12 dynamic), for
    any scalar the kernels take (float, AutoDiffXd, :class:`~geovs_drake.geometry.taylor.Jet`).

    The pose is ``X_WC = X_WC* (Cay(g), dp)`` (``Cay(g)`` the rotation of the quaternion
    ``(1, g/2)`` normalised; :func:`~geovs_drake.analysis.linear.region.states_of`), the
    twist ``(Omega, V)`` the camera's body twist.
    """
    p = loop_parameters(config) if p is None else p
    dynamic = config.dynamic
    X_RC = config.X_RC if dynamic else RigidTransform()
    X_WC_goal = config.X_WB @ config.X_BC_goal
    x = np.asarray(x, dtype=object)
    g, dp = x[0:3], x[3:6]
    q_g = gibbs_quaternion(tuple(g), NUMPY)
    q_WC = quaternion_multiply(tuple(X_WC_goal.rotation().ToQuaternion().wxyz()), q_g)
    w, a, b, c = X_RC.rotation().ToQuaternion().wxyz()
    q_WR = quaternion_multiply(q_WC, (w, -a, -b, -c))
    R_WR = quaternion_to_rotation(q_WR, NUMPY)
    p_RC = tuple(X_RC.translation())
    r_W = apply(R_WR, p_RC)  # the camera's offset from the rig's origin, in W
    p_WC = X_WC_goal.translation() + X_WC_goal.rotation().matrix() @ dp
    pose = (*q_WR, *(p_WC[i] - r_W[i] for i in range(3)))

    y = kernels.camera_image.python(pose, p.camera)[CAMERA_IMAGE.y]
    dphi = kernels.navigation.python(y, p.navigation)[NAVIGATION.dphi]
    if dynamic:
        twist = x[6:12]
    else:  # Eqs. (18)-(19)
        twist = np.asarray(kernels.kinematic_velocity.python(y, dphi, p.controller), dtype=object)
    Omega, V = twist[0:3], twist[3:6]
    # The Gibbs vector's kinematics (from qdot = q (0, Omega) / 2) and dp's.
    G = np.eye(3) + 0.5 * _hat(g) + 0.25 * np.outer(g, g)
    R_g = np.asarray(quaternion_to_rotation(q_g, NUMPY), dtype=object).reshape(3, 3)
    pose_rate = np.concatenate([G @ Omega, R_g @ V])
    if not dynamic:
        return pose_rate

    # The twist's rate from the rig's Newton-Euler (the plant's state layout): Omega =
    # R_WC^T w, V = R_WC^T (v_Ro + w x r), so Omega_dot = R_WC^T wdot (the term
    # -[Omega] Omega vanishes) and V_dot = -Omega x V + R_WC^T (vdot + wdot x r + w x (w x r)).
    R_WC = matmul(R_WR, tuple(X_RC.rotation().matrix().ravel()))
    velocity = rig_velocity(R_WR, R_WC, tuple(twist), p_RC)
    state = pose + tuple(velocity)
    force = kernels.servo_force.python(state, y, dphi, p.controller)[SERVO_FORCE.generalized]
    state_rate = kernels.free_body.python(state, force, p.body)[FREE_BODY.xdot]
    w_W, wdot, vdot = velocity[0:3], state_rate[7:10], state_rate[10:13]
    R_CW = np.asarray(R_WC, dtype=object).reshape(3, 3).T
    accel = np.asarray(vdot) + np.asarray(cross(wdot, r_W)) + cross(w_W, cross(w_W, r_W))
    Omega_dot = R_CW @ np.asarray(wdot)
    V_dot = -np.asarray(cross(tuple(Omega), tuple(V)), dtype=object) + R_CW @ accel
    return np.concatenate([pose_rate, Omega_dot, V_dot])


@dataclass
class TaylorField:
    """The degree-d Taylor polynomial of :func:`minimal_field` at the goal in the scaled
    coordinates ``x = T w``: ``wdot_i = sum_k coefficients[i, k] w^monomials[k]``."""

    degree: int
    T: np.ndarray
    coefficients: np.ndarray  # (n, number of monomials)
    monomials: np.ndarray  # (number of monomials, n) exponents

    def __call__(self, w: np.ndarray) -> np.ndarray:
        """wdot at rows of w (N, n)."""
        w = np.atleast_2d(w)
        basis = np.prod(w[:, None, :] ** self.monomials[None], axis=2)
        return basis @ self.coefficients.T

    def expressions(self, w: np.ndarray) -> list:
        """The polynomial as Drake Expressions of the Variables w."""
        terms = [
            sym.Monomial({w[i]: int(e) for i, e in enumerate(exps) if e}).ToExpression()
            for exps in self.monomials
        ]
        zero = sym.Expression(0)
        return [
            sum((float(c) * m for c, m in zip(row, terms, strict=True) if c != 0), zero)
            for row in self.coefficients
        ]


def taylor_field(
    config: ScenarioConfig,
    degree: int,
    T: np.ndarray | None = None,
    p: LoopParameters | None = None,
) -> TaylorField:
    """The exact degree-d Taylor polynomial of the loop at the goal, in ``w = T^-1 x``
    (T = I when None; ``p``: the loop's parameters, built when None). Raises ValueError
    if the goal is not an equilibrium."""
    p = loop_parameters(config) if p is None else p
    n = 12 if config.dynamic else 6
    T = np.eye(n) if T is None else np.asarray(T, dtype=float)
    w = variables(np.zeros(n), degree)
    wdot = np.linalg.inv(T) @ minimal_field(config, T @ w, p)
    coefficients = np.array([jet.coefficients for jet in wdot])
    residual = np.abs(coefficients[:, 0]).max()
    if residual > _EQUILIBRIUM_TOLERANCE * max(1.0, np.abs(coefficients).max()):
        raise ValueError(f"the goal is not an equilibrium of the loop: |f(0)| = {residual:.3g}")
    coefficients[:, 0] = 0.0  # rounding at the goal (Drake's check wants <= 1e-14)
    return TaylorField(degree, T, coefficients, np.array(monomials(n, degree)))


@dataclass
class CertifiedRegion:
    """The certified region ``{x^T P x <= rho}`` (:func:`certify_region`).

    Attributes:
        plant, degree, solver: the loop, the Taylor degree and the SDP solver.
        sampled: the sampled region (its P is this region's P).
        rho: the certified level of V = x^T P x (for the Taylor polynomial).
        T: the scaling ``x = T w`` of the certified program (``V = failing level |w|^2``).
        seconds: the wall time of Drake's ``RegionOfAttraction``.
        nonlinear_check: on :data:`_BOUNDARY_POINTS` points of the certified boundary,
            the state lies in D and the nonlinear loop's Vdot < 0 at every one.
        boundary_max_vdot: the largest nonlinear Vdot there (< 0 when the check holds).
    """

    plant: str
    degree: int
    solver: str
    sampled: LyapunovRegion
    rho: float
    T: np.ndarray
    seconds: float
    nonlinear_check: bool
    boundary_max_vdot: float

    @property
    def P(self) -> np.ndarray:
        """The Lyapunov matrix, the sampled region's (``A^T P + P A = -I``)."""
        return self.sampled.P

    @property
    def largest_distance_m(self) -> float:
        """The largest position offset from the goal at rest, any direction [m]."""
        return self.sampled.largest_distance_m * math.sqrt(self.rho / self.sampled.rho)

    @property
    def largest_roll_rad(self) -> float:
        """The largest roll about the optical axis at rest [rad]."""
        g_z = self.sampled.largest_offset(2) * math.sqrt(self.rho / self.sampled.rho)
        return 2.0 * math.atan(g_z / 2.0)

    def summary(self) -> dict:
        """The certificate as JSON values (``linearize --certify --json``'s
        ``region.certified``)."""
        return json_ready(
            {
                "level": self.rho,
                "degree": self.degree,
                "solver": self.solver,
                "seconds": self.seconds,
                "largest_distance_m": self.largest_distance_m,
                "largest_roll_rad": self.largest_roll_rad,
                "nonlinear_check": self.nonlinear_check,
            }
        )

    def as_region(self) -> LyapunovRegion:
        """The certified set as a :class:`LyapunovRegion` (for
        :func:`~geovs_drake.analysis.linear.region.sample_inside` and ``check_inside``)."""
        s = self.sampled
        return LyapunovRegion(
            s.plant, s.A, s.P, self.rho, s.rays, s.failing_level, f"certified ({self.solver})"
        )


def check_solver(solver: str) -> None:
    """ValueError, in one line, unless ``solver`` names one of :data:`SOLVERS`."""
    if solver not in SOLVERS:
        raise ValueError(f"the SOS solver must be one of {', '.join(sorted(SOLVERS))}: {solver!r}")


def certify_region(
    config: ScenarioConfig,
    degree: int | None = None,
    solver: str = "scs",
    sampled: LyapunovRegion | None = None,
) -> CertifiedRegion:
    """Certify a level of the sampled region's V by SOS (module docstring).

    ``sampled`` is computed (200 rays) when None; its P is the candidate, its failing
    level the scale of w. ``degree`` defaults to :data:`DEFAULT_DEGREE` of the plant.
    """
    check_solver(solver)
    degree = DEFAULT_DEGREE[type(config.plant)] if degree is None else degree
    if degree < 2:
        raise ValueError(
            f"the Taylor degree must be >= 2 (degree 1 is the linearisation): {degree}"
        )
    sampled = lyapunov_region(config) if sampled is None else sampled
    scale = sampled.failing_level
    T = math.sqrt(scale) * np.linalg.inv(np.linalg.cholesky(sampled.P).T)  # V = scale |w|^2
    p = loop_parameters(config)
    model = taylor_field(config, degree, T, p)
    n = len(T)
    w = np.array([sym.Variable(f"w{i}") for i in range(n)])
    system = SymbolicVectorSystem(state=w, dynamics=model.expressions(w))
    options = RegionOfAttractionOptions()
    options.lyapunov_candidate = sum((v * v for v in w), sym.Expression(0))
    options.state_variables = w
    options.solver_id = SOLVERS[solver]
    start = time.perf_counter()
    V_normalised = RegionOfAttraction(system, system.CreateDefaultContext(), options)
    seconds = time.perf_counter() - start
    # Drake returns |w|^2 / level: its value at a unit w is 1 / level.
    unit = {v: 1.0 if i == 0 else 0.0 for i, v in enumerate(w)}
    rho = scale / V_normalised.Evaluate(unit)

    # The nonlinear loop on the certified boundary: in D, and Vdot < 0.
    rng = np.random.default_rng(0)
    u = rng.normal(size=(_BOUNDARY_POINTS, n))
    x = (T @ (u / np.linalg.norm(u, axis=1, keepdims=True)).T).T * math.sqrt(rho / scale)
    X_BC, states = states_of(config, x)
    inside = poses_in_domain(config, X_BC)
    vdot = np.full(len(x), np.inf)
    if np.any(inside):
        vdot[inside] = _vdot(config, sampled.P, states[inside], p)
    return CertifiedRegion(
        plant=variant_name(config.plant),
        degree=degree,
        solver=solver,
        sampled=sampled,
        rho=float(rho),
        T=T,
        seconds=seconds,
        nonlinear_check=bool(np.all(inside) and np.all(vdot < 0)),
        boundary_max_vdot=float(vdot.max()),
    )
