"""Carriers: what moves the camera (a loop is carrier + sensor + law, :mod:`.build`).

A carrier adds its bodies to the builder and returns :class:`CarrierParts`:
what it *offers* (the pose the camera system reads, the body state a force law
damps, its own state for the loggers) and what it *takes* (a wrench through
:attr:`CarrierParts.connect_force`, or a twist at :attr:`CarrierParts.twist_input`).
:data:`CARRIERS` registers one factory per carrier variant and plant
(:func:`carrier_key`: the types of ``config.carrier`` and ``config.plant``). Each carrier
is a module of its own (:mod:`.free_rig`, :mod:`.fixed_camera`, :mod:`.arm`,
:mod:`.quadrotor`) that holds
its factories and their ``ENTRIES``; adding a carrier is one variant with its traits
(:mod:`geovs_drake.scenario.carriers`), one module here and its line below.
"""

from geovs_drake.loop.carriers import arm, fixed_camera, free_rig, quadrotor
from geovs_drake.loop.carriers.arm import add_arm_scene, world_view_meshcat
from geovs_drake.loop.carriers.parts import (
    RIG_BODY_NAME,
    TARGET_BODY_NAME,
    CarrierFactory,
    CarrierParts,
    carrier_key,
    leading_pose,
    no_initial_state,
)

__all__ = [
    "CARRIERS",
    "RIG_BODY_NAME",
    "TARGET_BODY_NAME",
    "CarrierParts",
    "add_arm_scene",
    "carrier_key",
    "leading_pose",
    "no_initial_state",
    "world_view_meshcat",
]

#: The carriers, by the carrier variant's and the plant's types (:func:`carrier_key`):
#: each carrier module's entries.
CARRIERS: dict[tuple[type, type], CarrierFactory] = {
    **free_rig.ENTRIES,
    **fixed_camera.ENTRIES,
    **arm.ENTRIES,
    **quadrotor.ENTRIES,
}
