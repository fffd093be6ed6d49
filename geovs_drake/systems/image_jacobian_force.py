"""ImageJacobianForce: the dynamic servo law F = C(y)^T dphi - B (Omega, V) of Eq. (45)."""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from geovs_drake.camera import image_jacobian
from geovs_drake.systems._common import (
    STATE_SIZE,
    camera_velocity,
    inputs_and_parameters,
    param_to_pose,
    pose_from_state,
    pose_to_param,
    set_output_or_nan,
)

__all__ = ["ImageJacobianForce", "ImageJacobianForce_", "servo_wrench"]


def servo_wrench(
    y: np.ndarray,
    dphi: np.ndarray,
    V_C: np.ndarray,
    radius: object,
    potential_gain: object,
    damping: np.ndarray,
) -> np.ndarray:
    """Eq. (45): ``F_C = k_p C(y)^T dphi - B (Omega, V)``, torque and force on the camera.

    Expressed in the camera frame C, about its origin Co: the pairing with
    the camera's body velocity ``(Omega, V)`` is the power. With ``(Omega, V) =
    -(omega, v)`` (Eq. 16), ``d/dt (k_p phi) = -(k_p C^T dphi) . (Omega, V)``,
    so the energy ``1/2 nu^T M nu + k_p phi`` decreases at the rate
    ``(Omega, V)^T B (Omega, V)``.
    """
    C = image_jacobian(y, radius)
    return potential_gain * (C.T @ dphi) - damping * V_C


@TemplateSystem.define("ImageJacobianForce_")
def ImageJacobianForce_(T):
    class Impl(LeafSystem_[T]):
        """The navigation-function force on the free camera rig (Appendix C).

        .. pydrake_system::

            name: ImageJacobianForce
            input_ports:
            - image_features
            - dphi
            - body_state
            output_ports:
            - generalized_force
            - wrench_C

        ``body_state`` is the rig's 13-vector free-body state (see
        :mod:`geovs_drake.systems._common`), from which the camera's body
        velocity ``(Omega, V) = G^-1 Gdot`` (Eq. 16) is formed at the camera
        frame C = X_RC on the rig.

        ``wrench_C`` is ``F_C = k_p C(y)^T dphi - B (Omega, V)`` of Eq. (45):
        torque and force on the camera about Co, in C. ``generalized_force`` is
        the same wrench in the plant's convention for a quaternion floating
        body: ``[tau_Ro_W, f_W]``, the torque about the rig origin Ro and the
        force, both in W, i.e. the shift of Appendix C.0.6 (``Ad*``), ready for
        MultibodyPlant's ``applied_generalized_force`` input.

        Numeric parameters: the radius rho, the potential gain k_p (the
        potential is ``k_p phi``), the diagonal damping B (6, rotational first)
        and X_RC.
        """

        def _construct(
            self,
            radius: float = 0.1,
            potential_gain: float = 1.0,
            damping: tuple[float, ...] | np.ndarray = (1.0,) * 6,
            X_RC: RigidTransform | None = None,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            X_RC = RigidTransform() if X_RC is None else X_RC
            damping = np.asarray(damping, dtype=float)
            if damping.shape != (6,) or np.any(damping < 0):
                raise ValueError(f"damping must be 6 non-negative numbers, got {damping}")
            self._defaults = (radius, potential_gain, damping, X_RC)
            self._radius_index = self.DeclareNumericParameter(BasicVector_[T]([radius]))
            self._gain_index = self.DeclareNumericParameter(BasicVector_[T]([potential_gain]))
            self._damping_index = self.DeclareNumericParameter(BasicVector_[T](damping))
            self._X_RC_index = self.DeclareNumericParameter(BasicVector_[T](pose_to_param(X_RC)))
            self.image_features_input = self.DeclareVectorInputPort(name="image_features", size=13)
            self.dphi_input = self.DeclareVectorInputPort(name="dphi", size=7)
            self.body_state_input = self.DeclareVectorInputPort(name="body_state", size=STATE_SIZE)
            self.generalized_force_output = self.DeclareVectorOutputPort(
                name="generalized_force",
                size=6,
                calc=self.CalcGeneralizedForce,
                prerequisites_of_calc=inputs_and_parameters(self),
            )
            self.wrench_C_output = self.DeclareVectorOutputPort(
                name="wrench_C",
                size=6,
                calc=self.CalcWrenchC,
                prerequisites_of_calc=inputs_and_parameters(self),
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _param(self, context, index):
            return context.get_numeric_parameter(index).CopyToVector()

        def set_damping(self, context, damping: np.ndarray) -> None:
            damping = np.asarray(damping, dtype=float)
            if damping.shape != (6,) or np.any(damping < 0):
                raise ValueError(f"damping must be 6 non-negative numbers, got {damping}")
            context.get_mutable_numeric_parameter(self._damping_index).SetFromVector(damping)

        def set_potential_gain(self, context, gain: float) -> None:
            if not gain > 0:
                raise ValueError(f"potential gain must be > 0, got {gain}")
            context.get_mutable_numeric_parameter(self._gain_index).SetAtIndex(0, gain)

        def CalcWrenchC(self, context, output) -> None:
            x = self.body_state_input.Eval(context)
            X_RC = self._param(context, self._X_RC_index)
            set_output_or_nan(
                output,
                lambda: servo_wrench(
                    self.image_features_input.Eval(context),
                    self.dphi_input.Eval(context),
                    camera_velocity(x, X_RC),
                    self._param(context, self._radius_index)[0],
                    self._param(context, self._gain_index)[0],
                    self._param(context, self._damping_index),
                ),
            )

        def CalcGeneralizedForce(self, context, output) -> None:
            F_C = self.wrench_C_output.Eval(context)
            x = self.body_state_input.Eval(context)
            R_WR, _ = pose_from_state(x[0:7])
            R_RC, p_RC = param_to_pose(self._param(context, self._X_RC_index))
            R_WC = R_WR @ R_RC
            tau_W, f_W = R_WC @ F_C[0:3], R_WC @ F_C[3:6]
            # Shift the torque from Co to the rig origin Ro: tau_Ro = tau_Co + p_RoCo x f.
            tau_Ro_W = tau_W + np.cross(R_WR @ p_RC, f_W)
            output.SetFromVector(np.concatenate([tau_Ro_W, f_W]))

    return Impl


ImageJacobianForce = ImageJacobianForce_[None]
