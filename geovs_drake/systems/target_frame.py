"""TargetFrame: a carrier that moves in the world, seen from a moving target."""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem_

from geovs_drake.geometry.target_motion import adjoint
from geovs_drake.systems._parameters import POSE_SIZE, STATE_SIZE
from geovs_drake.systems._template import template_system
from geovs_drake.systems.target_motion import TWIST_SIZE, matrix_of_pose, pose_of_matrix

__all__ = ["TargetFrame", "TargetFrame_"]


@template_system("TargetFrame_", T_list=[float])
def TargetFrame_(T):
    class Impl(LeafSystem_[T]):
        """The pose and state of a carrier's body R, which moves in the world W, in the
        frame W' of a moving target: what the camera system, the monitor and the laws
        read (issue 32, the arms).

        .. pydrake_system::

            name: TargetFrame
            input_ports:
            - world_pose
            - world_state
            - target_pose
            - twist_estimate
            output_ports:
            - body_pose
            - body_state
            - feedforward_twist

        W' is the frame where the target stands still at ``X_WB0`` (its pose at t = 0):
        ``X_W'W(t) = X_WB0 X_WB(t)^-1``, ``target_pose`` the target's X_WB(t) as
        ``[q, p]``. ``body_pose`` is ``X_W'R = X_W'W(t) X_WR`` of ``world_pose`` (7):
        the relative pose X_BR as a still target's loop reads it, so the camera map
        (Eq. 6), the safe domain and the logs are unchanged.

        ``body_state`` (13, a free body's layout ``[q, p, w, v]`` in W') is what a force
        law damps (Eq. 45): that pose, and R's twist relative to the target *as the loop
        believes it*, ``V_R - Ad_{X_RB} xi_hat`` in R (``world_state``'s twist made R's,
        ``twist_estimate`` the believed target twist xi_hat in B, zero without
        feed-forward), rotated to W'. It reads ``world_state`` (the carrier's own state
        in W, the same layout); a twist-driven carrier leaves it unconnected and never
        evaluates ``body_state``.

        ``feedforward_twist`` is that believed target twist carried to R,
        ``Ad_{X_RB} xi_hat`` (6, in R): the twist the carrier must have to move with the
        target (an arm's joint damping lets it pass,
        :class:`~geovs_drake.systems.ArmCamera`).

        Unlike the free rig's :class:`~geovs_drake.systems.TargetRelativeWrench`, the
        carrier here is simulated in the world, where its physics is (an arm's base
        stands on the ground): the target's motion reaches the loop through this view
        alone.
        """

        def _construct(self, X_WB0: RigidTransform | None = None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            X_WB0 = RigidTransform() if X_WB0 is None else X_WB0
            self._defaults = (X_WB0,)
            self._X_WB0 = X_WB0.GetAsMatrix4()
            self.world_pose_input = self.DeclareVectorInputPort("world_pose", POSE_SIZE)
            self.world_state_input = self.DeclareVectorInputPort("world_state", STATE_SIZE)
            self.target_pose_input = self.DeclareVectorInputPort("target_pose", POSE_SIZE)
            self.twist_estimate_input = self.DeclareVectorInputPort("twist_estimate", TWIST_SIZE)
            self.body_pose_output = self.DeclareVectorOutputPort(
                "body_pose",
                POSE_SIZE,
                self.CalcBodyPose,
                prerequisites_of_calc={
                    self.world_pose_input.ticket(),
                    self.target_pose_input.ticket(),
                },
            )
            self.body_state_output = self.DeclareVectorOutputPort(
                "body_state",
                STATE_SIZE,
                self.CalcBodyState,
                prerequisites_of_calc={
                    self.world_state_input.ticket(),
                    self.target_pose_input.ticket(),
                    self.twist_estimate_input.ticket(),
                },
            )

            self.feedforward_twist_output = self.DeclareVectorOutputPort(
                "feedforward_twist",
                TWIST_SIZE,
                self.CalcFeedforwardTwist,
                prerequisites_of_calc={
                    self.world_pose_input.ticket(),
                    self.target_pose_input.ticket(),
                    self.twist_estimate_input.ticket(),
                },
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _world_in_target(self, context) -> np.ndarray:
            """X_W'W(t) = X_WB0 X_WB(t)^-1 (4 x 4)."""
            X_WB = matrix_of_pose(self.target_pose_input.Eval(context))
            return self._X_WB0 @ np.linalg.inv(X_WB)

        def CalcBodyPose(self, context, output) -> None:
            X_WR = matrix_of_pose(self.world_pose_input.Eval(context))
            output.SetFromVector(pose_of_matrix(self._world_in_target(context) @ X_WR))

        def CalcFeedforwardTwist(self, context, output) -> None:
            X_WR = matrix_of_pose(self.world_pose_input.Eval(context))
            X_WpR = self._world_in_target(context) @ X_WR
            Ad = adjoint(np.linalg.solve(X_WpR, self._X_WB0))
            output.SetFromVector(Ad @ self.twist_estimate_input.Eval(context))

        def CalcBodyState(self, context, output) -> None:
            x = self.world_state_input.Eval(context)
            X_WR = matrix_of_pose(x[0:7])
            X_WpR = self._world_in_target(context) @ X_WR
            R_WR = X_WR[:3, :3]
            V_R = np.concatenate([R_WR.T @ x[7:10], R_WR.T @ x[10:13]])
            # Ad_{X_RB}: the target's twist in B to R; X_RB = X_W'R^-1 X_W'B = X_W'R^-1 X_WB0.
            Ad = adjoint(np.linalg.solve(X_WpR, self._X_WB0))
            V = V_R - Ad @ self.twist_estimate_input.Eval(context)
            R = X_WpR[:3, :3]
            output.SetFromVector(np.concatenate([pose_of_matrix(X_WpR), R @ V[:3], R @ V[3:]]))

    return Impl


TargetFrame = TargetFrame_[None]
