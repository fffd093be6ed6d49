"""geovs_drake: geometric visual servoing (Cowan & Chang) as Drake systems."""

from geovs_drake.camera import (
    ImageFeatures,
    camera_map,
    camera_map_inverse,
    image_jacobian,
    image_jacobian_inverse,
    validate_features,
    visibility,
)
from geovs_drake.so3 import hat, so3_exp, vee

__all__ = [
    "ImageFeatures",
    "camera_map",
    "camera_map_inverse",
    "hat",
    "image_jacobian",
    "image_jacobian_inverse",
    "so3_exp",
    "validate_features",
    "vee",
    "visibility",
]
