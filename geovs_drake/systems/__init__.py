"""The servo's Drake systems, one LeafSystem per module, all TemplateSystems."""

from geovs_drake.systems.feature_extractor import FeatureExtractor, FeatureExtractor_
from geovs_drake.systems.image_jacobian_force import ImageJacobianForce, ImageJacobianForce_
from geovs_drake.systems.kinematic_controller import KinematicController, KinematicController_
from geovs_drake.systems.kinematic_rigid_body import KinematicRigidBody, KinematicRigidBody_
from geovs_drake.systems.navigation_controller import (
    NavigationController,
    NavigationController_,
)
from geovs_drake.systems.pinhole_feature_sensor import (
    PinholeFeatureSensor,
    PinholeFeatureSensor_,
)
from geovs_drake.systems.spherical_camera import SphericalCamera, SphericalCamera_

__all__ = [
    "FeatureExtractor",
    "FeatureExtractor_",
    "ImageJacobianForce",
    "ImageJacobianForce_",
    "KinematicController",
    "KinematicController_",
    "KinematicRigidBody",
    "KinematicRigidBody_",
    "NavigationController",
    "NavigationController_",
    "PinholeFeatureSensor",
    "PinholeFeatureSensor_",
    "SphericalCamera",
    "SphericalCamera_",
]
