"""KinematicRigidBody: the first-order plant Gdot = G (Omega, V)^ of Eq. (17)."""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.kernels import for_scalar_type, kinematic_body
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems._template import template_system

__all__ = ["KinematicRigidBody", "KinematicRigidBody_", "pose_state"]


def pose_state(X_WC: RigidTransform) -> np.ndarray:
    """``[qw, qx, qy, qz, x, y, z]`` for a pose, the layout of the body_pose ports."""
    q = X_WC.rotation().ToQuaternion()
    return np.concatenate([[q.w(), q.x(), q.y(), q.z()], X_WC.translation()])


@template_system("KinematicRigidBody_")
def KinematicRigidBody_(T):
    _kinematic_body = for_scalar_type(kinematic_body, T)

    class Impl(LeafSystem_[T]):
        """A free body whose pose integrates a commanded body velocity on SE(3).

        .. pydrake_system::

            name: KinematicRigidBody
            input_ports:
            - camera_velocity
            output_ports:
            - body_pose

        Continuous state ``[qw, qx, qy, qz, x, y, z]`` = X_WC, the same layout
        as a MultibodyPlant free body's positions, so the same
        :class:`SphericalCamera` reads it. Dynamics (Eq. 17 with the target
        frame B fixed in W)::

            qdot = 1/2 q (x) (0, Omega),   pdot = R(q) V.

        Why a LeafSystem and not a MultibodyPlant: a kinematic plant has no
        mass, and a MultibodyPlant would need its velocities prescribed through
        a constraint or a stiff servo. This keeps the first-order loop exactly
        Eq. (17), with the quaternion's norm as its only redundant direction
        (a zero eigenvalue of the linearisation, as for the free body).
        ``body_pose`` depends on the state only, so the loop through the camera
        and controller has no algebraic loop.
        """

        def _construct(self, X_WC0: RigidTransform | None = None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            X_WC0 = RigidTransform() if X_WC0 is None else X_WC0
            self._defaults = (X_WC0,)
            self.DeclareContinuousState(BasicVector_[T](pose_state(X_WC0)))
            self.camera_velocity_input = self.DeclareVectorInputPort(name="camera_velocity", size=6)
            self.body_pose_output = self.DeclareVectorOutputPort(
                name="body_pose",
                size=POSE_SIZE,
                calc=self.CalcBodyPose,
                prerequisites_of_calc={self.xc_ticket()},
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def set_pose(self, context, X_WC: RigidTransform) -> None:
            """Set the state to the camera pose X_WC in ``context``."""
            context.SetContinuousState(pose_state(X_WC))

        def CalcBodyPose(self, context, output) -> None:
            output.SetFromVector(context.get_continuous_state_vector().CopyToVector())

        def DoCalcTimeDerivatives(self, context, derivatives) -> None:
            # Eq. (17), kinematic_body_derivative of geometry.rigid, as a kernel.
            derivatives.get_mutable_vector().SetFromVector(
                _kinematic_body(
                    context.get_continuous_state_vector().CopyToVector(),
                    self.camera_velocity_input.Eval(context),
                )
            )

    return Impl


KinematicRigidBody = KinematicRigidBody_[None]
