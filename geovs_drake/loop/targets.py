"""The moving target: its motion, the loop in its frame, and the feed-forward (issue 32).

A loop whose ``target_motion`` is not :class:`~geovs_drake.scenario.Still` is read in the
target's frame W' (where the target stands at ``config.X_WB`` for all time): the exact
camera, the sensors, the NF, the safe-domain monitor and the logs read the camera's pose
relative to the target as they read a still target's, and the run's errors are those of
X_BC against X_BC*. How a carrier gets there is its entry of :data:`TARGET_FRAMES`:

* the free rig is *simulated* in W': its state is the rig's pose and twist relative to
  the target (Meshcat draws it in the world, :func:`~geovs_drake.loop.carriers.
  world_view_meshcat`);
* an arm is simulated in the world, where its base stands, the target drawn moving in
  its scene; a :class:`~geovs_drake.systems.TargetFrame` shows the loop its camera from
  W', the kinematic arm is commanded the law's twist plus the feed-forward, and the
  dynamic arm adds the torque of the motion that follows the target
  (:class:`~geovs_drake.systems.ArmCamera`'s ``feedforward_twist``);
* the quadrotor likewise, in the world where gravity acts: its attitude cascade adds the
  believed target's velocity (to its damping) and acceleration to the thrust vector
  (:class:`~geovs_drake.systems.AttitudeCascade`'s ``feedforward_twist`` and
  ``feedforward_acceleration``).

On the free rig the target's motion enters where physics puts it:

* the kinematic free body (Eq. 17): the camera's twist relative to the target is the
  commanded one less the target's carried to C
  (:class:`~geovs_drake.systems.target_relative_twist.TargetRelativeTwist`);
* the dynamic free rig (Appendix C): the moving frame's wrench (acceleration, Coriolis,
  centripetal) is added to the law's
  (:class:`~geovs_drake.systems.target_relative_wrench.TargetRelativeWrench`).

Both add the feed-forward of the twist the loop believes, :data:`FEEDFORWARD` (one entry per
:data:`~geovs_drake.scenario.FEEDFORWARD_MODES` name): none (zero), the known twist, or
the estimate of
:class:`~geovs_drake.systems.target_twist_estimator.TargetTwistEstimator`, which reads the
camera's y and the carrier's pose in the world
(:class:`~geovs_drake.systems.target_motion.TargetMotion`'s ``world_body_pose``, the
odometry). A still target adds nothing to the diagram.

Every law gets that feed-forward: the adapter adds ``Ad_{X_CB} xi_hat`` to whatever
twist the law commands (the NF's, PBVS's: the target's twist carried to C, the whole
of Chaumette & Hutchinson's tracking term for a law whose features' Jacobian it
inverts exactly), and on the dynamic rig cancels the frame's wrench under whatever
force the law makes. A law whose own estimate of the features' Jacobian makes its
term differ (point IBVS with estimated depths: ``-L^+ de/dt`` with ``L != L_e``,
:func:`~geovs_drake.systems.ibvs_controller.ibvs_target_term`) declares an input
:data:`LAW_FEEDFORWARD_INPUT` for the believed twist, and :func:`connect_law_feedforward`
(called by :mod:`geovs_drake.loop.laws` for each law it adds) fills it: the one place
that decides which laws read the believed twist themselves.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, PassThrough

from geovs_drake.loop.carriers import CarrierParts, world_view_meshcat
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.scenario import ESTIMATOR_RATE_HZ, FEEDFORWARD_MODES, Arm, FreeRig, Quadrotor
from geovs_drake.scenario.targets import target_motion_arguments
from geovs_drake.systems.target_frame import TargetFrame
from geovs_drake.systems.target_motion import TargetMotion
from geovs_drake.systems.target_relative_twist import TargetRelativeTwist
from geovs_drake.systems.target_relative_wrench import TargetRelativeWrench
from geovs_drake.systems.target_twist_estimator import TargetTwistEstimator

__all__ = [
    "ESTIMATE_LOG_NAMES",
    "BELIEVED_TWIST_NAME",
    "FEEDFORWARD",
    "LAW_FEEDFORWARD_INPUT",
    "TARGET_FRAMES",
    "TargetParts",
    "add_target_motion",
    "connect_feedforward",
    "connect_law_feedforward",
    "estimator_timing",
]

#: The estimator's loggers (``estimated`` feed-forward): its twist and its covariance's
#: diagonal, sampled at its own updates.
ESTIMATE_LOG_NAMES = ("log_target_twist_estimate", "log_target_covariance")
#: The subsystem that offers the believed twist xi_hat (6, in B) of a moving target's
#: loop, whatever the feed-forward mode (a pass-through of :data:`FEEDFORWARD`'s port).
BELIEVED_TWIST_NAME = "target_twist_believed"
#: The input a law declares to read the believed twist itself
#: (:func:`connect_law_feedforward`); unconnected (a still target) it reads zero.
LAW_FEEDFORWARD_INPUT = "target_twist"


@dataclass
class TargetParts:
    """What a moving target adds: its ``motion`` (TargetMotion), the carrier seen from it,
    and the ``twist_estimate`` input the feed-forward mode fills."""

    motion: LeafSystem
    carrier: CarrierParts
    adapter: LeafSystem


def add_target_motion(
    builder: DiagramBuilder, resolved: ResolvedScenario, carrier: CarrierParts
) -> TargetParts | None:
    """The target's motion and the carrier's adapter to the target's frame (module
    docstring), or None for a still target (nothing added): the carrier's entry of
    :data:`TARGET_FRAMES` (the scenario's check refuses the others)."""
    config = resolved.config
    if not config.moving_target:
        return None
    motion = builder.AddNamedSystem(
        "target_motion",
        TargetMotion(X_WB0=config.X_WB, **target_motion_arguments(config.target_motion)),
    )
    return TARGET_FRAMES[type(config.carrier)](builder, resolved, carrier, motion)


def _relative(builder, resolved, carrier: CarrierParts, motion) -> TargetParts:
    """The free rig, simulated in the target's frame W': its plant's state is the
    relative one, and the target's motion enters as the frame's twist or wrench. Meshcat
    draws it in the world (:func:`~geovs_drake.loop.carriers.world_view_meshcat`: the rig
    at its world pose, the target moving), the renderer in W' (the same image)."""
    config = resolved.config
    builder.Connect(carrier.body_pose, motion.body_pose_input)
    carrier = dataclasses.replace(
        carrier,
        add_meshcat=world_view_meshcat(
            resolved, carrier.X_RC, motion.world_body_pose_output, motion.target_pose_output
        ),
    )
    if carrier.takes_wrench:
        return _wrench_driven(builder, config, carrier, motion)
    # The kinematic body integrates the camera's twist relative to the target.
    return _twist_driven(builder, config, carrier, motion, carrier.body_pose, "relative_velocity")


def _twist_driven(
    builder, config, carrier: CarrierParts, motion, body_pose: OutputPort, drives: str
) -> TargetParts:
    """A twist-driven carrier behind the target: a :class:`TargetRelativeTwist` reads the
    law's twist (and the camera's pose in W', ``body_pose``) and its output ``drives``
    (``relative_velocity`` or ``commanded_velocity``) drives the carrier."""
    adapter = builder.AddNamedSystem(
        "target_relative_twist", TargetRelativeTwist(X_WB0=config.X_WB)
    )
    builder.Connect(body_pose, adapter.body_pose_input)
    builder.Connect(motion.target_twist_output, adapter.target_twist_input)
    builder.Connect(adapter.GetOutputPort(drives), carrier.twist_input)
    moved = dataclasses.replace(carrier, twist_input=adapter.camera_velocity_input)
    return TargetParts(motion, moved, adapter)


def _wrench_driven(builder, config, carrier: CarrierParts, motion) -> TargetParts:
    rig = config.carrier
    adapter = builder.AddNamedSystem(
        "target_relative_wrench",
        TargetRelativeWrench(X_WB0=config.X_WB, mass=rig.mass, inertia=tuple(rig.inertia_diagonal)),
    )
    plant = carrier.plant
    builder.Connect(plant.get_state_output_port(), adapter.rig_state_input)
    builder.Connect(motion.target_twist_output, adapter.target_twist_input)
    builder.Connect(motion.target_acceleration_output, adapter.target_acceleration_input)

    def connect_force(builder: DiagramBuilder, force: LeafSystem) -> None:
        # The law reads the rig's state through the adapter (body_state: the believed
        # relative twist), and its wrench reaches the plant with the frame's and the
        # feed-forward.
        builder.Connect(force.generalized_force_output, adapter.generalized_force_input)
        builder.Connect(
            adapter.plant_generalized_force_output,
            plant.get_applied_generalized_force_input_port(),
        )

    moved = dataclasses.replace(
        carrier, connect_force=connect_force, body_state=adapter.law_body_state_output
    )
    return TargetParts(motion, moved, adapter)


def _in_world(builder, resolved, carrier: CarrierParts, motion) -> TargetParts:
    """An arm, simulated in the world where its base stands: the target is drawn moving
    in its scene (``draw_target``), and a :class:`TargetFrame` shows the loop the arm's
    camera from the target's frame (its pose; the believed relative twist the law damps).
    A twist-driven arm is commanded the law's twist plus the feed-forward
    (:class:`TargetRelativeTwist`'s ``commanded_velocity``); a torque-driven one takes
    the law's wrench as it is, its damping acting on the believed relative twist, and
    its joint damping on the joint velocity less the one that follows the believed
    target (``feedforward_input``; the arm's inertia along the path is not fed
    forward)."""
    config = resolved.config
    view = builder.AddNamedSystem("target_frame", TargetFrame(X_WB0=config.X_WB))
    builder.Connect(carrier.body_pose, view.world_pose_input)
    builder.Connect(motion.target_pose_output, view.target_pose_input)
    # The odometry (world_body_pose) is the arm's own pose again, through W'.
    builder.Connect(view.body_pose_output, motion.body_pose_input)
    if carrier.draw_target is not None:
        carrier.draw_target(builder, motion.target_pose_output)
    X_WB0 = config.X_WB.GetAsMatrix4()

    def world_in_loop(t: float) -> np.ndarray:
        return X_WB0 @ np.linalg.inv(motion.X_WB(t))

    moved = dataclasses.replace(
        carrier, body_pose=view.body_pose_output, world_in_loop=world_in_loop
    )
    if carrier.takes_wrench:
        builder.Connect(carrier.body_state, view.world_state_input)
        if carrier.feedforward_input is not None:
            builder.Connect(view.feedforward_twist_output, carrier.feedforward_input)
        moved = dataclasses.replace(moved, body_state=view.body_state_output)
        return TargetParts(motion, moved, view)
    # The arm is commanded the law's twist plus the feed-forward, in the world.
    return _twist_driven(
        builder, config, moved, motion, view.body_pose_output, "commanded_velocity"
    )


#: How each carrier sees a moving target, by the carrier variant's type: the free rig is
#: simulated in the target's frame, an arm in the world (its base stands there).
#: The quadrotor too: gravity acts in the world, and its cascade takes the believed
#: target's velocity and acceleration (``feedforward_input``, ``feedforward_rate_input``).
TARGET_FRAMES: dict[type, Callable[..., TargetParts]] = {
    FreeRig: _relative,
    Arm: _in_world,
    Quadrotor: _in_world,
}


def estimator_timing(resolved: ResolvedScenario) -> tuple[float, int]:
    """``(period [s], delay_frames)`` of the estimator: a camera's frame period, its held
    frame read ``latency_frames + 1`` periods after it was taken (the frame's update and
    the estimator's are simultaneous, so it reads the one before); the exact sensor's y is
    read as it is taken, at :data:`~geovs_drake.scenario.ESTIMATOR_RATE_HZ`."""
    sensor = resolved.config.sensor
    if sensor.traits.camera:
        return 1.0 / sensor.rate, int(sensor.latency_frames) + 1
    return 1.0 / ESTIMATOR_RATE_HZ, 0


def _zero(builder: DiagramBuilder) -> OutputPort:
    return builder.AddNamedSystem(
        "target_twist_zero", ConstantVectorSource(np.zeros(6))
    ).get_output_port()


def _none(builder, resolved, target, camera) -> tuple[OutputPort, OutputPort]:
    zero = _zero(builder)
    return zero, zero


def _known(builder, resolved, target, camera) -> tuple[OutputPort, OutputPort]:
    return target.motion.target_twist_output, target.motion.target_acceleration_output


def _estimated(builder, resolved, target, camera) -> tuple[OutputPort, OutputPort]:
    config = resolved.config
    period, delay = estimator_timing(resolved)
    estimator = builder.AddNamedSystem(
        "target_twist_estimator",
        TargetTwistEstimator(
            radius=resolved.believed_radius,
            X_RC=target.carrier.X_RC,
            period=period,
            delay_frames=delay,
            pose_noise=config.target_motion.pose_noise,
            twist_noise=config.target_motion.twist_noise,
        ),
    )
    # The frame as the camera took it (not a predictor's), or the exact y.
    y = (
        builder.GetSubsystemByName("feature_sensor").image_features_output
        if builder.HasSubsystemNamed("feature_sensor")
        else camera.image_features_output
    )
    builder.Connect(y, estimator.image_features_input)
    builder.Connect(target.motion.world_body_pose_output, estimator.body_pose_input)
    for port, name in zip(
        (estimator.twist_estimate_output, estimator.covariance_diagonal_output),
        ESTIMATE_LOG_NAMES,
        strict=True,
    ):
        # At the estimator's own updates: no step of the integrator is cut for it.
        LogVectorOutput(port, builder, publish_period=period).set_name(name)
    # The filter's model is a constant twist: it believes no acceleration.
    return estimator.twist_estimate_output, _zero(builder)


#: The twist and its rate each feed-forward mode believes: ``add(builder, resolved,
#: target, camera)`` returns their ports (6 each), by the names of
#: :data:`~geovs_drake.scenario.FEEDFORWARD_MODES`.
FEEDFORWARD: dict[str, Callable[..., tuple[OutputPort, OutputPort]]] = {
    "none": _none,
    "known": _known,
    "estimated": _estimated,
}
assert set(FEEDFORWARD) == set(FEEDFORWARD_MODES), "one system per feed-forward mode"


def connect_feedforward(
    builder: DiagramBuilder, resolved: ResolvedScenario, target: TargetParts, camera: LeafSystem
) -> None:
    """Fill the adapter's ``twist_estimate`` by the scenario's feed-forward mode
    (:data:`FEEDFORWARD`); after the sensor is added (the estimator reads its frames)."""
    mode = resolved.config.target_motion.feedforward
    port, rate = FEEDFORWARD[mode](builder, resolved, target, camera)
    believed = builder.AddNamedSystem(BELIEVED_TWIST_NAME, PassThrough(6))
    builder.Connect(port, believed.get_input_port())
    builder.Connect(believed.get_output_port(), target.adapter.twist_estimate_input)
    if target.adapter.HasInputPort("acceleration_estimate"):  # the free rig's wrench
        builder.Connect(rate, target.adapter.GetInputPort("acceleration_estimate"))
    if target.carrier.feedforward_rate_input is not None:  # the quadrotor's cascade
        builder.Connect(rate, target.carrier.feedforward_rate_input)


def connect_law_feedforward(builder: DiagramBuilder, law: LeafSystem) -> None:
    """Connect the believed twist to ``law``'s :data:`LAW_FEEDFORWARD_INPUT`, where the
    law declares one and the target moves (:func:`connect_feedforward` ran); otherwise
    nothing (the law reads zero: a still target, or a law the adapter's
    ``Ad_{X_CB} xi_hat`` serves whole)."""
    if not (
        law.HasInputPort(LAW_FEEDFORWARD_INPUT) and builder.HasSubsystemNamed(BELIEVED_TWIST_NAME)
    ):
        return
    believed = builder.GetSubsystemByName(BELIEVED_TWIST_NAME)
    builder.Connect(believed.get_output_port(), law.GetInputPort(LAW_FEEDFORWARD_INPUT))
