"""The quadrotor, eye-in-hand: a MultibodyPlant free body under gravity, pushed by four of
Drake's ``Propeller`` systems, whose thrusts the NF's wrench sets through an attitude cascade
(:class:`~geovs_drake.systems.AttitudeCascade`)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from pydrake.geometry import Box, Cylinder
from pydrake.math import RigidTransform
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    MultibodyPlant,
    Propeller,
    PropellerInfo,
)
from pydrake.multibody.tree import RigidBody, RotationalInertia, SpatialInertia
from pydrake.systems.framework import Context, DiagramBuilder, LeafSystem

from geovs_drake.loop.carriers.arm import target_drawing
from geovs_drake.loop.carriers.parts import (
    CarrierFactory,
    CarrierParts,
    RotorDrive,
    leading_pose,
    meshcat_with_camera,
    out_of_view,
    pose_head,
    set_plant_state,
)
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.state import QUATERNION, initial_rig_pose
from geovs_drake.scenario import Dynamic, Quadrotor, ScenarioConfig
from geovs_drake.systems.attitude_cascade import AttitudeCascade, mixer
from geovs_drake.systems.level_view import LevelView
from geovs_drake.visualization import (
    add_camera_geometry,
    add_goal_ghost,
    add_marked_target_geometry,
    add_target_geometry,
)

__all__ = ["ENTRIES", "QUADROTOR_BODY_NAME", "rotor_layout"]

QUADROTOR_BODY_NAME = "quadrotor"
#: The drawn body: a box [m] and the rotors' discs (radius, thickness [m]), above the box.
_BOX, _DISC_RADIUS, _DISC_THICKNESS, _DISC_HEIGHT = (0.12, 0.12, 0.04), 0.06, 0.005, 0.03


def rotor_layout(quad: Quadrotor) -> tuple[np.ndarray, np.ndarray]:
    """The rotors in a + (Drake's quadrotor example): their positions (4, 3) [m] in the
    body frame, front, left, back, right, and their drag moment ratios [m], alternating
    in sign (rotors 0 and 2 turn one way, 1 and 3 the other)."""
    L, k = quad.arm_length, quad.moment_ratio
    positions = np.array([[L, 0, 0], [0, L, 0], [-L, 0, 0], [0, -L, 0]], dtype=float)
    return positions, np.array([k, -k, k, -k])


def _add_body_geometry(plant: MultibodyPlant, body: RigidBody, quad: Quadrotor) -> list:
    """The body's box and its four rotor discs (Meshcat and any renderer draw them)."""
    ids = [
        plant.RegisterVisualGeometry(
            body, RigidTransform(), Box(*_BOX), "quad_box", [0.3, 0.3, 0.35, 1.0]
        )
    ]
    for i, p in enumerate(rotor_layout(quad)[0]):
        ids.append(
            plant.RegisterVisualGeometry(
                body,
                RigidTransform(p + [0, 0, _DISC_HEIGHT]),
                Cylinder(_DISC_RADIUS, _DISC_THICKNESS),
                f"quad_rotor_{i}",
                [0.8, 0.2, 0.2, 0.6] if i == 0 else [0.2, 0.2, 0.2, 0.6],  # the front red
            )
        )
    return ids


def heading_W(config: ScenarioConfig) -> np.ndarray:
    """The goal's heading: the body's x axis at the goal, X_WB X_BC* X_RC^-1, in W (level:
    the scenario's checks ask the goal to be a level hover)."""
    X_WR = config.X_WB @ config.X_BC_goal @ config.X_RC.inverse()
    x = X_WR.rotation().matrix()[:, 0].copy()
    x[2] = 0.0
    return x / np.linalg.norm(x)


def _rotor_drive(
    builder: DiagramBuilder, resolved: ResolvedScenario, plant: MultibodyPlant, propellers
) -> tuple[RotorDrive, list, object, LeafSystem | None]:
    """What drives the rotors: the attitude cascade from the NF's wrench (its
    ``connect_force``), or, where the law drives them itself (its traits' ``commands``,
    ``"rotors"``: Hamel & Mahony's), the law, through the returned :class:`RotorDrive`
    (``connect_force`` None then). The list holds the driver once connected; the last
    entry is the cascade (its feed-forward inputs behind a moving target), else None."""
    config = resolved.config
    quad = config.carrier
    positions, moment_ratios = rotor_layout(quad)
    model = dict(
        mass=quad.mass,
        inertia_diagonal=tuple(quad.inertia_diagonal),
        gravity=float(-plant.gravity_field().gravity_vector()[2]),
        attitude_gains=tuple(quad.attitude_gains),
        mixer_matrix=mixer(positions, moment_ratios),
        max_thrust=quad.max_rotor_thrust,
        max_tilt=float(np.radians(quad.max_tilt_deg)),
    )
    drivers: list[LeafSystem] = []

    def drive_rotors(builder: DiagramBuilder, driver: LeafSystem) -> None:
        builder.Connect(plant.get_state_output_port(), driver.body_state_input)
        builder.Connect(driver.rotor_thrusts_output, propellers.get_command_input_port())
        drivers.append(driver)

    connect_force, cascade = None, None
    if resolved.law.traits.commands != "rotors":
        cascade = builder.AddNamedSystem(
            "attitude_cascade",
            AttitudeCascade(
                heading_W=tuple(heading_W(config)),
                velocity_damping=quad.velocity_damping,
                # A moving target translates (the scenario's check): X_WB(0)'s rotation.
                target_rotation=config.X_WB.rotation().matrix(),
                heading=quad.heading,
                **model,
            ),
        )
        drive_rotors(builder, cascade)

        def connect_force(builder: DiagramBuilder, force: LeafSystem) -> None:
            # The NF's wrench enters the cascade, which keeps its force (in W).
            builder.Connect(force.generalized_force_output, cascade.generalized_force_input)

    return RotorDrive(drive_rotors, model), drivers, connect_force, cascade


def _run_entries(drivers: list) -> Callable[[Context, np.ndarray, np.ndarray], dict]:
    """The run's JSON entries: the share of logged states at which the rotors' driver (the
    cascade or the law, ``drivers[0]``) gave anything up, and the peak tilt."""

    def run_entries(root: Context, states: np.ndarray, times: np.ndarray) -> dict:
        # The allocation's verdict at each logged state (the diagram evaluated there, at
        # its time: a moving target's pose is the time's; a twist estimator's discrete
        # state is its last).
        context = root.Clone()
        saturated = np.empty(len(states))
        for k, x in enumerate(states):
            context.SetTime(float(times[k]))
            context.SetContinuousState(x)
            sub = drivers[0].GetMyContextFromRoot(context)
            saturated[k] = drivers[0].saturated_output.Eval(sub)[0]
        q = np.asarray(states)[:, QUATERNION]
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        # The body's z axis's height: 1 - 2 (qx^2 + qy^2); its angle from up is the tilt.
        up = np.clip(1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1.0, 1.0)
        return {
            "rotor_saturation_fraction": float(np.mean(saturated)) if len(states) else 0.0,
            "max_tilt_deg": float(np.degrees(np.max(np.arccos(up)))) if len(states) else 0.0,
        }

    return run_entries


def _quadrotor(builder: DiagramBuilder, resolved: ResolvedScenario, draws_marks: bool):
    """The quadrotor on the dynamic plant: its free body (gravity on), its propellers, the
    cascade that drives them, and the scene. With ``draws_marks`` (the camera on board
    renders) the body's and the camera's drawings are kept out of the renderer: the front
    rotor would cover the top of a forward camera's image."""
    config = resolved.config
    quad = config.carrier
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    body = plant.AddRigidBody(
        QUADROTOR_BODY_NAME,
        SpatialInertia.MakeFromCentralInertia(
            quad.mass, np.zeros(3), RotationalInertia(*quad.inertia_diagonal)
        ),
    )
    # Gravity stays on (Drake's default field): the cascade holds the weight itself, where
    # the free rig of Appendix C has it cancelled.
    moving = config.moving_target
    if not moving:  # a moving one is drawn apart, at X_WB(t) (draw_target)
        (add_marked_target_geometry if draws_marks else add_target_geometry)(plant, config)
    theta = resolved.domain.fov_half_angle
    drawing = _add_body_geometry(plant, body, quad)
    drawing += add_camera_geometry(plant, body, config.X_RC, theta)
    drawing += [] if moving else add_goal_ghost(plant, config)
    plant.Finalize()
    plant.SetDefaultFloatingBaseBodyPose(body, initial_rig_pose(config))
    if draws_marks:
        out_of_view(scene_graph, plant, drawing)
    positions, moment_ratios = rotor_layout(quad)
    propellers = builder.AddNamedSystem(
        "propellers",
        Propeller(
            [
                PropellerInfo(body.index(), RigidTransform(p), 1.0, k)
                for p, k in zip(positions, moment_ratios, strict=True)
            ]
        ),
    )
    builder.Connect(propellers.get_output_port(), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_body_poses_output_port(), propellers.get_body_poses_input_port())
    rotors, drivers, connect_force, cascade = _rotor_drive(builder, resolved, plant, propellers)

    # The NF reads the image of a camera on the level body, and its damping that camera's
    # velocity: a tilt then moves nothing the NF sees (LevelView's docstring).
    level = builder.AddNamedSystem("level_view", LevelView(X_RC=config.X_RC))
    builder.Connect(plant.get_state_output_port(), level.body_state_input)

    def view(builder: DiagramBuilder, y):
        builder.Connect(y, level.image_features_input)
        return level.level_image_features_output

    return CarrierParts(
        body_pose=pose_head(builder, plant.get_state_output_port()),
        state=plant.get_state_output_port(),
        state_log_name="log_body_state",
        X_WB=config.X_WB,
        X_RC=config.X_RC,
        pose_of_states=leading_pose,
        set_initial_state=set_plant_state(plant, config),
        body_state=level.level_body_state_output,
        connect_force=connect_force,
        add_meshcat=meshcat_with_camera(scene_graph, body, config.X_RC),
        plant=plant,
        scene_graph=scene_graph,
        body=body,
        run_entries=_run_entries(drivers),
        view=view,
        rotors=rotors,
        # Behind a moving target (simulated in the world, loop.targets): the believed
        # target's velocity and acceleration enter the cascade's thrust vector.
        draw_target=target_drawing(scene_graph, resolved, draws_marks) if moving else None,
        feedforward_input=None if cascade is None else cascade.feedforward_twist_input,
        feedforward_rate_input=(
            None if cascade is None else cascade.feedforward_acceleration_input
        ),
    )


#: The quadrotor's factory: the dynamic plant only (the scenario refuses the kinematic).
ENTRIES: dict[tuple[type, type], CarrierFactory] = {(Quadrotor, Dynamic): _quadrotor}
