"""Diagram builders: the visual-servo loops as named Diagrams.

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

The loops with a camera (:func:`make_rendered_servo_diagram`,
:func:`make_pinhole_servo_diagram`) add ``feature_sensor`` (the
:class:`~geovs_drake.systems.FeatureExtractor` or
:class:`~geovs_drake.systems.PinholeFeatureSensor`), whose held y drives the
controller, and, rendered, ``rgbd_sensor``; their ``spherical_camera`` still
computes the exact y, which nothing in the loop reads: it is the truth the
safe-domain monitor and the logs use. :func:`make_servo_diagram` picks the
builder from ``config.plant`` and ``config.camera.sensor``.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import (
    ClippingRange,
    ColorRenderCamera,
    DepthRange,
    DepthRenderCamera,
    LightParameter,
    MakeRenderEngineVtk,
    Meshcat,
    MeshcatVisualizer,
    RenderCameraCore,
    RenderEngineVtkParams,
    Role,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import RotationalInertia, SpatialInertia
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import Demultiplexer, LogVectorOutput, TrajectorySource
from pydrake.systems.sensors import CameraInfo, RgbdSensor
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
    FeatureExtractor,
    FixedCameraKinematicMount,
    FixedCameraMount,
    IbvsController,
    ImageJacobianForce,
    KinematicController,
    KinematicRigidBody,
    NavigationController,
    PathFollowingController,
    PbvsController,
    PinholeFeatureSensor,
    SphericalCamera,
    SphericalFeatureController,
    VelocityTrackingForce,
)
from geovs_drake.systems.feature_extractor import SCENE_COLOURS
from geovs_drake.visualization import (
    add_camera_geometry,
    add_goal_ghost,
    add_marked_target_geometry,
    add_target_geometry,
)

__all__ = [
    "RENDERER_NAME",
    "RIG_BODY_NAME",
    "TARGET_BODY_NAME",
    "TWIST_CONTROLLERS",
    "VTK_PRINCIPAL_POINT_SHIFT",
    "initial_body_states",
    "initial_rig_pose",
    "initial_rig_state",
    "fixed_camera_pose",
    "make_dynamic_servo_diagram",
    "make_fixed_camera_diagram",
    "make_kinematic_servo_diagram",
    "make_servo_diagram",
    "make_pinhole_servo_diagram",
    "make_rendered_servo_diagram",
    "scene_lights",
    "vtk_camera_info",
]

RIG_BODY_NAME = "camera_rig"
#: The name of the VTK render engine the rendered loop adds to SceneGraph.
RENDERER_NAME = "geovs_vtk"
TARGET_BODY_NAME = "target_sphere"

#: A law that commands the camera's body twist: ``factory(builder, config, features)``
#: adds its system (and any sources it needs) to ``builder``, connects every input
#: but ``image_features``, and returns the system, whose output port
#: ``camera_velocity`` is (Omega, V) in C. The builder then connects the system's
#: ``image_features`` input (if it has one) to ``features``, the output port y comes
#: from. Keyed by ``ScenarioConfig.controller``; the NF ("nf") is built in.
TwistControllerFactory = Callable[[DiagramBuilder, ScenarioConfig, object], LeafSystem]


def _baseline(law: type, **options: Callable[[ScenarioConfig], object]) -> TwistControllerFactory:
    """The factory of a baseline law toward the goal image: ``law(goal=y*, radius=rho
    believed, gain=control.baseline_gain, **{name: option(config)})``."""

    def factory(builder: DiagramBuilder, config: ScenarioConfig, features) -> LeafSystem:
        return builder.AddSystem(
            law(
                goal=config.goal_features(),
                radius=config.believed_radius,
                gain=config.control.baseline_gain,
                **{name: option(config) for name, option in options.items()},
            )
        )

    return factory


TWIST_CONTROLLERS: dict[str, TwistControllerFactory] = {
    "ibvs": _baseline(IbvsController, depth=lambda config: config.control.ibvs_depth),
    "pbvs": _baseline(PbvsController),
    "spherical": _baseline(SphericalFeatureController),
}


def _add_twist_controller(builder: DiagramBuilder, config: ScenarioConfig, features) -> LeafSystem:
    """The registered law of ``config.controller``, named ``controller``, its
    ``image_features`` input connected to ``features`` (the port y comes from: the
    exact camera's, or a camera model's measurement)."""
    try:
        factory = TWIST_CONTROLLERS[config.controller]
    except KeyError:
        raise ValueError(
            f"controller {config.controller!r} has no diagram (registered: nf, "
            f"{', '.join(sorted(TWIST_CONTROLLERS))})"
        ) from None
    law = factory(builder, config, features)
    law.set_name("controller")
    if law.HasInputPort("image_features"):
        builder.Connect(features, law.GetInputPort("image_features"))
    return law


def _path_following(builder: DiagramBuilder, config: ScenarioConfig, features) -> LeafSystem:
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
    *,
    connect: bool = True,
):
    """The exact camera (the truth) and the NF controller; ``connect`` feeds the former to
    the latter (the exact loop). ``X_WB`` defaults to ``config.X_WB``."""
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
    if connect:
        builder.Connect(camera.image_features_output, nav.image_features_input)
    return camera, nav


def _add_rig(builder: DiagramBuilder, config: ScenarioConfig, rendered: bool):
    """The MultibodyPlant with the free camera rig, the target and the camera's drawing.

    ``rendered``: the target in the extractor's colours
    (:func:`~geovs_drake.visualization.add_marked_target_geometry`), and the camera's
    own drawing and the goal ghost kept out of the renderer (illustration only).
    """
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    # The rig's body frame R has its origin at the centre of mass.
    rig = plant.AddRigidBody(
        RIG_BODY_NAME,
        SpatialInertia.MakeFromCentralInertia(
            config.rig.mass, np.zeros(3), RotationalInertia(*config.rig.inertia_diagonal)
        ),
    )
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    theta = config.domain.to_domain().fov_half_angle
    if rendered:
        add_marked_target_geometry(plant, config)
    else:
        add_target_geometry(plant, config)
    drawing = add_camera_geometry(plant, rig, config.X_RC, theta) + add_goal_ghost(plant, config)
    plant.Finalize()
    plant.SetDefaultFloatingBaseBodyPose(rig, initial_rig_pose(config))
    if rendered:
        for geometry_id in drawing:
            scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kPerception)
    return plant, scene_graph, rig


def _close_dynamic_loop(builder, config, plant, features_port, log: bool):
    """Camera (truth) -> law -> force -> plant, with y from ``features_port`` (None: the
    exact camera's). The NF's law is Eq. (45)'s force, with ``control.damping`` on the
    exact y and ``camera.damping`` on a camera model's; any other law
    (:data:`TWIST_CONTROLLERS`) commands a twist that ``VelocityTrackingForce`` tracks.
    The NF controller stays in the diagram for phi on D either way."""
    demux = builder.AddNamedSystem("state_demux", Demultiplexer([7, 6]))
    builder.Connect(plant.get_state_output_port(), demux.get_input_port())
    camera, nav = _camera_and_navigation(
        builder, config, config.X_RC, connect=features_port is None
    )
    builder.Connect(demux.get_output_port(0), camera.body_pose_input)
    exact = features_port is None
    features_port = camera.image_features_output if exact else features_port
    if not exact:
        builder.Connect(features_port, nav.image_features_input)
    if config.controller == "nf":
        force = builder.AddNamedSystem(
            "image_jacobian_force",
            ImageJacobianForce(
                radius=config.believed_radius,
                potential_gain=config.control.potential_gain,
                damping=np.asarray(
                    config.control.damping if exact else config.camera.damping, dtype=float
                ),
                X_RC=config.X_RC,
            ),
        )
        builder.Connect(features_port, force.image_features_input)
        builder.Connect(nav.dphi_output, force.dphi_input)
    else:
        law = _add_twist_controller(builder, config, features_port)
        force = builder.AddNamedSystem(
            "velocity_tracking_force",
            VelocityTrackingForce(gains=config.control.tracking_gains, X_RC=config.X_RC),
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
    return demux


def _add_meshcat(builder, scene_graph, rig, config, meshcat: Meshcat | None) -> None:
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
        AddFrameTriadIllustration(
            scene_graph=scene_graph,
            body=rig,
            X_FT=config.X_RC,
            length=0.08,
            radius=0.003,
            name="C",
        )


def make_dynamic_servo_diagram(
    config: ScenarioConfig | None = None, meshcat: Meshcat | None = None, log: bool = True
) -> Diagram:
    """The dynamic loop of Appendix C around a continuous MultibodyPlant free body.

    Gravity is off: the paper assumes it is cancelled by the controller, and a
    gravity-compensation term would add nothing to the servo's analysis. The
    camera frame may sit off the rig's centre of mass (``rig.camera_offset``,
    Appendix C.0.6). Pass ``meshcat`` to add a MeshcatVisualizer and the camera
    frame's axes (double only: leave it out of diagrams you will convert to
    AutoDiffXd). The controller reads the exact y = c(H), whatever
    ``config.camera.sensor`` says (see :func:`make_servo_diagram`).
    """
    config = config or ScenarioConfig()
    config.validate()
    builder = DiagramBuilder()
    plant, scene_graph, rig = _add_rig(builder, config, rendered=False)
    _close_dynamic_loop(builder, config, plant, None, log)
    _add_meshcat(builder, scene_graph, rig, config, meshcat)
    diagram = builder.Build()
    diagram.set_name("dynamic_visual_servo")
    return diagram


def _camera_config(config: ScenarioConfig, sensor: str, rate, resolution) -> ScenarioConfig:
    """A copy of ``config`` with the camera's sensor, rate and resolution set, validated."""
    config = copy.deepcopy(config or ScenarioConfig())
    config.camera.sensor = sensor
    if rate is not None:
        config.camera.rate = rate
    if resolution is not None:
        config.camera.resolution = [int(v) for v in resolution]
    config.validate()
    return config


def _add_feature_loggers(builder, sensor, rate: float) -> None:
    for port, name in (
        (sensor.image_features_output, "log_measured_features"),
        (sensor.feature_status_output, "log_feature_status"),
    ):
        LogVectorOutput(port, builder, publish_period=1.0 / rate).set_name(name)


#: Where Drake's RenderEngineVtk (drake 1.51) puts the optical axis, in pixel-centre
#: coordinates, relative to ``CameraInfo``'s ``(center_x, center_y)``: half a pixel up
#: and left, OpenGL's convention of pixel corners at integers. Measured (a test renders
#: a small sphere on the optical axis and finds its centroid there).
VTK_PRINCIPAL_POINT_SHIFT = -0.5


def vtk_camera_info(intrinsics) -> CameraInfo:
    """The ``CameraInfo`` with which RenderEngineVtk renders an image that ``intrinsics``
    (pixel centres at integers, :mod:`geovs_drake.geometry.pinhole`) describes exactly."""
    return CameraInfo(
        intrinsics.width,
        intrinsics.height,
        intrinsics.fx,
        intrinsics.fy,
        intrinsics.cx - VTK_PRINCIPAL_POINT_SHIFT,
        intrinsics.cy - VTK_PRINCIPAL_POINT_SHIFT,
    )


def scene_lights() -> list[LightParameter]:
    """A headlight and four side lights, all in the camera frame, intensity 0.5 each.

    Why not Drake's default headlight alone: it shades by the cosine between the
    normal and the view, so near the limb a mark turns black and the extractor
    loses it (a mark seen at 82 deg from face-on read 1 dark pixel). With side lights
    from +-x and +-y a diffuse surface gets between 0.5 and 0.87 of full light
    wherever it is seen, the limb included.
    """
    directions = ([0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0])
    return [
        LightParameter(type="directional", frame="camera", intensity=0.5, direction=d)
        for d in directions
    ]


def make_rendered_servo_diagram(
    config: ScenarioConfig | None = None,
    camera_rate: float | None = None,
    resolution: tuple[int, int] | None = None,
    meshcat: Meshcat | None = None,
    log: bool = True,
) -> Diagram:
    """The dynamic loop closed through rendered images.

    plant -> SceneGraph -> ``RgbdSensor`` (``RenderEngineVtk``, EGL backend:
    headless) -> :class:`~geovs_drake.systems.FeatureExtractor` (a frame every
    ``1 / camera_rate`` s, held between frames) -> NF controller ->
    ``ImageJacobianForce`` -> plant. ``camera_rate`` [Hz] and ``resolution``
    (W, H) default to ``config.camera``'s (30 Hz, 320x240); the camera's
    intrinsics are :meth:`~geovs_drake.scenario.CameraConfig.intrinsics` (its
    inscribed cone is D's field of view, so no pose of D cuts the sphere), the
    extractor's those times ``1 + camera.focal_error``. The renderer draws
    the marked target (:func:`~geovs_drake.visualization.add_marked_target_geometry`)
    on a blue background; the camera's own drawing is illustration only.
    Double only (``RgbdSensor`` does not convert).
    """
    config = _camera_config(config, "rendered", camera_rate, resolution)
    cam = config.camera
    theta = config.domain.to_domain().fov_half_angle
    intrinsics = cam.intrinsics(theta)
    builder = DiagramBuilder()
    plant, scene_graph, rig = _add_rig(builder, config, rendered=True)
    scene_graph.AddRenderer(
        RENDERER_NAME,
        MakeRenderEngineVtk(
            RenderEngineVtkParams(
                backend="EGL",
                default_clear_color=list(SCENE_COLOURS["background"]),
                lights=scene_lights(),
            )
        ),
    )
    # Clip well short of the nearest sphere of D and well beyond the farthest.
    d = config.domain
    near = 0.5 * config.radius * (1 / d.lam_max - 1)
    far = 2.0 * config.radius * (1 / d.lam_min + 1)
    core = RenderCameraCore(
        RENDERER_NAME, vtk_camera_info(intrinsics), ClippingRange(near, far), RigidTransform()
    )
    rgbd = builder.AddNamedSystem(
        "rgbd_sensor",
        RgbdSensor(
            plant.GetBodyFrameIdOrThrow(rig.index()),
            config.X_RC,
            ColorRenderCamera(core, False),
            DepthRenderCamera(core, DepthRange(1.01 * near, 0.99 * far)),
        ),
    )
    builder.Connect(scene_graph.get_query_output_port(), rgbd.query_object_input_port())
    sensor = builder.AddNamedSystem(
        "feature_sensor",
        FeatureExtractor(
            intrinsics=cam.believed_intrinsics(theta),
            period=1.0 / cam.rate,
            latency_frames=int(cam.latency_frames),
            max_lost_frames=int(cam.max_lost_frames),
            pixel_noise=cam.pixel_noise,
            seed=int(cam.seed),
        ),
    )
    builder.Connect(rgbd.color_image_output_port(), sensor.color_image_input)
    _close_dynamic_loop(builder, config, plant, sensor.image_features_output, log)
    if log:
        _add_feature_loggers(builder, sensor, config.log_rate)
    _add_meshcat(builder, scene_graph, rig, config, meshcat)
    diagram = builder.Build()
    diagram.set_name("rendered_visual_servo")
    return diagram


def make_pinhole_servo_diagram(
    config: ScenarioConfig | None = None, meshcat: Meshcat | None = None, log: bool = True
) -> Diagram:
    """The dynamic loop closed through :class:`~geovs_drake.systems.PinholeFeatureSensor`:
    the rendered loop's measurement (camera rate, latency, pixel noise, focal error, the
    same fit) on exact projected points, without a renderer."""
    config = _camera_config(config, "pinhole", None, None)
    cam = config.camera
    theta = config.domain.to_domain().fov_half_angle
    builder = DiagramBuilder()
    plant, scene_graph, rig = _add_rig(builder, config, rendered=True)
    sensor = builder.AddNamedSystem(
        "feature_sensor",
        PinholeFeatureSensor(
            radius=config.radius,
            intrinsics=cam.intrinsics(theta),
            believed=cam.believed_intrinsics(theta),
            X_WB=config.X_WB,
            X_RC=config.X_RC,
            period=1.0 / cam.rate,
            latency_frames=int(cam.latency_frames),
            max_lost_frames=int(cam.max_lost_frames),
            pixel_noise=cam.pixel_noise,
            seed=int(cam.seed),
        ),
    )
    demux = _close_dynamic_loop(builder, config, plant, sensor.image_features_output, log)
    builder.Connect(demux.get_output_port(0), sensor.body_pose_input)
    if log:
        _add_feature_loggers(builder, sensor, config.log_rate)
    _add_meshcat(builder, scene_graph, rig, config, meshcat)
    diagram = builder.Build()
    diagram.set_name("pinhole_visual_servo")
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
            KinematicController(radius=config.believed_radius, gain=config.control.kinematic_gain),
        )
        builder.Connect(camera.image_features_output, controller.image_features_input)
        builder.Connect(nav.dphi_output, controller.dphi_input)
        builder.Connect(controller.camera_velocity_output, body.camera_velocity_input)
    else:
        law = _add_twist_controller(builder, config, camera.image_features_output)
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
            law = _add_twist_controller(builder, config, camera.image_features_output)
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
            command = _add_twist_controller(
                builder, config, camera.image_features_output
            ).GetOutputPort("camera_velocity")
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
    """The loop ``config`` describes: its ``mount`` (hand or fixed), ``plant`` and
    ``camera.sensor`` (exact, rendered or pinhole; the camera models run eye-in-hand
    on the dynamic plant, which ``ScenarioConfig.validate`` checks)."""
    config = config or ScenarioConfig()
    config.validate()
    if config.mount == "fixed":
        return make_fixed_camera_diagram(config, meshcat=meshcat, log=log)
    if config.camera.sensor == "rendered":
        return make_rendered_servo_diagram(config, meshcat=meshcat, log=log)
    if config.camera.sensor == "pinhole":
        return make_pinhole_servo_diagram(config, meshcat=meshcat, log=log)
    if config.plant == "dynamic":
        return make_dynamic_servo_diagram(config, meshcat=meshcat, log=log)
    if meshcat is not None:
        raise ValueError("meshcat needs the dynamic plant (the kinematic one has no geometry)")
    return make_kinematic_servo_diagram(config, log=log)
