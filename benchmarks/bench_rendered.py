"""The loop closed through rendered images: what a frame costs and how fast the loop runs.

Everything is measured in this process, the exact loop included, because the
machine is shared and noisy: the ratios are the figures to compare.

Reported:

* rendering: ``RgbdSensor``'s colour image (RenderEngineVtk, EGL) per 320x240
  frame, at poses along the rendered run from the default start, against the
  renderer's floor: SceneGraph's plain ``Sphere`` alone, Drake's default light,
  the same camera;
* feature extraction per 320x240 frame (:func:`extract_features` on those frames;
  target <= 5 ms), and its parts: OpenCV's segmentation and blobs
  (:func:`find_target_pixels`) and the geometry (rays and fits);
* the real-time factor (simulated / wall seconds of ``simulate()``) from the
  default start: the rendered loop at 30 Hz (target >= 5x), the pinhole loop
  (the same measurement without rendering) and the exact loop, and the
  rendered loop's share spent rendering and extracting.

    .venv/bin/python benchmarks/bench_rendered.py [--duration 6] [--repeat 3]
"""

from __future__ import annotations

import argparse
import copy
import time
import timeit

import numpy as np
from _record import Figure, record

from geovs_drake.analysis.studies.camera_accuracy import render_frames
from geovs_drake.geometry.features import TargetMarks
from geovs_drake.scenario import SENSOR_VARIANTS, Rendered, ScenarioConfig
from geovs_drake.simulation import simulate
from geovs_drake.systems.feature_extractor import (
    FeatureExtractor_,
    extract_features,
    find_target_pixels,
)


def best(fn, number: int, repeat: int) -> float:
    """Seconds per call: the best of ``repeat`` timings (the least disturbed)."""
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def renderer_floor(frames: int, repeat: int) -> float:
    """ms per 320x240 colour frame of a bare ``Sphere`` with Drake's default light."""
    from pydrake.geometry import (
        ClippingRange,
        ColorRenderCamera,
        DepthRange,
        DepthRenderCamera,
        MakeRenderEngineVtk,
        RenderCameraCore,
        RenderEngineVtkParams,
        Sphere,
    )
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.sensors import CameraInfo, RgbdSensor

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    scene_graph.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams(backend="EGL")))
    plant.RegisterVisualGeometry(
        plant.world_body(), RigidTransform([0, 0, 0.5]), Sphere(0.1), "s", [1, 1, 1, 1]
    )
    plant.Finalize()
    core = RenderCameraCore(
        "vtk", CameraInfo(320, 240, 168.5, 168.5, 160, 120), ClippingRange(0.05, 5.0),
        RigidTransform(),
    )  # fmt: skip
    sensor = builder.AddSystem(
        RgbdSensor(
            scene_graph.world_frame_id(),
            RigidTransform(),
            ColorRenderCamera(core, False),
            DepthRenderCamera(core, DepthRange(0.06, 4.0)),
        )
    )
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    port = sensor.color_image_output_port()
    k = [0]

    def render() -> None:
        k[0] += 1
        root.SetTime(1e-3 * k[0])  # every cache out of date: a new frame
        port.Eval(sensor.GetMyContextFromRoot(root))

    return 1e3 * best(render, frames, repeat)


def rtf(config: ScenarioConfig, repeat: int) -> tuple[float, object]:
    """The best real-time factor of ``repeat`` runs, and the last run."""
    factors, result = [], None
    for _ in range(repeat):
        result = simulate(config)
        factors.append(result.sim_time_s / result.wall_time_s)
    return max(factors), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--duration", type=float, default=6.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    config = ScenarioConfig(duration=args.duration)

    # Frames along the rendered run from the default start (what the loop sees).
    rendered_config = copy.deepcopy(config)
    rendered_config.sensor = Rendered()
    run = simulate(rendered_config)
    picks = np.linspace(0, len(run.times) - 1, 40).astype(int)
    frames, believed, _ = render_frames(rendered_config, run.X_BC[picks], (320, 240))
    render_ms = min(
        render_frames(rendered_config, run.X_BC[picks], (320, 240))[2] for _ in range(args.repeat)
    )
    delta = TargetMarks().arrow_angle
    k = [0]

    def extract() -> None:
        extract_features(frames[k[0] % len(frames)], believed, delta)
        k[0] += 1

    def pixels() -> None:
        find_target_pixels(frames[k[0] % len(frames)])
        k[0] += 1

    floor_ms = renderer_floor(len(frames), args.repeat)
    extract_ms = 1e3 * best(extract, len(frames), args.repeat)
    pixels_ms = 1e3 * best(pixels, len(frames), args.repeat)
    print("per 320x240 frame (best of", args.repeat, "passes over", len(frames), "frames):")
    print(f"  render (RgbdSensor, VTK EGL):        {render_ms:7.2f} ms")
    print(f"    renderer's floor (bare Sphere):    {floor_ms:7.2f} ms")
    print(f"  extract y (target <= 5 ms):          {extract_ms:7.2f} ms")
    print(f"    of which OpenCV pixels and blobs:  {pixels_ms:7.2f} ms")
    print(f"    of which rays and fits:            {extract_ms - pixels_ms:7.2f} ms")

    # Time the extractor's frames (render and extract) inside the rendered loop.
    spent = [0.0, 0]
    original = FeatureExtractor_[float]._measure

    def timed(self, context):
        start = time.perf_counter()
        out = original(self, context)
        spent[0] += time.perf_counter() - start
        spent[1] += 1
        return out

    FeatureExtractor_[float]._measure = timed
    factors, walls = {}, {}
    for sensor in ("exact", "pinhole", "rendered"):
        c = copy.deepcopy(config)
        c.sensor = SENSOR_VARIANTS[sensor]()
        spent[:] = [0.0, 0]
        factors[sensor], result = rtf(c, args.repeat)
        walls[sensor] = result.wall_time_s
        print(
            f"real-time factor, {sensor:>8} loop: {factors[sensor]:7.1f}x "
            f"({result.status}, {result.steps} steps in {result.sim_time_s:g} s)"
        )
    FeatureExtractor_[float]._measure = original
    frames = spent[1] / args.repeat  # the last rendered run's share, per run
    camera_s = spent[0] / args.repeat
    print(f"rendered loop (target >= 5x): {factors['rendered']:.1f}x real time at 30 Hz;")
    print(
        f"  its camera ({frames:.0f} frames a run, render + extract) took "
        f"{1e3 * camera_s / frames:.1f} ms a frame, {100 * camera_s / walls['rendered']:.0f}% "
        f"of its wall time; the exact loop runs {factors['exact'] / factors['rendered']:.0f}x "
        f"faster, the pinhole loop {factors['pinhole'] / factors['rendered']:.1f}x"
    )
    print(f"(measured {time.strftime('%Y-%m-%d %H:%M')})")
    figures = [
        Figure("rendering a 320x240 frame (RgbdSensor, VTK EGL)", render_ms, "ms",
               "the renderer's floor: a bare Sphere, default light", floor_ms),
        Figure("extracting y from a frame (OpenCV + fits)", extract_ms, "ms",
               "rendering the frame", render_ms, target="<= 5 ms"),
        Figure(f"rendered loop at 30 Hz, default start, {args.duration:g} s", factors["rendered"],
               "x real time", "the exact-sensor loop, same run", factors["exact"], target=">= 5x"),
        Figure(f"pinhole loop at 30 Hz, default start, {args.duration:g} s", factors["pinhole"],
               "x real time", "the exact-sensor loop, same run", factors["exact"]),
    ]  # fmt: skip
    record("bench_rendered", "The camera loops: rendering, extraction, real time", figures)


if __name__ == "__main__":
    main()
