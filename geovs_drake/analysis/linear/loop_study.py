"""A loop with no closed-form model at the goal (the quadrotor's cascade): Drake's
``Linearize`` of the whole built loop at rest at the goal, checked against a
central-difference Jacobian of the loop's own time derivatives.

Where the carrier's state is a free body's (13: a quaternion first), the quaternion's
norm is a structural zero: the plant's state scales it and the pose does not change, so
it is a continuum of equilibria at rest (named and left out of the verdict, as
:mod:`geovs_drake.spectrum` does for an arm's self-motion).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import InputPortSelection, OutputPortSelection
from pydrake.systems.primitives import Linearize

from geovs_drake._json import json_ready
from geovs_drake.loop import build_loop, exact_twin, resolve
from geovs_drake.scenario import ScenarioConfig, variant_name
from geovs_drake.spectrum import EigenvalueFacts, continuum_modes

__all__ = ["QUATERNION_NORM", "LoopAtGoal", "linearize_loop_at_goal"]

#: What a free body's eigenvalue 0 along its quaternion is.
QUATERNION_NORM = (
    "the quaternion's norm (the plant's state scales it, the pose does not change): a "
    "continuum of equilibria"
)
#: The central difference's step on the loop's state.
_STEP = 1e-6


@dataclass
class LoopAtGoal(EigenvalueFacts):
    """Drake's A of the whole loop at rest at the goal (the carrier's own state), the
    largest entry of its difference from the central-difference Jacobian relative to A's
    largest, and the eigenvalues of A in the canonical order."""

    A_drake: np.ndarray
    finite_difference_error: float
    eigenvalues: np.ndarray
    carrier: str = ""
    plant: str = "dynamic"
    at_equilibrium: bool = True
    continuum: tuple[int, ...] = ()
    continuum_name: str | None = None

    def summary(self) -> dict:
        """As the free rig's linearisation reports it, A on the carrier's state, with the
        finite-difference check."""
        return json_ready(
            {
                "plant": self.plant,
                "carrier": self.carrier,
                "at_equilibrium": self.at_equilibrium,
                "A": self.A_drake,
                **self.eigenvalue_summary(),
                "finite_difference_relative_error": self.finite_difference_error,
            }
        )


def linearize_loop_at_goal(config: ScenarioConfig) -> LoopAtGoal:
    """Drake's ``Linearize`` of ``config``'s loop (its exact twin: a sampled camera has
    discrete state) at rest at the goal, and the central-difference check."""
    config = copy.deepcopy(exact_twin(config))
    config.initial = copy.deepcopy(config.goal)
    config.initial_velocity = [0.0] * 6
    loop = build_loop(resolve(config), log=False)
    diagram = loop.diagram
    context = diagram.CreateDefaultContext()
    loop.carrier.set_initial_state(context)
    x0 = context.get_continuous_state_vector().CopyToVector()
    A = Linearize(
        diagram,
        context,
        input_port_index=InputPortSelection.kNoInput,
        output_port_index=OutputPortSelection.kNoOutput,
    ).A()
    at_rest = float(np.max(np.abs(diagram.EvalTimeDerivatives(context).CopyToVector())))

    def derivatives(x: np.ndarray) -> np.ndarray:
        context.SetContinuousState(x)
        return diagram.EvalTimeDerivatives(context).CopyToVector()

    columns = [
        (derivatives(x0 + _STEP * e) - derivatives(x0 - _STEP * e)) / (2 * _STEP)
        for e in np.eye(len(x0))
    ]
    error = float(np.max(np.abs(A - np.column_stack(columns))) / np.max(np.abs(A)))
    directions = np.zeros((len(x0), 0))
    if len(x0) == 13:  # a free body's state: its quaternion first
        directions = np.concatenate([x0[0:4] / np.linalg.norm(x0[0:4]), np.zeros(9)])[:, None]
    eigenvalues, continuum = continuum_modes(A, directions)
    return LoopAtGoal(
        A_drake=A,
        finite_difference_error=error,
        eigenvalues=eigenvalues,
        carrier=variant_name(config.carrier),
        plant=variant_name(config.plant),
        at_equilibrium=at_rest < 1e-9,
        continuum=continuum,
        continuum_name=QUATERNION_NORM if continuum else None,
    )
