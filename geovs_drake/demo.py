"""The default demo: the dynamic loop from a visibly hard start, with every picture.

Writes to the output folder:

* ``summary.json``: the run's summary (the CLI's ``--json`` fields);
* ``servo.html``: the Meshcat recording, standalone (``Meshcat.StaticHtml``);
* ``image_view.png``, ``run.png``: what the camera sees; phi, energy, margins
  and pose error over time;
* ``nf_slices.png``: the navigation function along slices through the goal;
* ``block_diagram.svg`` / ``.png``: the closed loop (needs Graphviz's ``dot``);
* ``rendered_vs_exact.png``, ``camera_frames.png``, ``rendered_summary.json``: the
  same start through the loop closed by rendered images (320x240, 30 Hz, the
  first :data:`RENDERED_DURATION` seconds), next to the exact sensor with the
  same gains, and three of the frames with what the extractor read.
"""

from __future__ import annotations

import json
import logging
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from geovs_drake._optional import MissingExtra, require
from geovs_drake.loop import exact_twin
from geovs_drake.progress import HorizonProgress
from geovs_drake.scenario import (
    CarrierConfig,
    FreeRig,
    PoseConfig,
    Rendered,
    ScenarioConfig,
    camera_like,
)

if TYPE_CHECKING:
    import numpy as np

    from geovs_drake.simulation import SimulationResult

__all__ = [
    "HARD_START",
    "RENDERED_DURATION",
    "check_demo_args",
    "demo_config",
    "record_meshcat",
    "run_demo",
    "run_rendered_demo",
]

#: Rolled 160 deg about the optical axis, offset sideways and 0.35 m further out.
HARD_START = PoseConfig(xyz=[0.18, -0.12, -0.85], rpy=[0.12, -0.15, 2.8])
#: How long the demo's rendered run lasts [s]: long enough to converge from
#: HARD_START (about 4.5 s), short enough to cost a few seconds (a frame is
#: rendered and read 30 times a second).
RENDERED_DURATION = 6.0


def demo_config(
    duration: float | None = None, carrier: CarrierConfig | None = None
) -> ScenarioConfig:
    """The demo's scenario: the default one from :data:`HARD_START`, run for ``duration`` [s]
    (default: the scenario's), on ``carrier`` (default :class:`FreeRig`, the paper's rig;
    ``Arm()``: the shipped arm, whose joints IK finds for the same start).
    """
    config = ScenarioConfig(initial=HARD_START, carrier=carrier or FreeRig())
    if duration is not None:
        config.duration = duration
    return config


def check_demo_args(out: str | Path, duration: float | None) -> None:
    """Raise ValueError (one line naming the option and its value) for a duration that is
    not finite and > 0, or an output folder that is a file or cannot be created/written."""
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"--duration must be finite and > 0 [s]: --duration {duration}")
    out = Path(out)
    if out.exists():
        if not out.is_dir():
            raise ValueError(f"--out {out} exists and is not a directory")
        if not os.access(out, os.W_OK | os.X_OK):
            raise ValueError(f"--out {out}: the folder is not writable")
        return
    parent = out.absolute().parent
    while not parent.exists():  # the nearest existing ancestor is where mkdir starts
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"--out {out}: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"--out {out}: cannot create it, {parent} is not writable")


def record_meshcat(config: ScenarioConfig, html_path: str | Path, progress=None):
    """Simulate with Meshcat recording; write the standalone HTML; return the result."""
    from pydrake.geometry import Meshcat

    from geovs_drake.simulation import simulate
    from geovs_drake.visualization import draw_trail

    # Meshcat() logs "listening for connections at http://localhost:7000", a URL that
    # dies with this process: the lasting result is the HTML file, which callers name.
    drake_log = logging.getLogger("drake")
    level = drake_log.level
    drake_log.setLevel(max(level, logging.WARNING))
    try:
        meshcat = Meshcat()
    finally:
        drake_log.setLevel(level)
    # Look at the target and the camera's path from above and to the side.
    p_WB = config.X_WB.translation()
    p_WC = (config.X_WB @ config.X_BC_initial).translation()
    mid = 0.5 * (p_WB + p_WC)
    meshcat.SetCameraPose(camera_in_world=mid + [0.4, -1.4, 0.6], target_in_world=mid)
    meshcat.StartRecording(frames_per_second=30.0)
    result = simulate(config, meshcat=meshcat, progress=progress)
    meshcat.StopRecording()
    draw_trail(meshcat, _drawn_target_poses(result) @ result.X_BC)
    meshcat.PublishRecording()
    Path(html_path).write_text(meshcat.StaticHtml())
    return result


def _drawn_target_poses(result) -> np.ndarray:
    """The target's pose in the world Meshcat draws, at the result's times (N, 4, 4):
    X_WB, or a moving target's X_WB(t) (every carrier that takes one is drawn in the
    world)."""
    import numpy as np

    from geovs_drake.scenario import target_motion_arguments
    from geovs_drake.systems.target_motion import TargetMotion

    config = result.config
    X_WB = config.X_WB.GetAsMatrix4()
    if not config.moving_target:
        return np.broadcast_to(X_WB, (len(result.times), 4, 4))
    motion = TargetMotion(X_WB0=config.X_WB, **target_motion_arguments(config.target_motion))
    return np.stack([motion.X_WB(t) for t in result.times])


def run_rendered_demo(config: ScenarioConfig, out: Path) -> SimulationResult:
    """The demo's start through the rendered loop and, with the same gains, the exact sensor;
    write ``rendered_vs_exact.png``, ``camera_frames.png`` and ``rendered_summary.json``;
    return the rendered run."""
    import copy

    import numpy as np

    from geovs_drake.analysis.studies.camera_accuracy import render_frames
    from geovs_drake.geometry.features import TargetMarks
    from geovs_drake.plotting import plot_camera_frames, plot_sensor_comparison
    from geovs_drake.simulation import simulate
    from geovs_drake.systems.feature_extractor import extract_features

    rendered_config = copy.deepcopy(config)
    rendered_config.duration = min(config.duration, RENDERED_DURATION)
    rendered_config.sensor = camera_like(config.sensor, Rendered)
    rendered = simulate(rendered_config)
    exact_config = exact_twin(rendered_config)
    exact_config.control.damping = list(rendered_config.sensor.damping)  # the same gains
    exact = simulate(exact_config)
    plot_sensor_comparison(
        {"exact y": exact, "rendered 320x240": rendered}, out / "rendered_vs_exact.png"
    )
    picks = np.unique(np.linspace(0, len(rendered.times) - 1, 3).astype(int))
    frames, believed, _ = render_frames(
        rendered_config,
        rendered.X_BC[picks],
        tuple(rendered_config.sensor.resolution),
        states=rendered.states[picks],
    )
    read = [extract_features(f, believed, TargetMarks().arrow_angle)[0] for f in frames]
    plot_camera_frames(frames, read, believed, rendered.times[picks], out / "camera_frames.png")
    summary = {"rendered": rendered.summary(), "exact_same_gains": exact.summary()}
    (out / "rendered_summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return rendered


def run_demo(
    out: str | Path = "results",
    duration: float | None = None,
    meshcat: bool = True,
    rendered: bool = True,
    carrier: CarrierConfig | None = None,
) -> SimulationResult:
    """Run the demo, write its files to ``out`` and print the run's line; return the run.

    ``rendered``: also run :func:`run_rendered_demo` (it needs OpenCV and an EGL-capable
    OpenGL) and print its line after the others.

    ``carrier``: :class:`FreeRig` (default) or :class:`Arm` (the recording then shows the
    arm servoing, and the rendered run is the arm's camera's).

    Bad ``out`` or ``duration`` raise ValueError before anything is written."""
    from geovs_drake.geometry.navigation import NavigationFunction
    from geovs_drake.loop import build_loop
    from geovs_drake.plotting import (
        plot_image_view,
        plot_navigation_slices,
        plot_run,
        write_block_diagram,
    )
    from geovs_drake.simulation import simulate

    check_demo_args(out, duration)
    config = demo_config(duration, carrier)
    config.validate()
    on_arm = config.carrier.traits.joints
    if rendered:
        # The rendered run is the demo's extra: without the vision extra the demo
        # still runs (like the block diagram without Graphviz), and says so first.
        try:
            require("cv2", "vision", "the demo's rendered run", package="opencv-python-headless")
        except MissingExtra as e:
            print(f"geovs-drake: skipping the rendered run: {e}", file=sys.stderr)
            rendered = False
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    label = "dynamic servo on the arm" if on_arm else "dynamic servo"
    bar = HorizonProgress(config.duration, label)
    try:
        if meshcat:
            result = record_meshcat(config, out / "servo.html", progress=bar)
        else:
            result = simulate(config, progress=bar)
    finally:
        bar.close()
    (out / "summary.json").write_text(json.dumps(result.summary(), indent=2) + "\n")
    plot_image_view(result, out / "image_view.png")
    plot_run(result, out / "run.png")
    nf = NavigationFunction(
        config.domain.to_domain(), config.goal_features(), config.navigation.to_gains()
    )
    plot_navigation_slices(nf, out / "nf_slices.png")
    write_block_diagram(build_loop(config, log=False).diagram, out / "block_diagram")
    print(result.one_line())
    if meshcat:
        # Drake's log line names a localhost URL that dies with this process; the
        # recording is the standalone HTML file.
        html = (out / "servo.html").resolve()
        print(f"Meshcat recording: {html} (open it in a web browser; it needs no server)")
    if rendered:
        camera_run = run_rendered_demo(config, out)
        print(f"rendered camera: {camera_run.one_line()} (see {out / 'rendered_vs_exact.png'})")
    return result
