"""simulate(config): run a servo loop with a safe-domain monitor and return its logs.

Three parts: :mod:`.result` (the run's logs and summary, the convergence
tolerances), :mod:`.monitor` (the safe-domain monitor, the simulator it
watches, the camera's signals along states) and :mod:`.run` (``simulate``).
The names below are imported from their modules on first use
(:mod:`geovs_drake._lazy`): the batch engine reads the tolerances and the step limit
without the loop's Drake systems.
"""

from geovs_drake._lazy import attach

__getattr__, __dir__, __all__ = attach(
    __name__,
    {
        "monitor": (
            "FeaturePointCheck",
            "SafeDomainMonitor",
            "camera_signals",
            "feature_point_check",
            "make_simulator",
        ),
        "result": (
            "CONVERGENCE_POSITION_M",
            "CONVERGENCE_ROTATION_RAD",
            "SimulationResult",
            "TargetTrace",
            "convergence_tolerance",
            "energy_note",
            "pose_error",
            "saddle_note",
        ),
        "geovs_drake.loop.state": ("camera_pose_in_target",),
        "run": ("StartOutsideDomain", "check_start", "simulate"),
    },
)
