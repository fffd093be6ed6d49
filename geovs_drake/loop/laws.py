"""Laws: what the loop does with y (a loop is carrier + sensor + law, :mod:`.build`).

A law takes y and offers either a twist (Omega, V) in C or, on a
force-driven carrier, a force system. :data:`LAWS` holds one entry per law
variant; ``add(builder, resolved, y, nav, carrier)`` adds the law's systems and
returns the twist's output port, or the force system (``ImageJacobianForce``)
for the carrier to wire in. The loop builder adapts a twist to a force-driven
carrier with the velocity-tracking force.

* :class:`~geovs_drake.scenario.Nf`: the navigation function. On a force-driven
  carrier Eq. (45)'s wrench ``F = C(y)^T dphi k_p - B (Omega, V)`` (``image_jacobian_force``); on a
  twist-driven one the kinematic law ``-k Tc^-1 dphi`` (Eqs. 18-19,
  ``kinematic_controller``).
* :class:`~geovs_drake.scenario.Ibvs`, :class:`~geovs_drake.scenario.Pbvs`,
  :class:`~geovs_drake.scenario.Spherical`: the baselines toward the goal image (the
  subsystem ``controller``).
* :class:`~geovs_drake.scenario.PathFollowing`: the planned y_d(t) (``desired_image``)
  followed by Eq. (18).
* :class:`~geovs_drake.scenario.HamelMahony`: Hamel & Mahony's law (``hamel_mahony``),
  which drives the quadrotor's rotors itself (the carrier's ``rotors``,
  :class:`~geovs_drake.loop.carriers.parts.RotorDrive`), from the image the carrier's view
  gives; the NF's systems stay in the loop (its phi is logged) and drive nothing.

A moving target's feed-forward reaches every law through the target's adapter
(:mod:`geovs_drake.loop.targets`); a twist law that declares a ``target_twist`` input
(point IBVS) also reads the believed twist there (``connect_law_feedforward``).

Every law believes the same radius, ``resolved.believed_radius``, in C(y) and
in y*; the damping is ``resolved.damping``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.primitives import TrajectorySource

from geovs_drake.loop.carriers import CarrierParts
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.targets import connect_law_feedforward
from geovs_drake.planning import plan_for_scenario
from geovs_drake.scenario import HamelMahony, Ibvs, Nf, PathFollowing, Pbvs, Spherical
from geovs_drake.systems import (
    HamelMahonyController,
    IbvsController,
    ImageJacobianForce,
    KinematicController,
    NavigationController,
    PathFollowingController,
    PbvsController,
    SphericalFeatureController,
)

__all__ = ["LAWS", "Law", "add_nf_law", "twist_law"]

#: What a law adds: the twist's output port, or a force system for the carrier.
LawOutput = OutputPort | LeafSystem


@dataclass(frozen=True)
class Law:
    """A law: ``add(builder, resolved, y, nav, carrier)`` (``y`` the port the sensor
    offers, ``nav`` the ``navigation_controller``) adds its systems and returns
    :data:`LawOutput`."""

    add: Callable[
        [DiagramBuilder, ResolvedScenario, OutputPort, NavigationController, CarrierParts],
        LawOutput,
    ]


def add_nf_law(
    builder: DiagramBuilder,
    resolved: ResolvedScenario,
    y: OutputPort,
    nav: NavigationController,
    takes_wrench: bool,
    X_RC: RigidTransform | None = None,
) -> LeafSystem:
    """The NF law's own system on ``y`` and ``nav``'s dphi: the wrench
    ``F = C(y)^T dphi - B (Omega, V)`` (:class:`ImageJacobianForce`, Eq. 45; ``X_RC`` the
    camera on the body it shifts the wrench to) or the velocity ``-k Tc^-1 grad phi``
    (:class:`KinematicController`, Eqs. 18-19). The loop's carriers and the LCM
    controller (:mod:`geovs_drake.hardware.controller`) both build it here."""
    config = resolved.config
    if takes_wrench:
        law = builder.AddNamedSystem(
            "image_jacobian_force",
            ImageJacobianForce(
                radius=resolved.believed_radius,
                potential_gain=config.control.potential_gain,
                damping=np.asarray(resolved.damping),
                X_RC=X_RC,
            ),
        )
    else:
        law = builder.AddNamedSystem(
            "kinematic_controller",
            KinematicController(
                radius=resolved.believed_radius, gain=config.control.kinematic_gain
            ),
        )
    builder.Connect(y, law.image_features_input)
    builder.Connect(nav.dphi_output, law.dphi_input)
    return law


def _nf(builder, resolved, y, nav, carrier) -> LawOutput:
    law = add_nf_law(builder, resolved, y, nav, carrier.takes_wrench, carrier.X_RC)
    return law if carrier.takes_wrench else law.camera_velocity_output


def twist_law(make: Callable[[DiagramBuilder, ResolvedScenario], LeafSystem]) -> Law:
    """A law that commands a twist: ``make(builder, resolved)`` adds its system, which
    is named ``controller``, reads y at an ``image_features`` input (if it has one) and
    offers ``camera_velocity``, (Omega, V) in C. It runs on every carrier: a force-driven
    one gets the velocity-tracking force."""

    def add(builder, resolved, y, nav, carrier) -> LawOutput:
        law = make(builder, resolved)
        law.set_name("controller")
        if law.HasInputPort("image_features"):
            builder.Connect(y, law.GetInputPort("image_features"))
        # A moving target: a law that reads the believed twist itself (point IBVS's
        # -L^+ de/dt) gets it; the rest, the adapter's Ad_{X_CB} xi_hat (loop.targets).
        connect_law_feedforward(builder, law)
        return law.GetOutputPort("camera_velocity")

    return Law(add)


def _baseline(law: type, **options: Callable[[ResolvedScenario], object]) -> Law:
    """A baseline law toward the goal image: ``law(goal=y*, radius=rho believed,
    gain=control.baseline_gain, **{name: option(resolved)})``."""

    def make(builder: DiagramBuilder, resolved: ResolvedScenario) -> LeafSystem:
        return builder.AddSystem(
            law(
                goal=resolved.y_goal,
                radius=resolved.believed_radius,
                gain=resolved.config.control.baseline_gain,
                **{name: option(resolved) for name, option in options.items()},
            )
        )

    return twist_law(make)


def _path_following(builder: DiagramBuilder, resolved: ResolvedScenario) -> LeafSystem:
    """The planned y_d(t) (:func:`~geovs_drake.planning.plan_for_scenario`) through a
    ``TrajectorySource`` named ``desired_image`` (value and derivative) into a
    :class:`PathFollowingController` (Eq. 18, with the law's ``feedback_gain``).
    Raises PathPlanningError (a ValueError) if there is no path inside D."""
    law = resolved.law
    plan = plan_for_scenario(resolved.config, law)
    source = builder.AddNamedSystem(
        "desired_image", TrajectorySource(plan.trajectory, output_derivative_order=1)
    )
    follower = builder.AddSystem(
        PathFollowingController(
            radius=resolved.believed_radius * law.radius_scale, gain=law.feedback_gain
        )
    )
    builder.Connect(source.get_output_port(), follower.desired_image_input)
    return follower


def _hamel_mahony(builder, resolved, y, nav, carrier) -> LawOutput:
    """Hamel & Mahony's controller on ``y``, with the carrier's body model; the loop
    builder hands it to ``carrier.rotors`` (the scenario has checked the carrier)."""
    law = resolved.law
    if carrier.rotors is None:  # the scenario's check refuses this first
        raise ValueError("controller hamel_mahony needs a carrier with rotors (quadrotor)")
    system = builder.AddNamedSystem(
        "hamel_mahony_controller",
        HamelMahonyController(
            goal=resolved.y_goal,
            X_RC=carrier.X_RC,
            image_gain=law.image_gain,
            velocity_gain=law.velocity_gain,
            depth_balance=law.depth_balance,
            **carrier.rotors.body,
        ),
    )
    builder.Connect(y, system.image_features_input)
    return system


#: The laws, by their variant (``ScenarioConfig.controller``'s type,
#: :data:`~geovs_drake.scenario.LawConfig`). A law of one's own is a variant dataclass
#: and an entry here (:doc:`/adding-a-part`).
LAWS: dict[type, Law] = {
    Nf: Law(_nf),
    Ibvs: _baseline(IbvsController, depth=lambda resolved: resolved.law.depth),
    Pbvs: _baseline(PbvsController),
    Spherical: _baseline(SphericalFeatureController),
    PathFollowing: twist_law(_path_following),
    HamelMahony: Law(_hamel_mahony),
}
