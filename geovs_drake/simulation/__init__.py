"""simulate(config): run a servo loop with a safe-domain monitor and return its logs.

Three parts: :mod:`.result` (the run's logs and summary, the convergence
tolerances), :mod:`.monitor` (the safe-domain monitor, the simulator it
watches, the camera's signals along states) and :mod:`.run` (``simulate``).
"""

from geovs_drake.loop.state import camera_pose_in_target
from geovs_drake.simulation.monitor import (
    FeaturePointCheck,
    SafeDomainMonitor,
    camera_signals,
    feature_point_check,
    make_simulator,
)
from geovs_drake.simulation.result import (
    CONVERGENCE_POSITION_M,
    CONVERGENCE_ROTATION_RAD,
    SimulationResult,
    convergence_tolerance,
    energy_note,
    pose_error,
    saddle_note,
)
from geovs_drake.simulation.run import StartOutsideDomain, check_start, simulate

__all__ = [
    "CONVERGENCE_POSITION_M",
    "CONVERGENCE_ROTATION_RAD",
    "FeaturePointCheck",
    "SafeDomainMonitor",
    "SimulationResult",
    "StartOutsideDomain",
    "camera_pose_in_target",
    "camera_signals",
    "check_start",
    "convergence_tolerance",
    "energy_note",
    "feature_point_check",
    "make_simulator",
    "pose_error",
    "saddle_note",
    "simulate",
]
