"""The robustness study's settings, apart from the study
(:mod:`geovs_drake.analysis.studies.robustness`): the
command line reads them for its help without importing the loop."""

from __future__ import annotations

__all__ = ["LEVELS", "NOMINAL", "SHRINK"]

#: The error levels of each sweep (the others at zero).
LEVELS: dict[str, tuple[float, ...]] = {
    "pixel_noise": (0.0, 0.5, 1.0, 2.0),
    "focal_error": (-0.10, -0.05, 0.0, 0.05, 0.10),
    "radius_error": (-0.20, -0.10, 0.0, 0.10, 0.20),
    "latency_frames": (0, 1, 2, 3),
    "rate": (15.0, 30.0, 60.0, 120.0),
}
#: Each parameter's value in the nominal case (the camera's defaults).
NOMINAL = {"pixel_noise": 0.0, "focal_error": 0.0, "radius_error": 0.0, "latency_frames": 0,
           "rate": 30.0}  # fmt: skip
#: Starts are drawn in this fraction of D's model chart (1: all of D). The outer rim is
#: where the marks are seen nearly edge-on (2 to 3 px apart at 320x240) and where the
#: 30 Hz hold alone lets starts out (the ``rate`` sweep at shrink 0.98 shows it).
SHRINK = 0.8
