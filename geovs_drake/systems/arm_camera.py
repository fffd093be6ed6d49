"""ArmCamera: the camera on a torque-driven arm, its state and the law's wrench as torques."""

from __future__ import annotations

import functools

import numpy as np
import pydrake.math as pm
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.geometry.arm_kernels import camera_torque
from geovs_drake.geometry.joint_barrier import joint_barrier, per_joint
from geovs_drake.geometry.target_motion import lie_bracket
from geovs_drake.systems._parameters import STATE_SIZE, param_vector
from geovs_drake.systems._template import template_system
from geovs_drake.systems.arm_model import (
    CAMERA_FRAME,
    ArmError,
    ArmModel,
    arm_plant,
    camera_jacobian,
    default_arm_model,
)
from geovs_drake.systems.arm_tree import ArmTree, ArmTreeError, CameraTerms, arm_tree

__all__ = [
    "FEEDFORWARD_MU",
    "NULL_SPACE_MU",
    "ArmCamera",
    "ArmCamera_",
    "actuation_permutation",
    "null_space_projector",
]

#: The damped least squares' mu in the null-space projector of a redundant arm,
#: N = I - J_C^T (J_C J_C^T + mu^2 I)^-1 J_C: symmetric with eigenvalues in (0, 1] at
#: any q (singular ones included), so the damping torque -d N v only dissipates.
NULL_SPACE_MU = 1e-3
#: The twist's dimension: an arm with more velocities than this is redundant.
_TWIST = 6
#: The damped least squares' mu of the feed-forward's joint motion v_ff = J_C^T (J_C
#: J_C^T + mu^2 I)^-1 V_ff: near a singularity of the arm (the UR5's wrist, on the slow
#: circle of docs/moving-target.md) the motion that follows the target asks unbounded
#: joint rates; damped, it fades there and the NF carries the camera.
FEEDFORWARD_MU = 0.01
#: The camera frame's origin, where J_C's velocities are taken (camera_jacobian's point).
_ORIGIN = np.zeros(3)
#: The joint step [rad] of the central difference that gives J_C's rate (its error is
#: of the step squared, below 1e-10 relative).
_JACOBIAN_STEP = 1e-5


def actuation_permutation(plant) -> np.ndarray:
    """The plant's actuation matrix B (nv x nu) when every joint has its own actuator (a
    permutation); ArmError naming the first joint without one otherwise."""
    B = plant.MakeActuationMatrix()
    if B.shape[0] != B.shape[1] or not np.allclose(np.abs(B).sum(axis=1), 1):
        unactuated = [
            plant.get_joint(j).name()
            for j in plant.GetJointIndices()
            if plant.get_joint(j).num_velocities() > 0
            and not np.any(B[plant.get_joint(j).velocity_start()])
        ]
        raise ArmError(
            "the arm's law needs an actuator on every joint: "
            f"{', '.join(unactuated) or 'the actuation matrix is not square'} has none"
        )
    return B


@template_system("ArmCamera_")
def ArmCamera_(T):
    class Impl(LeafSystem_[T]):
        """The interface between the camera's laws and a torque-driven arm (eye-in-hand).

        .. pydrake_system::

            name: ArmCamera
            input_ports:
            - arm_state
            - wrench_C
            - phi
            - potential_gain
            - feedforward_twist
            output_ports:
            - camera_state
            - actuation

        ``arm_state`` is the arm's MultibodyPlant state (q, v). ``camera_state``
        is the camera frame C's pose and spatial velocity in W in the layout of a
        free body's state ``[q_WC, p_WC, w_WC_W, v_WCo_W]``, so the camera system
        and the force laws, built with X_RC = identity, read it as they read the
        free rig's. ``wrench_C`` is the law's wrench on the camera (about Co, in
        C: Eq. 45 for the NF); ``actuation`` is the joint torque

            tau = J_C(q)^T F_C - tau_g(q) - B_q v,

        with J_C the camera frame's spatial-velocity Jacobian expressed in C
        (Drake's ``CalcJacobianSpatialVelocity``), so that J_C v = (Omega, V),
        the body twist of Eqs. (16)-(17); tau_g Drake's gravity generalized force
        (compensated); B_q a joint damping. The power J_C^T F_C . v equals
        F_C . (Omega, V): the arm receives exactly the power the free rig would,
        which is what keeps E = 1/2 v^T M(q) v + k_p phi non-increasing (the
        rig's M becomes the arm's M(q)).

        With a joint-limit barrier of width w > 0 (``joint_barrier_width``, rad: one
        for every joint, or one per joint, e.g. a fraction of each joint's range;
        :mod:`geovs_drake.geometry.joint_barrier`) the torque becomes

            tau = (1 - phi_q) J_C^T F_C - k_p (1 - phi) dphi_q/dq - tau_g - B_q v,

        reading the NF's value ``phi`` and k_p at ``potential_gain`` (the
        ImageJacobianForce's own, so one k_p rules the wrench and the barrier; both
        ports are read only then), so that E = 1/2 v^T M v + k_p phi_total,
        phi_total = 1 - (1 - phi)(1 - phi_q), does not increase: the arm stays off its
        limits as it stays in D. With w = 0 neither port is read nor need be
        connected.

        Behind a moving target, ``feedforward_twist`` is the camera twist (Omega, V) in C
        that the target's believed motion asks of it, ``Ad_{X_CB} xi_hat``
        (:class:`~geovs_drake.systems.TargetFrame`). The torque then adds the motion's
        own, Slotine and Li's ``M(q) a_r + C(q, v) v_ff`` for the joint motion that
        moves the camera with the target, ``v_ff = J_C^T (J_C J_C^T + mu^2 I)^-1
        (Omega, V)_ff`` (:data:`FEEDFORWARD_MU`), and the joint damping acts on
        ``v - v_ff``, not on v (``_feedforward``): otherwise the NF would hold a lag
        to push the arm's inertia and damping along the target's path. Unconnected it
        reads zero (a still target: the torque above).

        A redundant arm (nv > 6: the camera's pose fixes 6 of its joints) adds
        ``-d N v``, N = I - J_C^T (J_C J_C^T + mu^2 I)^-1 J_C (:data:`NULL_SPACE_MU`),
        the self-motion's damping: the potential does not act on the self-motion, so
        without it only B_q slows it. Its power ``-d v^T N v`` is never positive (N
        is symmetric, its eigenvalues in (0, 1]): E still does not increase.

        The arm's kinematics and dynamics come from this system's own model of
        the arm (a MultibodyPlant of its scalar type, as Drake's
        InverseDynamicsController keeps its own). For float the camera's state, J_C
        and tau_g come from the arm's compiled kinematics
        (:class:`~geovs_drake.systems.arm_tree.CameraTerms`, one kernel call a state,
        generated from that plant's tree), where the tree is
        one the kernels take; ``compiled=False``, another scalar type, or a tree they
        refuse (a branch, a ball joint) use Drake's ``CalcPose``,
        ``CalcSpatialVelocity``, ``CalcJacobianSpatialVelocity`` and
        ``CalcGravityGeneralizedForces`` on the private plant, the reference the
        compiled path is tested against. ``camera_state`` depends on
        ``arm_state`` only: no algebraic loop through the laws. One numeric
        parameter vector: B_q per joint [N m s/rad], then d [N m s/rad].
        """

        def _construct(
            self,
            model: ArmModel | None = None,
            joint_damping=None,
            joint_barrier_width: float | tuple[float, ...] = 0.0,
            null_space_damping: float = 0.0,
            compiled: bool = True,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            model = default_arm_model() if model is None else model
            self._plant = arm_plant(model, T)
            self._context = self._plant.CreateDefaultContext()
            # The arm state last seen (its bytes) and the camera_state computed there,
            # or None (float only: _set).
            self._last: tuple = (None, None)
            # The compiled kinematics (float), and whether the private context lags the
            # last state (set there only where Drake's own calls need it).
            tree = _tree(model) if T is float and compiled else None
            self._terms = None if tree is None else CameraTerms(tree)  # its own arrays
            self._context_behind = False
            self._camera = self._plant.GetFrameByName(CAMERA_FRAME)
            self._world = self._plant.world_frame()
            float_plant = arm_plant(model)
            # B^T tau as an index (B a permutation): actuator j drives velocity _actuated[j].
            self._B = actuation_permutation(float_plant)
            self._actuated = np.argmax(self._B, axis=0)
            self._identity = bool(np.array_equal(self._actuated, np.arange(len(self._actuated))))
            nq, nv = self._plant.num_positions(), self._plant.num_velocities()
            self._nq = nq
            damping = np.zeros(nv) if joint_damping is None else np.asarray(joint_damping)
            self._defaults = (model, damping, joint_barrier_width, null_space_damping, compiled)
            self._redundant = nv > _TWIST
            # The barrier's limits and widths are the model's: fixed, like the model
            # itself (a parameter would let them drift from the plant's). A scalar 0 is
            # no barrier; anything else must be a width > 0 for every joint.
            off = np.ndim(joint_barrier_width) == 0 and joint_barrier_width == 0
            self._barrier = (
                None
                if off
                else (
                    float_plant.GetPositionLowerLimits(),
                    float_plant.GetPositionUpperLimits(),
                    per_joint(joint_barrier_width, nq),
                )
            )
            # The plain torque (no barrier, no self-motion's damping) in one compiled call
            # on the compiled kinematics (a moving target's feed-forward aside).
            self._plain = self._terms is not None and self._barrier is None and not self._redundant
            self._tau = np.empty(nv)
            self._params_index = self.DeclareNumericParameter(
                BasicVector_[T](
                    np.append(np.broadcast_to(damping, (nv,)).astype(float), null_space_damping)
                )
            )
            self.arm_state_input = self.DeclareVectorInputPort(name="arm_state", size=nq + nv)
            self.wrench_C_input = self.DeclareVectorInputPort(name="wrench_C", size=6)
            self.phi_input = self.DeclareVectorInputPort(name="phi", size=1)
            self.potential_gain_input = self.DeclareVectorInputPort(name="potential_gain", size=1)
            self.feedforward_twist_input = self.DeclareVectorInputPort(
                name="feedforward_twist", size=_TWIST
            )
            state = self.input_port_ticket(self.arm_state_input.get_index())
            self.camera_state_output = self.DeclareVectorOutputPort(
                name="camera_state",
                size=STATE_SIZE,
                calc=self.CalcCameraState,
                prerequisites_of_calc={state},
            )
            self.actuation_output = self.DeclareVectorOutputPort(
                name="actuation",
                size=len(self._actuated),
                calc=self.CalcActuation,
                prerequisites_of_calc={
                    state,
                    self.input_port_ticket(self.wrench_C_input.get_index()),
                    self.input_port_ticket(self.phi_input.get_index()),
                    self.input_port_ticket(self.potential_gain_input.get_index()),
                    self.input_port_ticket(self.feedforward_twist_input.get_index()),
                    self.all_parameters_ticket(),
                },
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _set(self, context) -> np.ndarray:
            """The arm's state, its terms computed there; for float not again where they
            are at that state already (``camera_state`` and ``actuation`` read the same
            state within a step, and the monitor reads ``camera_state`` at the state the
            next step starts from). The compiled kinematics fill ``_terms`` (the private
            context is then set only where Drake's own calls need it:
            :meth:`_drake_context`); else the state goes into the private context, whose
            cached kinematics, and the camera state kept in ``_last``, serve them all."""
            x = self.arm_state_input.Eval(context)
            if T is float:
                key = x.tobytes()  # the exact values: a bytes compare costs 0.1 us
                if key == self._last[0]:
                    return x
                if self._terms is not None:
                    self._terms.at(x)
                    self._last = (key, self._terms.state)
                    self._context_behind = True
                    return x
                self._last = (key, None)
            self._plant.SetPositionsAndVelocities(self._context, x)
            return x

        def _drake_context(self, x: np.ndarray):
            """The private plant's context at the arm's state ``x`` (``_set``'s)."""
            if self._context_behind:
                self._plant.SetPositionsAndVelocities(self._context, x)
                self._context_behind = False
            return self._context

        def CalcCameraState(self, context, output) -> None:
            self._set(context)
            if self._last[1] is not None:  # computed at this state already (float)
                output.SetFromVector(self._last[1])
                return
            world = self._world
            X_WC = self._camera.CalcPose(self._context, world)
            V_WC = self._camera.CalcSpatialVelocity(self._context, world, world)
            # [q_WC, p_WC, w_WC_W, v_WCo_W]: the spatial velocity's coefficients are
            # rotational first, one array (three pieces, not four: 1 us a call).
            camera_state = np.concatenate(
                (X_WC.rotation().ToQuaternion().wxyz(), X_WC.translation(), V_WC.get_coeffs())
            )
            if T is float:
                self._last = (self._last[0], camera_state)
            output.SetFromVector(camera_state)

        def _feedforward(self, J_C, v, V_ff) -> tuple:
            """``(v_ff, tau_ff)``: the joint velocity that moves the camera with the
            believed target, ``v_ff = J_C^+ V_ff``, and the torque that motion takes,
            Slotine and Li's ``M(q) a_r + C(q, v) v_ff`` with the reference acceleration
            ``a_r = J_C^+ (V_ff' - J_C' v_ff)``. ``V_ff' = -[V_r, V_ff]`` is the rate of
            ``Ad_{X_CB} xi_hat`` for a constant believed twist, V_r = J_C v - V_ff the
            camera's twist relative to the target; ``J_C'`` is J_C's rate along the arm's
            motion, a central difference of J_C(q +- h v); ``C(q, v) v_ff`` the
            Christoffel form, by polarisation of Drake's bias term ``c(v) = C(q, v) v``:
            ``(c(v + v_ff) - c(v - v_ff)) / 4``. No believed motion (V_ff = 0) adds
            nothing; at a steady track (V_r = 0, v = v_ff) it is the torque of the
            arm's own motion, so the NF holds no lag against the arm's inertia."""
            plant, ctx = self._plant, self._context
            inverse = pm.inv(J_C @ J_C.T + FEEDFORWARD_MU**2 * np.eye(_TWIST))
            v_ff = J_C.T @ (inverse @ V_ff)
            q_v = plant.GetPositionsAndVelocities(ctx)
            q = plant.GetPositions(ctx)
            # J_C's rate along q' = v: a step of _JACOBIAN_STEP rad in q, both ways.
            h = _JACOBIAN_STEP / max(float(np.max(np.abs(v))), _JACOBIAN_STEP)
            jacobians = []
            for sign in (1.0, -1.0):
                plant.SetPositions(ctx, q + sign * h * v)
                jacobians.append(camera_jacobian(plant, ctx, self._camera))
            Jdot = (jacobians[0] - jacobians[1]) / (2.0 * h)
            plant.SetPositionsAndVelocities(ctx, q_v)
            rate = -lie_bracket(J_C @ v - V_ff, V_ff)
            a_r = J_C.T @ (inverse @ (rate - Jdot @ v_ff))
            M = plant.CalcMassMatrix(ctx)
            coriolis = []
            for sign in (1.0, -1.0):
                plant.SetVelocities(ctx, v + sign * v_ff)
                coriolis.append(plant.CalcBiasTerm(ctx))
            plant.SetPositionsAndVelocities(ctx, q_v)  # the arm's state back
            return v_ff, M @ a_r + 0.25 * (coriolis[0] - coriolis[1])

        def CalcActuation(self, context, output) -> None:
            x = self._set(context)
            if self._plain and not self.feedforward_twist_input.HasValue(context):
                # Every joint actuated (the usual arm): written into the port's array.
                tau = output.get_mutable_value() if self._identity else self._tau
                camera_torque(
                    self._terms.J_C,
                    self.wrench_C_input.Eval(context),
                    self._terms.tau_g,
                    param_vector(context, self._params_index, T),  # B_q first
                    x,
                    tau,
                )
                if not self._identity:
                    output.SetFromVector(tau[self._actuated])
                return
            q, v = x[: self._nq], x[self._nq :]  # the state is (q, v)
            if self._terms is not None:  # the compiled kinematics, at x
                J_C, tau = self._terms.J_C, -self._terms.tau_g
            else:
                J_C = self._plant.CalcJacobianSpatialVelocity(
                    self._context,
                    JacobianWrtVariable.kV,
                    self._camera,
                    _ORIGIN,
                    self._world,
                    self._camera,
                )  # camera_jacobian's, its arguments built once
                tau = -self._plant.CalcGravityGeneralizedForces(self._context)
            F_C = self.wrench_C_input.Eval(context)
            p = param_vector(context, self._params_index, T)
            damping, null_damping = p[:-1], p[-1]
            if self.feedforward_twist_input.HasValue(context):  # a moving target's
                self._drake_context(x)
                v_ff, tau_ff = self._feedforward(J_C, v, self.feedforward_twist_input.Eval(context))
                v = v - v_ff
                tau = tau + tau_ff
            tau = tau - damping * v
            if self._redundant:
                tau = tau - null_damping * (null_space_projector(J_C) @ v)
            if self._barrier is None:
                tau = tau + J_C.T @ F_C
            else:
                lower, upper, width = self._barrier
                k_p = self.potential_gain_input.Eval(context)[0]
                phi_q, dphi_q = joint_barrier(q, lower, upper, width, min if T is float else pm.min)
                phi = self.phi_input.Eval(context)[0]
                tau = tau + (1 - phi_q) * (J_C.T @ F_C) - k_p * (1 - phi) * np.asarray(dphi_q)
            # B a permutation: its inverse B^T picks tau's entries (none to pick for I).
            output.SetFromVector(tau if self._identity else tau[self._actuated])

    return Impl


ArmCamera = ArmCamera_[None]


@functools.lru_cache(maxsize=8)
def _tree(model: ArmModel) -> ArmTree | None:
    """``model``'s tree for the compiled kinematics (read once per model, as its plant),
    or None where the kernels refuse it (Drake's calls then)."""
    try:
        return arm_tree(model)
    except ArmTreeError:
        return None


def null_space_projector(J: np.ndarray, mu: float = NULL_SPACE_MU) -> np.ndarray:
    """N = I - J^T (J J^T + mu^2 I)^-1 J (nv x nv) for J (6 x nv), of any scalar type
    (pydrake.math's inverse): the damped projector on J's null space."""
    n = J.shape[1]
    return np.eye(n) - J.T @ pm.inv(J @ J.T + mu**2 * np.eye(J.shape[0])) @ J
