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
    .venv/bin/python benchmarks/bench_rendered.py --station [--duration 1] [--repeat 3]

``--station`` (issue 44, item 7; its own record, ``bench_rendered_station.json``): the
simulated Panda station (``geovs-drake station``'s diagram on ``memq://``, unpaced, the
arm held at rest: no controller) over ``--duration`` simulated seconds, alternating,
medians of ``--repeat`` (after a short warm-up run of each camera): the stations of
:data:`STATIONS`, the rendered and the pinhole one as built now (the plant with no
SceneGraph; the rendered camera on a SceneGraph of its own, posed at its frames) and as
before (the plant on a SceneGraph that holds its collision geometry, queried at each
derivative evaluation; the camera on that SceneGraph, whose every perceived geometry
was moved in the renderer at each query); then, at the station's start, what one frame
costs: the colour image (what the station sends), the label image (what the
controller's self-filter draws) and the colour image made into its LCM message.
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
from geovs_drake.systems.arm_model import CAMERA_FRAME
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


def _camera_on_plant_scene(builder, resolved, arm_state):
    """The camera on the plant's own SceneGraph, as the station built it before its
    camera had a scene of its own (the comparison's)."""
    from geovs_drake.hardware import images
    from geovs_drake.loop.sensors import add_scene_renderer

    plant = builder.GetSubsystemByName("plant")
    scene_graph = builder.GetSubsystemByName("scene_graph")
    camera = plant.GetFrameByName(CAMERA_FRAME)
    add_scene_renderer(scene_graph)
    images.perceive_collision_shapes(plant, scene_graph, camera.body().model_instance())
    rgbd = images._rgbd(builder, "rgbd_sensor", resolved, plant, scene_graph, camera.body(),
                        camera.GetFixedPoseInBodyFrame())  # fmt: skip
    return images.CameraScene(scene_graph, plant, rgbd, rgbd.color_image_output_port())


def _plant_with_scene(builder, resolved):
    """The station's plant as it was built before: the loop's arm scene, the plant on a
    SceneGraph holding the arm's collision geometry and the target (its geometry
    queried at each derivative evaluation)."""
    from geovs_drake.loop.carriers import add_arm_scene

    model, plant, _, _, _ = add_arm_scene(builder, resolved, True, True)
    return model, plant


def _station(sensor: str, before: bool = False, own_scene: bool = True):
    """(the station, its Simulator initialized): memq://, unpaced. ``before``: its plant
    on a SceneGraph (as before), and ``own_scene`` False: the camera on that SceneGraph."""
    from geovs_drake.hardware import images, station
    from geovs_drake.hardware.run import _simulator, load_setup, open_lcm

    setup = load_setup(
        None,
        [("bench", f"{{sensor: !{sensor} {{}}}}")],
        {"lcm_url": "memq://", "real_time_rate": 0.0},
    )
    originals = station._station_plant, images.add_camera_scene
    if before:
        station._station_plant = _plant_with_scene
    if not own_scene:
        images.add_camera_scene = _camera_on_plant_scene
    try:
        built = station.build_station(setup.resolved, setup.hardware, open_lcm("memq://"))
    finally:
        station._station_plant, images.add_camera_scene = originals
    simulator = _simulator(built.diagram, setup, built.set_initial_state)
    simulator.Initialize()
    return built, simulator


def _station_rtf(
    sensor: str, duration: float, before: bool = False, own_scene: bool = True
) -> tuple[float, float]:
    """The station's real-time factor over ``duration`` and its process's CPU time per
    simulated second [s] (the renderer's threads included; less disturbed by the load)."""
    _, simulator = _station(sensor, before, own_scene)
    start, cpu = time.perf_counter(), time.process_time()
    simulator.AdvanceTo(duration)
    return duration / (time.perf_counter() - start), (time.process_time() - cpu) / duration


def _frame_costs(repeat: int) -> dict[str, float]:
    """ms per frame at the station's start: colour, label, colour + its LCM message."""
    station, simulator = _station("Rendered")
    root = simulator.get_mutable_context()
    camera = station.camera
    to_lcm = station.diagram.GetSubsystemByName("image_to_lcm")
    camera_context = camera.GetMyContextFromRoot(root)
    lcm_context = to_lcm.GetMyContextFromRoot(root)
    plant_context = station.plant.GetMyMutableContextFromRoot(root)
    q = station.plant.GetPositions(plant_context).copy()
    k = [0]

    def moved() -> None:  # a new configuration: the cached image is out of date
        k[0] += 1
        station.plant.SetPositions(plant_context, q + 1e-9 * (k[0] % 2))

    def colour() -> None:
        moved()
        camera.color_image_output_port().Eval(camera_context)

    def label() -> None:
        moved()
        camera.label_image_output_port().Eval(camera_context)

    def message() -> None:
        colour()
        to_lcm.image_array_t_msg_output_port().EvalAbstract(lcm_context)

    return {name: 1e3 * best(fn, 20, repeat) for name, fn in
            (("colour", colour), ("label", label), ("message", message))}  # fmt: skip


#: The stations compared by ``--station``: (sensor, the plant on a SceneGraph as before,
#: the camera on a SceneGraph of its own).
STATIONS = {
    "rendered": ("Rendered", False, True),
    "rendered, plant on a SceneGraph": ("Rendered", True, True),
    "rendered, camera on the plant's SceneGraph": ("Rendered", True, False),
    "pinhole": ("Pinhole", False, True),
    "pinhole, plant on a SceneGraph": ("Pinhole", True, True),
}


def station_main(args: argparse.Namespace) -> None:
    for sensor in ("Rendered", "Pinhole"):  # warm: EGL's and the renderer's first frames
        _station_rtf(sensor, 0.1)
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in STATIONS}
    for _ in range(args.repeat):
        for name, case in STATIONS.items():
            runs[name].append(_station_rtf(case[0], args.duration, *case[1:]))
    rate = {name: float(np.median([r for r, _ in v])) for name, v in runs.items()}
    cpu = {name: float(np.median([c for _, c in v])) for name, v in runs.items()}
    costs = _frame_costs(args.repeat)
    print(f"station, unpaced, {args.duration:g} s, median of {args.repeat}:")
    for name, value in rate.items():
        print(f"  {name:45s} {value:5.2f}x real time, {cpu[name]:.3f} s CPU a simulated s")
    print(
        f"per frame: colour {costs['colour']:.1f} ms, label {costs['label']:.1f} ms, "
        f"colour + LCM message {costs['message']:.1f} ms"
    )
    name = f"the rendered Panda station, unpaced, arm at rest, {args.duration:g} s"
    before = "rendered, camera on the plant's SceneGraph"
    figures = [
        Figure(name, rate["rendered"], "x real time", "the pinhole station, same run",
               rate["pinhole"], target=">= 1x"),
        Figure(f"{name}, as before: the camera on the plant's SceneGraph", rate[before],
               "x real time", "the station as built now", rate["rendered"]),
        Figure(f"{name}, the camera's own scene, the plant still on a SceneGraph",
               rate["rendered, plant on a SceneGraph"], "x real time", "the station as built now",
               rate["rendered"]),
        Figure(f"the pinhole Panda station, unpaced, arm at rest, {args.duration:g} s, the "
               "plant on a SceneGraph (as before)", rate["pinhole, plant on a SceneGraph"],
               "x real time", "the pinhole station as built now", rate["pinhole"]),
        Figure("the rendered station's CPU time a simulated second", cpu["rendered"], "s",
               "the pinhole station's, same run", cpu["pinhole"]),
        Figure("the rendered station's CPU time a simulated second, as before",
               cpu[before], "s", "the station as built now", cpu["rendered"]),
        Figure("the station's colour frame (320x240)", costs["colour"], "ms",
               "the label image of the same frame", costs["label"]),
        Figure("the colour frame and its LCM message", costs["message"], "ms",
               "the colour frame alone", costs["colour"]),
    ]  # fmt: skip
    record("bench_rendered_station", "The rendered station: real time and frames", figures)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--duration", type=float, default=None)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--station", action="store_true")
    args = parser.parse_args()
    if args.station:
        args.duration = args.duration or 1.0
        station_main(args)
        return
    args.duration = args.duration or 6.0
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
