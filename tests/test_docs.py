"""The API reference's port diagrams say what the systems declare (Drake's port
names are the truth), and the docs extension rejects a malformed block."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from geovs_drake import systems
from geovs_drake.scenario import ScenarioConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "docs" / "_ext"))
pydrake_system = pytest.importorskip("pydrake_system")  # needs sphinx (the docs extra)

BLOCK = re.compile(r"\.\. pydrake_system::\n\n((?:[ \t]+\S.*\n)+)")


def _required_values() -> dict:
    """Values for the constructor arguments some systems require, by name."""
    config = ScenarioConfig()
    return {
        "goal": config.goal_features(),
        "radius": config.radius,
        "intrinsics": config.camera.intrinsics(config.domain.to_domain().fov_half_angle),
    }


def _instance(cls):
    """A system with its defaults, and the scenario's values where an argument is required."""
    import inspect

    required = [
        name
        for name, p in inspect.signature(cls._construct).parameters.items()
        if name != "self" and p.default is inspect.Parameter.empty
    ]
    values = _required_values()
    return cls(**{name: values[name] for name in required})


def _instances():
    """Every public system of geovs_drake.systems, built with its defaults."""
    names = sorted(n for n in systems.__all__ if not n.endswith("_"))
    return {n: _instance(getattr(systems, n)) for n in names}


@pytest.mark.parametrize("name", list(_instances()))
def test_port_block_lists_the_declared_ports_in_order(name):
    system = _instances()[name]
    doc = type(system).__doc__
    blocks = BLOCK.findall(doc)
    assert len(blocks) == 1, f"{name}: expected one '.. pydrake_system::' block"
    title, inputs, outputs = pydrake_system.parse_block(blocks[0])
    assert title == name
    declared_in = [system.get_input_port(i).get_name() for i in range(system.num_input_ports())]
    declared_out = [system.get_output_port(i).get_name() for i in range(system.num_output_ports())]
    assert inputs == declared_in
    assert outputs == declared_out


def test_every_system_in_the_package_is_checked():
    """Every LeafSystem module of the package is exported, so the block test sees it."""
    modules = {p.stem for p in Path(systems.__file__).parent.glob("*.py")} - {"__init__"}
    exported = {type(s).__module__.rsplit(".", 1)[1] for s in _instances().values()}
    assert {m for m in modules if not m.startswith("_")} == exported


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("name: X\ninputs:\n- a\n", "unknown keys ['inputs']"),
        ("input_ports:\n- a\n", "'name' must be"),
        ("name: X\noutput_ports: y\n", "'output_ports' must be a list"),
        ("- a\n- b\n", "expected a mapping"),
        ("name: [X\n", "malformed YAML"),
    ],
)
def test_malformed_block_is_one_clear_error(text, needle):
    with pytest.raises(ValueError, match=re.escape(needle)):
        pydrake_system.parse_block(text)
