"""The default demo: the dynamic loop from a visibly hard start."""

from __future__ import annotations

import json
from pathlib import Path

from geovs_drake.scenario import PoseConfig, ScenarioConfig
from geovs_drake.simulation import simulate

__all__ = ["HARD_START", "demo_config", "run_demo"]

#: Rolled 160 deg about the optical axis, offset sideways and 0.35 m further out.
HARD_START = PoseConfig(xyz=[0.18, -0.12, -0.85], rpy=[0.12, -0.15, 2.8])


def demo_config(duration: float | None = None) -> ScenarioConfig:
    config = ScenarioConfig(initial=HARD_START)
    if duration is not None:
        config.duration = duration
    return config


def run_demo(
    out: str | Path = "results", duration: float | None = None, meshcat: bool = True
) -> int:
    from geovs_drake.cli import one_line

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    result = simulate(demo_config(duration))
    (out / "summary.json").write_text(json.dumps(result.summary(), indent=2) + "\n")
    print(one_line(result))
    return 0 if result.converged else 1
