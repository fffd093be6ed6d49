"""The plant, one variant each (``ScenarioConfig.plant``): how the carrier is driven.

In YAML a plant is tagged with its class name, ``plant: !Kinematic {}``; a scenario
file's bare name (``plant: kinematic``) reads as that variant. The code asks its
``traits`` (or :attr:`ScenarioConfig.dynamic <geovs_drake.scenario.ScenarioConfig>`),
never a name or a type.
"""

from dataclasses import dataclass
from typing import ClassVar

from geovs_drake.scenario.traits import PlantTraits

__all__ = ["PLANT_VARIANTS", "Dynamic", "Kinematic", "PlantConfig"]


@dataclass
class Dynamic:
    """Second order (Appendix C): the carrier is a MultibodyPlant driven by a wrench (the
    free rig, the target under a fixed camera) or by joint torques (the arm); the NF's
    loop is Eq. (45), its energy bounded by k_p. Gains: ``control.potential_gain``, the
    damping B and, for the twist laws, ``control.tracking_gains``."""

    #: The ``control`` field that scales the NF's loop on this plant, and its symbol.
    gain_field: ClassVar[str] = "potential_gain"
    gain_symbol: ClassVar[str] = "k_p"
    traits: ClassVar[PlantTraits] = PlantTraits(dynamic=True)


@dataclass
class Kinematic:
    """First order (Eqs. 17-19): the camera's body twist (or the arm's joint velocities)
    is commanded; the NF's loop is ``ydot = -control.kinematic_gain grad phi``."""

    gain_field: ClassVar[str] = "kinematic_gain"
    gain_symbol: ClassVar[str] = "k"
    traits: ClassVar[PlantTraits] = PlantTraits(dynamic=False)


#: A plant's configuration: one of the variants above.
PlantConfig = Dynamic | Kinematic
#: The plant of each name, as ``--plant`` and a file's bare name give it.
PLANT_VARIANTS: dict[str, type] = {"dynamic": Dynamic, "kinematic": Kinematic}
