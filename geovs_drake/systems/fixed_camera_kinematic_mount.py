"""FixedCameraKinematicMount: a fixed camera and a kinematic target (Eqs. 16-17)."""

from __future__ import annotations

from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry._ops import namespace
from geovs_drake.geometry.rigid import fixed_camera_relative_pose, target_twist_from_camera
from geovs_drake.systems._parameters import POSE_SIZE, read
from geovs_drake.systems._template import template_system
from geovs_drake.systems.fixed_camera_mount import fixed_camera_param

__all__ = ["FixedCameraKinematicMount", "FixedCameraKinematicMount_"]


@template_system("FixedCameraKinematicMount_")
def FixedCameraKinematicMount_(T):
    class Impl(LeafSystem_[T]):
        """A camera fixed in the world; the target's body twist is commanded (eye-to-hand).

        .. pydrake_system::

            name: FixedCameraKinematicMount
            input_ports:
            - target_pose
            - camera_velocity
            output_ports:
            - camera_pose
            - target_velocity

        The first-order counterpart of :class:`FixedCameraMount`.
        ``target_pose`` is X_WB as ``[q_WB, p_WB]`` (a :class:`KinematicRigidBody`
        carrying the target); ``camera_pose`` is ``G = X_BC`` in the same layout,
        what :class:`SphericalCamera` (X_WB = X_RC = identity) reads as its rig
        pose. ``camera_velocity`` is a law's command ``(Omega, V) = G^-1 Gdot``;
        ``target_velocity`` is the target's body twist that realises it,
        ``-Ad_G (Omega, V)`` (Eq. 16: ``H^-1 Hdot = -Ad_G G^-1 Gdot``), the input
        of the target's :class:`KinematicRigidBody`. The relative pose then
        obeys Eq. (17), ``Gdot = G (Omega, V)^``, exactly as on the eye-in-hand
        loop. One numeric parameter vector: X_WC as ``[R_WC (9), p_WC (3), q_WC (4)]``.
        """

        def _construct(self, X_WC: RigidTransform | None = None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            X_WC = RigidTransform() if X_WC is None else X_WC
            self._defaults = (X_WC,)
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T](fixed_camera_param(X_WC))
            )
            self.target_pose_input = self.DeclareVectorInputPort(name="target_pose", size=POSE_SIZE)
            self.camera_velocity_input = self.DeclareVectorInputPort(name="camera_velocity", size=6)
            pose_ticket = self.input_port_ticket(self.target_pose_input.get_index())
            self.camera_pose_output = self.DeclareVectorOutputPort(
                name="camera_pose",
                size=POSE_SIZE,
                calc=self.CalcCameraPose,
                prerequisites_of_calc={pose_ticket, self.all_parameters_ticket()},
            )
            self.target_velocity_output = self.DeclareVectorOutputPort(
                name="target_velocity",
                size=6,
                calc=self.CalcTargetVelocity,
                prerequisites_of_calc={
                    pose_ticket,
                    self.input_port_ticket(self.camera_velocity_input.get_index()),
                    self.all_parameters_ticket(),
                },
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def CalcCameraPose(self, context, output) -> None:
            x = self.target_pose_input.Eval(context).tolist()
            p = read(context, self._params_index)
            output.SetFromVector(fixed_camera_relative_pose(x, p[12:16], p[9:12], namespace(x[0])))

        def CalcTargetVelocity(self, context, output) -> None:
            x = self.target_pose_input.Eval(context).tolist()
            twist = self.camera_velocity_input.Eval(context).tolist()
            p = read(context, self._params_index)
            output.SetFromVector(
                target_twist_from_camera(twist, x, p[0:9], p[9:12], namespace(x[0]))
            )

    return Impl


FixedCameraKinematicMount = FixedCameraKinematicMount_[None]
