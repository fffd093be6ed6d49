"""Scene geometry and Meshcat recordings.

Everything visual that moves is SceneGraph geometry (so Meshcat records it
with the run): the target sphere with its marked point and arrow, the camera
body with its field-of-view cone, and a translucent ghost of the goal camera
pose. The camera frame's axes come from ``AddFrameTriadIllustration``; the
camera's trail is a Meshcat line drawn from the run's log.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
from pydrake.geometry import Box, Cylinder, Mesh, Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RigidBody

from geovs_drake.scenario import ScenarioConfig

__all__ = [
    "add_camera_geometry",
    "add_goal_ghost",
    "add_target_geometry",
    "draw_trail",
    "fov_cone_obj",
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


def add_target_geometry(
    plant: MultibodyPlant,
    config: ScenarioConfig,
    body: RigidBody | None = None,
    X_WB: RigidTransform | None = None,
    alpha: float = 1.0,
    prefix: str = "",
) -> None:
    """The target sphere, its marked point b and its arrow a.

    Fixed in the world at ``X_WB`` (default ``config.X_WB``), or, with ``body``,
    on that body with B its body frame (the fixed-camera loop's moving
    target). ``alpha`` < 1 and a ``prefix`` draw a ghost (the target's goal).
    """
    rho = config.radius
    frame_body = plant.world_body() if body is None else body
    X = RigidTransform() if body is not None else (config.X_WB if X_WB is None else X_WB)
    plant.RegisterVisualGeometry(
        frame_body, X, Sphere(rho), f"{prefix}target_sphere", [0.85, 0.85, 0.9, 0.9 * alpha]
    )
    X_Bb = RigidTransform([0.0, 0.0, -rho])
    plant.RegisterVisualGeometry(
        frame_body, X @ X_Bb, Sphere(0.12 * rho), f"{prefix}marked_point", [0.9, 0.1, 0.1, alpha]
    )
    length = 0.6 * rho
    # A cylinder's axis is its z; Rx(-pi/2) turns it onto the arrow a_B = e2.
    X_Ba = RigidTransform(RollPitchYaw(-np.pi / 2, 0, 0), [0.0, 0.5 * length, -1.02 * rho])
    plant.RegisterVisualGeometry(
        frame_body, X @ X_Ba, Cylinder(0.05 * rho, length), f"{prefix}arrow", [0.1, 0.6, 0.1, alpha]
    )


def _camera_shapes(fov_half_angle: float) -> list[tuple[str, object, RigidTransform]]:
    return [
        ("box", Box(0.06, 0.04, 0.04), RigidTransform([0.0, 0.0, -0.02])),
        ("lens", Cylinder(0.012, 0.02), RigidTransform([0.0, 0.0, 0.005])),
        ("fov_cone", Mesh(str(fov_cone_obj(fov_half_angle))), RigidTransform()),
    ]


def add_camera_geometry(
    plant: MultibodyPlant, body: RigidBody, X_RC: RigidTransform, fov_half_angle: float
) -> None:
    """The camera body and its FOV cone, on the rig at X_RC."""
    colors = {
        "box": [0.2, 0.2, 0.25, 1.0],
        "lens": [0.1, 0.1, 0.1, 1.0],
        "fov_cone": [1, 0.8, 0.1, 0.18],
    }
    for name, shape, X_CS in _camera_shapes(fov_half_angle):
        plant.RegisterVisualGeometry(body, X_RC @ X_CS, shape, f"camera_{name}", colors[name])


def add_goal_ghost(plant: MultibodyPlant, config: ScenarioConfig) -> None:
    """A translucent camera at the goal pose X_WC* = X_WB X_BC*."""
    X_WC = config.X_WB @ config.X_BC_goal
    theta = math.radians(config.domain.fov_half_angle_deg)
    for name, shape, X_CS in _camera_shapes(theta):
        alpha = 0.08 if name == "fov_cone" else 0.3
        plant.RegisterVisualGeometry(
            plant.world_body(), X_WC @ X_CS, shape, f"goal_{name}", [0.2, 0.5, 1.0, alpha]
        )


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
