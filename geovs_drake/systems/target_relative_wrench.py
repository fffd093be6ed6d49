"""TargetRelativeWrench: a wrench-driven rig's dynamics relative to a moving target."""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem_

from geovs_drake.geometry.target_motion import adjoint, frame_wrench
from geovs_drake.systems._parameters import STATE_SIZE
from geovs_drake.systems._template import template_system
from geovs_drake.systems.target_motion import TWIST_SIZE, matrix_of_pose

__all__ = ["TargetRelativeWrench", "TargetRelativeWrench_"]


@template_system("TargetRelativeWrench_", T_list=[float])
def TargetRelativeWrench_(T):
    class Impl(LeafSystem_[T]):
        """The free rig in the target's frame: the frame's wrench, the feed-forward that
        cancels it, and the rig's state as the law reads it.

        .. pydrake_system::

            name: TargetRelativeWrench
            input_ports:
            - rig_state
            - generalized_force
            - target_twist
            - target_acceleration
            - twist_estimate
            - acceleration_estimate
            output_ports:
            - law_body_state
            - plant_generalized_force

        The rig's MultibodyPlant runs in the frame W' where the target stands still at
        ``X_WB0``: ``rig_state`` (13, ``[q, p, w, v]``) is the rig's pose and twist
        *relative to the target*, so its kinetic energy is the relative one.
        ``target_twist`` and ``target_acceleration`` are the target's true xi_B and its
        rate; ``twist_estimate`` the twist the loop believes (zero: no feed-forward) and
        ``acceleration_estimate`` its believed rate (the known motion's own along a
        trajectory; zero for a constant-twist estimate).

        ``plant_generalized_force`` is the law's ``generalized_force`` (torque about R's
        origin, then force, in W') plus, both rotated to W':

        * F_frame of the true motion
          (:func:`~geovs_drake.geometry.target_motion.frame_wrench`): the physics of a
          rigid body seen from the moving frame (its acceleration, Coriolis and
          centripetal terms), for the rig's ``mass`` and ``inertia`` about its centre;
        * the feed-forward ``-F_frame`` of the believed twist and its believed rate, at
          the relative twist the rig believes, ``V - Ad_{X_RB} xi_hat`` (V the rig's own
          twist in the world, from its odometry). With the known twist the two cancel
          and the relative dynamics are those of a still target: Appendix C's energy
          argument holds in the target's frame.

        ``law_body_state`` is the rig's state as the law reads it: the relative pose and
        that believed relative twist, in W' (the law damps it, Eq. 45). With no
        feed-forward it is the rig's own twist in the world, as the still target's law
        reads it; the lag it makes is :func:`geovs_drake.goal.linear_model.tracking_lag`'s.
        """

        def _construct(
            self,
            X_WB0: RigidTransform | None = None,
            mass: float = 1.0,
            inertia: tuple[float, float, float] = (0.02, 0.02, 0.02),
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            X_WB0 = RigidTransform() if X_WB0 is None else X_WB0
            self._defaults = (X_WB0, mass, tuple(inertia))
            self._X_WB0 = X_WB0.GetAsMatrix4()
            self._mass, self._inertia = float(mass), np.diag(np.asarray(inertia, dtype=float))
            self.rig_state_input = self.DeclareVectorInputPort("rig_state", STATE_SIZE)
            self.generalized_force_input = self.DeclareVectorInputPort("generalized_force", 6)
            self.target_twist_input = self.DeclareVectorInputPort("target_twist", TWIST_SIZE)
            self.target_acceleration_input = self.DeclareVectorInputPort(
                "target_acceleration", TWIST_SIZE
            )
            self.twist_estimate_input = self.DeclareVectorInputPort("twist_estimate", TWIST_SIZE)
            self.acceleration_estimate_input = self.DeclareVectorInputPort(
                "acceleration_estimate", TWIST_SIZE
            )
            self.law_body_state_output = self.DeclareVectorOutputPort(
                "law_body_state",
                STATE_SIZE,
                self.CalcLawBodyState,
                prerequisites_of_calc={
                    self.rig_state_input.ticket(),
                    self.target_twist_input.ticket(),
                    self.twist_estimate_input.ticket(),
                },
            )
            self.plant_generalized_force_output = self.DeclareVectorOutputPort(
                "plant_generalized_force",
                6,
                self.CalcPlantGeneralizedForce,
                prerequisites_of_calc={self.all_input_ports_ticket()},
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _terms(self, context) -> tuple:
            """(R_W'R, V_r in R, Ad_{X_RB}): the rig's rotation, its relative body twist
            and the map of the target's twist to R."""
            x = self.rig_state_input.Eval(context)
            X_WpR = matrix_of_pose(x[0:7])
            R = X_WpR[:3, :3]
            V_r = np.concatenate([R.T @ x[7:10], R.T @ x[10:13]])
            return R, V_r, adjoint(np.linalg.solve(X_WpR, self._X_WB0))

        def CalcLawBodyState(self, context, output) -> None:
            R, V_r, Ad = self._terms(context)
            x = self.rig_state_input.Eval(context)
            true = self.target_twist_input.Eval(context)
            believed = self.twist_estimate_input.Eval(context)
            V_law = V_r + Ad @ (true - believed)
            output.SetFromVector(np.concatenate([x[0:7], R @ V_law[:3], R @ V_law[3:]]))

        def CalcPlantGeneralizedForce(self, context, output) -> None:
            R, V_r, Ad = self._terms(context)
            true = Ad @ self.target_twist_input.Eval(context)
            rate = Ad @ self.target_acceleration_input.Eval(context)
            believed = Ad @ self.twist_estimate_input.Eval(context)
            believed_rate = Ad @ self.acceleration_estimate_input.Eval(context)
            V_believed = V_r + true - believed  # the odometry's twist less the belief
            J, m = self._inertia, self._mass
            F_R = frame_wrench(V_r, true, rate, J, m) - frame_wrench(
                V_believed, believed, believed_rate, J, m
            )
            F = self.generalized_force_input.Eval(context)
            output.SetFromVector(F + np.concatenate([R @ F_R[:3], R @ F_R[3:]]))

    return Impl


TargetRelativeWrench = TargetRelativeWrench_[None]
