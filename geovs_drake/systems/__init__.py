"""The servo's Drake systems, one LeafSystem per module, all TemplateSystems.

The names below are imported from their modules on first use
(:mod:`geovs_drake._lazy`): a loop imports the systems it uses, not all of them.
"""

from geovs_drake._lazy import attach

__getattr__, __dir__, __all__ = attach(
    __name__,
    {
        "arm_camera": ("ArmCamera", "ArmCamera_"),
        "attitude_cascade": ("AttitudeCascade", "AttitudeCascade_"),
        "feature_extractor": ("FeatureExtractor", "FeatureExtractor_"),
        "fixed_camera_kinematic_mount": ("FixedCameraKinematicMount", "FixedCameraKinematicMount_"),
        "fixed_camera_mount": ("FixedCameraMount", "FixedCameraMount_"),
        "frame_predictor": ("FramePredictor", "FramePredictor_"),
        "frame_wait": ("FrameWait", "FrameWait_"),
        "hamel_mahony_controller": ("HamelMahonyController", "HamelMahonyController_"),
        "ibvs_controller": ("IbvsController", "IbvsController_"),
        "image_jacobian_force": ("ImageJacobianForce", "ImageJacobianForce_"),
        "kinematic_arm": ("KinematicArm", "KinematicArm_"),
        "kinematic_controller": ("KinematicController", "KinematicController_"),
        "kinematic_rigid_body": ("KinematicRigidBody", "KinematicRigidBody_"),
        "level_view": ("LevelView", "LevelView_"),
        "navigation_controller": ("NavigationController", "NavigationController_"),
        "path_following_controller": ("PathFollowingController", "PathFollowingController_"),
        "pbvs_controller": ("PbvsController", "PbvsController_"),
        "pinhole_feature_sensor": ("PinholeFeatureSensor", "PinholeFeatureSensor_"),
        "self_mask": ("SelfMask", "SelfMask_"),
        "spherical_camera": ("SphericalCamera", "SphericalCamera_"),
        "target_frame": ("TargetFrame", "TargetFrame_"),
        "target_motion": ("TargetMotion", "TargetMotion_"),
        "target_relative_twist": ("TargetRelativeTwist", "TargetRelativeTwist_"),
        "target_relative_wrench": ("TargetRelativeWrench", "TargetRelativeWrench_"),
        "target_twist_estimator": ("TargetTwistEstimator", "TargetTwistEstimator_"),
        "spherical_feature_controller": (
            "SphericalFeatureController",
            "SphericalFeatureController_",
        ),
        "velocity_tracking_force": ("VelocityTrackingForce", "VelocityTrackingForce_"),
    },
)
