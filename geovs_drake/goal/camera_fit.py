"""Whether the loop's gains survive its camera: the goal's sampled-data model, checked
when a run starts (issue 31).

The NF's loop at the goal, in closed form (:mod:`geovs_drake.goal.linear_model`), splits at
the camera: the law's stiffness reads the held image, its damping the carrier's own
velocity, continuously. With the camera's displacement eps (in C, rotation first):

* free rig, dynamic (Eq. 45 on Eq. 46): ``M eps'' + s B eps' = -s K eps_held``, M the
  rig's spatial inertia at the camera, ``K = k_p C_chart^T H C_chart``;
* arm, dynamic: the same through ``J_C`` at the goal's joints,
  ``M(q*) dq'' + (s J^T B J + D_joint) dq' = -s J^T K J dq_held``
  (:class:`~geovs_drake.goal.arm.ArmGoalModel`);
* kinematic (free rig or arm, Eqs. 17-19): ``eps' = -s k C_chart^-1 H C_chart eps_held``.

The hold over a frame and the frames of latency make it a sampled loop
(:class:`~geovs_drake.goal.linear_model.SampledModel`); its spectral radius at the camera's
rate decides local stability. ``s`` scales the law's gains (k_p and B, or k), as the
arm's ``gain_scale`` does: :func:`camera_fit` finds the largest stable ``s``, and a run
whose gains keep less than :data:`GAIN_MARGIN` of it gets one warning line naming it.

The energy argument (Appendix C) needs continuous feedback; a held image breaks it, and
this local model is what is left to check.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from geovs_drake.goal.arm import arm_goal_model
from geovs_drake.goal.inputs import GoalInputs
from geovs_drake.goal.linear_model import (
    SampledModel,
    goal_stiffness,
    log_bisection,
    rig_spatial_inertia,
)
from geovs_drake.scenario import PREDICTIONS, variant_name

__all__ = ["GAIN_MARGIN", "CameraFit", "camera_fit", "goal_sampled_model"]

#: The factor by which a run's gains must stay below the largest stable ones at its
#: camera's rate and latency (a gain margin of 2, 6 dB, the classic figure): less, and
#: the run starts with a warning line.
GAIN_MARGIN = 2.0
#: The range of gain scales searched.
_SCALE_RANGE = (1e-4, 1e4)
#: How far below the margin a gain may sit and pass: the bisection's resolution, so that
#: the gain a warning suggests passes.
_MARGIN_TOLERANCE = 1e-6
#: The scan's ratio between neighbouring scales, then bisection steps on log(scale).
_SCAN_STEP = 1.05
_BISECTIONS = 30


def goal_sampled_model(
    resolved: GoalInputs, scale: float = 1.0, continuous: bool = False
) -> SampledModel | None:
    """The goal's closed-form model split at the camera (module docstring), the law's
    gains times ``scale``, ``continuous`` where a predictor feeds the law between frames;
    None where the closed form does not model the loop (a law other than the NF, the
    fixed camera)."""
    parts = _goal_parts(resolved)
    return None if parts is None else parts.split(scale, continuous)


@dataclass(frozen=True)
class _GoalParts:
    """The goal's closed form at scale 1: the inertia M (None: kinematic), the held
    stiffness K, the law's damping B and the damping that reads the carrier alone, and
    R, an orthonormal basis of the positions the image sees (the row space of J_C; the
    identity on the free rig).

    Why R: a redundant arm's self-motion (J_C's null space) has no stiffness, so its
    position is a pure integrator of the velocity, an eigenvalue 0 of A and 1 of the
    sampled loop, whose rounding would decide "stable". Nothing reads it (the image does
    not see it, the damping reads velocities), so the model keeps the positions in R
    and every velocity: the other eigenvalues are unchanged."""

    M: np.ndarray | None
    K: np.ndarray
    B: np.ndarray
    D_carrier: np.ndarray
    R: np.ndarray

    def scaled(self, factor: float) -> _GoalParts:
        """The same goal with the law's gains (K and B) times ``factor``."""
        return dataclasses.replace(self, K=factor * self.K, B=factor * self.B)

    def split(self, scale: float, continuous: bool = False) -> SampledModel:
        """The model at gains times ``scale``; ``continuous``: the law reads the image
        continuously (a predictor between frames), so the stiffness joins ``A_c`` and
        nothing is held."""
        model = self._split(scale)
        return model.continuous() if continuous else model

    def _split(self, scale: float) -> SampledModel:
        if self.M is None:  # kinematic: the held image is all there is
            n = len(self.K)
            return SampledModel(A_c=np.zeros((n, n)), B_n=np.eye(n), C_xi=-scale * self.K)
        n, m = self.R.shape  # velocities, seen positions
        M_inv = np.linalg.inv(self.M)
        A_c = np.zeros((m + n, m + n))
        A_c[:m, m:] = self.R.T  # z' = R^T v
        A_c[m:, m:] = -M_inv @ (scale * self.B + self.D_carrier)
        B_n = np.vstack([np.zeros((m, n)), M_inv])
        C_xi = np.hstack([-scale * self.K @ self.R, np.zeros((n, n))])
        return SampledModel(A_c=A_c, B_n=B_n, C_xi=C_xi)


def _goal_parts(resolved: GoalInputs) -> _GoalParts | None:
    config = resolved.config
    if not (resolved.law.traits.navigation and config.carrier.traits.goal_model):
        return None
    K1, KC = goal_stiffness(resolved)
    if not config.dynamic:
        KC = config.control.kinematic_gain * KC
        zero = np.zeros_like(KC)
        return _GoalParts(M=None, K=KC, B=zero, D_carrier=zero, R=np.eye(len(KC)))
    K = config.control.potential_gain * K1
    B = np.diag(resolved.damping)
    if config.carrier.traits.joints:
        goal = arm_goal_model(config)
        J = goal.J
        R = np.linalg.svd(J, full_matrices=False)[2].T  # the row space of J (nv x 6)
        return _GoalParts(M=goal.M, K=J.T @ K @ J, B=J.T @ B @ J, D_carrier=goal.D_joint, R=R)
    return _GoalParts(
        M=rig_spatial_inertia(config), K=K, B=B, D_carrier=np.zeros_like(B), R=np.eye(len(K))
    )


@dataclass(frozen=True)
class CameraFit:
    """The run's gains against its camera (:func:`camera_fit`): the camera's ``rate``
    [Hz] and ``latency_frames``, the sampled loop's ``spectral_radius`` with the run's
    gains, and ``largest_stable_scale``, the largest factor on the law's gains that
    keeps it below 1 for every factor between it and the run's (inf where every factor
    searched does; 0 where none does)."""

    carrier: str
    plant: str
    #: The field a user turns to scale the law's gains, and its value in this run: the
    #: arm's ``gain_scale`` (either plant), ``control.kinematic_gain`` (the kinematic free
    #: rig), or a factor on ``control.potential_gain`` and the damping (the dynamic free
    #: rig; 1).
    gain_name: str
    gain_value: float
    rate: float
    latency_frames: int
    #: The camera's ``prediction`` (:data:`~geovs_drake.scenario.PREDICTIONS`): with a
    #: continuous one the model is the continuous loop's, sampled at the camera's rate.
    prediction: str
    spectral_radius: float
    largest_stable_scale: float
    #: The goal's model the fit searched (at this run's gains), kept so that
    #: :meth:`rebased` moves the run's gains without a second search.
    model: _GoalParts | None = field(default=None, repr=False, compare=False)

    def rebased(self, factor: float) -> CameraFit:
        """The fit of the same loop with its gains times ``factor``: the spectral radius
        there, and the same largest stable gain (so the scale relative to the new gains
        is ``largest_stable_scale / factor``). What the resolver reports after it has
        chosen the arm's ``gain_scale: auto`` from this fit."""
        continuous = PREDICTIONS[self.prediction].continuous
        radius = self.model.split(factor, continuous).spectral_radius(
            self.rate, self.latency_frames
        )
        return dataclasses.replace(
            self,
            gain_value=self.gain_value * factor,
            spectral_radius=radius,
            largest_stable_scale=self.largest_stable_scale / factor,
            model=self.model.scaled(factor),
        )

    @property
    def stable(self) -> bool:
        """The model predicts the run's loop stable at the goal."""
        return self.spectral_radius < 1

    @property
    def largest_stable_gain(self) -> float:
        """The largest stable value of :attr:`gain_name` (the scale times this run's)."""
        return self.largest_stable_scale * self.gain_value

    @property
    def margin(self) -> float:
        """The gain margin: the largest stable scale over the run's (1 is the run's)."""
        return self.largest_stable_scale

    def warning(self) -> str | None:
        """One line where the run's gains keep less than :data:`GAIN_MARGIN` of the largest
        stable ones, naming the largest stable gain scale; None where they keep enough."""
        if self.margin >= GAIN_MARGIN * (1 - _MARGIN_TOLERANCE):  # the suggested gain: no warning
            return None
        verdict = (
            f"predicts the loop unstable (spectral radius {self.spectral_radius:.3g})"
            if not self.stable
            else f"leaves a gain margin of only {self.margin:.2g} (under {GAIN_MARGIN:g})"
        )
        if self.largest_stable_scale == 0:
            fix = "no scale of these gains down to 1e-4 is stable: raise the camera's rate"
        else:
            largest = self.largest_stable_gain
            fix = (
                f"the largest stable {self.gain_name} is {largest:.3g} (this run's: "
                f"{self.gain_value:g}); {self.gain_name} {largest / GAIN_MARGIN:.3g} keeps "
                f"a margin of {GAIN_MARGIN:g}"
            )
        return (
            f"the {self.rate:g} Hz camera, {self.latency_frames} frames late, on the "
            f"{self.plant} {self.carrier}: the sampled-data model at the goal {verdict}; {fix}"
        )


def camera_fit(resolved: GoalInputs) -> CameraFit | None:
    """The run's gains against its camera (:class:`CameraFit`), or None where the loop
    has no camera (the exact sensor) or the closed form does not model it. The resolver
    calls it once (:func:`~geovs_drake.loop.resolver`); a run reads ``resolved.camera_fit``."""
    camera = resolved.config.sensor
    parts = _goal_parts(resolved) if camera.traits.camera else None
    if parts is None:
        return None
    rate, latency = float(camera.rate), camera.model_latency_frames
    continuous = PREDICTIONS[camera.prediction].continuous

    def radius(scale: float) -> float:
        return parts.split(scale, continuous).spectral_radius(rate, latency)

    return CameraFit(
        carrier=variant_name(resolved.config.carrier),
        plant=variant_name(resolved.config.plant),
        **_gain_field(resolved),
        rate=rate,
        latency_frames=latency,
        prediction=camera.prediction,
        spectral_radius=radius(1.0),
        largest_stable_scale=_largest_stable_scale(radius),
        model=parts,
    )


def _gain_field(resolved: GoalInputs) -> dict:
    """The field that scales the law's gains in this run, and its value (:class:`CameraFit`)."""
    config = resolved.config
    if config.carrier.traits.gain_scale:
        return dict(gain_name="gain_scale", gain_value=resolved.gain_scale)
    if not config.dynamic:
        return dict(gain_name="control.kinematic_gain", gain_value=config.control.kinematic_gain)
    return dict(gain_name="factor on control.potential_gain and the damping", gain_value=1.0)


def _largest_stable_scale(radius) -> float:
    """The edge of the stable scales next to 1 (the stable set need not be one interval:
    a damping that grows with the scale can bring stability back): scanned in steps of
    :data:`_SCAN_STEP` up from 1 where 1 is stable, else down to the first stable
    scale; then bisection on log(scale) within the step."""
    low, high = _SCALE_RANGE
    if radius(1.0) < 1:
        stable = 1.0
        while radius(stable * _SCAN_STEP) < 1:
            stable *= _SCAN_STEP
            if stable >= high:
                return math.inf
        unstable = stable * _SCAN_STEP
    else:
        unstable = 1.0
        while radius(unstable / _SCAN_STEP) >= 1:
            unstable /= _SCAN_STEP
            if unstable <= low:
                return 0.0
        stable = unstable / _SCAN_STEP
    return log_bisection(lambda scale: radius(scale) < 1, stable, unstable, _BISECTIONS)
