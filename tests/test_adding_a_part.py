"""The sensor and carrier examples of docs/adding-a-part.rst, run as the page writes them
(the law's example is held in test_loop.py): each registers a variant of its own against
the scenario's unions and closes a loop with it."""

from pathlib import Path

import numpy as np
import pytest

from geovs_drake.loop.carriers import CARRIERS
from geovs_drake.loop.sensors import SENSORS

PAGE = Path(__file__).resolve().parents[1] / "docs" / "adding-a-part.rst"


def _run_example(title: str) -> dict:
    """The first python block after ``title`` on the page, run; its namespace."""
    example = PAGE.read_text().split(title)[1].split(".. code-block:: python")[1]
    code = "\n".join(
        line[4:] for line in example.splitlines() if line.startswith("    ") or not line.strip()
    )
    namespace: dict = {}
    exec(compile(code, PAGE.name, "exec"), namespace)
    return namespace


@pytest.fixture
def registries():
    """SENSORS and CARRIERS as they were, after the test."""
    sensors, carriers = dict(SENSORS), dict(CARRIERS)
    yield
    SENSORS.clear()
    SENSORS.update(sensors)
    CARRIERS.clear()
    CARRIERS.update(carriers)


def test_the_sensor_example_holds_y_for_a_frame_and_converges(registries):
    from geovs_drake.loop import build_loop, exact_twin
    from geovs_drake.simulation import simulate

    ns = _run_example("Example: a sensor of one's own")
    result, config = ns["result"], ns["config"]
    assert result.summary()["sensor"] == "HeldExact" and result.status == "converged"
    # Drake's own reading of the diagram: one periodic discrete update, every 1 / rate s.
    diagram = build_loop(config, log=False).diagram
    attribute = diagram.GetUniquePeriodicDiscreteUpdateAttribute()
    assert attribute is not None
    assert attribute.period_sec() == pytest.approx(1.0 / config.sensor.rate, rel=1e-12)
    assert diagram.HasSubsystemNamed("sample_and_hold")
    # The hold is in the loop: the exact sensor's run from the same start takes another
    # path (both end at the goal).
    exact = simulate(exact_twin(config))
    t = np.linspace(0.0, 2.0, 41)
    paths = [
        np.stack([np.interp(t, run.times, run.X_BC[:, k, 3]) for k in range(3)], axis=-1)
        for run in (result, exact)
    ]
    assert exact.status == "converged"
    assert np.max(np.abs(paths[0] - paths[1])) > 1e-4


def test_the_carrier_example_turns_the_camera_in_place_to_the_goal(registries):
    ns = _run_example("Example: a carrier of one's own")
    result, config = ns["result"], ns["config"]
    assert result.summary()["carrier"] == "PanTiltHead" and result.status == "converged"
    # The geometry: the camera's origin never moves (the translational twist is dropped),
    # and it ends turned to the goal's rotation.
    X_BC = result.X_BC
    np.testing.assert_allclose(
        X_BC[:, :3, 3],
        np.broadcast_to(config.X_BC_initial.translation(), (len(X_BC), 3)),
        atol=1e-12,
    )
    R_end = X_BC[-1, :3, :3]
    R_goal = config.X_BC_goal.rotation().matrix()
    angle = np.arccos(np.clip((np.trace(R_goal.T @ R_end) - 1) / 2, -1.0, 1.0))
    assert angle < 1e-3
    start_angle = np.arccos(
        np.clip((np.trace(R_goal.T @ config.X_BC_initial.rotation().matrix()) - 1) / 2, -1, 1)
    )
    assert start_angle > 0.5  # it had somewhere to turn from
