"""VelocityTrackingForce: F = B (nu_cmd - nu), a commanded body twist on the free rig."""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.kernels import for_scalar_type, tracking_force
from geovs_drake.systems._parameters import (
    STATE_SIZE,
    inputs_and_parameters,
    param_vector,
    pose_to_param,
)
from geovs_drake.systems._template import template_system

__all__ = ["VelocityTrackingForce", "VelocityTrackingForce_", "check_tracking_gains"]

# Layout of the one numeric parameter: B (6), X_RC (12).
_GAINS, _X_RC = slice(0, 6), slice(6, 18)


def check_tracking_gains(gains) -> list[float]:
    """The 6 diagonal entries of B as floats; ValueError unless finite and > 0."""
    b = np.asarray(gains, dtype=float)
    if b.shape != (6,) or not np.all(np.isfinite(b)) or np.any(b <= 0):
        raise ValueError(f"tracking gains must be 6 finite numbers > 0, got {gains}")
    return b.tolist()


@template_system("VelocityTrackingForce_")
def VelocityTrackingForce_(T):
    _tracking_force = for_scalar_type(tracking_force, T)

    class Impl(LeafSystem_[T]):
        """The wrench that makes the rig's camera track a commanded body twist.

        .. pydrake_system::

            name: VelocityTrackingForce
            input_ports:
            - camera_velocity_command
            - body_state
            output_ports:
            - generalized_force
            - wrench_C

        Every law that commands a camera twist ``(Omega, V)`` (the kinematic
        laws: Eqs. 18-19, the baselines, path following) runs on the dynamic
        plant through this one system, so two laws on that plant differ by
        their law only. ``wrench_C`` is ``F_C = B ((Omega, V)_cmd - (Omega,
        V))`` on the camera about Co, in C, where ``(Omega, V) = G^-1 Gdot``
        (Eq. 16) is formed from ``body_state`` (the rig's 13-vector) at the
        camera frame C = X_RC. Per axis, on a rig whose camera sits at its
        centre of mass, this is the first-order lag ``m nudot = B (nu_cmd -
        nu)`` with time constants ``m / B_i`` (``I_i / B_i`` for rotation).
        ``generalized_force`` is the same wrench as ``[tau_Ro_W, f_W]``, the
        plant's convention (see :class:`ImageJacobianForce`).

        One numeric parameter vector: ``[B (6, rotational first), X_RC (12)]``.
        """

        def _construct(
            self,
            gains: tuple[float, ...] | np.ndarray = (1.0,) * 6,
            X_RC: RigidTransform | None = None,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            X_RC = RigidTransform() if X_RC is None else X_RC
            gains = check_tracking_gains(gains)
            self._defaults = (gains, X_RC)
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T](gains + pose_to_param(X_RC))
            )
            self.camera_velocity_command_input = self.DeclareVectorInputPort(
                name="camera_velocity_command", size=6
            )
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

        def set_gains(self, context, gains: np.ndarray) -> None:
            """Set the diagonal of B (rotational first); validated."""
            v = context.get_mutable_numeric_parameter(self._params_index)
            full = v.CopyToVector()
            full[_GAINS] = check_tracking_gains(gains)
            v.SetFromVector(full)

        def _force(self, context) -> tuple:
            return _tracking_force(
                self.body_state_input.Eval(context),
                self.camera_velocity_command_input.Eval(context),
                param_vector(context, self._params_index, T),
            )

        def CalcWrenchC(self, context, output) -> None:
            output.SetFromVector(self._force(context)[0:6])

        def CalcGeneralizedForce(self, context, output) -> None:
            output.SetFromVector(self._force(context)[6:12])

    return Impl


VelocityTrackingForce = VelocityTrackingForce_[None]
