"""FrameWait: the law's image before a camera's first frame arrives (issue 31)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_

from geovs_drake.systems._held_frames import waiting
from geovs_drake.systems._template import template_system

__all__ = ["FrameWait", "FrameWait_"]

#: Sizes of the ports: y, and a sampled sensor's ``[valid, code, lost]``.
_FEATURES, _STATUS = 13, 3


@template_system("FrameWait_", T_list=[float])
def FrameWait_(T):
    class Impl(LeafSystem_[T]):
        """y as the camera gives it once a frame has arrived; the goal image y* before.

        .. pydrake_system::

            name: FrameWait
            input_ports:
            - image_features
            - feature_status
            output_ports:
            - image_features_or_goal

        A camera whose first frame arrives after t = 0 (Drake's ``RgbdSensorAsync``
        delivers each frame ``output_delay`` after its capture; ``capture_offset`` puts
        the first capture later) gives the law no image until then: its held y is NaN
        and ``feature_status`` says *waiting* (``[0, 0, 0]``,
        :func:`~geovs_drake.systems._held_frames.waiting`). A NaN y would make every
        law's command NaN. Until the first frame this system gives the law the goal
        image ``goal`` instead: the navigation function's gradient vanishes there, so
        the kinematic law commands no motion and the dynamic one only its damping
        ``-B (Omega, V)`` (the controller holds, as a real one does before its first
        image). Once a frame has arrived the sensor's y passes unchanged, and a lost
        frame is the sensor's and the monitor's business, as before. Double only, as
        the sensors it follows.
        """

        def _construct(self, goal: Sequence[float], converter=None):
            LeafSystem_[T].__init__(self, converter)
            goal = np.asarray(goal, dtype=float)
            if goal.shape != (_FEATURES,) or not np.all(np.isfinite(goal)):
                raise ValueError(f"goal must be {_FEATURES} finite numbers (y*), got {goal}")
            self._goal = goal
            self.image_features_input = self.DeclareVectorInputPort("image_features", _FEATURES)
            self.feature_status_input = self.DeclareVectorInputPort("feature_status", _STATUS)
            self.image_features_or_goal_output = self.DeclareVectorOutputPort(
                "image_features_or_goal", BasicVector_[T](_FEATURES), self._calc
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._goal, converter=converter)

        def _calc(self, context, output) -> None:
            if waiting(self.feature_status_input.Eval(context)):
                output.SetFromVector(self._goal)
            else:
                output.SetFromVector(self.image_features_input.Eval(context))

    return Impl


FrameWait = FrameWait_[None]
