"""SelfMask: a robot's own pixels taken out of its camera's colour image (issue 31)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import RenderLabel
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.sensors import ImageLabel16I, ImageRgba8U

from geovs_drake.systems._template import template_system
from geovs_drake.systems.feature_extractor import SCENE_COLOURS

__all__ = ["MASK_GROWTH_PX", "SelfMask", "SelfMask_"]

#: How far [px] the mask grows past the robot's labelled pixels, into pixels that show no
#: geometry: the colour image blends the robot's edges into the background over a pixel
#: (anti-aliasing) where the label image does not, and those blended pixels read as
#: something in front of the background (the UR5 from far_off_axis at 640x480: "marked
#: point outside the silhouette" with the edges left).
MASK_GROWTH_PX = 2
#: The label of a pixel that shows no geometry (Drake's ``RenderLabel.kEmpty``).
_EMPTY = int(RenderLabel.kEmpty)


@template_system("SelfMask_", T_list=[float])
def SelfMask_(T):
    class Impl(LeafSystem_[T]):
        """The colour image with the robot's own pixels painted the background's colour.

        .. pydrake_system::

            name: SelfMask
            input_ports:
            - color_image
            - label_image
            output_ports:
            - masked_color_image

        ``color_image`` (``ImageRgba8U``) and ``label_image`` (``ImageLabel16I``) come
        from the same ``RgbdSensor``; every pixel whose label is one of ``labels`` (the
        render labels of the robot's bodies: MultibodyPlant labels a body's geometry
        with its body index) becomes ``background`` (RGB in [0, 1], the extractor's
        background by default), so that the feature extractor sees the target alone.
        Why: an arm that carries its camera enters its own view from some poses, and
        the extractor took it for the sphere (the suite's far_off_axis and
        translation_and_roll on the UR5 stopped with feature_lost at t = 0). On
        hardware the label image is the robot's model rendered at the joint state, as a
        robot self-filter does. The masked image is computed when it is read, so a
        sampled extractor reads it once per frame.
        """

        def _construct(
            self,
            width: int,
            height: int,
            labels: Sequence[int],
            background: Sequence[float] = SCENE_COLOURS["background"],
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            self._defaults = (width, height, tuple(int(v) for v in labels), tuple(background))
            self._labels = np.asarray(self._defaults[2], dtype=np.int16)
            self._background = np.array(
                [round(255 * v) for v in background] + [255], dtype=np.uint8
            )
            self.color_image_input = self.DeclareAbstractInputPort(
                "color_image", AbstractValue.Make(ImageRgba8U(width, height))
            )
            self.label_image_input = self.DeclareAbstractInputPort(
                "label_image", AbstractValue.Make(ImageLabel16I(width, height))
            )
            self.masked_color_image_output = self.DeclareAbstractOutputPort(
                "masked_color_image",
                lambda: AbstractValue.Make(ImageRgba8U(width, height)),
                self._mask,
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._defaults, converter=converter)

        def _mask(self, context, output) -> None:
            color = self.color_image_input.Eval(context).data
            label = self.label_image_input.Eval(context).data[..., 0]
            out = output.get_mutable_value().mutable_data
            out[...] = color
            robot = np.isin(label, self._labels)
            # Grown into the empty background only: not into the target where the robot
            # passes in front of it (its marks may lie next to the robot's edge).
            edge = _grown(robot, MASK_GROWTH_PX) & (label == _EMPTY)
            out[robot | edge] = self._background

    return Impl


SelfMask = SelfMask_[None]


def _grown(mask: np.ndarray, pixels: int) -> np.ndarray:
    """``mask`` grown by ``pixels`` in each of the 8 directions (a square dilation)."""
    padded = np.pad(mask, pixels)
    out = np.zeros_like(mask)
    h, w = mask.shape
    for dy in range(2 * pixels + 1):
        for dx in range(2 * pixels + 1):
            out |= padded[dy : dy + h, dx : dx + w]
    return out
