"""Scene geometry and Meshcat recordings.

Everything visual that moves is SceneGraph geometry (so Meshcat records it
with the run): the target sphere with its marked point and arrow, the camera
body with its field-of-view cone, and a translucent ghost of the goal camera
pose. The camera frame's axes come from ``AddFrameTriadIllustration``; the
camera's trail is a Meshcat line drawn from the run's log.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np
from pydrake.geometry import Box, Cylinder, GeometryId, Mesh, Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RigidBody

from geovs_drake.geometry.features import TargetMarks
from geovs_drake.scenario import ScenarioConfig
from geovs_drake.systems.feature_extractor import SCENE_COLOURS

__all__ = [
    "add_camera_geometry",
    "add_goal_ghost",
    "add_marked_target_geometry",
    "add_target_geometry",
    "draw_trail",
    "fov_cone_obj",
    "sphere_obj",
]

FOV_CONE_LENGTH = 0.25  # [m] how far the drawn cone reaches


def fov_cone_obj(
    fov_half_angle: float, length: float = FOV_CONE_LENGTH, segments: int = 48
) -> Path:
    """An OBJ of the FOV cone in the camera frame: apex at Co, axis +z, half-angle theta.

    Written once per (angle, length) to the temp folder, since SceneGraph's Mesh
    takes a file.
    """
    path = Path(tempfile.gettempdir()) / (
        f"geovs_drake_fov_cone_{fov_half_angle:.6f}_{length:.4f}_{segments}.obj"
    )
    if path.exists():
        return path
    r = length * math.tan(fov_half_angle)
    lines = ["v 0 0 0"]
    for k in range(segments):
        a = 2 * math.pi * k / segments
        lines.append(f"v {r * math.cos(a):.6f} {r * math.sin(a):.6f} {length:.6f}")
    lines.append(f"v 0 0 {length:.6f}")
    centre = segments + 2
    for k in range(segments):
        i, j = 2 + k, 2 + (k + 1) % segments
        lines.append(f"f 1 {j} {i}")  # the side, seen from outside
        lines.append(f"f {centre} {i} {j}")  # the base
    path.write_text("\n".join(lines) + "\n")
    return path


def sphere_obj(segments: int = 128) -> Path:
    """An OBJ of the unit sphere, ``segments`` around and ``segments / 2`` from pole to pole,
    with vertex normals (smooth shading); written once per resolution to the temp folder.

    Why not SceneGraph's ``Sphere``: RenderEngineVtk draws it as a coarse polyhedron whose
    silhouette lies about 0.13% inside the true circle (measured: lambda read 0.13%
    low). At 128 segments the polygon's mean shortfall, about (2/3)(1 - cos(pi/128)),
    is 2e-4 of the radius, and a 320x240 frame costs about 1.5 ms more to render
    than with ``Sphere`` (192 segments: 1e-4, but twice that cost).
    """
    rings = segments // 2
    path = Path(tempfile.gettempdir()) / f"geovs_drake_sphere_{segments}.obj"
    if path.exists():
        return path
    lines = []
    for i in range(rings + 1):
        theta = math.pi * i / rings
        for j in range(segments):
            phi = 2 * math.pi * j / segments
            x = math.sin(theta) * math.cos(phi)
            y = math.sin(theta) * math.sin(phi)
            z = math.cos(theta)
            lines.append(f"v {x:.9f} {y:.9f} {z:.9f}")
            lines.append(f"vn {x:.9f} {y:.9f} {z:.9f}")
    for i in range(rings):
        for j in range(segments):
            a = 1 + i * segments + j
            b = 1 + i * segments + (j + 1) % segments
            c, d = a + segments, b + segments
            # Counter-clockwise seen from outside; the degenerate ones at the poles are skipped.
            if i > 0:
                lines.append(f"f {a}//{a} {c}//{c} {b}//{b}")
            if i < rings - 1:
                lines.append(f"f {b}//{b} {c}//{c} {d}//{d}")
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)  # atomic: parallel workers never read half a file
    return path


def add_target_geometry(
    plant: MultibodyPlant,
    config: ScenarioConfig,
    body: RigidBody | None = None,
    X_WB: RigidTransform | None = None,
    alpha: float = 1.0,
    prefix: str = "",
) -> list[GeometryId]:
    """The target sphere, its marked point b and its arrow a; returns their ids.

    Fixed in the world at ``X_WB`` (default ``config.X_WB``), or, with ``body``,
    on that body with B its body frame (the fixed-camera loop's moving
    target). ``alpha`` < 1 and a ``prefix`` draw a ghost (the target's goal).
    """
    rho = config.radius
    frame_body = plant.world_body() if body is None else body
    X = RigidTransform() if body is not None else (config.X_WB if X_WB is None else X_WB)
    X_Bb = RigidTransform([0.0, 0.0, -rho])
    length = 0.6 * rho
    # A cylinder's axis is its z; Rx(-pi/2) turns it onto the arrow a_B = e2.
    X_Ba = RigidTransform(RollPitchYaw(-np.pi / 2, 0, 0), [0.0, 0.5 * length, -1.02 * rho])
    return [
        plant.RegisterVisualGeometry(frame_body, X_BG, shape, prefix + name, rgba)
        for X_BG, shape, name, rgba in (
            (X, Sphere(rho), "target_sphere", [0.85, 0.85, 0.9, 0.9 * alpha]),
            (X @ X_Bb, Sphere(0.12 * rho), "marked_point", [0.9, 0.1, 0.1, alpha]),
            (X @ X_Ba, Cylinder(0.05 * rho, length), "arrow", [0.1, 0.6, 0.1, alpha]),
        )
    ]


#: The marks' discs: thickness and lift of their underside off the tangent plane,
#: fractions of rho. Thin, so that a disc near the limb does not change the
#: silhouette (its rim stands about (radius^2 / 2) rho above the sphere: 0.005 rho
#: for the default marks); low, because the extractor takes the disc's centroid for
#: the mark's point and a top face h above it shifts by h sin(view angle) (0.003 rho
#: put q1 0.12 px off at 640x480); lifted at all so that the depth test never mixes the
#: disc with the sphere's mesh (which lies up to 1.3e-4 rho inside the true sphere).
MARK_THICKNESS = 0.0006
MARK_LIFT = 0.0004


def add_marked_target_geometry(
    plant: MultibodyPlant,
    config: ScenarioConfig,
    marks: TargetMarks | None = None,
    body: RigidBody | None = None,
) -> list[GeometryId]:
    """The target as the rendered camera sees it, fixed in the world at X_WB (or on
    ``body``, whose frame is B: the fixed camera's target that the rig moves): a grey
    sphere, a red disc on the marked point b and a green disc on the arrow mark
    (:class:`TargetMarks`), in the colours the
    :class:`~geovs_drake.systems.FeatureExtractor` looks for
    (:data:`~geovs_drake.systems.feature_extractor.SCENE_COLOURS`).

    Each disc is a thin cylinder tangent to the sphere at its mark, its axis along
    the sphere's normal there. Registered with illustration and perception
    roles, so Meshcat shows what the camera renders.
    """
    marks = marks or TargetMarks()
    world = plant.world_body() if body is None else body
    rho = config.radius
    X_WB = config.X_WB if body is None else RigidTransform()
    rgba = {k: list(v) + [1.0] for k, v in SCENE_COLOURS.items()}
    ids = [
        plant.RegisterVisualGeometry(
            world, X_WB, Mesh(str(sphere_obj()), rho), "target_sphere", rgba["sphere"]
        )
    ]
    b_B, m_B = marks.points_B(rho)
    offset = (MARK_LIFT + 0.5 * MARK_THICKNESS) * rho
    for name, centre, radius, angle in (
        ("marked_point", b_B, marks.mark_radius, 0.0),
        ("arrow_mark", m_B, marks.arrow_mark_radius, marks.arrow_angle),
    ):
        # Rx(angle) turns the cylinder's axis e3 onto -(the mark's outward normal).
        normal = centre / rho
        X_BM = RigidTransform(RotationMatrix.MakeXRotation(angle), centre + offset * normal)
        ids.append(
            plant.RegisterVisualGeometry(
                world,
                X_WB @ X_BM,
                Cylinder(radius * rho, MARK_THICKNESS * rho),
                name,
                rgba[name],
            )
        )
    return ids


def _camera_shapes(fov_half_angle: float) -> list[tuple[str, object, RigidTransform]]:
    return [
        ("box", Box(0.06, 0.04, 0.04), RigidTransform([0.0, 0.0, -0.02])),
        ("lens", Cylinder(0.012, 0.02), RigidTransform([0.0, 0.0, 0.005])),
        ("fov_cone", Mesh(str(fov_cone_obj(fov_half_angle))), RigidTransform()),
    ]


def add_camera_geometry(
    plant: MultibodyPlant, body: RigidBody, X_RC: RigidTransform, fov_half_angle: float
) -> list[GeometryId]:
    """The camera body and its FOV cone, on the rig at X_RC; returns their geometry ids."""
    colors = {
        "box": [0.2, 0.2, 0.25, 1.0],
        "lens": [0.1, 0.1, 0.1, 1.0],
        "fov_cone": [1, 0.8, 0.1, 0.18],
    }
    return [
        plant.RegisterVisualGeometry(body, X_RC @ X_CS, shape, f"camera_{name}", colors[name])
        for name, shape, X_CS in _camera_shapes(fov_half_angle)
    ]


def add_goal_ghost(
    plant: MultibodyPlant, config: ScenarioConfig, body: RigidBody | None = None
) -> list[GeometryId]:
    """A translucent camera at the goal pose X_WC* = X_WB X_BC*, or with ``body`` (a
    moving target's, B its frame) at X_BC* on it; returns its geometry ids."""
    X_WC = config.X_BC_goal if body is not None else config.X_WB @ config.X_BC_goal
    theta = math.radians(config.domain.fov_half_angle_deg)
    return [
        plant.RegisterVisualGeometry(
            plant.world_body() if body is None else body,
            X_WC @ X_CS,
            shape,
            f"goal_{name}",
            [0.2, 0.5, 1.0, 0.08 if name == "fov_cone" else 0.3],
        )
        for name, shape, X_CS in _camera_shapes(theta)
    ]


def draw_trail(meshcat: Meshcat, X_WC: np.ndarray, path: str = "/trail", beads: int = 60) -> None:
    """The camera's trail through the logged camera origins (N, 4, 4): a polyline and
    ``beads`` small spheres along it.

    Why the spheres: browsers draw WebGL lines 1 px wide whatever ``line_width``
    says, which is hard to see; spheres keep their size.
    """
    points = X_WC[:, :3, 3]
    colour = Rgba(0.9, 0.4, 0.1, 1.0)
    meshcat.SetLine(f"{path}/line", points.T.copy(), line_width=3.0, rgba=colour)
    for k, i in enumerate(np.unique(np.linspace(0, len(points) - 1, beads).astype(int))):
        meshcat.SetObject(f"{path}/bead_{k}", Sphere(0.006), colour)
        meshcat.SetTransform(f"{path}/bead_{k}", RigidTransform(points[i]))
