"""Whether the arm's gains stay inside its effort limits (issue 31): the largest gain
scale whose torques stay within the limits over the run's energy level set E <= E0 (E0 <
k_p: the states the run can reach), or over all of E < k_p.

Why: MultibodyPlant clamps each joint's torque at its effort limit, and a clamped torque
no longer does the work the energy argument counts on (Appendix C): over 1000 moving
starts on the UR5 at gain_scale 10 the one start that left D, and every start whose
energy rose, asked for 1.8 times or more of an effort limit at t = 0 (docs/arm.md).

The arm's torque (:class:`~geovs_drake.systems.ArmCamera`) at a state (q, v) splits by
how it scales with the law's gain scale s (k_p and B both times s)::

    tau(q, v) = -tau_g(q) + s a(q) - (s P(q) + D(q)) v

with ``-tau_g`` the gravity compensation, ``s a(q)`` the NF's wrench through J_C^T at
rest (and the joint barrier's, also times k_p), ``P = J_C^T B J_C / s`` and ``D`` the
damping that reads the joints alone (``B_q``, the model's own, a redundant arm's
``d N``). The level set ``E = 1/2 v^T M v + k_p phi < k_p`` holds, at each q, the
velocities of the ellipsoid ``1/2 v^T M v < k_p (1 - phi(q))``; over it the largest
``|tau_i|`` is exactly::

    |-tau_g,i + s a_i| + sqrt(2 k_p (1 - phi)) |M^-1/2 (s P + D)^T e_i|,

which grows with s. :func:`effort_fit` draws configurations of the level set (joint
positions near the goal's, within the limits, whose camera pose is in D), evaluates
``a`` and ``phi`` through the built loop itself (the diagram's own torque, not a second
formula), and bisects on s for the largest scale with every sampled torque inside its
limit. A sample is not the whole set: the scale it gives is an upper estimate (the set
may hold a worse configuration), which is why :data:`SAMPLES` is large.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from geovs_drake.goal.arm import (
    arm_goal_model,
    initial_joints,
    joint_names,
    model_joint_damping,
)
from geovs_drake.systems.arm_camera import null_space_projector

__all__ = ["SAMPLES", "EffortFit", "TorqueTerms", "effort_fit"]

#: Configurations of the level set drawn for the estimate, and the seed that draws them.
SAMPLES = 300
_SEED = 0
#: The half-width [rad] of the box about the goal's joints the configurations are drawn
#: from (cut by the joint limits): the level set's configurations on the goal's branch.
_BOX_RAD = 1.2
#: Configurations are drawn in batches; where under a tenth of a batch lies in the set,
#: the box halves (a small set about the goal). At most this many batches.
_BATCH, _BATCHES = 100, 40
_BISECTIONS = 40


@dataclass(frozen=True)
class EffortFit:
    """The arm's torques over the sub-level set E <= level k_p against its effort limits.

    ``gain_scale``: the run's; ``largest_scale``: the largest gain scale whose sampled
    torques stay within every joint's limit (inf where every scale up to 1e3 times the
    run's does, 0 where gravity alone breaks one); ``joint``: the joint that sets it;
    ``samples``: the configurations drawn; ``worst_ratio``: the largest ``|tau_i| /
    limit_i`` at the run's gain scale over the samples."""

    gain_scale: float
    #: The energy level checked, E / k_p (the run's start's E0 / k_p, or 1: every start).
    level: float
    largest_scale: float
    joint: str
    samples: int
    worst_ratio: float
    #: What the estimate was made of (the sampled configurations' torque terms, the
    #: effort limits, the gains at ``gain_scale``, the joints' names), kept so that
    #: :meth:`at` reads another gain scale without a second sampling.
    basis: _Basis | None = field(default=None, repr=False, compare=False)

    def at(self, gain_scale: float) -> EffortFit:
        """The same estimate at another gain scale: the same sampled configurations and
        level (so exact where the level does not depend on k_p: a start at rest), the
        worst ratio and the joint at ``gain_scale``."""
        basis = self.basis
        k_p = basis.k_p * gain_scale / self.gain_scale
        return _largest_scale(basis.rows, basis.limits, gain_scale, k_p, self.level, basis.names)

    @property
    def within(self) -> bool:
        """The run's torques stay inside the limits over the sampled level set."""
        return self.worst_ratio <= 1

    def warning(self) -> str | None:
        """One line where the run's gain scale asks more than an effort limit allows."""
        if self.within:
            return None
        return (
            f"the arm's torques over the energy level set E <= {self.level:.3g} k_p reach "
            f"{self.worst_ratio:.2g} times {self.joint}'s effort limit at gain_scale "
            f"{self.gain_scale:g}, where MultibodyPlant clamps them and the energy argument "
            f"no longer covers the run; gain_scale {self.largest_scale:.3g} keeps them "
            f"inside (carrier torque_limits: respect chooses it; {self.samples} sampled "
            "configurations)"
        )


def effort_fit(loop, level: float | None = None) -> EffortFit:
    """The loop's torques against the arm's effort limits over the sub-level set
    ``E <= level k_p`` (module docstring). ``loop`` is a dynamic arm's
    :class:`~geovs_drake.loop.Loop` with the exact sensor (the law read at each
    configuration's own y; :func:`~geovs_drake.loop.effort_check` builds it);
    ``level`` None is the run's own start's, ``E0 / k_p`` (E never rises above E0, so
    these are all the states the run can reach); 1 is every start the guarantee covers."""
    return _effort_fit(_ArmTorques(loop), level)


@dataclass(frozen=True)
class TorqueTerms:
    """The arm's torque at one configuration q split by how it scales with the gain scale
    s (module docstring): ``tau(s, v) = compensation + s a - (s P + D) v``; ``phi`` the
    NF's value there, ``M`` the mass matrix and ``M_inv`` its inverse."""

    compensation: np.ndarray
    a: np.ndarray
    phi: float
    M: np.ndarray
    P: np.ndarray
    D: np.ndarray
    M_inv: np.ndarray

    def torque(self, scale: float, v: np.ndarray) -> np.ndarray:
        """The torque at gain scale ``scale`` and joint velocity ``v``."""
        return self.compensation + scale * self.a - (scale * self.P + self.D) @ v

    def largest(self, scale: float, k_p: float, level: float) -> np.ndarray:
        """Each joint's largest ``|torque|`` over the velocities ``1/2 v^T M v <= k_p (level -
        phi)`` at gain scale ``scale`` (``k_p`` is that scale's)."""
        K = scale * self.P + self.D
        reach = np.sqrt(np.einsum("ij,jk,ik->i", K, self.M_inv, K))
        speed = math.sqrt(2 * k_p * max(level - self.phi, 0.0))
        return np.abs(self.compensation + scale * self.a) + speed * reach


class _ArmTorques:
    """A dynamic arm's loop with the exact sensor, read at configurations: the law at
    the true y (a camera's held frame is state, not the configuration's) with the run's
    gains and damping."""

    def __init__(self, loop) -> None:
        resolved = loop.resolved
        config = resolved.config
        if not (config.carrier.traits.effort_limits and config.dynamic):
            raise ValueError(
                f"effort_fit needs the dynamic arm, got {type(config.carrier).__name__} on "
                f"{type(config.plant).__name__}"
            )
        if config.sensor.traits.camera:
            raise ValueError(
                "effort_fit reads the law at each configuration's own y: build the loop with "
                f"the exact sensor, not {type(config.sensor).__name__}"
            )
        self.config = config
        self.loop = loop
        self.plant = loop.carrier.plant
        self.context = loop.diagram.CreateDefaultContext()
        self.plant_context = self.plant.GetMyMutableContextFromRoot(self.context)
        self.camera_context = loop.camera.GetMyContextFromRoot(self.context)
        self.navigation_context = loop.navigation.GetMyContextFromRoot(self.context)
        self.scale = resolved.gain_scale
        self.domain = resolved.domain
        self.B = np.diag(resolved.damping)
        nq = self.plant.num_positions()
        self.own = config.carrier.joint_damping * np.eye(nq) + np.diag(
            model_joint_damping(self.plant)
        )

    def terms(self, q: np.ndarray, bound: float = 1.0) -> TorqueTerms | None:
        """:class:`TorqueTerms` at q, None where the camera is not in D or phi > bound."""
        loop, plant, context = self.loop, self.plant, self.plant_context
        nq = plant.num_positions()
        plant.SetPositions(context, q)
        plant.SetVelocities(context, np.zeros(nq))
        margins = loop.camera.domain_margins_output.Eval(self.camera_context)
        if not np.all(margins > 0):
            return None
        phi = float(loop.navigation.phi_output.Eval(self.navigation_context)[0])
        if not 0 <= phi <= bound:
            return None
        rest = plant.get_actuation_input_port().Eval(context)
        compensation = -plant.CalcGravityGeneralizedForces(context)
        J = _camera_jacobian(plant, context)
        D = self.own
        if nq > 6:  # a redundant arm's self-motion damping (ArmCamera)
            D = D + self.config.carrier.null_space_damping * null_space_projector(J)
        M = plant.CalcMassMatrix(context)
        return TorqueTerms(
            compensation=compensation,
            a=(rest - compensation) / self.scale,
            phi=phi,
            M=M,
            P=J.T @ self.B @ J / self.scale,
            D=D,
            M_inv=np.linalg.inv(M),
        )


def _effort_fit(arm: _ArmTorques, level: float | None) -> EffortFit:
    config, plant = arm.config, arm.plant
    nq = plant.num_positions()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    k_p = config.control.potential_gain
    rows = []
    if level is None:  # the run's own start: in the set, and where E is largest
        start = arm.terms(initial_joints(config, arm.domain))
        if start is None:
            raise ValueError("the arm's start is not in D: no energy level to check")
        v0 = np.asarray(config.carrier.initial_joint_velocity or np.zeros(nq), dtype=float)
        level = start.phi + 0.5 * v0 @ start.M @ v0 / k_p
        rows.append(start)
    q_goal = arm_goal_model(config).q
    rng = np.random.default_rng(_SEED)
    box = _BOX_RAD
    for _ in range(_BATCHES):
        draws = (np.clip(q_goal + rng.uniform(-box, box, nq), lower, upper) for _ in range(_BATCH))
        kept = [t for t in (arm.terms(q, level) for q in draws) if t is not None]
        rows += kept
        if len(rows) >= SAMPLES:
            break
        if len(kept) < _BATCH // 10:  # a small set: draw closer to the goal
            box /= 2
    return _largest_scale(
        rows, plant.GetEffortUpperLimits(), arm.scale, k_p, level, joint_names(plant)
    )


def _camera_jacobian(plant, context) -> np.ndarray:
    from geovs_drake.systems.arm_model import CAMERA_FRAME, camera_jacobian

    return camera_jacobian(plant, context, plant.GetFrameByName(CAMERA_FRAME))


@dataclass(frozen=True)
class _Basis:
    """What an :class:`EffortFit` was estimated from (:meth:`EffortFit.at`)."""

    rows: tuple[TorqueTerms, ...]
    limits: np.ndarray
    k_p: float
    names: tuple[str, ...]


def _largest_scale(
    rows: list[TorqueTerms], effort: np.ndarray, s1: float, k_p1: float, level: float, names
) -> EffortFit:
    """Bisection on the gain scale s for the largest with every sampled joint's largest
    torque within its limit (the torques grow with s, so the set of good scales is an
    interval from 0)."""
    basis = _Basis(tuple(rows), effort, k_p1, tuple(names))

    def ratios(s: float) -> np.ndarray:
        return np.array([t.largest(s, k_p1 * s / s1, level) for t in rows]) / effort

    worst = ratios(s1)
    joint = names[int(np.argmax(worst.max(axis=0)))]
    if ratios(0.0).max() > 1:
        return EffortFit(s1, level, 0.0, joint, len(rows), float(worst.max()), basis)
    low, high = 0.0, 1e3 * s1
    if ratios(high).max() <= 1:
        return EffortFit(s1, level, math.inf, joint, len(rows), float(worst.max()), basis)
    for _ in range(_BISECTIONS):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if ratios(mid).max() <= 1 else (low, mid)
    at_edge = ratios(high).max(axis=0)
    return EffortFit(
        s1, level, low, names[int(np.argmax(at_edge))], len(rows), float(worst.max()), basis
    )
