"""The servo's Drake systems, one LeafSystem per module, all TemplateSystems."""

from geovs_drake.systems.arm_camera import ArmCamera, ArmCamera_
from geovs_drake.systems.feature_extractor import FeatureExtractor, FeatureExtractor_
from geovs_drake.systems.fixed_camera_kinematic_mount import (
    FixedCameraKinematicMount,
    FixedCameraKinematicMount_,
)
from geovs_drake.systems.fixed_camera_mount import FixedCameraMount, FixedCameraMount_
from geovs_drake.systems.ibvs_controller import IbvsController, IbvsController_
from geovs_drake.systems.image_jacobian_force import ImageJacobianForce, ImageJacobianForce_
from geovs_drake.systems.kinematic_arm import KinematicArm, KinematicArm_
from geovs_drake.systems.kinematic_controller import KinematicController, KinematicController_
from geovs_drake.systems.kinematic_rigid_body import KinematicRigidBody, KinematicRigidBody_
from geovs_drake.systems.navigation_controller import (
    NavigationController,
    NavigationController_,
)
from geovs_drake.systems.path_following_controller import (
    PathFollowingController,
    PathFollowingController_,
)
from geovs_drake.systems.pbvs_controller import PbvsController, PbvsController_
from geovs_drake.systems.pinhole_feature_sensor import (
    PinholeFeatureSensor,
    PinholeFeatureSensor_,
)
from geovs_drake.systems.spherical_camera import SphericalCamera, SphericalCamera_
from geovs_drake.systems.spherical_feature_controller import (
    SphericalFeatureController,
    SphericalFeatureController_,
)
from geovs_drake.systems.velocity_tracking_force import (
    VelocityTrackingForce,
    VelocityTrackingForce_,
)

__all__ = [
    "ArmCamera",
    "ArmCamera_",
    "KinematicArm",
    "KinematicArm_",
    "FixedCameraKinematicMount",
    "FixedCameraKinematicMount_",
    "FixedCameraMount",
    "FixedCameraMount_",
    "IbvsController",
    "IbvsController_",
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
    "PathFollowingController",
    "PathFollowingController_",
    "PbvsController",
    "PbvsController_",
    "PinholeFeatureSensor",
    "PinholeFeatureSensor_",
    "SphericalCamera",
    "SphericalCamera_",
    "SphericalFeatureController",
    "SphericalFeatureController_",
    "VelocityTrackingForce",
    "VelocityTrackingForce_",
]
