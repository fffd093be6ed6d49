"""Loop assembly: a visual-servo loop is carrier + sensor + law (:func:`build_loop`)."""

from geovs_drake.loop.build import Loop, build_loop, loop_of, refusal
from geovs_drake.loop.carriers import CARRIERS, CarrierParts
from geovs_drake.loop.laws import LAWS, TWIST_CONTROLLERS
from geovs_drake.loop.sensors import SENSORS

__all__ = [
    "CARRIERS",
    "LAWS",
    "SENSORS",
    "TWIST_CONTROLLERS",
    "CarrierParts",
    "Loop",
    "build_loop",
    "loop_of",
    "refusal",
]
