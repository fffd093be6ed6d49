"""Diagram builders: the dynamic and kinematic visual-servo loops as named Diagrams.

Subsystem names (for ``diagram.GetSubsystemByName``): ``plant``,
``scene_graph``, ``spherical_camera``, ``navigation_controller``,
``image_jacobian_force`` (dynamic), ``kinematic_controller`` and
``kinematic_rigid_body`` (kinematic), and, with ``log=True`` (the default),
Drake's ``LogVectorOutput`` loggers ``log_image_features``, ``log_phi``,
``log_margins``, ``log_visibility``, ``log_body_state`` / ``log_body_pose`` at
``config.log_rate``. :func:`geovs_drake.simulation.simulate` builds with
``log=False`` and logs from its recorded steps instead: periodic loggers cut
every integrator step at each sample time.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import RotationalInertia, SpatialInertia
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Demultiplexer, LogVectorOutput
from pydrake.visualization import AddFrameTriadIllustration

from geovs_drake.geometry.rigid import rig_velocity
from geovs_drake.scenario import ScenarioConfig
from geovs_drake.systems import (
    ImageJacobianForce,
    KinematicController,
    KinematicRigidBody,
    NavigationController,
    SphericalCamera,
)
from geovs_drake.visualization import add_camera_geometry, add_goal_ghost, add_target_geometry

__all__ = [
    "RIG_BODY_NAME",
    "initial_rig_pose",
    "initial_rig_state",
    "make_dynamic_servo_diagram",
    "make_kinematic_servo_diagram",
]

RIG_BODY_NAME = "camera_rig"


def initial_rig_pose(config: ScenarioConfig) -> RigidTransform:
    """X_WR(0) = X_WB X_BC(0) X_RC^-1."""
    return config.X_WB @ config.X_BC_initial @ config.X_RC.inverse()


def initial_rig_state(config: ScenarioConfig) -> np.ndarray:
    """The rig's free-body state at t = 0, in the plant's layout (13 numbers).

    ``[qw, qx, qy, qz, x, y, z, wx, wy, wz, vx, vy, vz]``: X_WR(0) of
    :func:`initial_rig_pose`, then the angular velocity of R in W and the
    translational velocity of R's origin in W, both expressed in W, that give
    the camera the body twist ``config.initial_velocity`` = (Omega, V) =
    G^-1 Gdot of Eqs. (16)-(17). For :meth:`MultibodyPlant.SetPositionsAndVelocities`
    (the plant has no default velocity, so a simulator's context must be set).
    """
    X_WR = initial_rig_pose(config)
    X_RC = config.X_RC
    R_WR = X_WR.rotation().matrix()
    R_WC = R_WR @ X_RC.rotation().matrix()
    velocity = rig_velocity(
        tuple(R_WR.ravel().tolist()),
        tuple(R_WC.ravel().tolist()),
        tuple(float(v) for v in config.initial_velocity),
        tuple(X_RC.translation().tolist()),
    )
    return np.concatenate(
        [X_WR.rotation().ToQuaternion().wxyz(), X_WR.translation(), np.asarray(velocity)]
    )


def _add_loggers(builder: DiagramBuilder, camera, nav, rate: float) -> None:
    period = 1.0 / rate
    for port, name in (
        (camera.image_features_output, "log_image_features"),
        (camera.visibility_output, "log_visibility"),
        (camera.domain_margins_output, "log_margins"),
        (nav.phi_output, "log_phi"),
    ):
        LogVectorOutput(port, builder, publish_period=period).set_name(name)


def _camera_and_navigation(builder: DiagramBuilder, config: ScenarioConfig, X_RC: RigidTransform):
    domain = config.domain.to_domain()
    camera = builder.AddNamedSystem(
        "spherical_camera",
        SphericalCamera(radius=config.radius, X_WB=config.X_WB, X_RC=X_RC, domain=domain),
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

    The kinematic body *is* the camera frame (X_RC = identity).
    """
    config = config or ScenarioConfig()
    config.validate()
    builder = DiagramBuilder()
    body = builder.AddNamedSystem(
        "kinematic_rigid_body", KinematicRigidBody(X_WC0=config.X_WB @ config.X_BC_initial)
    )
    camera, nav = _camera_and_navigation(builder, config, RigidTransform())
    builder.Connect(body.body_pose_output, camera.body_pose_input)
    controller = builder.AddNamedSystem(
        "kinematic_controller",
        KinematicController(radius=config.radius, gain=config.control.kinematic_gain),
    )
    builder.Connect(camera.image_features_output, controller.image_features_input)
    builder.Connect(nav.dphi_output, controller.dphi_input)
    builder.Connect(controller.camera_velocity_output, body.camera_velocity_input)
    if log:
        _add_loggers(builder, camera, nav, config.log_rate)
        LogVectorOutput(
            body.body_pose_output, builder, publish_period=1.0 / config.log_rate
        ).set_name("log_body_pose")
    diagram = builder.Build()
    diagram.set_name("kinematic_visual_servo")
    return diagram
