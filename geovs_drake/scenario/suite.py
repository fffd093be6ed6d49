"""The comparison suite (``geovs-drake compare``): the starts every law runs from."""

import importlib.resources
import math
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_load_typed

from geovs_drake.scenario.load import _describe, load_tagged_yaml
from geovs_drake.scenario.pose import PoseConfig, finite_numbers
from geovs_drake.scenario.targets import Still, Trajectory, Twist, check_target_motion

__all__ = ["SuiteConfig", "SuiteScenario", "default_suite_path", "load_suite"]


@dataclass
class SuiteScenario:
    """One start of a comparison suite: X_BC(0) as xyz [m] and RollPitchYaw [deg], and
    how the target moves (``target_motion``, as a scenario's:
    ``target_motion: !Twist {twist: [0, 0, 0.2, 0.05, 0, 0], feedforward: known}``;
    by default it stands still)."""

    name: str = ""
    description: str = ""
    xyz: list[float] = field(default_factory=lambda: [0.0, 0.0, -0.5])
    rpy_deg: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    target_motion: Still | Twist | Trajectory = field(default_factory=Still)

    @property
    def moving_target(self) -> bool:
        """Whether the target moves (``target_motion`` is not :class:`Still`)."""
        return not isinstance(self.target_motion, Still)

    def initial(self) -> PoseConfig:
        """The start as a :class:`PoseConfig` (radians)."""
        return PoseConfig(list(self.xyz), [math.radians(v) for v in self.rpy_deg])


@dataclass
class SuiteConfig:
    """The scenarios every law of ``geovs-drake compare`` runs from, each for
    ``duration`` seconds; ``conundrum`` names the scenario whose image-sphere
    trajectories are plotted."""

    duration: float = 20.0
    conundrum: str = ""
    scenarios: list[SuiteScenario] = field(default_factory=list)

    def validate(self) -> None:
        """Raise ValueError naming the first bad field and its value."""
        if not (math.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"duration must be finite and > 0 [s]: duration = {self.duration}")
        if not self.scenarios:
            raise ValueError("scenarios: the suite has none")
        names = [s.name for s in self.scenarios]
        for i, s in enumerate(self.scenarios):
            if not s.name:
                raise ValueError(f"scenarios[{i}].name is empty")
            if names.count(s.name) > 1:
                raise ValueError(f"scenarios[{i}].name {s.name!r} is not unique")
            for key in ("xyz", "rpy_deg"):
                if finite_numbers(getattr(s, key), 3) is None:
                    raise ValueError(
                        f"scenarios[{i}].{key} ({s.name}) must be 3 finite numbers, "
                        f"got {getattr(s, key)!r}"
                    )
            try:
                check_target_motion(s.target_motion)
            except ValueError as e:
                raise ValueError(f"scenarios[{i}] ({s.name}): {e}") from None
        if self.conundrum and self.conundrum not in names:
            raise ValueError(
                f"conundrum {self.conundrum!r} is not a scenario of the suite ({', '.join(names)})"
            )


def default_suite_path() -> Path:
    """The suite shipped with the package, ``geovs_drake/scenarios/suite.yaml``."""
    return Path(str(importlib.resources.files("geovs_drake.scenarios") / "suite.yaml"))


def load_suite(path: str | Path | None = None) -> SuiteConfig:
    """A :class:`SuiteConfig` from a YAML file (default: :func:`default_suite_path`),
    read with Drake's ``yaml_load_typed`` and validated; a missing or malformed
    file or a bad field is a one-line ValueError naming the file."""
    path = default_suite_path() if path is None else Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: cannot read: {e}") from None
    try:
        tree = load_tagged_yaml(text)  # a SafeLoader that reads the variant tags (!Twist)
    except yaml.YAMLError as e:
        raise ValueError(f"{path}: malformed YAML: {str(e).splitlines()[0]}") from None
    if not isinstance(tree, dict):
        raise ValueError(f"{path}: expected a mapping of SuiteConfig fields, got {_describe(tree)}")
    try:
        suite = yaml_load_typed(schema=SuiteConfig, data=text, defaults=SuiteConfig())
    except (RuntimeError, ValueError, TypeError) as e:
        lines = str(e).strip().splitlines() or [type(e).__name__]
        raise ValueError(f"{path}: {lines[0]}") from None
    try:
        suite.validate()
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    return suite
