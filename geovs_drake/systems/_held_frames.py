"""What the two sampled feature sensors share: a frame clock, a latency line, a held y.

A camera delivers y once per frame, not continuously. :class:`FeatureExtractor`
(rendered images) and :class:`PinholeFeatureSensor` (the same measurement on
exact projected points) both:

* measure at t = 0 (an initialization event, so the loop starts from a frame)
  and then every ``period`` seconds (a periodic discrete update); or, for a camera
  whose frames arrive at ``offset + k period`` (``offset > 0``: a frame taken at
  ``capture_offset`` and delivered ``output_delay`` later, as Drake's ``CameraConfig``
  times them), at those times only, *waiting* until the first: y NaN and
  ``feature_status`` ``[0, 0, 0]`` (no frame, none lost), which :func:`waiting`
  recognises;
* keep the last ``latency_frames + 1`` measurements in their discrete state and
  output the oldest: the controller acts on the frame taken ``latency_frames``
  periods ago, held constant between frames (a zero-order hold);
* on a failed measurement keep the last good y (never a garbage y) and count
  the frames lost in a row. ``feature_status`` is ``[valid, code, lost]``:
  ``lost`` failed frames in a row, ``code`` the last failure's reason
  (:data:`~geovs_drake.geometry.features.FEATURE_FAILURES`, 0 if the frame was
  good) and ``valid`` 1 while the held y is usable: some frame gave y and at
  most ``max_lost_frames`` have failed since. The simulation's monitor stops the
  run on ``valid = 0`` with the status ``feature_lost`` naming the reason.
  Why a tolerance: with pixel noise a single frame's marks can fail the
  consistency check now and then (1 px of noise on marks 8 px apart, about one
  frame in 300) while the next frame is fine; holding y through a few such
  frames is what a camera loop does, and a run then stops only when the target
  is really lost. Before any good frame the held y is NaN and ``valid`` is 0.

* give the held y's capture time, ``capture_time`` [s]: the frame's read time less
  ``capture_delay`` (the ``output_delay`` after its capture at which it is read), of
  the frame that gave the held y (a failed frame keeps the last good y, and its
  capture); NaN before any good frame. Why: a frame ``latency_frames`` old, or one
  held through failures, was not taken when it is read, and a consumer that moves it
  by the body's motion since (the LCM controller) must know when it was.

State layout: ``latency_frames + 1`` entries of ``[y (13), has_y, code, lost,
capture]``, oldest first. The outputs depend on the discrete state only, so Drake caches
them between frames: a frame is measured once, however often the continuous
integrator evaluates the controller.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

ENTRY_SIZE = 17
_Y, _HAS_Y, _CODE, _LOST, _CAPTURE = slice(0, 13), 13, 14, 15, 16


def frame_index(t: float, period: float, offset: float = 0.0) -> int:
    """The frame read at time t (frames read at offset, offset + period, ...)."""
    return int(round((t - offset) / period))


def waiting(status) -> bool:
    """Whether ``feature_status`` ``[valid, code, lost]`` is a camera's before its first
    frame: nothing valid, no failure, nothing lost."""
    return status[0] == 0 and status[1] == 0 and status[2] == 0


def declare_sampled_features(
    system,
    period: float,
    latency_frames: int,
    max_lost_frames: int,
    measure: Callable,
    offset: float = 0.0,
    capture_delay: float = 0.0,
) -> tuple[object, object, object]:
    """Declare the state, events and the ``image_features``, ``feature_status`` and
    ``capture_time`` outputs.

    ``measure(context) -> (y tuple | None, code)`` takes the current frame; frames are
    read at ``offset + k period`` (and at t = 0 where ``offset`` is 0), each taken
    ``capture_delay`` [s] before it is read. Returns the three output ports.
    """
    if not (math.isfinite(period) and period > 0):
        raise ValueError(f"camera period must be finite and > 0 [s], got {period}")
    if not (math.isfinite(offset) and offset >= 0):
        raise ValueError(f"frame offset must be finite and >= 0 [s], got {offset}")
    for name, value in (("latency_frames", latency_frames), ("max_lost_frames", max_lost_frames)):
        if isinstance(value, bool) or not (isinstance(value, int) and value >= 0):
            raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    n = latency_frames + 1
    initial = np.zeros(n * ENTRY_SIZE)
    initial.reshape(n, ENTRY_SIZE)[:, _Y] = math.nan
    initial.reshape(n, ENTRY_SIZE)[:, _CAPTURE] = math.nan
    state = system.DeclareDiscreteState(initial)

    def entry(context, previous: np.ndarray) -> np.ndarray:
        y, code = measure(context)
        out = previous.copy()
        if y is None:  # keep the last good y; one more frame lost
            out[_CODE], out[_LOST] = float(code), previous[_LOST] + 1
        else:
            out[_Y], out[_HAS_Y], out[_CODE], out[_LOST] = y, 1.0, 0.0, 0.0
            out[_CAPTURE] = context.get_time() - capture_delay
        return out

    def on_frame(context, discrete_state) -> None:
        buffer = context.get_discrete_state(state).get_value().reshape(n, ENTRY_SIZE)
        new = np.vstack([buffer[1:], entry(context, buffer[-1])])
        discrete_state.get_mutable_vector(state).SetFromVector(new.ravel())

    def on_start(context, discrete_state) -> None:
        # The first frame fills the latency line: before it, the loop has seen nothing else.
        empty = np.zeros(ENTRY_SIZE)
        empty[_Y] = empty[_CAPTURE] = math.nan
        first = entry(context, empty)
        discrete_state.get_mutable_vector(state).SetFromVector(np.tile(first, n))

    if offset == 0:  # the frame at t = 0 is there at the start
        system.DeclareInitializationDiscreteUpdateEvent(on_start)
    system.DeclarePeriodicDiscreteUpdateEvent(period, offset, on_frame)

    def features(context, output) -> None:
        output.SetFromVector(context.get_discrete_state(state).get_value()[_Y])

    def status(context, output) -> None:
        v = context.get_discrete_state(state).get_value()
        usable = v[_HAS_Y] > 0 and v[_LOST] <= max_lost_frames
        output.SetFromVector([1.0 if usable else 0.0, v[_CODE], v[_LOST]])

    def capture(context, output) -> None:
        output.SetAtIndex(0, context.get_discrete_state(state).get_value()[_CAPTURE])

    ticket = {system.xd_ticket()}
    features_port = system.DeclareVectorOutputPort(
        "image_features", 13, features, prerequisites_of_calc=ticket
    )
    status_port = system.DeclareVectorOutputPort(
        "feature_status", 3, status, prerequisites_of_calc=ticket
    )
    capture_port = system.DeclareVectorOutputPort(
        "capture_time", 1, capture, prerequisites_of_calc=ticket
    )
    return features_port, status_port, capture_port
