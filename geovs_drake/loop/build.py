"""``build_loop(config)``: the loop a scenario describes, resolved once at this edge of the
Python API (:func:`~geovs_drake.loop.resolver`) and assembled from the registries
(:func:`~geovs_drake.loop.assembly.assemble_loop`, where the parts and their names are
listed)."""

from __future__ import annotations

from pydrake.geometry import Meshcat

from geovs_drake.loop.assembly import Loop, assemble_loop
from geovs_drake.loop.resolved import ResolvedScenario
from geovs_drake.loop.resolver import resolve
from geovs_drake.scenario import ScenarioConfig

__all__ = ["build_loop"]


def build_loop(
    config: ScenarioConfig | ResolvedScenario | None = None,
    meshcat: Meshcat | None = None,
    log: bool = True,
    study_ports: bool = False,
) -> Loop:
    """The loop ``config`` describes (default: the default scenario), resolved once
    (:func:`~geovs_drake.loop.resolver`: a :class:`ResolvedScenario` is taken as it is).

    ``meshcat`` adds a MeshcatVisualizer and the camera frame's axes (a carrier
    with geometry only; double only: leave it out of diagrams you will convert to
    AutoDiffXd). ``study_ports`` exports the disturbance and noise inputs and the
    y and pose outputs (:mod:`~geovs_drake.loop.assembly`). Raises ValueError in one line
    for parts that make no loop.
    """
    return assemble_loop(resolve(config), meshcat=meshcat, log=log, study_ports=study_ports)
