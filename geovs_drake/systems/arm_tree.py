"""The arm's kinematic tree, read once from its MultibodyPlant, for the compiled kernels.

:func:`arm_tree` reads the plant the package builds for the arm
(:func:`~geovs_drake.systems.arm_model.arm_plant`), so any model file the ``Arm``
carrier accepts works: one moving body per revolute or prismatic joint, welded bodies
folded into the moving body they hang on (their inertia shifted and summed), and per
joint its parent, the fixed transforms X_PF (parent body to the joint's frame F) and
X_MB (the joint's child frame M to the body), its axis, the body's spatial inertia
(Drake's ``default_spatial_inertia``), the joint's damping, the reflected rotor inertia
of its actuator (``default_reflected_inertia``), its effort, position and velocity
limits, and the camera frame's X_BC on its body. All as plain float64 and int64 arrays
(:class:`ArmTree`), which :mod:`geovs_drake.geometry.arm_kernels` takes.

It refuses, in one line naming the joint (:class:`ArmTreeError`, an
:class:`~geovs_drake.systems.arm_model.ArmError`: exit 2 from the CLI), what the
kernels cannot take: a joint that is not revolute, prismatic or welded (a floating,
ball or planar joint), a closed chain (the plant's constraints: loop welds, a mimic's
coupler; a body with two parent joints, which Drake's Finalize refuses first), a joint
off the one chain from the world to the camera (a branch), or a camera on no moving
body.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, SpatialInertia

from geovs_drake.geometry import arm_kernels as _k
from geovs_drake.systems.arm_model import CAMERA_FRAME, ArmError, ArmModel, arm_plant

__all__ = [
    "JOINT_COLUMNS",
    "ArmTree",
    "ArmTreeError",
    "CameraTerms",
    "arm_tree",
    "warm_arm_kernels",
]

#: The columns of :attr:`ArmTree.joint`, per joint.
JOINT_COLUMNS = ("damping", "reflected_inertia", "effort_limit", "lower", "upper", "velocity")
_KINDS = {"revolute": _k.KIND_REVOLUTE, "prismatic": _k.KIND_PRISMATIC}


class ArmTreeError(ArmError):
    """The arm's tree is not one the generated kernels take (the message names the joint)."""


@dataclass(frozen=True)
class ArmTree:
    """The arm's tree as arrays, one row per moving body (= its joint), parents first.

    ``parent`` (n, int64; -1: the world); ``index`` (n x 2, int64): the joint's
    position and velocity index in the plant's q and v; ``kind`` (n, int64:
    :data:`~geovs_drake.geometry.arm_kernels.KIND_REVOLUTE` or ``KIND_PRISMATIC``);
    ``frames`` (n x 24): R_PF (9, row-major), p_PF, R_MB (9), p_MB, with P the parent's
    moving body (or W, the base's weld folded in); ``axis`` (n x 3, unit, in F);
    ``inertia`` (n x 13): m, p_BoBcm_B, I_BBo_B (9) of the body and everything welded to
    it; ``joint`` (n x 6): :data:`JOINT_COLUMNS`; ``camera_body`` and ``X_BC`` (R_BC (9),
    p_BC) the camera frame on its moving body; ``gravity`` (3) g in W [m/s^2].
    """

    joint_names: tuple[str, ...]
    parent: np.ndarray
    index: np.ndarray
    kind: np.ndarray
    frames: np.ndarray
    axis: np.ndarray
    inertia: np.ndarray
    joint: np.ndarray
    camera_body: int
    X_BC: np.ndarray
    gravity: np.ndarray

    @property
    def nv(self) -> int:
        """The number of joints (= positions = velocities)."""
        return int(self.parent.shape[0])

    def kernel_args(self) -> tuple:
        """The arrays in the kernels' order: (parent, index, kind, frames, axis, inertia,
        joint, camera_body, X_BC, gravity)."""
        return (
            self.parent, self.index, self.kind, self.frames, self.axis, self.inertia,
            self.joint, self.camera_body, self.X_BC, self.gravity,
        )  # fmt: skip

    def workspace(self) -> np.ndarray:
        """A fresh workspace for the kernels (n x WS_COLUMNS)."""
        return np.zeros((self.nv, _k.WS_COLUMNS))

    def _forward(self, q: np.ndarray) -> np.ndarray:
        ws = self.workspace()
        q = np.ascontiguousarray(q, dtype=float)
        _k.arm_forward(q, self.parent, self.index, self.kind, self.frames, self.axis, ws)
        return ws

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) (nv x nv), as Drake's ``CalcMassMatrix`` (allocating: for checks)."""
        ws = self._forward(q)
        M = np.empty((self.nv, self.nv))
        _k.mass_matrix(self.parent, self.index, self.inertia, self.joint, ws, M)
        return M

    def inverse_dynamics(self, q: np.ndarray, v: np.ndarray, gravity: bool) -> np.ndarray:
        """C(q, v) v - tau_g(q) (``gravity``) or C(q, v) v alone (Drake's
        ``CalcBiasTerm``); with v = 0 and gravity, -tau_g (Drake's
        ``CalcGravityGeneralizedForces``, negated)."""
        ws = self._forward(q)
        tau = np.empty(self.nv)
        g = self.gravity if gravity else np.zeros(3)
        v = np.ascontiguousarray(v, dtype=float)
        _k.inverse_dynamics(v, self.parent, self.index, self.inertia, g, ws, tau)
        return tau

    def camera_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R_WC, p_WC) at q."""
        ws = self._forward(q)
        R_WC, p_WC = np.empty((3, 3)), np.empty(3)
        _k.camera_pose(self.camera_body, self.X_BC, ws, R_WC, p_WC)
        return R_WC, p_WC

    def camera_jacobian(self, q: np.ndarray) -> np.ndarray:
        """J_C (6 x nv): frame C's spatial velocity at Co in W, expressed in W, per joint
        velocity (Drake's ``CalcJacobianSpatialVelocity``, kV, expressed in W)."""
        ws = self._forward(q)
        R_WC, p_WC = np.empty((3, 3)), np.empty(3)
        _k.camera_pose(self.camera_body, self.X_BC, ws, R_WC, p_WC)
        J = np.empty((6, self.nv))
        _k.camera_jacobian_W(self.camera_body, self.parent, self.index, p_WC, ws, J)
        return J


class CameraTerms:
    """ArmCamera's compiled kinematics (float): :meth:`at` fills the camera's state, J_C
    expressed in C and tau_g at an arm state in one kernel call
    (:func:`~geovs_drake.geometry.arm_kernels.camera_terms`), into arrays this object
    owns and reuses: read them before the next call.

    Made, it has called its kernels once (and ArmCamera's torque kernel, with the
    signatures ArmCamera calls them with): numba's first call in a process loads the
    compiled code, 0.01 s, or 0.3-0.5 s where it is the process's first numba call on a
    loaded machine. Paid at a real-time run's first frame instead, that stall put the
    LCM station behind its clock, and the two-process pinhole run with a frame of
    latency lost the target in about half of the runs on a loaded machine."""

    def __init__(self, tree: ArmTree) -> None:
        n = tree.nv
        self.state = np.empty(13)  # [q_WC, p_WC, w_WC_W, v_WCo_W]
        self.J_C = np.empty((6, n))
        self.tau_g = np.empty(n)
        self._args = (
            tree.parent, tree.index, tree.kind, tree.frames, tree.axis, tree.inertia,
            tree.gravity, tree.camera_body, tree.X_BC, tree.workspace(), np.empty((3, 3)),
            np.empty((6, n)), self.state, self.J_C, self.tau_g,
        )  # fmt: skip

        self._load(n)

    def at(self, x: np.ndarray) -> None:
        """The terms at the arm's state ``x`` = (q, v) (float64, contiguous)."""
        _k.camera_terms(x, *self._args)

    def _load(self, n: int) -> None:
        """Each kernel called once, with the types ArmCamera's calls have (its parameter
        vector a read-only view)."""
        x = np.zeros(2 * n)
        self.at(x)
        damping = np.zeros(n + 1)
        damping.flags.writeable = False
        _k.camera_torque(self.J_C, np.zeros(6), self.tau_g, damping, x, np.empty(n))


def _row(X) -> np.ndarray:
    """[R (9, row-major), p (3)] of a RigidTransform."""
    return np.concatenate([X.rotation().matrix().ravel(), X.translation()])


def _moving_ancestor(plant: MultibodyPlant, body, parent_joint: dict) -> object:
    """The moving body that ``body`` is welded to (itself if its joint moves), or the
    world body, through any chain of welds."""
    while body.index() != plant.world_body().index():
        joint = parent_joint[body.index()]
        if joint.num_velocities() > 0:
            return body
        body = joint.parent_body()
    return body


def _checked_joints(plant: MultibodyPlant) -> dict:
    """{child body index: its joint}, after refusing what the kernels cannot take."""
    if plant.num_constraints() > 0:
        raise ArmTreeError(
            f"the arm's plant has {plant.num_constraints()} constraint(s) (a closed chain or "
            "a coupled joint): the batch kernels take an open chain"
        )
    parent_joint: dict = {}
    for j in plant.GetJointIndices():
        joint = plant.get_joint(j)
        kind = joint.type_name()
        if kind != "weld" and kind not in _KINDS:
            raise ArmTreeError(
                f"joint {joint.name()!r} is {kind}: the batch kernels take revolute, "
                "prismatic and welded joints only"
            )
        child = joint.child_body().index()
        if child in parent_joint:
            raise ArmTreeError(
                f"joint {joint.name()!r}: body {joint.child_body().name()!r} already has "
                f"parent joint {parent_joint[child].name()!r} (a closed chain)"
            )
        parent_joint[child] = joint
    for b in range(1, plant.num_bodies()):
        body = plant.get_body(BodyIndex(b))
        if body.index() not in parent_joint:  # Finalize gives a free body a floating joint
            raise ArmTreeError(f"body {body.name()!r} has no joint to the world")
    return parent_joint


def _joint_row(plant: MultibodyPlant, joint, actuators: dict) -> list[float]:
    """[damping, reflected inertia, effort limit, lower, upper, velocity limit]."""
    actuator = actuators.get(joint.index())
    return [
        float(joint.default_damping_vector()[0]),
        0.0 if actuator is None else float(actuator.default_reflected_inertia()),
        np.inf if actuator is None else float(actuator.effort_limit()),
        float(joint.position_lower_limits()[0]),
        float(joint.position_upper_limits()[0]),
        float(joint.velocity_upper_limits()[0]),
    ]


def arm_tree(
    model_or_plant: ArmModel | MultibodyPlant, camera_frame: str = CAMERA_FRAME
) -> ArmTree:
    """The :class:`ArmTree` of an :class:`~geovs_drake.systems.arm_model.ArmModel` (its
    cached plant) or of a Finalized float MultibodyPlant holding one arm and the frame
    ``camera_frame``. :class:`ArmTreeError` in one line for a tree the kernels cannot
    take (the module's docstring)."""
    plant = arm_plant(model_or_plant) if isinstance(model_or_plant, ArmModel) else model_or_plant
    context = plant.CreateDefaultContext()
    parent_joint = _checked_joints(plant)
    world = plant.world_body()
    camera = plant.GetFrameByName(camera_frame)
    camera_body = _moving_ancestor(plant, camera.body(), parent_joint)
    if camera_body.index() == world.index():
        raise ArmTreeError(f"the camera frame {camera_frame!r} is on no moving body")
    # The chain from the camera's body to the world, by parent joints: its moving joints,
    # root first. Any moving joint off it is a branch.
    chain = []
    body = camera_body
    while body.index() != world.index():
        joint = parent_joint[body.index()]
        if joint.num_velocities() > 0:
            chain.append(joint)
        body = joint.parent_body()
    chain.reverse()
    on_chain = {joint.index() for joint in chain}
    for joint in parent_joint.values():
        if joint.num_velocities() > 0 and joint.index() not in on_chain:
            raise ArmTreeError(
                f"joint {joint.name()!r} is off the chain from the world to the camera (a "
                "branch): the batch kernels take one chain"
            )
    actuators = {}
    for a in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(a)
        actuators[actuator.joint().index()] = actuator
    moving = {joint.child_body().index(): i for i, joint in enumerate(chain)}
    n = len(chain)
    frames, axis, inertia = np.zeros((n, 24)), np.zeros((n, 3)), np.zeros((n, 13))
    parent, index, kind = np.zeros(n, np.int64), np.zeros((n, 2), np.int64), np.zeros(n, np.int64)
    joint_rows = []
    for i, joint in enumerate(chain):
        ancestor = _moving_ancestor(plant, joint.parent_body(), parent_joint)
        parent[i] = moving.get(ancestor.index(), -1)
        index[i] = (joint.position_start(), joint.velocity_start())
        kind[i] = _KINDS[joint.type_name()]
        # X_PF through the welds between the parent's moving body and F: fixed at any q.
        X_PF = plant.CalcRelativeTransform(context, ancestor.body_frame(), joint.frame_on_parent())
        X_MB = joint.frame_on_child().GetFixedPoseInBodyFrame().inverse()
        frames[i] = np.concatenate([_row(X_PF), _row(X_MB)])
        a = joint.revolute_axis() if kind[i] == _k.KIND_REVOLUTE else joint.translation_axis()
        axis[i] = np.asarray(a) / np.linalg.norm(a)
        joint_rows.append(_joint_row(plant, joint, actuators))
    if not all(parent[i] < i for i in range(n)) or len(set(index[:, 1])) != n:
        raise ArmTreeError("the arm's joints are not ordered parent first (Drake's velocities)")
    for b in range(plant.num_bodies()):  # each body's inertia into its moving body's
        body = plant.get_body(BodyIndex(b))
        owner = _moving_ancestor(plant, body, parent_joint) if b else world
        if owner.index() == world.index():
            continue
        X_AB = plant.CalcRelativeTransform(context, owner.body_frame(), body.body_frame())
        M_BBo_B = body.default_spatial_inertia()
        M_BAo_A = M_BBo_B.ReExpress(X_AB.rotation()).Shift(-X_AB.translation())
        inertia[moving[owner.index()]] += _inertia_row(M_BAo_A)
    mass = inertia[:, 0:1]
    inertia[:, 1:4] /= np.where(mass > 0, mass, 1.0)  # the summed first moments, m p_BoBcm
    X_BC = plant.CalcRelativeTransform(context, camera_body.body_frame(), camera)
    return ArmTree(
        joint_names=tuple(joint.name() for joint in chain),
        parent=parent,
        index=index,
        kind=kind,
        frames=frames,
        axis=axis,
        inertia=inertia,
        joint=np.array(joint_rows, dtype=float).reshape(n, len(JOINT_COLUMNS)),
        camera_body=int(moving[camera_body.index()]),
        X_BC=_row(X_BC),
        gravity=np.array(plant.gravity_field().gravity_vector(), dtype=float),
    )


def _inertia_row(M: SpatialInertia) -> np.ndarray:
    """[m, p_BoBcm (3), I_BBo (9)] of a SpatialInertia about Bo (m times the unit
    inertia: Drake keeps mass and the unit inertia apart); summable about a common point
    as (m, m p_BoBcm, I_BBo) are, hence the first moment's quotient at the end."""
    m = M.get_mass()
    return np.concatenate(
        [[m], m * np.asarray(M.get_com()), M.CalcRotationalInertia().CopyToFullMatrix3().ravel()]
    )


def warm_arm_kernels() -> None:
    """Call each arm kernel once on the shipped UR5, so that numba compiles them into
    its on-disk cache (:mod:`geovs_drake.batch.warm`;
    :func:`~geovs_drake.batch.arm_rhs.warm_arm_loop` adds the closed loop's)."""
    from geovs_drake.systems.arm_model import default_arm_model

    tree = arm_tree(default_arm_model())
    q = np.zeros(tree.nv)
    tree.mass_matrix(q)
    tree.inverse_dynamics(q, q, gravity=True)
    tree.camera_jacobian(q)
    CameraTerms(tree)  # its kernels, called once as ArmCamera calls them
