"""Diagram builders: the dynamic and kinematic visual-servo loops as named Diagrams.

Subsystem names (for ``diagram.GetSubsystemByName``): ``plant``,
``scene_graph``, ``spherical_camera``, ``navigation_controller``,
``image_jacobian_force`` (dynamic), ``kinematic_controller`` and
``kinematic_rigid_body`` (kinematic). A law other than the NF
(``config.controller``, registered in :data:`TWIST_CONTROLLERS`) commands a
camera twist: its system is ``controller`` (output port ``camera_velocity``),
driving the kinematic body directly or the rig through
``velocity_tracking_force`` (dynamic); the ``navigation_controller`` stays in
the diagram to report phi on D, unconnected to the actuation. ``controller:
path`` adds ``desired_image``, the planned y_d(t) as a ``TrajectorySource``. The
fixed-camera loop (:func:`make_fixed_camera_diagram`) has the same names plus
``fixed_camera_mount``; its ``plant`` (or ``kinematic_rigid_body``) carries the
target sphere. With ``log=True`` (the default),
Drake's ``LogVectorOutput`` loggers ``log_image_features``, ``log_phi``,
``log_margins``, ``log_visibility``, ``log_body_state`` / ``log_body_pose`` at
``config.log_rate``. :func:`geovs_drake.simulation.simulate` builds with
``log=False`` and logs from its recorded steps instead: periodic loggers cut
every integrator step at each sample time.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import Meshcat, MeshcatVisualizer
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import RotationalInertia, SpatialInertia
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import Demultiplexer, LogVectorOutput, TrajectorySource
from pydrake.visualization import AddFrameTriadIllustration

from geovs_drake.geometry._ops import MATH, NUMPY
from geovs_drake.geometry.rigid import (
    apply,
    matmul,
    quaternion_to_rotation,
    rig_velocity,
    target_twist_from_camera,
)
from geovs_drake.planning import plan_for_scenario
from geovs_drake.scenario import ScenarioConfig
from geovs_drake.systems import (
    FixedCameraKinematicMount,
    FixedCameraMount,
    IbvsController,
    ImageJacobianForce,
    KinematicController,
    KinematicRigidBody,
    NavigationController,
    PathFollowingController,
    PbvsController,
    SphericalCamera,
    SphericalFeatureController,
    VelocityTrackingForce,
)
from geovs_drake.visualization import add_camera_geometry, add_goal_ghost, add_target_geometry

__all__ = [
    "RIG_BODY_NAME",
    "TARGET_BODY_NAME",
    "TWIST_CONTROLLERS",
    "initial_body_states",
    "initial_rig_pose",
    "initial_rig_state",
    "fixed_camera_pose",
    "make_dynamic_servo_diagram",
    "make_fixed_camera_diagram",
    "make_kinematic_servo_diagram",
    "make_servo_diagram",
]

RIG_BODY_NAME = "camera_rig"
TARGET_BODY_NAME = "target_sphere"

#: A law that commands the camera's body twist: ``factory(builder, config, camera)``
#: adds its system (and any sources it needs) to ``builder``, connects every input
#: but the ones it wants from the camera, and returns the system, whose output port
#: ``camera_velocity`` is (Omega, V) in C. The builder then connects the system's
#: ``image_features`` input (if it has one) to the camera's y. Keyed by
#: ``ScenarioConfig.controller``; the NF ("nf") is built in.
TwistControllerFactory = Callable[[DiagramBuilder, ScenarioConfig, SphericalCamera], LeafSystem]


def _ibvs(builder: DiagramBuilder, config: ScenarioConfig, camera) -> LeafSystem:
    return builder.AddSystem(
        IbvsController(
            goal=config.goal_features(),
            radius=config.radius,
            gain=config.control.baseline_gain,
            depth=config.control.ibvs_depth,
        )
    )


def _pbvs(builder: DiagramBuilder, config: ScenarioConfig, camera) -> LeafSystem:
    return builder.AddSystem(
        PbvsController(
            goal=config.goal_features(), radius=config.radius, gain=config.control.baseline_gain
        )
    )


def _spherical(builder: DiagramBuilder, config: ScenarioConfig, camera) -> LeafSystem:
    return builder.AddSystem(
        SphericalFeatureController(
            goal=config.goal_features(), radius=config.radius, gain=config.control.baseline_gain
        )
    )


TWIST_CONTROLLERS: dict[str, TwistControllerFactory] = {
    "ibvs": _ibvs,
    "pbvs": _pbvs,
    "spherical": _spherical,
}


def _add_twist_controller(builder: DiagramBuilder, config: ScenarioConfig, camera) -> LeafSystem:
    """The registered law of ``config.controller``, named ``controller`` and connected to y."""
    try:
        factory = TWIST_CONTROLLERS[config.controller]
    except KeyError:
        raise ValueError(
            f"controller {config.controller!r} has no diagram (registered: nf, "
            f"{', '.join(sorted(TWIST_CONTROLLERS))})"
        ) from None
    law = factory(builder, config, camera)
    law.set_name("controller")
    if law.HasInputPort("image_features"):
        builder.Connect(camera.image_features_output, law.GetInputPort("image_features"))
    return law


def _path_following(builder: DiagramBuilder, config: ScenarioConfig, camera) -> LeafSystem:
    """``controller: path``: the planned y_d(t) (:func:`~geovs_drake.planning.plan_for_scenario`)
    through a ``TrajectorySource`` named ``desired_image`` (value and derivative) into a
    :class:`PathFollowingController` (Eq. 18, with ``config.path.feedback_gain``). Raises
    PathPlanningError (a ValueError) if there is no path inside D."""
    plan = plan_for_scenario(config)
    source = builder.AddNamedSystem(
        "desired_image", TrajectorySource(plan.trajectory, output_derivative_order=1)
    )
    law = builder.AddSystem(
        PathFollowingController(
            radius=config.radius * config.path.radius_scale, gain=config.path.feedback_gain
        )
    )
    builder.Connect(source.get_output_port(), law.desired_image_input)
    return law


TWIST_CONTROLLERS["path"] = _path_following


def initial_rig_pose(config: ScenarioConfig) -> RigidTransform:
    """X_WR(0) = X_WB X_BC(0) X_RC^-1."""
    return config.X_WB @ config.X_BC_initial @ config.X_RC.inverse()


def initial_body_states(
    config: ScenarioConfig, X_BC: np.ndarray, twists: np.ndarray | None = None
) -> np.ndarray:
    """The loop's body states for camera poses X_BC (N, 4, 4) and body twists (N, 6).

    Dynamic loop: the rig's free-body state in the plant's layout (N, 13),
    ``[qw, qx, qy, qz, x, y, z, wx, wy, wz, vx, vy, vz]``: ``X_WR = X_WB X_BC
    X_RC^-1``, then the angular velocity of R in W and the translational
    velocity of R's origin in W, both expressed in W, that give the camera the
    body twist (Omega, V) = G^-1 Gdot of Eqs. (16)-(17)
    (:func:`~geovs_drake.geometry.rigid.rig_velocity`). Kinematic loop: the
    camera's pose ``X_WC = X_WB X_BC`` as (N, 7); that loop is first order, so
    a non-zero twist is an error.
    """
    X_BC = np.asarray(X_BC, dtype=float).reshape(-1, 4, 4)
    n = len(X_BC)
    dynamic = config.plant == "dynamic"
    if twists is not None and not dynamic and np.any(np.asarray(twists) != 0):
        raise ValueError(
            "an initial twist applies to the dynamic loop only (first-order kinematic)"
        )
    if config.mount == "fixed":
        return _initial_target_states(config, X_BC, twists)
    X_RC = config.X_RC if dynamic else RigidTransform()
    X_RC_inv = X_RC.inverse()
    states = np.zeros((n, 13 if dynamic else 7))
    for i in range(n):
        X_W = config.X_WB @ RigidTransform(X_BC[i]) @ X_RC_inv
        states[i, 0:4] = X_W.rotation().ToQuaternion().wxyz()
        states[i, 4:7] = X_W.translation()
    if dynamic and twists is not None:
        twists = np.asarray(twists, dtype=float).reshape(n, 6)
        R_WR = quaternion_to_rotation(tuple(states[:, 0:4].T), NUMPY)
        R_RC = tuple(X_RC.rotation().matrix().ravel())
        velocity = rig_velocity(
            R_WR, matmul(R_WR, R_RC), tuple(twists.T), tuple(X_RC.translation())
        )
        states[:, 7:13] = np.stack(np.broadcast_arrays(*velocity), axis=-1)
    return states


def fixed_camera_pose(config: ScenarioConfig) -> RigidTransform:
    """X_WC of the fixed camera (``mount: fixed``): where the eye-in-hand camera's goal is,
    ``X_WB X_BC*``, so the target comes to rest at ``config.X_WB``, where it stands
    in the eye-in-hand scene."""
    return config.X_WB @ config.X_BC_goal


def _initial_target_states(
    config: ScenarioConfig, X_BC: np.ndarray, twists: np.ndarray | None
) -> np.ndarray:
    """The fixed-camera loop's target states for relative poses G = X_BC and camera twists.

    ``X_WB = X_WC X_BC^-1`` with the camera fixed at :func:`fixed_camera_pose`;
    the target's twist is ``-Ad_G (Omega, V)`` in B (Eq. 16), then expressed in W
    as the plant's ``(w_WB_W, v_WBo_W)``.
    """
    dynamic = config.plant == "dynamic"
    X_WC = fixed_camera_pose(config)
    R_WC = tuple(X_WC.rotation().matrix().ravel())
    p_WC = tuple(X_WC.translation())
    states = np.zeros((len(X_BC), 13 if dynamic else 7))
    if twists is not None:
        twists = np.asarray(twists, dtype=float).reshape(len(X_BC), 6)
    for i, G in enumerate(X_BC):
        X_WB = X_WC @ RigidTransform(G).inverse()
        states[i, 0:4] = X_WB.rotation().ToQuaternion().wxyz()
        states[i, 4:7] = X_WB.translation()
        if dynamic and twists is not None:
            x = tuple(states[i, 0:7].tolist())
            twist = target_twist_from_camera(tuple(twists[i].tolist()), x, R_WC, p_WC, MATH)
            R_WB = tuple(X_WB.rotation().matrix().ravel())
            states[i, 7:10] = apply(R_WB, twist[0:3])
            states[i, 10:13] = apply(R_WB, twist[3:6])
    return states


def initial_rig_state(config: ScenarioConfig) -> np.ndarray:
    """The rig's free-body state at t = 0 (13 numbers, :func:`initial_body_states`):
    X_BC(0) and ``config.initial_velocity``. For
    :meth:`MultibodyPlant.SetPositionsAndVelocities` (the plant has no default
    velocity, so a simulator's context must be set)."""
    return initial_body_states(
        config, config.X_BC_initial.GetAsMatrix4(), np.asarray(config.initial_velocity)
    )[0]


def _add_loggers(builder: DiagramBuilder, camera, nav, rate: float) -> None:
    period = 1.0 / rate
    for port, name in (
        (camera.image_features_output, "log_image_features"),
        (camera.visibility_output, "log_visibility"),
        (camera.domain_margins_output, "log_margins"),
        (nav.phi_output, "log_phi"),
    ):
        LogVectorOutput(port, builder, publish_period=period).set_name(name)


def _camera_and_navigation(
    builder: DiagramBuilder,
    config: ScenarioConfig,
    X_RC: RigidTransform,
    X_WB: RigidTransform | None = None,
):
    domain = config.domain.to_domain()
    X_WB = config.X_WB if X_WB is None else X_WB
    camera = builder.AddNamedSystem(
        "spherical_camera",
        SphericalCamera(radius=config.radius, X_WB=X_WB, X_RC=X_RC, domain=domain),
    )
    nav = builder.AddNamedSystem(
        "navigation_controller",
        NavigationController(
            goal=config.goal_features(), domain=domain, gains=config.navigation.to_gains()
        ),
    )
    builder.Connect(camera.image_features_output, nav.image_features_input)
    return camera, nav


def make_dynamic_servo_diagram(
    config: ScenarioConfig | None = None, meshcat: Meshcat | None = None, log: bool = True
) -> Diagram:
    """The dynamic loop of Appendix C around a continuous MultibodyPlant free body.

    Gravity is off: the paper assumes it is cancelled by the controller, and a
    gravity-compensation term would add nothing to the servo's analysis. The
    camera frame may sit off the rig's centre of mass (``rig.camera_offset``,
    Appendix C.0.6). Pass ``meshcat`` to add a MeshcatVisualizer and the camera
    frame's axes (double only: leave it out of diagrams you will convert to
    AutoDiffXd).
    """
    config = config or ScenarioConfig()
    config.validate()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    # The rig's body frame R has its origin at the centre of mass.
    rig = plant.AddRigidBody(
        RIG_BODY_NAME,
        SpatialInertia.MakeFromCentralInertia(
            config.rig.mass, np.zeros(3), RotationalInertia(*config.rig.inertia_diagonal)
        ),
    )
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    X_RC = config.X_RC
    theta = config.domain.to_domain().fov_half_angle
    add_target_geometry(plant, config)
    add_camera_geometry(plant, rig, X_RC, theta)
    add_goal_ghost(plant, config)
    plant.Finalize()
    plant.SetDefaultFloatingBaseBodyPose(rig, initial_rig_pose(config))

    demux = builder.AddNamedSystem("state_demux", Demultiplexer([7, 6]))
    builder.Connect(plant.get_state_output_port(), demux.get_input_port())
    camera, nav = _camera_and_navigation(builder, config, X_RC)
    builder.Connect(demux.get_output_port(0), camera.body_pose_input)
    if config.controller == "nf":
        force = builder.AddNamedSystem(
            "image_jacobian_force",
            ImageJacobianForce(
                radius=config.radius,
                potential_gain=config.control.potential_gain,
                damping=np.asarray(config.control.damping, dtype=float),
                X_RC=X_RC,
            ),
        )
        builder.Connect(camera.image_features_output, force.image_features_input)
        builder.Connect(nav.dphi_output, force.dphi_input)
    else:
        law = _add_twist_controller(builder, config, camera)
        force = builder.AddNamedSystem(
            "velocity_tracking_force",
            VelocityTrackingForce(gains=config.control.tracking_gains, X_RC=X_RC),
        )
        builder.Connect(law.GetOutputPort("camera_velocity"), force.camera_velocity_command_input)
    builder.Connect(plant.get_state_output_port(), force.body_state_input)
    builder.Connect(
        force.generalized_force_output, plant.get_applied_generalized_force_input_port()
    )
    if log:
        _add_loggers(builder, camera, nav, config.log_rate)
        LogVectorOutput(
            plant.get_state_output_port(), builder, publish_period=1.0 / config.log_rate
        ).set_name("log_body_state")
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
        AddFrameTriadIllustration(
            scene_graph=scene_graph, body=rig, X_FT=X_RC, length=0.08, radius=0.003, name="C"
        )
    diagram = builder.Build()
    diagram.set_name("dynamic_visual_servo")
    return diagram


def make_kinematic_servo_diagram(config: ScenarioConfig | None = None, log: bool = True) -> Diagram:
    """The kinematic loop of Eqs. (17)-(19): camera map, NF, Tc^-1, integrated on SE(3).

    The kinematic body *is* the camera frame (X_RC = identity). With a law other
    than the NF (``config.controller``), that law's commanded twist drives the body.
    """
    config = config or ScenarioConfig()
    config.validate()
    builder = DiagramBuilder()
    body = builder.AddNamedSystem(
        "kinematic_rigid_body", KinematicRigidBody(X_WC0=config.X_WB @ config.X_BC_initial)
    )
    camera, nav = _camera_and_navigation(builder, config, RigidTransform())
    builder.Connect(body.body_pose_output, camera.body_pose_input)
    if config.controller == "nf":
        controller = builder.AddNamedSystem(
            "kinematic_controller",
            KinematicController(radius=config.radius, gain=config.control.kinematic_gain),
        )
        builder.Connect(camera.image_features_output, controller.image_features_input)
        builder.Connect(nav.dphi_output, controller.dphi_input)
        builder.Connect(controller.camera_velocity_output, body.camera_velocity_input)
    else:
        law = _add_twist_controller(builder, config, camera)
        builder.Connect(law.GetOutputPort("camera_velocity"), body.camera_velocity_input)
    if log:
        _add_loggers(builder, camera, nav, config.log_rate)
        LogVectorOutput(
            body.body_pose_output, builder, publish_period=1.0 / config.log_rate
        ).set_name("log_body_pose")
    diagram = builder.Build()
    diagram.set_name("kinematic_visual_servo")
    return diagram


def make_fixed_camera_diagram(
    config: ScenarioConfig | None = None, meshcat: Meshcat | None = None, log: bool = True
) -> Diagram:
    """The fixed-camera (eye-to-hand) loop: the camera still, the target sphere driven.

    Eq. (16), ``G = H^-1``, says the two configurations are one problem: the
    laws see only the relative pose. The camera is fixed in W at
    :func:`fixed_camera_pose`; the target is the driven body, with the rig's
    mass model (``config.rig``: mass and principal inertia about the sphere's
    centre, its body frame B): a MultibodyPlant free body pushed by a wrench
    (``config.plant == "dynamic"``) or a :class:`KinematicRigidBody` whose body
    twist is commanded (``"kinematic"``). The camera, the NF and the laws are
    the eye-in-hand systems, unchanged, built with the target frame as their
    world (X_WB = X_RC = identity); a :class:`FixedCameraMount` (or
    :class:`FixedCameraKinematicMount`) named ``fixed_camera_mount`` does the
    frame bookkeeping: the target's state to the camera's relative state, and
    the law's camera wrench (twist) to the reaction on (twist of) the target.

    The initial relative pose is ``config.initial`` (X_BC(0)), the goal
    ``config.goal``, as for the eye-in-hand loops, so both see the same image.
    ``rig.camera_offset`` does not apply (the camera is not on the body).
    Pass ``meshcat`` (dynamic only) to watch the sphere move in front of the
    still camera.
    """
    config = config or ScenarioConfig()
    config.validate()
    dynamic = config.plant == "dynamic"
    if meshcat is not None and not dynamic:
        raise ValueError("meshcat needs the dynamic plant (the kinematic one has no geometry)")
    X_WC = fixed_camera_pose(config)
    builder = DiagramBuilder()
    identity = RigidTransform()
    camera, nav = _camera_and_navigation(builder, config, identity, X_WB=identity)
    if dynamic:
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
        target = plant.AddRigidBody(
            TARGET_BODY_NAME,
            SpatialInertia.MakeFromCentralInertia(
                config.rig.mass, np.zeros(3), RotationalInertia(*config.rig.inertia_diagonal)
            ),
        )
        plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
        theta = config.domain.to_domain().fov_half_angle
        add_target_geometry(plant, config, body=target)
        add_target_geometry(plant, config, X_WB=config.X_WB, alpha=0.25, prefix="goal_")
        add_camera_geometry(plant, plant.world_body(), X_WC, theta)
        plant.Finalize()
        initial = _initial_target_states(config, config.X_BC_initial.GetAsMatrix4()[None], None)
        plant.SetDefaultFloatingBaseBodyPose(
            target, RigidTransform(Quaternion(initial[0, 0:4]), initial[0, 4:7])
        )
        mount = builder.AddNamedSystem("fixed_camera_mount", FixedCameraMount(X_WC=X_WC))
        builder.Connect(plant.get_state_output_port(), mount.target_state_input)
        demux = builder.AddNamedSystem("state_demux", Demultiplexer([7, 6]))
        builder.Connect(mount.camera_state_output, demux.get_input_port())
        builder.Connect(demux.get_output_port(0), camera.body_pose_input)
        if config.controller == "nf":
            force = builder.AddNamedSystem(
                "image_jacobian_force",
                ImageJacobianForce(
                    radius=config.radius,
                    potential_gain=config.control.potential_gain,
                    damping=np.asarray(config.control.damping, dtype=float),
                    X_RC=identity,
                ),
            )
            builder.Connect(camera.image_features_output, force.image_features_input)
            builder.Connect(nav.dphi_output, force.dphi_input)
        else:
            law = _add_twist_controller(builder, config, camera)
            force = builder.AddNamedSystem(
                "velocity_tracking_force",
                VelocityTrackingForce(gains=config.control.tracking_gains, X_RC=identity),
            )
            builder.Connect(
                law.GetOutputPort("camera_velocity"), force.camera_velocity_command_input
            )
        builder.Connect(mount.camera_state_output, force.body_state_input)
        builder.Connect(force.wrench_C_output, mount.wrench_C_input)
        builder.Connect(
            mount.generalized_force_output, plant.get_applied_generalized_force_input_port()
        )
        state_port = plant.get_state_output_port()
    else:
        X_WB0 = X_WC @ config.X_BC_initial.inverse()
        body = builder.AddNamedSystem("kinematic_rigid_body", KinematicRigidBody(X_WC0=X_WB0))
        mount = builder.AddNamedSystem("fixed_camera_mount", FixedCameraKinematicMount(X_WC=X_WC))
        builder.Connect(body.body_pose_output, mount.target_pose_input)
        builder.Connect(mount.camera_pose_output, camera.body_pose_input)
        if config.controller == "nf":
            controller = builder.AddNamedSystem(
                "kinematic_controller",
                KinematicController(radius=config.radius, gain=config.control.kinematic_gain),
            )
            builder.Connect(camera.image_features_output, controller.image_features_input)
            builder.Connect(nav.dphi_output, controller.dphi_input)
            command = controller.camera_velocity_output
        else:
            command = _add_twist_controller(builder, config, camera).GetOutputPort(
                "camera_velocity"
            )
        builder.Connect(command, mount.camera_velocity_input)
        builder.Connect(mount.target_velocity_output, body.camera_velocity_input)
        state_port = body.body_pose_output
    if log:
        _add_loggers(builder, camera, nav, config.log_rate)
        LogVectorOutput(state_port, builder, publish_period=1.0 / config.log_rate).set_name(
            "log_body_state" if dynamic else "log_body_pose"
        )
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
        AddFrameTriadIllustration(
            scene_graph=scene_graph,
            body=plant.world_body(),
            X_FT=X_WC,
            length=0.08,
            radius=0.003,
            name="C",
        )
    diagram = builder.Build()
    diagram.set_name(f"fixed_camera_{config.plant}_visual_servo")
    return diagram


def make_servo_diagram(
    config: ScenarioConfig | None = None, meshcat: Meshcat | None = None, log: bool = True
) -> Diagram:
    """The loop ``config`` describes: its ``mount`` (hand or fixed) and ``plant``."""
    config = config or ScenarioConfig()
    if config.mount == "fixed":
        return make_fixed_camera_diagram(config, meshcat=meshcat, log=log)
    if config.plant == "dynamic":
        return make_dynamic_servo_diagram(config, meshcat=meshcat, log=log)
    if meshcat is not None:
        raise ValueError("meshcat needs the dynamic plant (the kinematic one has no geometry)")
    return make_kinematic_servo_diagram(config, log=log)
