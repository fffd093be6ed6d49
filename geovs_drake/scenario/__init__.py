"""Scenario configuration: what a loop is, as typed configs: the schema, its loader and
its checks (the shape of Drake's hardware_sim ``Scenario``). What a run derives from a
scenario is resolved once, a layer up, by :func:`geovs_drake.loop.resolver`.

One file per job, each importing only the ones above it in this list:
* :mod:`~geovs_drake.scenario.traits`: what each variant can do (its ``traits``);

* :mod:`~geovs_drake.scenario.pose`: :class:`PoseConfig`, a pose in a file;
* the four axes of a loop, one variant each, in YAML tagged with the class name:
  :mod:`~geovs_drake.scenario.carriers` (``carrier: !Arm {model: panda}``),
  :mod:`~geovs_drake.scenario.plants` (``plant: !Kinematic {}``),
  :mod:`~geovs_drake.scenario.sensors` (``sensor: !Pinhole {rate: 15}``),
  :mod:`~geovs_drake.scenario.laws` (``controller: !Ibvs {depth: mean}``), and how
  the target moves, :mod:`~geovs_drake.scenario.targets` (``target_motion: !Twist
  {twist: [0, 0, 0.2, 0.05, 0, 0]}``);
* :mod:`~geovs_drake.scenario.schema`: :class:`ScenarioConfig` and its other parts,
  the checks of what no union can say, and the quantities derived from them;
* :mod:`~geovs_drake.scenario.load`: YAML files and fragments in layers
  (:func:`load_scenario`, the pattern of Drake's hardware_sim loader);
* :mod:`~geovs_drake.scenario.suite`: the comparison suite (:func:`load_suite`).

Every name is imported from here, ``from geovs_drake.scenario import ScenarioConfig``;
the objects say they live here (their ``__module__``), so that the reference documents
them on this page and pickles name this path.
"""

from geovs_drake.scenario.carriers import (
    AUTO,
    CARRIER_VARIANTS,
    NOMINAL_GAIN_SCALES,
    TORQUE_LIMITS,
    Arm,
    CarrierConfig,
    FixedCamera,
    FreeRig,
    Quadrotor,
    RigidBodyConfig,
)
from geovs_drake.scenario.laws import (
    CONTROLLERS,
    IBVS_DEPTHS,
    LAW_VARIANTS,
    HamelMahony,
    Ibvs,
    LawConfig,
    Nf,
    PathFollowing,
    Pbvs,
    Spherical,
)
from geovs_drake.scenario.load import load_scenario, variant_layer
from geovs_drake.scenario.plants import PLANT_VARIANTS, Dynamic, Kinematic, PlantConfig
from geovs_drake.scenario.pose import PoseConfig
from geovs_drake.scenario.schema import (
    AXES,
    DEFAULT_MAX_STEP,
    ControlConfig,
    DomainConfig,
    NavigationGainsConfig,
    ScenarioConfig,
    SimulatorSettings,
    damping_of,
    variant_name,
)
from geovs_drake.scenario.sensors import (
    PREDICTIONS,
    SENSOR_VARIANTS,
    CameraModel,
    Exact,
    Pinhole,
    Rendered,
    SensorConfig,
    camera_like,
    radius_error_of,
)
from geovs_drake.scenario.suite import SuiteConfig, SuiteScenario, default_suite_path, load_suite
from geovs_drake.scenario.targets import (
    ESTIMATOR_RATE_HZ,
    FEEDFORWARD_MODES,
    TARGET_VARIANTS,
    Still,
    TargetMotionConfig,
    Trajectory,
    Twist,
    target_motion_arguments,
    target_trajectory,
    trajectory_of,
)

__all__ = [
    "AUTO",
    "AXES",
    "CARRIER_VARIANTS",
    "CONTROLLERS",
    "DEFAULT_MAX_STEP",
    "ESTIMATOR_RATE_HZ",
    "FEEDFORWARD_MODES",
    "IBVS_DEPTHS",
    "LAW_VARIANTS",
    "NOMINAL_GAIN_SCALES",
    "TORQUE_LIMITS",
    "TARGET_VARIANTS",
    "PLANT_VARIANTS",
    "PREDICTIONS",
    "SENSOR_VARIANTS",
    "Arm",
    "CameraModel",
    "CarrierConfig",
    "ControlConfig",
    "DomainConfig",
    "Dynamic",
    "Exact",
    "FixedCamera",
    "FreeRig",
    "Ibvs",
    "Kinematic",
    "LawConfig",
    "NavigationGainsConfig",
    "Nf",
    "HamelMahony",
    "PathFollowing",
    "Pbvs",
    "Pinhole",
    "PlantConfig",
    "PoseConfig",
    "Quadrotor",
    "Rendered",
    "RigidBodyConfig",
    "ScenarioConfig",
    "SensorConfig",
    "SimulatorSettings",
    "Spherical",
    "Still",
    "SuiteConfig",
    "SuiteScenario",
    "TargetMotionConfig",
    "Trajectory",
    "Twist",
    "damping_of",
    "default_suite_path",
    "load_scenario",
    "load_suite",
    "target_motion_arguments",
    "target_trajectory",
    "trajectory_of",
    "camera_like",
    "radius_error_of",
    "variant_layer",
    "variant_name",
]

for _name in __all__:
    _object = globals()[_name]
    if isinstance(_object, type) or callable(_object) and hasattr(_object, "__code__"):
        _object.__module__ = __name__
del _name, _object
