"""Loop assembly: a visual-servo loop is carrier + sensor + law (:func:`build_loop`).

The names below are imported from their modules on first use (:mod:`geovs_drake._lazy`),
so that ``geovs_drake.loop.state`` comes without the Drake systems.
"""

from geovs_drake._lazy import attach

__getattr__, __dir__, __all__ = attach(
    __name__,
    {
        "build": ("Loop", "build_loop", "refusal"),
        "carriers": ("CARRIERS", "CarrierParts"),
        "laws": ("LAWS", "Law", "twist_law"),
        "sensors": ("SENSORS",),
    },
)
