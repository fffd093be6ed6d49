"""geovs_drake: geometric visual servoing (Cowan & Chang) as Drake systems."""

from geovs_drake.geometry.camera import (
    ImageFeatures,
    OutOfDomainError,
    camera_map,
    camera_map_inverse,
    image_jacobian,
    image_jacobian_inverse,
    validate_features,
    visibility,
)
from geovs_drake.geometry.domain import DEFAULT_DOMAIN, DomainMargins, SafeDomain
from geovs_drake.geometry.navigation import NavigationFunction, NavigationGains
from geovs_drake.geometry.pinhole import PinholeIntrinsics
from geovs_drake.geometry.so3 import hat, so3_exp, vee

#: The package's version: the one place it is written (pyproject.toml reads it,
#: ``geovs-drake --version`` shows it; CHANGELOG.md says what each version added).
__version__ = "0.1.0"

__all__ = [
    "DEFAULT_DOMAIN",
    "DomainMargins",
    "ImageFeatures",
    "NavigationFunction",
    "NavigationGains",
    "OutOfDomainError",
    "PinholeIntrinsics",
    "SafeDomain",
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
