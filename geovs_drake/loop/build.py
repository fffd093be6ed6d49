"""``build_loop(config)``: one visual-servo loop = carrier + sensor + law, as a named Diagram.

The parts come from three registries: :data:`~geovs_drake.loop.carriers.CARRIERS`
(what moves the camera), :data:`~geovs_drake.loop.sensors.SENSORS` (how the loop
sees the target) and :data:`~geovs_drake.loop.laws.LAWS` (what it does with y).
The builder is a straight line::

    carrier  = CARRIERS[(carrier, mount, plant)](builder, resolved, draws_marks)
    camera   = SphericalCamera(...)            # the truth: exact y of the true pose
    y        = SENSORS[camera.sensor].add(...)  # the y the law acts on
    nav      = NavigationController(...)       # phi on D, reported for every law
    command  = LAWS[controller].add(...)       # a twist, or a force system
    drive the carrier with it                  # velocity-tracking force if it needs one
    loggers and Meshcat on the parts' ports

Subsystem names (``diagram.GetSubsystemByName``): ``spherical_camera``,
``navigation_controller``; the carrier's ``plant``, ``scene_graph``,
``state_demux``, ``kinematic_rigid_body``, ``fixed_camera_mount``; the sensor's
``feature_sensor`` and ``rgbd_sensor``; the law's ``image_jacobian_force``,
``kinematic_controller``, ``controller``, ``desired_image``; the adapter
``velocity_tracking_force``. With ``log=True``, Drake's ``LogVectorOutput``
loggers ``log_image_features``, ``log_phi``, ``log_margins``,
``log_visibility``, the carrier's ``log_body_state`` / ``log_body_pose`` and a
camera model's ``log_measured_features`` and ``log_feature_status``, at
``config.log_rate``. :func:`geovs_drake.simulation.simulate` builds with
``log=False`` and logs from its recorded steps instead: periodic loggers cut
every integrator step at each sample time.
"""

from __future__ import annotations

from dataclasses import dataclass

from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.primitives import LogVectorOutput

from geovs_drake.loop.carriers import CARRIERS, CarrierParts, carrier_key
from geovs_drake.loop.laws import LAWS
from geovs_drake.loop.sensors import SENSORS, add_feature_loggers
from geovs_drake.scenario import ResolvedScenario, ScenarioConfig, resolve
from geovs_drake.systems import NavigationController, SphericalCamera, VelocityTrackingForce

__all__ = ["Loop", "build_loop", "loop_of", "refusal"]


@dataclass
class Loop:
    """A built loop: its Diagram, the scenario it was resolved from, and its parts.

    ``camera`` is the exact ``spherical_camera`` (the truth), ``navigation`` the
    ``navigation_controller``, ``features`` the y the law acts on, ``carrier``
    the carrier's :class:`~geovs_drake.loop.carriers.CarrierParts`, and
    ``feature_sensor`` the camera model, if any.
    """

    diagram: Diagram
    resolved: ResolvedScenario
    carrier: CarrierParts
    camera: LeafSystem
    navigation: LeafSystem
    features: OutputPort
    feature_sensor: LeafSystem | None = None


def refusal(config: ScenarioConfig) -> str | None:
    """Why the parts of ``config`` make no loop, in one line, or None if they do."""
    if carrier_key(config) not in CARRIERS:
        carrier, mount, plant = carrier_key(config)
        return (
            f"no carrier moves a camera with carrier {carrier!r}, mount {mount!r}, plant {plant!r}"
        )
    if config.camera.sensor not in SENSORS:
        return f"no sensor {config.camera.sensor!r} (registered: {', '.join(SENSORS)})"
    name = config.controller if isinstance(config.controller, str) else None
    if name is not None and name not in LAWS:
        return f"controller {name!r} has no law (registered: {', '.join(LAWS)})"
    return None


def _diagram_name(config: ScenarioConfig) -> str:
    if config.camera.sensor != "exact":
        return f"{config.camera.sensor}_visual_servo"
    if config.mount == "fixed":
        return f"fixed_camera_{config.plant}_visual_servo"
    return f"{config.plant}_visual_servo"


def build_loop(
    config: ScenarioConfig | ResolvedScenario | None = None,
    meshcat: Meshcat | None = None,
    log: bool = True,
) -> Loop:
    """The loop ``config`` describes (validated and resolved once, :func:`resolve`;
    a :class:`~geovs_drake.scenario.ResolvedScenario` is trusted as it is).

    ``meshcat`` adds a MeshcatVisualizer and the camera frame's axes (a carrier
    with geometry only; double only: leave it out of diagrams you will convert to
    AutoDiffXd). Raises ValueError in one line for parts that make no loop.
    """
    resolved = resolve(config)
    config = resolved.config
    why = refusal(config)
    if why is not None:
        raise ValueError(why)
    sensor = SENSORS[config.camera.sensor]
    builder = DiagramBuilder()
    carrier = CARRIERS[carrier_key(config)](builder, resolved, sensor.draws_marks)
    if meshcat is not None and carrier.add_meshcat is None:
        raise ValueError(
            f"meshcat needs the dynamic plant (the {config.plant} one has no geometry)"
        )
    camera = builder.AddNamedSystem(
        "spherical_camera",
        SphericalCamera(
            radius=config.radius, X_WB=carrier.X_WB, X_RC=carrier.X_RC, domain=resolved.domain
        ),
    )
    builder.Connect(carrier.body_pose, camera.body_pose_input)
    features = sensor.add(builder, resolved, carrier, camera)
    nav = builder.AddNamedSystem(
        "navigation_controller",
        NavigationController(goal=resolved.y_goal, domain=resolved.domain, gains=resolved.gains),
    )
    builder.Connect(features, nav.image_features_input)
    command = LAWS[resolved.controller].add(builder, resolved, features, nav, carrier)
    _drive(builder, resolved, carrier, command)
    feature_sensor = (
        builder.GetSubsystemByName("feature_sensor")
        if builder.HasSubsystemNamed("feature_sensor")
        else None
    )
    if log:
        period = 1.0 / config.log_rate
        for port, name in (
            (camera.image_features_output, "log_image_features"),
            (camera.visibility_output, "log_visibility"),
            (camera.domain_margins_output, "log_margins"),
            (nav.phi_output, "log_phi"),
            (carrier.state, carrier.state_log_name),
        ):
            LogVectorOutput(port, builder, publish_period=period).set_name(name)
        if feature_sensor is not None:
            add_feature_loggers(builder, feature_sensor, config.log_rate)
    if meshcat is not None:
        carrier.add_meshcat(builder, meshcat)
    diagram = builder.Build()
    diagram.set_name(_diagram_name(config))
    loop = Loop(diagram, resolved, carrier, camera, nav, features, feature_sensor)
    # The simulator, the monitor and the logs find the parts from the diagram
    # the earlier builders return (loop_of).
    diagram.geovs_loop = loop
    return loop


def _drive(builder: DiagramBuilder, resolved: ResolvedScenario, carrier, command) -> None:
    """Connect the law's command to the carrier; a twist on a force-driven carrier goes
    through ``VelocityTrackingForce`` (F = B (nu_cmd - nu))."""
    if isinstance(command, LeafSystem):  # a force system (the NF's Eq. 45)
        carrier.connect_force(builder, command)
        return
    if carrier.drive == "twist":
        builder.Connect(command, carrier.twist_input)
        return
    adapter = builder.AddNamedSystem(
        "velocity_tracking_force",
        VelocityTrackingForce(gains=resolved.config.control.tracking_gains, X_RC=carrier.X_RC),
    )
    builder.Connect(command, adapter.camera_velocity_command_input)
    carrier.connect_force(builder, adapter)


def loop_of(diagram: Diagram) -> Loop:
    """The :class:`Loop` a diagram was built as (by :func:`build_loop` or a builder over
    it); ValueError for a diagram built otherwise."""
    loop = getattr(diagram, "geovs_loop", None)
    if loop is None:
        raise ValueError(
            f"diagram {diagram.get_name()!r} was not built by geovs_drake.loop.build_loop"
        )
    return loop
