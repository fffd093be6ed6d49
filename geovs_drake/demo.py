"""The default demo: the dynamic loop from a visibly hard start, with every picture.

Writes to the output folder:

* ``summary.json``: the run's summary (the CLI's ``--json`` fields);
* ``servo.html``: the Meshcat recording, standalone (``Meshcat.StaticHtml``);
* ``image_view.png``, ``run.png``: what the camera sees; phi, energy, margins
  and pose error over time;
* ``nf_slices.png``: the navigation function along slices through the goal;
* ``block_diagram.svg`` / ``.png``: the closed loop (needs Graphviz's ``dot``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from geovs_drake.scenario import PoseConfig, ScenarioConfig

__all__ = ["HARD_START", "demo_config", "record_meshcat", "run_demo"]

#: Rolled 160 deg about the optical axis, offset sideways and 0.35 m further out.
HARD_START = PoseConfig(xyz=[0.18, -0.12, -0.85], rpy=[0.12, -0.15, 2.8])


def demo_config(duration: float | None = None) -> ScenarioConfig:
    config = ScenarioConfig(initial=HARD_START)
    if duration is not None:
        config.duration = duration
    return config


def _progress(total: float, description: str):
    """A tqdm bar on stderr, advanced with the simulated time."""
    from tqdm import tqdm

    bar = tqdm(total=total, desc=description, unit="sim s", file=sys.stderr, leave=False)

    def update(t: float) -> None:
        bar.update(t - bar.n)

    return bar, update


def record_meshcat(config: ScenarioConfig, html_path: str | Path, progress=None):
    """Simulate with Meshcat recording; write the standalone HTML; return the result."""
    from pydrake.geometry import Meshcat

    from geovs_drake.simulation import simulate
    from geovs_drake.visualization import draw_trail

    meshcat = Meshcat()
    # Look at the target and the camera's path from above and to the side.
    p_WB = config.X_WB.translation()
    p_WC = (config.X_WB @ config.X_BC_initial).translation()
    mid = 0.5 * (p_WB + p_WC)
    meshcat.SetCameraPose(camera_in_world=mid + [0.4, -1.4, 0.6], target_in_world=mid)
    meshcat.StartRecording(frames_per_second=30.0)
    result = simulate(config, meshcat=meshcat, progress=progress)
    meshcat.StopRecording()
    draw_trail(meshcat, config.X_WB.GetAsMatrix4() @ result.X_BC)
    meshcat.PublishRecording()
    Path(html_path).write_text(meshcat.StaticHtml())
    return result


def run_demo(
    out: str | Path = "results", duration: float | None = None, meshcat: bool = True
) -> int:
    from geovs_drake.diagrams import make_dynamic_servo_diagram
    from geovs_drake.geometry.navigation import NavigationFunction
    from geovs_drake.plotting import (
        plot_image_view,
        plot_navigation_slices,
        plot_run,
        write_block_diagram,
    )
    from geovs_drake.simulation import simulate

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    config = demo_config(duration)
    bar, update = _progress(config.duration, "dynamic servo")
    if meshcat:
        result = record_meshcat(config, out / "servo.html", progress=update)
    else:
        result = simulate(config, progress=update)
    bar.close()
    (out / "summary.json").write_text(json.dumps(result.summary(), indent=2) + "\n")
    plot_image_view(result, out / "image_view.png")
    plot_run(result, out / "run.png")
    nf = NavigationFunction(
        config.domain.to_domain(), config.goal_features(), config.navigation.to_gains()
    )
    plot_navigation_slices(nf, out / "nf_slices.png")
    write_block_diagram(make_dynamic_servo_diagram(config, log=False), out / "block_diagram")
    print(result.one_line())
    return 0 if result.converged else 1
