"""The lag behind a moving target without feed-forward, predicted for every law.

The NF's is closed form (:func:`geovs_drake.goal.linear_model.tracking_lag`); a baseline's
(PBVS, point IBVS, the sphere features) comes from Drake's ``Linearize`` of its own
closed loop (:func:`~geovs_drake.analysis.linear.linearization.linearize`). On the
kinematic free rig the loop runs in the target's frame, where the target's constant
body twist xi_B enters as the twist ``-nu_B``, ``nu_B = Ad_{X_C*B} xi_B``, added to the
law's command (Eq. 17 in the target's frame): exactly the study diagram's twist
disturbance. Its steady state, ``0 = A x + B u``, is the lag (Chaumette & Hutchinson
2007, Part II: ``e = b / lambda`` for ``e' = -lambda e + b``, with each law's own A).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from geovs_drake.analysis.linear.linearization import INPUTS, OUTPUTS, linearize
from geovs_drake.goal.linear_model import closed_form_refusal, velocity_adjoint
from geovs_drake.loop import ResolvedScenario, resolve
from geovs_drake.scenario import Kinematic, ScenarioConfig, Still

__all__ = ["kinematic_tracking_lag", "predicted_tracking_lag"]


def kinematic_tracking_lag(config: ScenarioConfig, twist_B: np.ndarray) -> np.ndarray:
    """The steady pose error (6: rotation, then position, as Linearize's ``pose_error``
    output) of ``config``'s law on the kinematic free rig behind a target moving with the
    constant body twist ``twist_B``, from Drake's ``Linearize`` of the still loop at the
    goal (module docstring). ValueError where ``linearize`` models no such loop."""
    # The study diagram's target stands still: the twist enters as its disturbance.
    config = dataclasses.replace(config, plant=Kinematic(), target_motion=Still())
    model = linearize(config).minimal
    A, B, C, D = model.A(), model.B(), model.C(), model.D()
    nu_B = velocity_adjoint(config.X_BC_goal.inverse()) @ np.asarray(twist_B, dtype=float)
    u = np.zeros(B.shape[1])
    u[INPUTS["disturbance"]] = -nu_B
    x = -np.linalg.solve(A, B @ u)
    return (C @ x + D @ u)[OUTPUTS["pose_error"]]


def predicted_tracking_lag(config: ScenarioConfig | ResolvedScenario) -> float | None:
    """``predicted_steady_error_m`` for every law: the position lag [m] behind the
    scenario's constant-twist target without feed-forward; the NF's closed form (either
    plant), a baseline's by :func:`kinematic_tracking_lag` (kinematic); None where no
    model covers the loop (a still target or a trajectory, a carrier other than the free
    rig, a baseline on the dynamic rig, the path follower)."""
    resolved = resolve(config)
    if resolved.law.traits.navigation:  # the closed form, the resolver's (simulate()'s own)
        return resolved.predicted_lag
    config = resolved.config
    motion = config.target_motion
    if not motion.traits.constant_twist or closed_form_refusal(config, "lag") is not None:
        return None
    # The path follower's law follows its plan in time: no constant-twist steady state.
    if config.dynamic or resolved.law.traits.plans:
        return None
    eps = kinematic_tracking_lag(config, np.asarray(motion.twist))
    return float(np.linalg.norm(eps[3:]))
