"""ImageJacobianForce: the dynamic servo law F = C(y)^T dphi - B (Omega, V) of Eq. (45)."""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.kernels import for_scalar_type, servo_force, servo_force_wrench_into
from geovs_drake.systems._parameters import (
    STATE_SIZE,
    inputs_and_parameters,
    param_vector,
    pose_to_param,
)
from geovs_drake.systems._template import template_system

__all__ = ["ImageJacobianForce", "ImageJacobianForce_"]

# Layout of the one numeric parameter: radius, k_p, damping (6), X_RC (12).
_RADIUS, _GAIN, _DAMPING, _X_RC = 0, 1, slice(2, 8), slice(8, 20)


def _check_damping(damping) -> list[float]:
    d = np.asarray(damping, dtype=float)
    if d.shape != (6,) or not np.all(np.isfinite(d)) or np.any(d < 0):
        raise ValueError(f"damping must be 6 finite non-negative numbers, got {damping}")
    return d.tolist()


@template_system("ImageJacobianForce_")
def ImageJacobianForce_(T):
    _servo_force = for_scalar_type(servo_force, T)

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
            - potential_gain

        ``body_state`` is the rig's 13-vector free-body state (see
        :mod:`geovs_drake.systems._parameters`), from which the camera's body
        velocity ``(Omega, V) = G^-1 Gdot`` (Eq. 16) is formed at the camera
        frame C = X_RC on the rig. ``image_features`` is expected in I (the
        :class:`NavigationController` on the same y checks it; NaN passes
        through as NaN).

        ``wrench_C`` is ``F_C = k_p C(y)^T dphi - B (Omega, V)`` of Eq. (45):
        torque and force on the camera about Co, in C. ``generalized_force`` is
        the same wrench in the plant's convention for a quaternion floating
        body: ``[tau_Ro_W, f_W]``, the torque about the rig origin Ro and the
        force, both in W, i.e. the shift of Appendix C.0.6 (``Ad*``), ready for
        MultibodyPlant's ``applied_generalized_force`` input. ``potential_gain`` is
        k_p, the parameter itself (no input is read): a part whose energy term
        shares the potential, the arm's joint barrier, reads it there, so that one
        k_p rules both (:class:`ArmCamera`).

        One numeric parameter vector: ``[rho, k_p, B (6, rotational first),
        X_RC (12)]`` (the potential is ``k_p phi``); use
        :meth:`set_potential_gain` and :meth:`set_damping`, which validate.
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
            damping = _check_damping(damping)
            if not (math.isfinite(potential_gain) and potential_gain > 0):
                raise ValueError(f"potential gain must be finite and > 0, got {potential_gain}")
            self._defaults = (radius, potential_gain, damping, X_RC)
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T]([radius, potential_gain] + damping + pose_to_param(X_RC))
            )
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
            self.potential_gain_output = self.DeclareVectorOutputPort(
                name="potential_gain",
                size=1,
                calc=self.CalcPotentialGain,
                prerequisites_of_calc={self.all_parameters_ticket()},
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _set(self, context, where, values) -> None:
            v = context.get_mutable_numeric_parameter(self._params_index)
            full = v.CopyToVector()
            full[where] = values
            v.SetFromVector(full)

        def set_damping(self, context, damping: np.ndarray) -> None:
            """Set the damping B, diagonal on (Omega, V), rotational first, in ``context``;
            ValueError unless 6 finite non-negative numbers.
            """
            self._set(context, _DAMPING, _check_damping(damping))

        def set_potential_gain(self, context, gain: float) -> None:
            """Set k_p, the potential's gain (``k_p phi`` [J]), in ``context``; ValueError
            unless finite and > 0.
            """
            if not (math.isfinite(gain) and gain > 0):
                raise ValueError(f"potential gain must be finite and > 0, got {gain}")
            self._set(context, _GAIN, gain)

        def _force(self, context) -> tuple:
            """(*F_C, *tau_Ro_W, *f_W) by the generated kernel (compiled for floats)."""
            return _servo_force(
                self.body_state_input.Eval(context),
                self.image_features_input.Eval(context),
                self.dphi_input.Eval(context),
                param_vector(context, self._params_index, T),
            )

        def CalcWrenchC(self, context, output) -> None:
            if T is float:  # F_C written into the port's array (geometry.kernels)
                servo_force_wrench_into(
                    self.body_state_input.Eval(context),
                    self.image_features_input.Eval(context),
                    self.dphi_input.Eval(context),
                    param_vector(context, self._params_index, T),
                    output.get_mutable_value(),
                )
                return
            output.SetFromVector(self._force(context)[0:6])

        def CalcGeneralizedForce(self, context, output) -> None:
            output.SetFromVector(self._force(context)[6:12])

        def CalcPotentialGain(self, context, output) -> None:
            output.SetFromVector([param_vector(context, self._params_index, T)[_GAIN]])

    return Impl


ImageJacobianForce = ImageJacobianForce_[None]
