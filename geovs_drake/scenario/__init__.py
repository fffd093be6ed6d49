"""Scenario configuration: what a loop is, as typed configs, loaded once and resolved once.

One file per job, each importing only the ones above it in this list:

* :mod:`~geovs_drake.scenario.laws`: the control laws, one variant each
  (``controller: !Ibvs {depth: mean}``);
* :mod:`~geovs_drake.scenario.schema`: :class:`ScenarioConfig` and its parts, each
  with its own checks (``validate``), and the quantities derived from them;
* :mod:`~geovs_drake.scenario.resolution`: :class:`ResolvedScenario`, the validated
  scenario with what follows from it (:func:`resolve`);
* :mod:`~geovs_drake.scenario.load`: YAML files and fragments in layers
  (:func:`load_scenario`, the pattern of Drake's hardware_sim loader);
* :mod:`~geovs_drake.scenario.suite`: the comparison suite (:func:`load_suite`).

Every name is imported from here, ``from geovs_drake.scenario import ScenarioConfig``;
the objects say they live here (their ``__module__``), so that the reference documents
them on this page and pickles name this path.
"""

from geovs_drake.scenario.laws import (
    CONTROLLERS,
    IBVS_DEPTHS,
    LAW_VARIANTS,
    Ibvs,
    LawConfig,
    Nf,
    PathFollowing,
    Pbvs,
    Spherical,
    law_name,
)
from geovs_drake.scenario.load import load_scenario
from geovs_drake.scenario.resolution import ResolvedScenario, exact_twin, free_twin, resolve
from geovs_drake.scenario.schema import (
    CARRIER_NAMES,
    DEFAULT_MAX_STEP,
    MOUNTS,
    PLANTS,
    SENSOR_NAMES,
    ArmConfig,
    CameraConfig,
    ControlConfig,
    DomainConfig,
    NavigationGainsConfig,
    PoseConfig,
    RigConfig,
    ScenarioConfig,
    SimulatorSettings,
    damping_of,
)
from geovs_drake.scenario.suite import SuiteConfig, SuiteScenario, default_suite_path, load_suite

__all__ = [
    "CARRIER_NAMES",
    "CONTROLLERS",
    "DEFAULT_MAX_STEP",
    "IBVS_DEPTHS",
    "LAW_VARIANTS",
    "MOUNTS",
    "PLANTS",
    "SENSOR_NAMES",
    "ArmConfig",
    "CameraConfig",
    "ControlConfig",
    "DomainConfig",
    "Ibvs",
    "LawConfig",
    "NavigationGainsConfig",
    "Nf",
    "PathFollowing",
    "Pbvs",
    "PoseConfig",
    "ResolvedScenario",
    "RigConfig",
    "ScenarioConfig",
    "SimulatorSettings",
    "Spherical",
    "SuiteConfig",
    "SuiteScenario",
    "damping_of",
    "default_suite_path",
    "exact_twin",
    "free_twin",
    "law_name",
    "load_scenario",
    "load_suite",
    "resolve",
]

for _name in __all__:
    _object = globals()[_name]
    if isinstance(_object, type) or callable(_object) and hasattr(_object, "__code__"):
        _object.__module__ = __name__
del _name, _object
