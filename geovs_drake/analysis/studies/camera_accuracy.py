"""How well the rendered camera measures y: the feature extractor against the exact c(H).

:func:`feature_accuracy` draws poses in D (images uniform in D's model chart),
renders each with the rendered loop's own ``RgbdSensor`` (the diagram of
:func:`~geovs_drake.loop.build_loop` with ``sensor: !Rendered {}``), extracts y with
:func:`~geovs_drake.systems.feature_extractor.extract_features` and compares it
with the exact y = c(H) of the same pose: the error of lambda (absolute and
relative) and the angles between the measured and exact s, q1 and q2. A pose
whose frame gives no y is counted by its reason, not averaged in.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from geovs_drake._json import json_ready
from geovs_drake.geometry.camera import camera_map_inverse
from geovs_drake.geometry.features import FEATURE_FAILURES, TargetMarks
from geovs_drake.loop.build import build_loop
from geovs_drake.loop.state import initial_body_states
from geovs_drake.sampling import random_features_in_domain
from geovs_drake.scenario import Rendered, ScenarioConfig, camera_like
from geovs_drake.systems.feature_extractor import extract_features

__all__ = ["AccuracyResult", "feature_accuracy", "render_frames"]


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The angle between unit vectors (rows), accurate near 0 (atan2 of |a x b| and a.b)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


@dataclass
class AccuracyResult:
    """Per-pose errors of the extracted y (NaN where the frame gave no y) and a summary."""

    resolution: tuple[int, int]
    pixel_angle: float  # 1 / f [rad]: the angle a pixel subtends at the image centre
    exact: np.ndarray  # (N, 13)
    measured: np.ndarray  # (N, 13), NaN rows where extraction failed
    codes: np.ndarray  # (N,) failure codes, 0 = ok
    errors: dict[str, np.ndarray] = field(default_factory=dict)
    render_ms: float = math.nan
    extract_ms: float = math.nan

    def summary(self) -> dict:
        """Median and worst of each error over the poses that gave a y, and failures by reason."""
        ok = self.codes == 0
        out = {
            "poses": int(len(self.codes)),
            "resolution": list(self.resolution),
            "pixel_angle_rad": self.pixel_angle,
            "extracted": int(ok.sum()),
            "failures": {
                FEATURE_FAILURES[k]: int(np.sum(self.codes == k))
                for k in np.unique(self.codes[~ok])
            },
            "render_ms_per_frame": self.render_ms,
            "extract_ms_per_frame": self.extract_ms,
        }
        for name, e in self.errors.items():
            e = e[ok]
            out[name] = {"median": float(np.median(e)), "worst": float(np.max(e))}
        return json_ready(out)


def render_frames(
    config: ScenarioConfig,
    X_BC: np.ndarray,
    resolution: tuple[int, int],
    states: np.ndarray | None = None,
):
    """Colour images (N, H, W, 4) of the rendered loop's camera at camera poses X_BC (N, 4, 4),
    with the extractor's believed intrinsics and the wall time per frame [ms].

    ``states``: the loop's continuous states at those poses (a run's ``states``), which
    an arm needs (its joints; a free body's state follows from X_BC)."""
    camera = camera_like(config.sensor, Rendered, resolution=[int(v) for v in resolution])
    diagram = build_loop(dataclasses.replace(config, sensor=camera), log=False).diagram
    root = diagram.CreateDefaultContext()
    plant = diagram.GetSubsystemByName("plant")
    rgbd = diagram.GetSubsystemByName("rgbd_sensor")
    extractor = diagram.GetSubsystemByName("feature_sensor")
    plant_context = plant.GetMyMutableContextFromRoot(root)
    rgbd_context = rgbd.GetMyContextFromRoot(root)
    if states is None:
        states = initial_body_states(config, X_BC)
    n = plant.num_positions() + plant.num_velocities()
    frames = []
    start = time.perf_counter()
    for x in states:
        plant.SetPositionsAndVelocities(plant_context, np.asarray(x)[:n])
        frames.append(np.array(rgbd.color_image_output_port().Eval(rgbd_context).data))
    ms = 1e3 * (time.perf_counter() - start) / max(1, len(states))
    believed = extractor.believed_intrinsics(extractor.GetMyContextFromRoot(root))
    return np.stack(frames), believed, ms


def feature_accuracy(
    config: ScenarioConfig | None = None,
    n: int = 200,
    resolution: tuple[int, int] = (640, 480),
    seed: int = 0,
    shrink: float = 1.0,
) -> AccuracyResult:
    """Extract y from ``n`` rendered frames at poses in D and compare with c(H).

    Poses: images uniform in D's model chart scaled by ``shrink`` (1: all of D),
    from ``seed``. The camera is the rendered loop's (``config.sensor``'s camera with
    ``resolution``); the extractor believes its intrinsics exactly (no
    ``focal_error``, no noise): this measures rendering and extraction alone.
    """
    config = copy.deepcopy(config or ScenarioConfig())
    config.sensor = camera_like(config.sensor, Rendered, focal_error=0.0, pixel_noise=0.0)
    domain = config.domain.to_domain()
    y = random_features_in_domain(np.random.default_rng(seed), n, domain, shrink)
    X_CB = camera_map_inverse(y, config.radius)
    X_BC = np.linalg.inv(X_CB)
    frames, believed, render_ms = render_frames(config, X_BC, resolution)
    arrow_angle = TargetMarks().arrow_angle
    exact = y.to_vector()
    measured = np.full_like(exact, np.nan)
    codes = np.zeros(n, dtype=int)
    start = time.perf_counter()
    for i, frame in enumerate(frames):
        yi, codes[i] = extract_features(frame, believed, arrow_angle)
        if yi is not None:
            measured[i] = yi
    extract_ms = 1e3 * (time.perf_counter() - start) / n
    errors = {
        "lambda_abs": np.abs(measured[:, 9] - exact[:, 9]),
        "lambda_rel": np.abs(measured[:, 9] / exact[:, 9] - 1),
        "s_rad": _angle(measured[:, 10:13], exact[:, 10:13]),
        "q1_rad": _angle(measured[:, 0:3], exact[:, 0:3]),
        "q2_rad": _angle(measured[:, 3:6], exact[:, 3:6]),
    }
    return AccuracyResult(
        resolution=tuple(resolution),
        pixel_angle=1.0 / believed.fx,
        exact=exact,
        measured=measured,
        codes=codes,
        errors=errors,
        render_ms=render_ms,
        extract_ms=extract_ms,
    )
