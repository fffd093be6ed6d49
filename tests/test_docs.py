"""The API reference's port diagrams say what the systems declare (Drake's port
names are the truth), and the docs extension rejects a malformed block."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from geovs_drake import systems
from geovs_drake.scenario import Pinhole, ScenarioConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "docs" / "_ext"))
pydrake_system = pytest.importorskip("pydrake_system")  # needs sphinx (the docs extra)

BLOCK = re.compile(r"\.\. pydrake_system::\n\n((?:[ \t]+\S.*\n)+)")


def _required_values() -> dict:
    """Values for the constructor arguments some systems require, by name."""
    config = ScenarioConfig()
    return {
        "goal": config.goal_features(),
        "radius": config.radius,
        "intrinsics": Pinhole().intrinsics(config.domain.to_domain().fov_half_angle),
        "width": 32,
        "height": 24,
        "labels": [1],
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
    # arm_model builds the arm's MultibodyPlant for the systems that carry one, arm_tree
    # reads that plant's tree for the compiled kinematics: public helpers of the layer,
    # not systems.
    helpers = {"arm_model", "arm_tree"}
    assert {m for m in modules if not m.startswith("_")} - helpers == exported


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


# ------------------------------------------------- the notebooks, as the docs show them
ROOT = Path(__file__).resolve().parents[1]
HTML = ROOT / "docs" / "_build" / "html"
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


@pytest.mark.built_docs
@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.name)
def test_each_notebook_has_a_page_that_shows_its_figures(notebook):
    """`make docs` (run by `make test` before pytest) executes the notebooks and renders
    them: each gets a page with at least one image of its own outputs, built from the
    notebook as it is now."""
    if not (HTML / "index.html").is_file():
        pytest.skip("the docs are not built here: `make docs` builds them (make test does)")
    page = HTML / "notebooks" / f"{notebook.stem}.html"
    assert page.is_file(), f"{page.relative_to(ROOT)}: no page for {notebook.name}"
    assert page.stat().st_mtime >= notebook.stat().st_mtime, "the page predates the notebook"
    images = re.findall(r'<img [^>]*src="\.\./(_images/[^"]+\.(?:png|svg))"', page.read_text())
    assert images, f"{page.name}: no figure"
    for image in images:
        assert (HTML / image).stat().st_size > 1000, image  # a real picture, not a stub


@pytest.mark.built_docs
def test_each_meshcat_recording_the_gallery_embeds_is_beside_it():
    """The gallery's iframes (notebook 01's servo, notebook 06's tracking arm, notebook
    07's quadrotor) point at standalone Meshcat pages this build copied into _static."""
    if not (HTML / "gallery.html").is_file():
        pytest.skip("the docs are not built here: `make docs` builds them (make test does)")
    frames = re.findall(r'<iframe src="(_static/[^"]+\.html)"', (HTML / "gallery.html").read_text())
    assert {"_static/servo.html", "_static/tracking.html", "_static/quadrotor.html"} <= set(frames)
    for frame in frames:
        html = (HTML / frame).read_text()
        assert "<html" in html.lower() and len(html) > 100_000, frame  # the scene embedded


RECORDS = sorted((ROOT / "benchmarks" / "results").glob("*.json"))


@pytest.mark.built_docs
@pytest.mark.parametrize("record", RECORDS, ids=lambda p: p.name)
def test_each_benchmark_record_holds_its_baselines_and_is_on_the_performance_page(record):
    """benchmarks/_record.py's files: every figure beside a baseline from the same run, and
    the provenance the performance page prints; the built page shows each record."""
    import json

    data = json.loads(record.read_text())
    assert data["benchmark"] == record.stem
    assert {"date", "commit", "command", "machine", "title"} <= set(data)
    assert data["figures"]
    for f in data["figures"]:
        assert f["baseline"] and f["baseline_value"] > 0, f["name"]
        assert f["ratio"] == pytest.approx(f["value"] / f["baseline_value"]), f["name"]
    # The built page's smart quotes turn ' and -- into other characters: the title would
    # not be found there.
    assert "'" not in data["title"] and "--" not in data["title"], data["title"]
    if not (HTML / "performance.html").is_file():
        pytest.skip("the docs are not built here: `make docs` builds them (make test does)")
    assert data["title"] in (HTML / "performance.html").read_text()


@pytest.mark.slow  # 7 s (a Sphinx build of its own): make test's budget
def test_a_failing_notebook_is_reported_with_its_cell_and_line(tmp_path):
    """The docs build's one line for a notebook whose cell raises: the cell's place, the
    failing line of that cell (not of a function an earlier cell defined) and the error.
    The notebook runs in a real kernel, as in the build."""
    from concurrent.futures import ProcessPoolExecutor

    import nbformat
    from notebook_pages import _execute

    notebook = nbformat.v4.new_notebook()
    notebook.cells = [
        nbformat.v4.new_markdown_cell("# a title"),
        nbformat.v4.new_code_cell("def check(x):\n    assert x > 1, f'x = {x}'"),
        nbformat.v4.new_code_cell("y = 1\n\ncheck(y)\nprint('never')"),
    ]
    source = tmp_path / "broken.ipynb"
    nbformat.write(notebook, source)
    # In a process of its own, as the build runs it (_execute silences that process's stderr).
    with ProcessPoolExecutor(1) as pool:
        _, _, error = pool.submit(_execute, str(source), str(tmp_path / "out.ipynb")).result()
    assert error == "cell 3 (code cell 2), line 3: check(y): AssertionError: x = 1"
    assert not (tmp_path / "out.ipynb").exists()  # no half-run copy for the pages
