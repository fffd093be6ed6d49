"""The loops by their earlier names: thin names over :func:`geovs_drake.loop.build_loop`.

Each builder returns the Diagram of ``build_loop`` for ``config`` with the part
its name fixes (``make_kinematic_servo_diagram``: the kinematic plant, and so on);
:func:`make_servo_diagram` is ``build_loop(config).diagram``. Subsystem and
logger names: :mod:`geovs_drake.loop.build`.
"""

from __future__ import annotations

import dataclasses

from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram

from geovs_drake.loop.build import build_loop
from geovs_drake.loop.carriers import RIG_BODY_NAME, TARGET_BODY_NAME
from geovs_drake.loop.sensors import (
    RENDERER_NAME,
    VTK_PRINCIPAL_POINT_SHIFT,
    scene_lights,
    vtk_camera_info,
)
from geovs_drake.loop.state import (
    fixed_camera_pose,
    initial_body_states,
    initial_rig_pose,
    initial_rig_state,
)
from geovs_drake.scenario import ScenarioConfig

__all__ = [
    "RENDERER_NAME",
    "RIG_BODY_NAME",
    "TARGET_BODY_NAME",
    "VTK_PRINCIPAL_POINT_SHIFT",
    "fixed_camera_pose",
    "initial_body_states",
    "initial_rig_pose",
    "initial_rig_state",
    "make_dynamic_servo_diagram",
    "make_fixed_camera_diagram",
    "make_kinematic_servo_diagram",
    "make_pinhole_servo_diagram",
    "make_rendered_servo_diagram",
    "make_servo_diagram",
    "scene_lights",
    "vtk_camera_info",
]


def _exact(config: ScenarioConfig) -> ScenarioConfig:
    """``config`` with the exact sensor: the camera model's own errors dropped (they
    need a camera), its ``radius_error`` (what the controller believes) kept."""
    camera = dataclasses.replace(
        config.camera, sensor="exact", pixel_noise=0.0, focal_error=0.0, latency_frames=0
    )
    return dataclasses.replace(config, camera=camera)


def make_dynamic_servo_diagram(
    config: ScenarioConfig | None = None, meshcat: Meshcat | None = None, log: bool = True
) -> Diagram:
    """The dynamic loop of Appendix C around a continuous MultibodyPlant free body,
    eye-in-hand, with the exact y = c(H), whatever ``config.camera.sensor`` says.

    Gravity is off: the paper assumes it is cancelled by the controller. The
    camera frame may sit off the rig's centre of mass (``rig.camera_offset``,
    Appendix C.0.6). Pass ``meshcat`` to add a MeshcatVisualizer and the camera
    frame's axes (double only).
    """
    config = _exact(config or ScenarioConfig())
    config = dataclasses.replace(config, plant="dynamic", mount="hand")
    return build_loop(config, meshcat=meshcat, log=log).diagram


def make_kinematic_servo_diagram(config: ScenarioConfig | None = None, log: bool = True) -> Diagram:
    """The kinematic loop of Eqs. (17)-(19): camera map, the law, integrated on SE(3).

    The kinematic body *is* the camera frame (X_RC = identity). With a law other
    than the NF (``config.controller``), that law's commanded twist drives the body.
    """
    config = dataclasses.replace(
        _exact(config or ScenarioConfig()),
        plant="kinematic",
        mount="hand",
        initial_velocity=[0.0] * 6,
    )
    return build_loop(config, log=log).diagram


def make_fixed_camera_diagram(
    config: ScenarioConfig | None = None, meshcat: Meshcat | None = None, log: bool = True
) -> Diagram:
    """The fixed-camera (eye-to-hand) loop: the camera still, the target sphere driven.

    Eq. (16), ``G = H^-1``, says the two configurations are one problem: the
    laws see only the relative pose. The camera is fixed in W at
    :func:`fixed_camera_pose`; the target is the driven body, with the rig's
    mass model: a MultibodyPlant free body pushed by a wrench (``config.plant ==
    "dynamic"``) or a kinematic body whose body twist is commanded
    (``"kinematic"``), through ``fixed_camera_mount``. The initial relative pose
    is ``config.initial`` (X_BC(0)), the goal ``config.goal``, as for the
    eye-in-hand loops, so both see the same image. Pass ``meshcat`` (dynamic
    only) to watch the sphere move in front of the still camera.
    """
    config = dataclasses.replace(config or ScenarioConfig(), mount="fixed")
    return build_loop(config, meshcat=meshcat, log=log).diagram


def make_rendered_servo_diagram(
    config: ScenarioConfig | None = None,
    camera_rate: float | None = None,
    resolution: tuple[int, int] | None = None,
    meshcat: Meshcat | None = None,
    log: bool = True,
) -> Diagram:
    """The dynamic loop closed through rendered images (``camera.sensor: rendered``):
    plant -> SceneGraph -> ``RgbdSensor`` (VTK, EGL) -> ``FeatureExtractor`` (a frame
    every ``1 / camera_rate`` s, held) -> law -> plant. ``camera_rate`` [Hz] and
    ``resolution`` (W, H) default to ``config.camera``'s (30 Hz, 320x240).
    Double only (``RgbdSensor`` does not convert)."""
    config = config or ScenarioConfig()
    camera = dataclasses.replace(config.camera, sensor="rendered")
    if camera_rate is not None:
        camera.rate = camera_rate
    if resolution is not None:
        camera.resolution = [int(v) for v in resolution]
    config = dataclasses.replace(config, camera=camera)
    return build_loop(config, meshcat=meshcat, log=log).diagram


def make_pinhole_servo_diagram(
    config: ScenarioConfig | None = None, meshcat: Meshcat | None = None, log: bool = True
) -> Diagram:
    """The dynamic loop closed through :class:`~geovs_drake.systems.PinholeFeatureSensor`:
    the rendered loop's measurement (camera rate, latency, pixel noise, focal error, the
    same fit) on exact projected points, without a renderer."""
    config = config or ScenarioConfig()
    config = dataclasses.replace(
        config, camera=dataclasses.replace(config.camera, sensor="pinhole")
    )
    return build_loop(config, meshcat=meshcat, log=log).diagram


def make_servo_diagram(
    config: ScenarioConfig | None = None, meshcat: Meshcat | None = None, log: bool = True
) -> Diagram:
    """The loop ``config`` describes: :func:`geovs_drake.loop.build_loop`'s Diagram."""
    return build_loop(config, meshcat=meshcat, log=log).diagram
