"""A pose in a scenario file: translation [m] and Drake's RollPitchYaw [rad]."""

import math
from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

__all__ = ["PoseConfig"]


@dataclass
class PoseConfig:
    """A pose as translation [m] and Drake RollPitchYaw [rad]."""

    xyz: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    rpy: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])

    def to_rigid_transform(self) -> RigidTransform:
        """The pose as a RigidTransform; ValueError for a wrong length or a non-finite entry."""
        if len(self.xyz) != 3 or len(self.rpy) != 3:
            raise ValueError(f"a pose needs 3 xyz and 3 rpy numbers, got {self.xyz}, {self.rpy}")
        values = list(self.xyz) + list(self.rpy)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"pose has a non-finite entry: xyz = {self.xyz}, rpy = {self.rpy}")
        return RigidTransform(RollPitchYaw(self.rpy), np.asarray(self.xyz, dtype=float))

    @staticmethod
    def from_rigid_transform(X: RigidTransform) -> "PoseConfig":
        """The PoseConfig of a RigidTransform (translation and RollPitchYaw)."""
        return PoseConfig(
            xyz=[float(v) for v in X.translation()],
            rpy=[float(v) for v in RollPitchYaw(X.rotation()).vector()],
        )


def finite_numbers(values, n: int) -> list[float] | None:
    """``values`` as n finite floats, or None if it is not that."""
    try:
        out = [float(v) for v in values]
    except (TypeError, ValueError):
        return None
    return out if len(out) == n and all(math.isfinite(v) for v in out) else None


def check_at_least(where: str, value: object, low: float, strict: bool, unit: str = "") -> None:
    """ValueError ``where must be finite and > low: name = value`` unless ``value`` is a
    finite number (not a bool) above ``low`` (or at it, where not ``strict``)."""
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if not (ok and math.isfinite(value) and (value > low if strict else value >= low)):
        name = where.rsplit(".", 1)[-1]
        raise ValueError(
            f"{where} must be finite and {'>' if strict else '>='} {low:g}{unit}: "
            f"{name} = {value!r}"
        )
