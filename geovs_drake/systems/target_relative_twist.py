"""TargetRelativeTwist: a twist-driven camera's motion relative to a moving target."""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem_

from geovs_drake.geometry.target_motion import adjoint
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems._template import template_system
from geovs_drake.systems.target_motion import TWIST_SIZE, matrix_of_pose

__all__ = ["TargetRelativeTwist", "TargetRelativeTwist_"]


@template_system("TargetRelativeTwist_", T_list=[float])
def TargetRelativeTwist_(T):
    class Impl(LeafSystem_[T]):
        """The law's camera twist with the feed-forward, and the motion it makes
        relative to the target (the kinematic plant in the target's frame).

        .. pydrake_system::

            name: TargetRelativeTwist
            input_ports:
            - camera_velocity
            - body_pose
            - target_twist
            - twist_estimate
            output_ports:
            - relative_velocity
            - commanded_velocity

        ``camera_velocity`` is the law's (Omega, V) in C, relative to the target as the
        law means it; ``body_pose`` the camera's pose X_W'C in the frame W' where the
        target stands at ``X_WB0``; ``target_twist`` the target's true body twist xi_B,
        ``twist_estimate`` the one the loop believes (zero: no feed-forward).

        ``commanded_velocity`` is what the camera is driven with, in the world: the law's
        twist plus the believed target twist carried to C, ``Ad_{X_CB} xi_hat`` (the
        feed-forward). ``relative_velocity`` is the camera's twist relative to the target,
        ``commanded - Ad_{X_CB} xi_B`` (Eq. 17 in the target's frame: G = X_BC moves with
        the camera's twist less the target's): what a
        :class:`~geovs_drake.systems.KinematicRigidBody` of the relative pose integrates.
        With the known twist it is the law's own, as for a still target.
        """

        def _construct(self, X_WB0: RigidTransform | None = None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            X_WB0 = RigidTransform() if X_WB0 is None else X_WB0
            self._defaults = (X_WB0,)
            self._X_WB0 = X_WB0.GetAsMatrix4()
            self.camera_velocity_input = self.DeclareVectorInputPort("camera_velocity", 6)
            self.body_pose_input = self.DeclareVectorInputPort("body_pose", POSE_SIZE)
            self.target_twist_input = self.DeclareVectorInputPort("target_twist", TWIST_SIZE)
            self.twist_estimate_input = self.DeclareVectorInputPort("twist_estimate", TWIST_SIZE)
            inputs = {self.all_input_ports_ticket()}
            self.relative_velocity_output = self.DeclareVectorOutputPort(
                "relative_velocity", 6, self.CalcRelativeVelocity, prerequisites_of_calc=inputs
            )
            self.commanded_velocity_output = self.DeclareVectorOutputPort(
                "commanded_velocity", 6, self.CalcCommandedVelocity, prerequisites_of_calc=inputs
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _target_to_camera(self, context) -> np.ndarray:
            """Ad_{X_CB}: the target's twist in B to the same motion's twist in C."""
            X_WpC = matrix_of_pose(self.body_pose_input.Eval(context))
            return adjoint(np.linalg.solve(X_WpC, self._X_WB0))

        def CalcCommandedVelocity(self, context, output) -> None:
            Ad = self._target_to_camera(context)
            nu = self.camera_velocity_input.Eval(context)
            output.SetFromVector(nu + Ad @ self.twist_estimate_input.Eval(context))

        def CalcRelativeVelocity(self, context, output) -> None:
            Ad = self._target_to_camera(context)
            nu = self.camera_velocity_input.Eval(context)
            believed = self.twist_estimate_input.Eval(context)
            true = self.target_twist_input.Eval(context)
            output.SetFromVector(nu + Ad @ (believed - true))

    return Impl


TargetRelativeTwist = TargetRelativeTwist_[None]
