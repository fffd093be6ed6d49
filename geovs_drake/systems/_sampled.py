"""What the two sampled feature sensors share: a frame clock, a latency line, a held y.

A camera delivers y once per frame, not continuously. :class:`FeatureExtractor`
(rendered images) and :class:`PinholeFeatureSensor` (the same measurement on
exact projected points) both:

* measure at t = 0 (an initialization event, so the loop starts from a frame)
  and then every ``period`` seconds (a periodic discrete update);
* keep the last ``latency_frames + 1`` measurements in their discrete state and
  output the oldest: the controller acts on the frame taken ``latency_frames``
  periods ago, held constant between frames (a zero-order hold);
* on a failed measurement keep the last good y and output ``valid = 0`` with the
  failure's code (:data:`~geovs_drake.geometry.features.FEATURE_FAILURES`):
  never a garbage y. The simulation's monitor stops the run on ``valid = 0``
  with the status ``feature_lost`` naming the reason. Before any good frame
  the held y is NaN (and ``valid = 0``).

State layout: ``latency_frames + 1`` entries of ``[y (13), valid, code]``,
oldest first. The outputs depend on the discrete state only, so Drake caches
them between frames: a frame is measured once, however often the continuous
integrator evaluates the controller.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

ENTRY_SIZE = 15
_Y, _VALID, _CODE = slice(0, 13), 13, 14


def frame_index(t: float, period: float) -> int:
    """The frame taken at time t (frames at 0, period, 2 period, ...)."""
    return int(round(t / period))


def declare_sampled_features(
    system, period: float, latency_frames: int, measure: Callable
) -> tuple[object, object]:
    """Declare the state, events and the ``image_features`` and ``feature_status`` outputs.

    ``measure(context) -> (y tuple | None, code)`` takes the current frame.
    Returns the two output ports.
    """
    if not (math.isfinite(period) and period > 0):
        raise ValueError(f"camera period must be finite and > 0 [s], got {period}")
    if isinstance(latency_frames, bool) or not (
        isinstance(latency_frames, int) and latency_frames >= 0
    ):
        raise ValueError(f"latency_frames must be an integer >= 0, got {latency_frames!r}")
    n = latency_frames + 1
    initial = np.zeros(n * ENTRY_SIZE)
    initial.reshape(n, ENTRY_SIZE)[:, _Y] = math.nan
    state = system.DeclareDiscreteState(initial)

    def entry(context, previous: np.ndarray) -> np.ndarray:
        y, code = measure(context)
        out = previous.copy()
        if y is None:
            out[_VALID], out[_CODE] = 0.0, float(code)  # keep the last good y
        else:
            out[_Y], out[_VALID], out[_CODE] = y, 1.0, 0.0
        return out

    def on_frame(context, discrete_state) -> None:
        buffer = context.get_discrete_state(state).get_value().reshape(n, ENTRY_SIZE)
        new = np.vstack([buffer[1:], entry(context, buffer[-1])])
        discrete_state.get_mutable_vector(state).SetFromVector(new.ravel())

    def on_start(context, discrete_state) -> None:
        # The first frame fills the latency line: before it, the loop has seen nothing else.
        first = entry(context, np.full(ENTRY_SIZE, math.nan))
        discrete_state.get_mutable_vector(state).SetFromVector(np.tile(first, n))

    system.DeclareInitializationDiscreteUpdateEvent(on_start)
    system.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, on_frame)

    def features(context, output) -> None:
        output.SetFromVector(context.get_discrete_state(state).get_value()[_Y])

    def status(context, output) -> None:
        v = context.get_discrete_state(state).get_value()
        output.SetFromVector([v[_VALID], v[_CODE]])

    ticket = {system.xd_ticket()}
    features_port = system.DeclareVectorOutputPort(
        "image_features", 13, features, prerequisites_of_calc=ticket
    )
    status_port = system.DeclareVectorOutputPort(
        "feature_status", 2, status, prerequisites_of_calc=ticket
    )
    return features_port, status_port
