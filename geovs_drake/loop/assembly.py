"""``assemble_loop(resolved)``: one visual-servo loop = carrier + sensor + law, as a named
Diagram, from a resolved scenario (:func:`~geovs_drake.loop.resolver`; the public
:func:`~geovs_drake.loop.build_loop` resolves a plain config first).

The parts come from three registries: :data:`~geovs_drake.loop.carriers.CARRIERS`
(what moves the camera), :data:`~geovs_drake.loop.sensors.SENSORS` (how the loop
sees the target) and :data:`~geovs_drake.loop.laws.LAWS` (what it does with y).
The builder is a straight line::

    carrier  = CARRIERS[type(carrier), type(plant)](builder, resolved, draws_marks)
    camera   = SphericalCamera(...)             # the truth: exact y of the true pose
    y        = SENSORS[type(sensor)].add(...)   # the y the law acts on
    nav      = NavigationController(...)       # phi on D, reported for every law
    command  = LAWS[type(law)].add(...)        # a twist, or a force system
    drive the carrier with it                  # velocity-tracking force if it needs one
    loggers and Meshcat on the parts' ports

Subsystem names (``diagram.GetSubsystemByName``): ``spherical_camera``,
``navigation_controller``; the carrier's ``plant``, ``scene_graph``,
``state_demux``, ``kinematic_rigid_body``, ``fixed_camera_mount``; the sensor's
``feature_sensor`` and ``rgbd_sensor``; the law's ``image_jacobian_force``,
``kinematic_controller``, ``controller``, ``desired_image``; the adapter
``velocity_tracking_force``; a moving target's ``target_motion``,
``target_relative_twist`` or ``target_relative_wrench`` and, with the estimated
feed-forward, ``target_twist_estimator`` (:mod:`geovs_drake.loop.targets`). With
``log=True``, Drake's ``LogVectorOutput``
loggers ``log_image_features``, ``log_phi``, ``log_margins``,
``log_visibility``, the carrier's ``log_body_state`` / ``log_body_pose`` and a
camera model's ``log_measured_features`` and ``log_feature_status``, at
``config.log_rate``. :func:`geovs_drake.simulation.simulate` builds with
``log=False`` and logs from its recorded steps instead: periodic loggers cut
every integrator step at each sample time.

With ``study_ports=True`` the diagram also exports what a linear study needs (Drake's
``Linearize`` takes the diagram's ports): the inputs ``disturbance`` (6), added to
the law's command where the carrier takes it, and ``feature_noise`` (13), added to
the sensor's y before the NF and the law read it; the outputs ``image_features``
(13, the true y) and ``body_pose`` (7, what the camera system reads).
:attr:`Loop.disturbance` names the disturbance's convention, :data:`DISTURBANCES`.
"""

from __future__ import annotations

from dataclasses import dataclass

from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.primitives import Adder, LogVectorOutput

from geovs_drake.loop.carriers import CARRIERS, CarrierParts, carrier_key
from geovs_drake.loop.laws import LAWS
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.sensors import SENSORS, add_feature_loggers
from geovs_drake.loop.targets import add_target_motion, connect_feedforward
from geovs_drake.scenario import ScenarioConfig, variant_name
from geovs_drake.systems import NavigationController, SphericalCamera, VelocityTrackingForce

__all__ = [
    "DISTURBANCES",
    "FEATURE_SIZE",
    "Loop",
    "assemble_loop",
    "refusal",
]

#: The size of y = (Q, lambda, s) as the ports carry it (Q as 9 entries).
FEATURE_SIZE = 13
#: What the ``disturbance`` input of a study diagram adds to, by the carrier's port it
#: enters: a twist-driven carrier's body twist, a wrench-driven carrier's wrench F_C
#: (the NF's Eq. 45 convention) or, on the free rig, the plant's generalized force.
DISTURBANCES = {
    "twist_C": "the camera's body twist (Omega, V) in C, added to the law's",
    "wrench_C": "a wrench F_C on the camera about Co in C (torque first), added to the law's",
    "generalized_force": (
        "the rig's generalized force (torque about R's origin, then force, in W), added "
        "to the law's"
    ),
}


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
    #: The ``disturbance`` input's convention (a :data:`DISTURBANCES` key), for a
    #: diagram built with ``study_ports``; else None.
    disturbance: str | None = None


def refusal(config: ScenarioConfig) -> str | None:
    """Why the parts of ``config`` make no loop, in one line, or None if they do."""
    if carrier_key(config) not in CARRIERS:
        carrier, plant = (kind.__name__ for kind in carrier_key(config))
        known = ", ".join(f"({c.__name__}, {p.__name__})" for c, p in CARRIERS)
        return (
            f"carrier {carrier} on plant {plant} has no factory: register "
            f"CARRIERS[{carrier}, {plant}] ({known})"
        )
    for axis, name, registry, part in (
        ("sensor", "SENSORS", SENSORS, "sensor"),
        ("controller", "LAWS", LAWS, "law"),
    ):
        kind = type(getattr(config, axis))
        if kind not in registry:
            known = ", ".join(variant.__name__ for variant in registry)
            return (
                f"{axis} {kind.__name__} has no {part}: register {name}[{kind.__name__}] ({known})"
            )
    return None


def _diagram_name(config: ScenarioConfig) -> str:
    """``<sensor>_visual_servo`` with a camera, else ``[fixed_camera_]<plant>_visual_servo``."""
    if config.sensor.traits.camera:
        return f"{variant_name(config.sensor)}_visual_servo"
    mount = "" if config.carrier.traits.camera_in_hand else "fixed_camera_"
    return f"{mount}{variant_name(config.plant)}_visual_servo"


def assemble_loop(
    resolved: ResolvedScenario,
    meshcat: Meshcat | None = None,
    log: bool = True,
    study_ports: bool = False,
) -> Loop:
    """The loop ``resolved`` describes, its parts read from the registries; what the
    scenario derives is read from ``resolved``, never derived again.

    ``meshcat`` adds a MeshcatVisualizer and the camera frame's axes (a carrier
    with geometry only; double only: leave it out of diagrams you will convert to
    AutoDiffXd). ``study_ports`` exports the disturbance and noise inputs and the
    y and pose outputs (module docstring). Raises ValueError in one line for parts
    that make no loop.
    """
    config = resolved.config  # its parts' entries were checked by the resolver (refusal)
    if study_ports and config.moving_target:
        # The target's systems are double only (a discrete estimator): Linearize and the
        # studies model the still target; a moving one's lag is linear_model.tracking_lag.
        raise ValueError(
            "study_ports: a study diagram's target stands still (target_motion Still()); "
            "a moving target's lag is geovs_drake.goal.linear_model.tracking_lag"
        )
    sensor = SENSORS[type(config.sensor)]
    builder = DiagramBuilder()
    carrier = CARRIERS[carrier_key(config)](builder, resolved, sensor.draws_marks)
    # A moving target: the carrier seen from the target's frame (None: a still target).
    target = add_target_motion(builder, resolved, carrier)
    if target is not None:
        carrier = target.carrier
    if meshcat is not None and carrier.add_meshcat is None:
        raise ValueError(
            f"meshcat needs a carrier with geometry (the {variant_name(config.plant)} "
            f"{type(config.carrier).__name__} has none)"
        )
    camera = builder.AddNamedSystem(
        "spherical_camera",
        SphericalCamera(
            radius=config.radius, X_WB=carrier.X_WB, X_RC=carrier.X_RC, domain=resolved.domain
        ),
    )
    builder.Connect(carrier.body_pose, camera.body_pose_input)
    features = sensor.add(builder, resolved, carrier, camera)
    if target is not None:  # the feed-forward: the estimator reads the sensor's frames
        connect_feedforward(builder, resolved, target, camera)
    if study_ports:
        # The law and the NF see y + n; the camera's own output stays the truth.
        noise = builder.AddNamedSystem("feature_noise_adder", Adder(2, FEATURE_SIZE))
        builder.Connect(features, noise.get_input_port(0))
        builder.ExportInput(noise.get_input_port(1), "feature_noise")
        builder.ExportOutput(camera.image_features_output, "image_features")
        builder.ExportOutput(carrier.body_pose, "body_pose")
        features = noise.get_output_port()
    if carrier.view is not None:  # the carrier's own view of y (the quadrotor's level one)
        features = carrier.view(builder, features)
    nav = builder.AddNamedSystem(
        "navigation_controller",
        NavigationController(goal=resolved.y_goal, domain=resolved.domain, gains=resolved.gains),
    )
    builder.Connect(features, nav.image_features_input)
    if carrier.phi_input is not None:
        builder.Connect(nav.phi_output, carrier.phi_input)
    command = LAWS[type(resolved.law)].add(builder, resolved, features, nav, carrier)
    disturbance = drive_carrier(builder, resolved, carrier, command, study_ports)
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
    return Loop(diagram, resolved, carrier, camera, nav, features, feature_sensor, disturbance)


def drive_carrier(
    builder: DiagramBuilder, resolved: ResolvedScenario, carrier, command, disturbed: bool
) -> str | None:
    """Connect the law's command to the carrier; a twist on a force-driven carrier goes
    through ``VelocityTrackingForce`` (F = B (nu_cmd - nu)). With ``disturbed``, a
    ``disturbance`` input is added to the command where the carrier takes it; returns
    its :data:`DISTURBANCES` key (None without). A law that drives the rotors itself
    (its traits' ``commands``, ``"rotors"``) goes to the carrier's ``rotors``."""
    if resolved.law.traits.commands == "rotors":
        if disturbed:
            raise ValueError(
                f"a study's disturbance input needs a wrench or a twist: controller "
                f"{variant_name(resolved.law)} drives the rotors itself"
            )
        carrier.rotors.connect(builder, command)
        return None
    if not isinstance(command, LeafSystem) and carrier.takes_wrench:
        adapter = builder.AddNamedSystem(
            "velocity_tracking_force",
            VelocityTrackingForce(gains=resolved.config.control.tracking_gains, X_RC=carrier.X_RC),
        )
        builder.Connect(command, adapter.camera_velocity_command_input)
        command = adapter
    if isinstance(command, LeafSystem):  # a force system (Eq. 45 or the adapter)
        force = _DisturbedForce(builder, command) if disturbed else command
        # What the law damps: the carrier's body state (as a moving target's loop
        # believes it, where the target moves); the carrier takes the law's output.
        builder.Connect(carrier.body_state, force.body_state_input)
        carrier.connect_force(builder, force)
        return force.convention if disturbed else None
    if disturbed:
        adder = builder.AddNamedSystem("disturbance_adder", Adder(2, 6))
        builder.Connect(command, adder.get_input_port(0))
        builder.ExportInput(adder.get_input_port(1), "disturbance")
        command = adder.get_output_port()
    builder.Connect(command, carrier.twist_input)
    return "twist_C" if disturbed else None


class _DisturbedForce:
    """A force system as a carrier's ``connect_force`` sees it, with the ``disturbance``
    input added to whichever of its outputs the carrier takes (a carrier reads one:
    the free rig the generalized force, the fixed mount and the arm F_C)."""

    def __init__(self, builder: DiagramBuilder, force: LeafSystem) -> None:
        self._builder, self._force = builder, force
        self.body_state_input = force.body_state_input
        self.convention: str | None = None

    def _disturbed(self, port: OutputPort, convention: str) -> OutputPort:
        adder = self._builder.AddNamedSystem("disturbance_adder", Adder(2, port.size()))
        self._builder.Connect(port, adder.get_input_port(0))
        self._builder.ExportInput(adder.get_input_port(1), "disturbance")
        self.convention = convention
        return adder.get_output_port()

    @property
    def generalized_force_output(self) -> OutputPort:
        return self._disturbed(self._force.generalized_force_output, "generalized_force")

    @property
    def wrench_C_output(self) -> OutputPort:
        return self._disturbed(self._force.wrench_C_output, "wrench_C")
