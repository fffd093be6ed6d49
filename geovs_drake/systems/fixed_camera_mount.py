"""FixedCameraMount: the frame bookkeeping of a fixed camera and a free target (Eq. 16)."""

from __future__ import annotations

from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry._ops import namespace
from geovs_drake.geometry.rigid import camera_state_in_target, target_wrench_from_camera
from geovs_drake.systems._parameters import STATE_SIZE, pose_to_param, read
from geovs_drake.systems._template import template_system

__all__ = ["FixedCameraMount", "FixedCameraMount_", "fixed_camera_param"]

# Layout of the one numeric parameter: X_WC as R_WC (9, row-major), p_WC, q_WC (wxyz).
_R_WC, _P_WC, _Q_WC = slice(0, 9), slice(9, 12), slice(12, 16)


def fixed_camera_param(X_WC: RigidTransform) -> list[float]:
    """``[R_WC row-major (9), p_WC (3), q_WC (4)]``: the camera's pose in W, as the
    mounts keep it (the quaternion for the relative pose, R for the wrench)."""
    return pose_to_param(X_WC) + X_WC.rotation().ToQuaternion().wxyz().tolist()


@template_system("FixedCameraMount_")
def FixedCameraMount_(T):
    class Impl(LeafSystem_[T]):
        """A camera fixed in the world, looking at the free target body (eye-to-hand).

        .. pydrake_system::

            name: FixedCameraMount
            input_ports:
            - target_state
            - wrench_C
            output_ports:
            - camera_state
            - generalized_force

        Eq. (16), ``G = H^-1``, makes eye-in-hand and fixed-camera servoing
        one problem: the laws only see the relative pose. This system is the
        whole difference. ``target_state`` is the target's MultibodyPlant
        free-body state (pose X_WB, then w_WB_W and v_WBo_W). ``camera_state``
        is the camera's pose and velocity relative to the target, in the
        layout of a rig state whose world is B and whose camera is at the rig's
        origin (:func:`~geovs_drake.geometry.rigid.camera_state_in_target`), so
        :class:`SphericalCamera`, :class:`ImageJacobianForce` and
        :class:`VelocityTrackingForce`, built with X_WB = X_RC = identity, read
        it unchanged. ``wrench_C`` is the wrench those laws put out for the
        camera (about Co, in C); ``generalized_force`` is its reaction on the
        target, ``[tau_Bo_W, f_W]`` for the plant
        (:func:`~geovs_drake.geometry.rigid.target_wrench_from_camera`), which
        delivers the same power, ``F_C . (Omega, V)``.

        ``camera_state`` depends on ``target_state`` only, so the loop through
        the laws back into ``wrench_C`` is not algebraic. One numeric parameter
        vector: X_WC as ``[R_WC (9), p_WC (3), q_WC (4)]``.
        """

        def _construct(self, X_WC: RigidTransform | None = None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            X_WC = RigidTransform() if X_WC is None else X_WC
            self._defaults = (X_WC,)
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T](fixed_camera_param(X_WC))
            )
            self.target_state_input = self.DeclareVectorInputPort(
                name="target_state", size=STATE_SIZE
            )
            self.wrench_C_input = self.DeclareVectorInputPort(name="wrench_C", size=6)
            state_ticket = self.input_port_ticket(self.target_state_input.get_index())
            self.camera_state_output = self.DeclareVectorOutputPort(
                name="camera_state",
                size=STATE_SIZE,
                calc=self.CalcCameraState,
                prerequisites_of_calc={state_ticket, self.all_parameters_ticket()},
            )
            self.generalized_force_output = self.DeclareVectorOutputPort(
                name="generalized_force",
                size=6,
                calc=self.CalcGeneralizedForce,
                prerequisites_of_calc={
                    state_ticket,
                    self.input_port_ticket(self.wrench_C_input.get_index()),
                    self.all_parameters_ticket(),
                },
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def X_WC_param(self, context) -> list:
            """``[R_WC (9), p_WC (3), q_WC (4)]`` in this context."""
            return read(context, self._params_index)

        def CalcCameraState(self, context, output) -> None:
            x = self.target_state_input.Eval(context).tolist()
            p = read(context, self._params_index)
            output.SetFromVector(camera_state_in_target(x, p[_Q_WC], p[_P_WC], namespace(x[0])))

        def CalcGeneralizedForce(self, context, output) -> None:
            x = self.target_state_input.Eval(context).tolist()
            F_C = self.wrench_C_input.Eval(context).tolist()
            p = read(context, self._params_index)
            output.SetFromVector(target_wrench_from_camera(F_C, x, p[_R_WC], p[_P_WC]))

    return Impl


FixedCameraMount = FixedCameraMount_[None]
