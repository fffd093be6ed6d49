"""TargetMotion: the moving target's pose and twist, in closed form (issue 32) or along a
trajectory of poses."""

from __future__ import annotations

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import LeafSystem_
from pydrake.trajectories import PiecewisePose

from geovs_drake.geometry.target_motion import (
    body_twist_of_spatial,
    body_twist_rate_of_spatial,
    target_pose,
)
from geovs_drake.systems._parameters import POSE_SIZE
from geovs_drake.systems._template import template_system

__all__ = ["TargetMotion", "TargetMotion_", "matrix_of_pose", "pose_of_matrix"]

#: A twist's size, (omega, v).
TWIST_SIZE = 6


def matrix_of_pose(x: np.ndarray) -> np.ndarray:
    """The 4 x 4 pose of ``[qw, qx, qy, qz, x, y, z]`` (the quaternion normalised)."""
    q = np.asarray(x[0:4], dtype=float)
    X = np.eye(4)
    X[:3, :3] = RotationMatrix(Quaternion(q / np.linalg.norm(q))).matrix()
    X[:3, 3] = x[4:7]
    return X


def pose_of_matrix(X: np.ndarray) -> np.ndarray:
    """``[qw, qx, qy, qz, x, y, z]`` of a 4 x 4 pose."""
    q = RotationMatrix(np.asarray(X[:3, :3])).ToQuaternion()
    return np.concatenate([[q.w(), q.x(), q.y(), q.z()], X[:3, 3]])


@template_system("TargetMotion_", T_list=[float])
def TargetMotion_(T):
    class Impl(LeafSystem_[T]):
        """The target moving with a constant body twist, or along a trajectory of poses,
        and the world seen from it.

        .. pydrake_system::

            name: TargetMotion
            input_ports:
            - body_pose
            output_ports:
            - target_pose
            - target_twist
            - target_acceleration
            - world_body_pose

        ``target_pose`` is X_WB(t) = X_WB(0) exp(t xi_B^) as ``[q, p]`` (7), closed form
        (:func:`~geovs_drake.geometry.target_motion.target_pose`); ``target_twist`` is
        xi_B = (omega, v) in B, ``target_acceleration`` its rate (zero: constant).

        With ``trajectory`` (a ``PiecewisePose`` of X_B0B, the displacement from the
        start, in place of ``twist``) the target's pose is X_WB(t) = X_WB(0) X_B0B(t);
        its twist and acceleration are the trajectory's velocity and acceleration made
        the body's (:func:`~geovs_drake.geometry.target_motion.body_twist_of_spatial`,
        the same for X_WB as for X_B0B: X_WB(0) is constant), now functions of the time.
        Outside the trajectory's time span the target holds its pose there (the last
        from its end time on) with zero twist and acceleration.

        The loop runs in the target's frame: its carrier's pose ``body_pose`` is given in
        the frame W' where the target stands still at X_WB(0). ``world_body_pose`` is
        that body's pose in the world, ``X_WB(t) X_WB(0)^-1 X_W'R``: what the carrier's
        own odometry reads (the estimator's input). No state: the outputs are functions
        of the time (and the input), so a still target's loop is untouched by it.
        """

        def _construct(
            self,
            X_WB0: RigidTransform | None = None,
            twist: np.ndarray | None = None,
            trajectory: PiecewisePose | None = None,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            X_WB0 = RigidTransform() if X_WB0 is None else X_WB0
            if trajectory is not None and twist is not None:
                raise ValueError("give the target's twist or its trajectory, not both")
            self._defaults = (X_WB0, twist, trajectory)
            twist = np.zeros(TWIST_SIZE) if twist is None else np.asarray(twist, dtype=float)
            if twist.shape != (TWIST_SIZE,) or not np.all(np.isfinite(twist)):
                raise ValueError(f"twist must be 6 finite numbers (omega, v), got {twist!r}")
            self._X_WB0 = X_WB0.GetAsMatrix4()
            self._X_B0W = X_WB0.inverse().GetAsMatrix4()
            self._twist = twist
            self._trajectory = trajectory
            self.body_pose_input = self.DeclareVectorInputPort("body_pose", POSE_SIZE)
            time = {self.time_ticket()}
            # A constant twist depends on nothing: the loop's algebraic paths stay short.
            rates = time if trajectory is not None else {self.nothing_ticket()}
            self.target_pose_output = self.DeclareVectorOutputPort(
                "target_pose", POSE_SIZE, self.CalcTargetPose, prerequisites_of_calc=time
            )
            self.target_twist_output = self.DeclareVectorOutputPort(
                "target_twist", TWIST_SIZE, self.CalcTargetTwist, prerequisites_of_calc=rates
            )
            self.target_acceleration_output = self.DeclareVectorOutputPort(
                "target_acceleration",
                TWIST_SIZE,
                self.CalcTargetAcceleration,
                prerequisites_of_calc=rates,
            )
            self.world_body_pose_output = self.DeclareVectorOutputPort(
                "world_body_pose",
                POSE_SIZE,
                self.CalcWorldBodyPose,
                prerequisites_of_calc={self.time_ticket(), self.all_input_ports_ticket()},
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def X_WB(self, t: float) -> np.ndarray:
            """X_WB(t), the target's pose at time t (4 x 4)."""
            if self._trajectory is None:
                return target_pose(self._X_WB0, self._twist, t)
            trajectory = self._trajectory
            t = min(max(t, trajectory.start_time()), trajectory.end_time())
            return self._X_WB0 @ trajectory.GetPose(t).GetAsMatrix4()

        def end_time(self) -> float:
            """When the target stops [s]: its trajectory's end, inf for a constant twist."""
            return np.inf if self._trajectory is None else float(self._trajectory.end_time())

        def _moving(self, t: float) -> bool:
            """Whether t is inside the trajectory's span, where the target moves."""
            trajectory = self._trajectory
            return trajectory.start_time() <= t < trajectory.end_time()

        def CalcTargetPose(self, context, output) -> None:
            output.SetFromVector(pose_of_matrix(self.X_WB(context.get_time())))

        def xi_B(self, t: float) -> np.ndarray:
            """The target's body twist xi_B (6) at time t."""
            if self._trajectory is None:
                return self._twist.copy()
            if not self._moving(t):
                return np.zeros(TWIST_SIZE)
            R_B0B = self._trajectory.GetPose(t).rotation().matrix()
            return body_twist_of_spatial(R_B0B, self._trajectory.GetVelocity(t))

        def CalcTargetTwist(self, context, output) -> None:
            output.SetFromVector(self.xi_B(context.get_time()))

        def CalcTargetAcceleration(self, context, output) -> None:
            t = context.get_time()
            if self._trajectory is None or not self._moving(t):
                output.SetFromVector(np.zeros(TWIST_SIZE))
            else:
                trajectory = self._trajectory
                R_B0B = trajectory.GetPose(t).rotation().matrix()
                V, A = trajectory.GetVelocity(t), trajectory.GetAcceleration(t)
                output.SetFromVector(body_twist_rate_of_spatial(R_B0B, V, A))

        def CalcWorldBodyPose(self, context, output) -> None:
            X_WpR = matrix_of_pose(self.body_pose_input.Eval(context))
            X_WR = self.X_WB(context.get_time()) @ self._X_B0W @ X_WpR
            output.SetFromVector(pose_of_matrix(X_WR))

    return Impl


TargetMotion = TargetMotion_[None]
