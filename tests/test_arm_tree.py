"""The arm's generated tree and kernels (geovs_drake.systems.arm_tree, arm_kernels) against
Drake's MultibodyPlant, the independent truth: ``CalcMassMatrix`` (reflected rotor
inertia included), ``CalcBiasTerm``, ``CalcGravityGeneralizedForces``,
``CalcJacobianSpatialVelocity`` (kV, frame C at Co, expressed in W) and the camera's
pose, on random seeded states of the UR5, the Panda (its welded fingers folded in) and
the stiff user arm; and the trees the kernels refuse, each in one line naming the joint.
"""

from __future__ import annotations

import importlib.metadata

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame, JacobianWrtVariable

from geovs_drake.goal.arm import arm_model
from geovs_drake.scenario import Arm, Dynamic, Kinematic, ScenarioConfig
from geovs_drake.systems.arm_model import CAMERA_FRAME, ArmError, arm_plant
from geovs_drake.systems.arm_tree import ArmTreeError, arm_tree

#: The check's tolerance: norm of the difference over the norm of Drake's.
RELATIVE = 1e-10
#: Random states per arm (about 0.6 s an arm once the kernels are compiled and cached).
STATES = 1000
#: The closed loop's check: its tolerance, states, their spread about the start [rad]
#: and the fast states' joint speeds [rad/s] (whose torques pass the effort limits).
RHS_RELATIVE, RHS_STATES, RHS_SPREAD, FAST_SPEED = 1e-9, 20, 0.05, 30.0
#: The UR5's wrist angle q5 [rad] about its singularity: sigma_min(J_C) about 1e-3, inside
#: the kinematic arm's singular zone (singularity_damping 0.05).
WRIST_NEAR_SINGULAR = 0.01
#: Joint velocities' scale [rad/s] of the random states.
VELOCITY_SCALE = 2.0

HAS_PANDA = True
try:
    importlib.metadata.distribution("example-robot-data")
except importlib.metadata.PackageNotFoundError:
    HAS_PANDA = False
NEEDS_PANDA = pytest.mark.skipif(
    not HAS_PANDA,
    reason='the Panda needs example-robot-data: pip install "geovs-drake[panda]" '
    "(make test installs it)",
)

ARMS = {
    "ur5": Arm(),
    "panda": Arm(model="panda"),
    "stiff_6r": Arm(model="tests/data/stiff_6r.urdf", end_effector_frame="tool0"),
}
ARM_PARAMS = [
    pytest.param("ur5"),
    pytest.param("panda", marks=NEEDS_PANDA),
    pytest.param("stiff_6r"),
]


def _relative(a: np.ndarray, truth: np.ndarray) -> float:
    return float(np.linalg.norm(a - truth) / np.linalg.norm(truth))


def _check_against_drake(name: str, states: int) -> None:
    model = arm_model(ScenarioConfig(carrier=ARMS[name]))
    tree = arm_tree(model)
    plant = arm_plant(model)
    context = plant.CreateDefaultContext()
    camera, world = plant.GetFrameByName(CAMERA_FRAME), plant.world_frame()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    lower, upper = np.maximum(lower, -np.pi), np.minimum(upper, np.pi)
    rng = np.random.default_rng(44)
    worst = np.zeros(6)
    for _ in range(states):
        q = rng.uniform(lower, upper)
        v = VELOCITY_SCALE * rng.standard_normal(tree.nv)
        plant.SetPositions(context, q)
        plant.SetVelocities(context, v)
        X_WC = camera.CalcPoseInWorld(context)
        J = plant.CalcJacobianSpatialVelocity(
            context, JacobianWrtVariable.kV, camera, np.zeros(3), world, world
        )
        R_WC, p_WC = tree.camera_pose(q)
        errors = (
            _relative(tree.mass_matrix(q), plant.CalcMassMatrix(context)),
            _relative(tree.inverse_dynamics(q, v, gravity=False), plant.CalcBiasTerm(context)),
            _relative(
                -tree.inverse_dynamics(q, np.zeros(tree.nv), gravity=True),
                plant.CalcGravityGeneralizedForces(context),
            ),
            _relative(tree.camera_jacobian(q), J),
            _relative(R_WC, X_WC.rotation().matrix()),
            _relative(p_WC, X_WC.translation()),
        )
        worst = np.maximum(worst, errors)
    assert np.all(worst < RELATIVE), f"{name}: worst M, Cv, tau_g, J_C, R_WC, p_WC {worst}"


@pytest.mark.parametrize("name", ARM_PARAMS)
def test_the_kernels_match_drake_on_random_states(name):
    """M, C v, tau_g, J_C and X_WC to 1e-10 relative on 1,000 seeded states."""
    _check_against_drake(name, STATES)


def test_the_tree_reads_the_plants_joint_data():
    """Per joint, the tree's damping, reflected inertia, limits and names are the plant's
    (the Panda's reflected inertias where the extra is there; the UR5's otherwise)."""
    model = arm_model(ScenarioConfig(carrier=ARMS["panda" if HAS_PANDA else "ur5"]))
    tree, plant = arm_tree(model), arm_plant(model)
    actuators = [plant.get_joint_actuator(a) for a in plant.GetJointActuatorIndices()]
    by_joint = {a.joint().name(): a for a in actuators}
    for i, name in enumerate(tree.joint_names):
        joint = plant.GetJointByName(name)
        assert tree.index[i, 1] == joint.velocity_start()
        damping, reflected, effort, lower, upper, velocity = tree.joint[i]
        assert damping == joint.default_damping_vector()[0]
        assert reflected == by_joint[name].default_reflected_inertia()
        assert effort == by_joint[name].effort_limit()
        assert (lower, upper) == (joint.position_lower_limit(), joint.position_upper_limit())
        assert velocity == joint.velocity_upper_limit()
    assert tree.nv == plant.num_velocities()


_LINK = (
    '<link name="{0}"><inertial><mass value="1"/>'
    '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
)


def _joint(name: str, kind: str, parent: str, child: str) -> str:
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        '<origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
    )


def _plant(links: list[str], joints: list[str], weld_loop: bool = False) -> MultibodyPlant:
    """A plant of the URDF, its base welded to the world, the camera on the last link."""
    urdf = (
        '<robot name="r" xmlns:drake="http://drake.mit.edu">'
        + "".join(_LINK.format(n) for n in links)
        + "".join(joints)
    )
    plant = MultibodyPlant(time_step=0.0)
    Parser(plant).AddModelsFromString(urdf + "</robot>", "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(links[0]))
    plant.AddFrame(
        FixedOffsetFrame(CAMERA_FRAME, plant.GetFrameByName(links[-1]), RigidTransform())
    )
    if weld_loop:  # a closed chain: the last link welded back onto the base
        plant.AddWeldConstraint(
            plant.GetBodyByName(links[-1]), RigidTransform(), plant.GetBodyByName(links[0]),
            RigidTransform(),
        )  # fmt: skip
    plant.Finalize()
    return plant


def test_a_user_tree_with_a_welded_link_is_read():
    """A fixed joint in the chain folds its link into its parent: the kernels' M is
    Drake's."""
    plant = _plant(
        ["a", "b", "c", "d"],
        [_joint("j1", "revolute", "a", "b"), _joint("w", "fixed", "b", "c"),
         _joint("j2", "prismatic", "c", "d")],
    )  # fmt: skip
    tree = arm_tree(plant)
    assert tree.joint_names == ("j1", "j2")
    context = plant.CreateDefaultContext()
    q = np.array([0.3, 0.2])
    plant.SetPositions(context, q)
    assert _relative(tree.mass_matrix(q), plant.CalcMassMatrix(context)) < RELATIVE


@pytest.mark.parametrize(
    "links, joints, weld_loop, message",
    [
        # Drake leaves a URDF's floating link free: its joint takes the link's name.
        (
            ["a", "b"],
            [_joint("f", "floating", "a", "b")],
            False,
            "joint 'b' is quaternion_floating",
        ),
        (["a", "b"], [_joint("p", "planar", "a", "b")], False, "joint 'p' is planar"),
        (
            ["a", "b"],
            ['<drake:joint name="s" type="ball"><parent link="a"/><child link="b"/></drake:joint>'],
            False,
            "joint 's' is ball",
        ),  # fmt: skip
        (["a", "b"], [_joint("w", "fixed", "a", "b")], False, "'camera' is on no moving body"),
        (
            ["a", "b", "c"],
            [_joint("j1", "revolute", "a", "b"), _joint("j2", "revolute", "a", "c")],
            False,
            "joint 'j1' is off the chain from the world to the camera",
        ),
        (["a", "b"], [_joint("j1", "revolute", "a", "b")], True, "1 constraint(s) (a closed chain"),
    ],
)
def test_a_tree_the_kernels_cannot_take_is_refused_in_one_line(links, joints, weld_loop, message):
    """A floating, planar or ball joint, a camera welded to the world, a branch off the
    camera's chain, a closed chain (a constraint: Drake's Finalize refuses a loop of
    joints itself): an ArmTreeError (an ArmError, a ValueError: the CLI's exit 2) of one
    line naming it."""
    with pytest.raises(ArmTreeError) as error:
        arm_tree(_plant(links, joints, weld_loop))
    assert message in str(error.value) and "\n" not in str(error.value)
    assert isinstance(error.value, ArmError) and isinstance(error.value, ValueError)


def _loop_case(name: str, plant) -> tuple:
    """The arm's Drake loop from its default start, and its compiled parameters."""
    from geovs_drake.batch.arm_rhs import arm_loop_parameters
    from geovs_drake.loop import build_loop, resolve

    resolved = resolve(ScenarioConfig(carrier=ARMS[name], plant=plant))
    return build_loop(resolved, log=False), arm_loop_parameters(resolved)


@pytest.mark.parametrize(
    "name, plant",
    [
        pytest.param("ur5", Dynamic(), id="ur5-dynamic"),
        pytest.param("ur5", Kinematic(), id="ur5-kinematic"),
        pytest.param("panda", Dynamic(), id="panda-dynamic", marks=NEEDS_PANDA),
        pytest.param("panda", Kinematic(), id="panda-kinematic", marks=NEEDS_PANDA),
    ],
)
def test_the_compiled_arm_loop_is_the_drake_loops_right_hand_side(name, plant):
    """At random states about the default start, arm_rhs is the diagram's
    EvalTimeDerivatives to 1e-9 relative: dynamic, fast states too, whose torques ArmCamera
    asks past the effort limits (the plant clamps them); kinematic, states whose joint
    rates the velocity limits scale (all about this start) and, on the UR5, states by the
    wrist's singularity (the pseudo-inverse's singular-zone damping)."""
    from geovs_drake.batch.arm_rhs import arm_rhs

    loop, parameters = _loop_case(name, plant)
    diagram = loop.diagram
    root = diagram.CreateDefaultContext()
    loop.carrier.set_initial_state(root)
    x0 = root.get_continuous_state_vector().CopyToVector()
    assert x0.size == parameters.state_size  # the arm's state is the diagram's only one
    rng = np.random.default_rng(45)
    n = parameters.tree.nv
    clamped = 0
    for k in range(RHS_STATES):
        x = x0 + RHS_SPREAD * rng.standard_normal(x0.size)
        if parameters.dynamic:
            x[n:] = (FAST_SPEED if k % 2 else 1.0) * rng.standard_normal(n)
        elif name == "ur5" and k % 2:  # the wrist near its singularity (q5 = 0): the
            x[4] = WRIST_NEAR_SINGULAR * rng.standard_normal()  # damping's singular zone
        root.SetContinuousState(x)
        truth = diagram.EvalTimeDerivatives(root).get_vector().CopyToVector()
        assert _relative(arm_rhs(parameters, x), truth) < RHS_RELATIVE, (k, x)
        if parameters.dynamic:
            arm = diagram.GetSubsystemByName("arm_camera")
            asked = arm.actuation_output.Eval(arm.GetMyContextFromRoot(root))
            clamped += int(np.any(np.abs(asked) > parameters.tree.joint[:, 2]))
    assert clamped > 0 or not parameters.dynamic  # the clamp's branch was taken


def test_the_compiled_arm_loop_refuses_the_barrier_in_one_line():
    """The joint-limit barrier is not in the compiled loop: a ValueError of one line
    naming the field and its value, not a loop that would run without it."""
    from geovs_drake.batch.arm_rhs import arm_loop_parameters

    with pytest.raises(ValueError, match="joint_barrier_fraction = 0.1$"):
        arm_loop_parameters(ScenarioConfig(carrier=Arm(joint_barrier_fraction=0.1)))


#: ArmCamera's check: random states per arm and case, and its tolerance (relative).
CAMERA_STATES, CAMERA_RELATIVE = 40, 1e-10


@pytest.mark.parametrize("name", ARM_PARAMS)
def test_arm_cameras_compiled_kinematics_are_drakes(name):
    """ArmCamera (float) reads the camera's state, J_C (expressed in C) and tau_g from the
    compiled kernels (CameraTerms); with ``compiled=False`` from Drake's ``CalcPose``,
    ``CalcSpatialVelocity``, ``CalcJacobianSpatialVelocity`` and
    ``CalcGravityGeneralizedForces`` on its private plant. On random states with a random
    wrench, joint damping and phi, both systems' ``camera_state`` and ``actuation`` agree
    to 1e-10 relative: the plain torque (its compiled call), with the joint-limit barrier,
    and behind a moving target's feed-forward twist (every other state)."""
    from geovs_drake.systems import ArmCamera

    model = arm_model(ScenarioConfig(carrier=ARMS[name]))
    plant = arm_plant(model)
    nv = plant.num_velocities()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    lower, upper = np.maximum(lower, -np.pi), np.minimum(upper, np.pi)
    rng = np.random.default_rng(46)
    damping = rng.uniform(0.1, 2.0, nv)
    for barrier in (0.0, 0.5):
        systems = [
            ArmCamera(
                model=model,
                joint_damping=damping,
                joint_barrier_width=barrier,
                null_space_damping=0.7,
                compiled=compiled,
            )
            for compiled in (True, False)
        ]
        assert systems[0]._terms is not None and systems[1]._terms is None
        for k in range(CAMERA_STATES):
            contexts = [system.CreateDefaultContext() for system in systems]
            x = np.concatenate(
                [rng.uniform(lower, upper), VELOCITY_SCALE * rng.standard_normal(nv)]
            )
            inputs = {
                "arm_state": x,
                "wrench_C": rng.standard_normal(6),
                "phi": [rng.uniform(0.0, 0.9)],
                "potential_gain": [rng.uniform(0.5, 5.0)],
            }
            if k % 2:
                inputs["feedforward_twist"] = 0.1 * rng.standard_normal(6)
            outputs = []
            for system, context in zip(systems, contexts, strict=True):
                for port, value in inputs.items():
                    system.GetInputPort(port).FixValue(context, value)
                outputs.append(
                    [
                        system.camera_state_output.Eval(context),
                        system.actuation_output.Eval(context),
                    ]
                )
            (state, tau), (state_drake, tau_drake) = outputs
            assert _relative(state, state_drake) < CAMERA_RELATIVE, (barrier, k)
            assert _relative(tau, tau_drake) < CAMERA_RELATIVE, (barrier, k)


def test_the_shared_cholesky_pieces_agree_with_numpy():
    """One Gram matrix and one Cholesky factor serve the batch arm's damped solve, its
    singular-zone test, its sigma_min, its M^-1 and the kinematic arm's zone test:
    ``shifted_gram`` is J J^T + shift I; ``cholesky_factor`` gives numpy's factor where A
    is positive definite and False where it is not (just past sigma_min^2, or NaN), and
    ``cholesky_solve`` then gives NaN, never a number."""
    from geovs_drake.geometry import arm_kernels as k

    rng = np.random.default_rng(11)
    for n in (6, 7):
        J = rng.normal(size=(6, n))
        A, L = np.empty((6, 6)), np.zeros((6, 6))
        k.shifted_gram(J, 0.3, A)
        np.testing.assert_allclose(A, J @ J.T + 0.3 * np.eye(6), rtol=1e-14, atol=1e-14)
        assert k.cholesky_factor(A, L)
        np.testing.assert_allclose(np.tril(L), np.linalg.cholesky(A), rtol=1e-12, atol=1e-13)
        b, x = rng.normal(size=6), np.empty(6)
        k.cholesky_solve(A, b, L, x)
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-10)
        sigma2 = np.linalg.svd(J, compute_uv=False)[-1] ** 2
        k.shifted_gram(J, -0.99 * sigma2, A)
        assert k.cholesky_factor(A, L)
        k.shifted_gram(J, -1.01 * sigma2, A)
        assert not k.cholesky_factor(A, L)
        k.cholesky_solve(A, b, L, x)
        assert np.all(np.isnan(x))
        A[2, 2] = np.nan
        assert not k.cholesky_factor(A, L)
