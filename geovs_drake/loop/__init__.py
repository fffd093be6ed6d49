"""Loop assembly: a visual-servo loop is carrier + sensor + law (:func:`build_loop`),
built from a scenario resolved once (:func:`resolve`, :class:`ResolvedScenario`).

The names below are imported from their modules on first use (:mod:`geovs_drake._lazy`),
so that ``geovs_drake.loop.state`` comes without the Drake systems.
"""

from geovs_drake._lazy import attach

__getattr__, __dir__, __all__ = attach(
    __name__,
    {
        "assembly": ("DISTURBANCES", "FEATURE_SIZE", "Loop", "assemble_loop", "refusal"),
        "build": ("build_loop",),
        "carriers": ("CARRIERS", "CarrierParts"),
        "laws": ("LAWS", "Law", "twist_law"),
        "resolver": ("effort_check", "resolve"),
        "resolved": ("ResolvedScenario", "exact_twin", "free_twin"),
        "sensors": ("SENSORS",),
    },
)
