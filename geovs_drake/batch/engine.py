"""The batch engine: N closed loops at once, on the kernels the LeafSystems run.

Each start is integrated by an embedded Runge-Kutta pair of the order of the loop's
Drake scheme (first same as last): Dormand and Prince's 5(4), the tableau of Drake's
RK5, where the loop's scheme is fifth-order (the dynamic plant's default under the NF's
law: six new evaluations a step), else Bogacki and Shampine's 3(2) (three); the tableaux
are data (``geovs_drake.batch._pairs``), one step's arithmetic shared by every batch
integrator. Each start's step is error-controlled by default or fixed, in a compiled
loop, the starts spread over the cores by numba's ``prange``. The right-hand side is
the diagram's, kernel for kernel:

* dynamic: ``camera_image -> navigation -> servo_force -> free_body`` (the
  free rig of MultibodyPlant: Newton-Euler about the centre of mass, the
  camera frame at X_RC, Eq. 45's wrench shifted to the rig's origin);
* kinematic: ``camera_image -> navigation -> kinematic_velocity ->
  kinematic_body`` (Eqs. 17-19).

Parameters are read from the systems' own parameter vectors of a diagram
built from the same :class:`~geovs_drake.scenario.ScenarioConfig`, so the
engine and the Drake loop cannot drift apart; a test runs both on the same
starts and compares their states.

**Step.** By default each start's step is error-controlled (the
tolerance is ``config.simulator.accuracy``, as for Drake's integrators, and
the Drake loop's step limit caps it,
:func:`~geovs_drake.goal.step_limit.step_limit`), because a fixed step
cannot serve the kinematic loop: its speed grows without bound near the
boundary of D (dphi ~ 1/beta),
and with a fixed 0.01 s step 122 of 400 random starts left D where error
control brought all home. A step that would leave D is rejected like an
inaccurate one (the exact flow of a start with E0 < k_p never leaves D), so
a start stops ``left_domain`` only where the step size underflows at the
boundary. On the dynamic loop, whose speed the energy bounds, a fixed step
works too (``step=``; :data:`DEFAULT_STEP` = 0.01 s was exact to the
tolerance on 400 starts; the linearisation's largest eigenvalue has modulus
about 37, so explicit third-order steps are stable up to about 0.06 s).
Error control is also the faster here: about 730 steps per start over 10 s
against 1000 on the third-order pair; the fifth-order pair takes about 300, about 140
of them at the step limit once the start has converged, where a step is the
third-order pair's if RK3's stability bound allows it (``third_order_at_limit``).

**Per-sample masking.** Each start stops on its own, with its own status
and time, when its state leaves D (a margin < 0: ``left_domain``), the
marked point turns away (nu <= 0: ``lost_visibility``) or a number is not
finite (``non_finite``); the others go on. Every accepted state is checked,
the initial one included, from the values its first Runge-Kutta stage
computes anyway. Nothing raises for a bad sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numba
import numpy as np
from numba import njit, prange

from geovs_drake.batch._checks import state_status as _state_status
from geovs_drake.batch._pairs import (
    BOGACKI_SHAMPINE,
    RETRY,
    UNDERFLOW,
    error_norm,
    pair_for,
    solution,
    stage_point,
    step_control,
)
from geovs_drake.geometry import kernels
from geovs_drake.geometry.kernels import CAMERA_IMAGE, FREE_BODY, NAVIGATION, SERVO_FORCE
from geovs_drake.loop.state import initial_body_states
from geovs_drake.scenario import ScenarioConfig, variant_name
from geovs_drake.simulation.result import (
    CONVERGENCE_POSITION_M,
    CONVERGENCE_ROTATION_RAD,
    convergence_tolerance,
)
from geovs_drake.systems.spherical_camera import CAMERA_OFFSET

if TYPE_CHECKING:  # the record only: the workers import no loop
    from geovs_drake.batch.sampled import SampledCamera
    from geovs_drake.goal.step_limit import StepLimit
    from geovs_drake.loop.resolved import ResolvedScenario

__all__ = [
    "DEFAULT_STEP",
    "STATUS_NAMES",
    "BatchResult",
    "LoopParameters",
    "loop_parameters",
    "run_batch",
]

#: Starts per chunk of the ``prange`` loop, handed to whichever thread is free (numba's
#: dynamic schedule; 0, its default, splits the starts in halves up front): the starts'
#: costs differ (their steps and each stage's luck), and work beside the loop (another
#: thread's Python) slows one core. 10 parts of 1000 starts: 3.43-3.87 s against
#: 3.96-4.13 s (three alternating rounds).
PARALLEL_CHUNK = 8
#: Default fixed step [s] (module docstring).
DEFAULT_STEP = 0.01
#: Per-start statuses, indexed by the engine's status codes.
STATUS_NAMES = ("converged", "not_converged", "left_domain", "lost_visibility", "non_finite")
#: Allowed rise of the Lyapunov function per step, relative to max(1, its initial value):
#: a fixed-step RK3 conserves no energy exactly; its local error at the default step is
#: below 1e-9 of the energy scale.
MONOTONE_TOLERANCE = 1e-7

_camera = kernels.camera_image.compiled
_navigation = kernels.navigation.compiled
_force = kernels.servo_force.compiled
_free_body = kernels.free_body.compiled
_kinematic_velocity = kernels.kinematic_velocity.compiled
_kinematic_body = kernels.kinematic_body.compiled
_pose_error = kernels.pose_error.compiled


@dataclass(frozen=True)
class LoopParameters:
    """What the kernels take, read from a diagram's systems (see :func:`loop_parameters`)."""

    plant: str  # the plant's name, for the results
    dynamic: bool  # the plant is Dynamic: the free body's kernels, not the kinematic ones
    camera: np.ndarray
    navigation: np.ndarray
    controller: np.ndarray  # ImageJacobianForce's vector, or KinematicController's [rho, k]
    body: np.ndarray  # (mass, Ixx, Iyy, Izz); unused by the kinematic plant
    pose_error: np.ndarray  # [R_RC, p_RC, R_WC*, p_WC*]
    potential_gain: float  # k_p: the energy bound of Appendix C (1 for phi, kinematic)
    #: The error control's step limit [s]: the Drake loop's, decided in one place
    #: (:func:`~geovs_drake.goal.step_limit.step_limit`).
    max_step_size: float
    #: The pinhole camera's clock and measurement (:mod:`.sampled`); None: the exact y.
    sampled: SampledCamera | None = None
    #: Within these (position [m], rotation [rad]) a start counts as converged: a
    #: camera's are coarser (:func:`~geovs_drake.simulation.result.convergence_tolerance`).
    tolerance: tuple[float, float] = (CONVERGENCE_POSITION_M, CONVERGENCE_ROTATION_RAD)
    #: The loop's Drake integration scheme, as resolved: the engine steps with the pair
    #: of its order (``geovs_drake.batch._pairs.pair_for``), under its step limit.
    scheme: str = "runge_kutta3"
    #: A step at the step limit may be Bogacki-Shampine's (variable order), on the
    #: fifth-order pair only (the third-order one takes such steps anyway): the limit is
    #: within the share of RK3's stability bound at the goal that the step limit keeps
    #: (``geovs_drake.goal.step_limit.STABILITY_MARGIN``), so both pairs are stable
    #: there, and where the limit holds the step both meet the accuracy; the third-order
    #: step takes three evaluations against six.
    third_order_at_limit: bool = False


def loop_parameters(config: ScenarioConfig | ResolvedScenario) -> LoopParameters:
    """The parameter vectors of the systems of ``config``'s diagram (``config.plant``),
    resolved once (:func:`~geovs_drake.loop.resolver`).

    The engine runs the parts whose entries declare a batch kernel (the NF on the free
    rig with the exact sensor), and a camera model that draws nothing (the pinhole,
    sampled: :mod:`.sampled`): another raises ValueError.
    """
    # Here, not at the top: a sweep's workers get these parameters from the client and
    # run the kernels without importing the Drake systems (geovs_drake._lazy).
    from geovs_drake.loop import assemble_loop, resolve

    resolved = resolve(config)
    config = resolved.config
    if not config.controller.traits.batch_kernel:
        raise ValueError(
            f"the batch engine runs the NF's loops only: controller = {config.controller!r} "
            "(use simulate() or the Drake engine for other laws)"
        )
    if not config.carrier.traits.batch_kernel:
        raise ValueError(
            f"the batch engine runs the eye-in-hand free rig only: carrier = "
            f"{type(config.carrier).__name__} (use the Drake engine, sweep --engine drake, "
            "or simulate())"
        )
    traits = config.sensor.traits
    if not (traits.batch_kernel or (traits.camera and not traits.renders)):
        raise ValueError(
            f"the batch engine reads the exact y = c(H) or a pinhole camera; sensor "
            f"{type(config.sensor).__name__} runs through simulate()"
        )
    dynamic = config.dynamic
    diagram = assemble_loop(resolved, log=False).diagram
    root = diagram.CreateDefaultContext()

    def params(name: str) -> np.ndarray:
        system = diagram.GetSubsystemByName(name)
        return system.GetMyContextFromRoot(root).get_numeric_parameter(0).CopyToVector()

    nav = diagram.GetSubsystemByName("navigation_controller")
    camera = params("spherical_camera")
    X_WC_goal = config.X_WB @ config.X_BC_goal
    goal = np.concatenate([X_WC_goal.rotation().matrix().ravel(), X_WC_goal.translation()])
    sampled = None
    if not traits.batch_kernel:
        from geovs_drake.batch.sampled import camera_parameters

        sampled = camera_parameters(resolved, diagram, root, camera[CAMERA_OFFSET])
    return LoopParameters(
        plant=variant_name(config.plant),
        dynamic=dynamic,
        camera=camera,
        navigation=np.array(nav.navigation_parameters(nav.GetMyContextFromRoot(root))),
        controller=params("image_jacobian_force" if dynamic else "kinematic_controller"),
        body=np.array([config.carrier.mass, *config.carrier.inertia_diagonal], dtype=float),
        pose_error=np.concatenate([camera[CAMERA_OFFSET], goal]),
        potential_gain=config.control.potential_gain if dynamic else 1.0,
        max_step_size=resolved.step_limit.max_step_size,
        sampled=sampled,
        tolerance=convergence_tolerance(resolved),
        scheme=config.simulator.integration_scheme,
        third_order_at_limit=(
            pair_for(config.simulator.integration_scheme) is not BOGACKI_SHAMPINE
            and _third_order_at_limit(resolved.step_limit)
        ),
    )


def _third_order_at_limit(limit: StepLimit) -> bool:
    """The step limit is within the stability margin of RK3's bound at the goal."""
    from geovs_drake.goal.step_limit import STABILITY_MARGIN

    bound = limit.third_order_step
    return bound is not None and limit.max_step_size <= STABILITY_MARGIN * bound


@dataclass
class BatchResult:
    """Per-start outcome of :func:`run_batch` (arrays of length N)."""

    plant: str
    step: float  # the fixed step, NaN when error-controlled
    accuracy: float  # the error control's tolerance, NaN with a fixed step
    duration: float
    status_code: np.ndarray
    t_stop: np.ndarray  # when the start stopped (the horizon if it ran to the end)
    t_converged: np.ndarray  # after this time the pose error stayed within tolerance; NaN if not
    final_position_error_m: np.ndarray
    final_rotation_error_rad: np.ndarray
    min_margins: np.ndarray  # (N, 4): fov, lam_min, lam_max, occlusion (the exit state included)
    initial_lyapunov: np.ndarray  # E0 (dynamic) or phi0 (kinematic)
    max_lyapunov_ratio: np.ndarray  # max E / k_p (dynamic) or max phi (kinematic)
    max_lyapunov_rise: np.ndarray  # the largest increase over one step
    steps: np.ndarray  # accepted steps per start
    final_states: np.ndarray
    names: tuple[str, ...] = field(default=STATUS_NAMES)

    @property
    def status(self) -> np.ndarray:
        """Each start's status name (``converged``, ``not_converged``, ...)."""
        return np.array(self.names)[self.status_code]

    @property
    def monotone(self) -> np.ndarray:
        """The Lyapunov function never rose by more than the integrator's error:
        10x the accuracy (error-controlled) or 1e-7 (fixed step), relative to
        max(1, its initial value), as :class:`~geovs_drake.simulation.SimulationResult`."""
        tol = 10 * self.accuracy if math.isfinite(self.accuracy) else MONOTONE_TOLERANCE
        return self.max_lyapunov_rise <= tol * np.maximum(1.0, np.abs(self.initial_lyapunov))

    def counts(self) -> dict[str, int]:
        """The number of starts per status."""
        return {name: int(np.sum(self.status_code == k)) for k, name in enumerate(self.names)}


# The kernels' output layouts as compile-time integers (numba freezes module globals).
_NU = CAMERA_IMAGE.nu
_Y0, _Y1 = CAMERA_IMAGE.y.start, CAMERA_IMAGE.y.stop
_M0, _M1 = CAMERA_IMAGE.margins.start, CAMERA_IMAGE.margins.stop
_D0, _D1 = NAVIGATION.dphi.start, NAVIGATION.dphi.stop
_PHI = NAVIGATION.phi
_F0, _F1 = SERVO_FORCE.generalized.start, SERVO_FORCE.generalized.stop
_KINETIC = FREE_BODY.kinetic_energy
_POSE, _FREE_STATE, _KINEMATIC_STATE = 7, 13, 7


@njit(cache=True, error_model="numpy", nogil=True)
def _rhs(kinematic, x, out, p_cam, p_nav, p_ctrl, p_body):
    """The loop's xdot into ``out``; returns (nu, margins, phi, kinetic energy) at x.

    Dynamic: camera -> NF -> Eq. (45) force -> free rig. Kinematic: camera -> NF
    -> Tc^-1 (Eqs. 18-19) -> Eq. (17). One function for both, with a flag, so
    that numba caches it (a closure over the right-hand side would recompile in
    every process).
    """
    cam = _camera(x[0:_POSE], p_cam)
    y = cam[_Y0:_Y1]
    nav = _navigation(y, p_nav)
    if kinematic:
        xdot = _kinematic_body(x, _kinematic_velocity(y, nav[_D0:_D1], p_ctrl))
        for j in range(_KINEMATIC_STATE):
            out[j] = xdot[j]
        return cam[_NU], cam[_M0:_M1], nav[_PHI], 0.0
    force = _force(x, y, nav[_D0:_D1], p_ctrl)
    body = _free_body(x, force[_F0:_F1], p_body)
    for j in range(_FREE_STATE):
        out[j] = body[j]
    return cam[_NU], cam[_M0:_M1], nav[_PHI], body[_KINETIC]


@njit(cache=True, error_model="numpy", parallel=True)
def _integrate(
    kinematic,
    pair,
    low,
    low_at_cap,
    X0,
    p_cam,
    p_nav,
    p_ctrl,
    p_body,
    p_err,
    k_p,
    h0,
    max_step,
    accuracy,
    t_end,
    tol_p2,
    tol_r2,
):
    n, dim = X0.shape
    status = np.ones(n, np.int64)  # not_converged unless shown otherwise
    t_stop = np.full(n, t_end)
    t_conv = np.full(n, np.nan)
    err_p = np.full(n, np.nan)
    err_r = np.full(n, np.nan)
    min_m = np.full((n, 4), np.inf)
    L0 = np.full(n, np.nan)
    max_ratio = np.full(n, -np.inf)
    max_rise = np.zeros(n)
    steps = np.zeros(n, np.int64)
    final = X0.copy()
    adaptive = accuracy > 0
    stages = max(pair[1].shape[0], low[1].shape[0])
    for i in prange(n):
        x = X0[i].copy()
        xs = np.empty(dim)
        x_new = np.empty(dim)
        K = np.empty((stages, dim))
        d = np.empty(dim)
        nu, margins, phi, kinetic = _rhs(kinematic, x, d, p_cam, p_nav, p_ctrl, p_body)
        t = 0.0
        h = h0
        capped = False  # the last step was the step limit's, and the next one will be
        inside_since = np.nan  # the first time after which the pose error stayed small
        previous = 0.0
        while True:
            # Check the accepted state x from the values its first stage computed.
            status[i] = _state_status(x, nu, margins, phi)
            if status[i] == 2:  # left D: the margins say by how much (meaningless if nu <= 0)
                for j in range(4):
                    min_m[i, j] = min(min_m[i, j], margins[j])
            if status[i] != 1:
                t_stop[i] = t
                break
            for j in range(4):
                min_m[i, j] = min(min_m[i, j], margins[j])
            lyapunov = kinetic + k_p * phi
            if steps[i] == 0:
                L0[i] = lyapunov
            else:
                max_rise[i] = max(max_rise[i], lyapunov - previous)
            previous = lyapunov
            max_ratio[i] = max(max_ratio[i], lyapunov / k_p)
            e = _pose_error(x[0:_POSE], p_err)
            err_p[i] = math.sqrt(e[0])
            err_r[i] = 2.0 * math.asin(min(1.0, math.sqrt(e[1] / 8.0)))
            if e[0] > tol_p2 or e[1] > tol_r2:
                inside_since = np.nan
            elif math.isnan(inside_since):
                inside_since = t
            if t >= t_end:
                break
            # One step of the pair (first same as last, :mod:`._pairs`); a fixed h
            # when accuracy <= 0, else error-controlled like Drake's integrators. At the
            # step limit the low-order pair where allowed (``LoopParameters``): both
            # pairs meet the accuracy there, and it takes half the evaluations.
            for j in range(dim):
                K[0, j] = d[j]
            accepted = False
            while True:
                last = h >= t_end - t
                if last:
                    h = t_end - t
                h = min(h, max_step)
                A, B, E, exponent = low if capped else pair
                for s in range(1, B.shape[0]):
                    stage_point(A, s, x, h, K, xs)
                    _rhs(kinematic, xs, K[s], p_cam, p_nav, p_ctrl, p_body)
                solution(B, x, h, K, x_new)
                nu, margins, phi, kinetic = _rhs(kinematic, x_new, d, p_cam, p_nav, p_ctrl, p_body)
                grow = 1.0
                if adaptive:
                    outside = _state_status(x_new, nu, margins, phi) != 1
                    err = error_norm(E, x, h, K, d)
                    verdict, grow = step_control(err, accuracy, outside, h, exponent)
                    if verdict == RETRY:
                        h *= grow
                        capped = False
                        continue
                    if verdict == UNDERFLOW:
                        break  # no accurate step exists here: non_finite below
                    capped = low_at_cap and h == max_step and h * grow >= max_step
                accepted = True
                t = t_end if last and h == t_end - t else t + h
                h *= grow
                break
            if not accepted:  # the step size underflowed: no accurate step exists here
                status[i] = 4
                t_stop[i] = t
                break
            for j in range(dim):
                x[j] = x_new[j]
            steps[i] += 1
        final[i] = x
        if status[i] == 1 and not math.isnan(inside_since):
            status[i] = 0
            t_conv[i] = inside_since
    return status, t_stop, t_conv, err_p, err_r, min_m, L0, max_ratio, max_rise, steps, final


def run_batch(
    config: ScenarioConfig,
    X_BC: np.ndarray,
    twists: np.ndarray | None = None,
    duration: float | None = None,
    step: float | None = None,
    accuracy: float | None = None,
    parameters: LoopParameters | None = None,
    seeds: np.ndarray | None = None,
) -> BatchResult:
    """Integrate ``config``'s loop from N starts at once (module docstring).

    Args:
        config: the scenario; ``config.plant`` picks the plant.
        X_BC: initial camera poses in the target frame, (N, 4, 4).
        twists: initial camera body twists (Omega, V) in C, (N, 6) (dynamic only).
        duration: the horizon [s], ``config.duration`` by default.
        step: a fixed step [s]: no error control. By default the step is
            error-controlled per start.
        accuracy: the error control's tolerance, ``config.simulator.accuracy``
            by default (with ``step`` it is ignored).
        parameters: :func:`loop_parameters` of ``config``, to skip building its diagram.
        seeds: a pinhole camera's noise seed per start (N,), ``sensor.seed + i`` by
            default (:mod:`.sampled`); unused with the exact sensor.
    """
    duration = config.duration if duration is None else duration
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be finite and > 0: duration = {duration}")
    if step is not None and not (math.isfinite(step) and 0 < step <= duration):
        raise ValueError(f"step must be in (0, duration]: step = {step}")
    if accuracy is None:
        accuracy = config.simulator.accuracy
    if step is None and not (math.isfinite(accuracy) and 0 < accuracy < 1):
        raise ValueError(f"accuracy must be in (0, 1): accuracy = {accuracy}")
    p = parameters or loop_parameters(config)
    X0 = initial_body_states(config, X_BC, twists)
    # The step limit the Drake loop runs with (LoopParameters.max_step_size), the
    # stability bound of its scheme, which the pair of its order shares: Bogacki-
    # Shampine's third-order solution has RK3's stability polynomial, Dormand-Prince's
    # fifth-order one is RK5's.
    max_step = p.max_step_size if step is None else step
    h0 = min(DEFAULT_STEP, max_step) if step is None else step
    tol_p2 = p.tolerance[0] ** 2
    tol_r2 = 8.0 * math.sin(0.5 * p.tolerance[1]) ** 2
    names = STATUS_NAMES
    if p.sampled is not None:
        from geovs_drake.batch.sampled import run_sampled

        n = len(X0)
        seeds = p.sampled.seed + np.arange(n) if seeds is None else np.asarray(seeds)
        if seeds.shape != (n,):
            raise ValueError(f"seeds must have one entry per start ({n}): shape {seeds.shape}")
        settings = dict(
            h0=float(h0),
            max_step=float(max_step),
            accuracy=-1.0 if step is not None else float(accuracy),
            duration=float(duration),
            tol_p2=tol_p2,
            tol_r2=tol_r2,
            seeds=seeds,
        )
        out = run_sampled(not p.dynamic, X0, p, p.sampled, settings)
        names = (*STATUS_NAMES, "feature_lost")
    else:
        out = _exact(p, X0, h0, max_step, step, accuracy, duration, tol_p2, tol_r2)
    status, t_stop, t_conv, err_p, err_r, min_m, L0, max_ratio, max_rise, steps, final = out
    return BatchResult(
        plant=p.plant,
        step=float(step) if step is not None else float("nan"),
        accuracy=float(accuracy) if step is None else float("nan"),
        duration=float(duration),
        status_code=status,
        t_stop=t_stop,
        t_converged=t_conv,
        final_position_error_m=err_p,
        final_rotation_error_rad=err_r,
        min_margins=min_m,
        initial_lyapunov=L0,
        max_lyapunov_ratio=max_ratio,
        max_lyapunov_rise=max_rise,
        steps=steps,
        final_states=final,
        names=names,
    )


def _exact(p, X0, h0, max_step, step, accuracy, duration, tol_p2, tol_r2) -> tuple:
    """The exact sensor's run: :func:`_integrate` on ``p``'s vectors."""
    pair = pair_for(p.scheme)
    with numba.parallel_chunksize(PARALLEL_CHUNK):
        return _integrate(
            not p.dynamic,
            pair.kernel_args(),
            BOGACKI_SHAMPINE.kernel_args(),
            p.third_order_at_limit,
            X0,
            p.camera,
            p.navigation,
            p.controller,
            p.body,
            p.pose_error,
            float(p.potential_gain),
            float(h0),
            float(max_step),
            -1.0 if step is not None else float(accuracy),
            float(duration),
            tol_p2,
            tol_r2,
        )
