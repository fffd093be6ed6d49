"""The documentation stays inside the repository and names what exists.

* Every link in README.md and docs/ is a web address or a file of this
  repository that exists: no path outside it (a clone has no ../shared/...).
* docs/paper-notes.md names functions and tests; each must exist.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
NOTES = ROOT / "docs" / "paper-notes.md"

_INLINE = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_REFERENCE = re.compile(r"^\s*\[[^\]]+\]:\s*<?(\S+?)>?(?:\s|$)", re.M)
_HTML = re.compile(r"<(?:a|img)\b[^>]*?\b(?:href|src)=\"([^\"]+)\"", re.I)
_WEB = re.compile(r"^(?:https?|mailto):", re.I)


#: Where the docs build puts each notebook it runs (``docs/notebooks/NAME.ipynb``, ignored by
#: git) and renders as a page: a page's link there names ``notebooks/NAME.ipynb`` of the
#: repository, and is checked against that file, never against the build's output (which
#: exists only once a build has run, and only for the notebooks that ran).
BUILT_NOTEBOOKS = Path("docs", "notebooks")


def link_problems(text: str, where: Path, root: Path = ROOT) -> list[str]:
    """Each link of a markdown text that is not a web address or an existing file of the
    repository at ``root``, with the reason."""
    problems = []
    targets = _INLINE.findall(text) + _REFERENCE.findall(text) + _HTML.findall(text)
    for target in targets:
        if _WEB.match(target) or target.startswith("#"):
            continue
        path = target.split("#")[0]
        if re.match(r"^[a-z][a-z0-9+.-]*:", path, re.I) or path.startswith("/"):
            problems.append(f"{target}: an absolute address outside the repository")
            continue
        resolved = (where.parent / path).resolve()
        if resolved.parent == (root / BUILT_NOTEBOOKS).resolve() and resolved.suffix == ".ipynb":
            resolved = root / "notebooks" / resolved.name
        if not resolved.is_relative_to(root):
            problems.append(f"{target}: outside the repository")
        elif not resolved.exists():
            problems.append(f"{target}: no such file")
    return problems


def test_the_link_check_can_fail():
    text = (
        "[errata](../shared/paper/ERRATA.md) [a](docs/nope.md) ![i](/work/x.png) "
        '[w](https://drake.mit.edu) [n](docs/paper-notes.md#notation) <img src="file:///etc">'
        "\n[ref]: ../../outside.md\n"
    )
    problems = link_problems(text, ROOT / "README.md")
    assert problems == [
        "../shared/paper/ERRATA.md: outside the repository",
        "docs/nope.md: no such file",
        "/work/x.png: an absolute address outside the repository",
        "../../outside.md: outside the repository",
        "file:///etc: an absolute address outside the repository",
    ]


def test_a_docs_link_to_a_notebook_is_checked_against_the_repositorys_notebook(tmp_path):
    """In a checkout whose docs were never built (no docs/notebooks/): a page's link to
    notebooks/NAME.ipynb holds when notebooks/NAME.ipynb exists at the root, and names
    the missing notebook otherwise; a built copy without its source does not count."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "notebooks").mkdir()
    (tmp_path / "notebooks" / "02_study.ipynb").write_text("{}")
    page = tmp_path / "docs" / "page.md"
    text = "[nb](notebooks/02_study.ipynb#section) [gone](notebooks/03_gone.ipynb)"
    assert link_problems(text, page, tmp_path) == ["notebooks/03_gone.ipynb: no such file"]
    (tmp_path / "docs" / "notebooks").mkdir()
    (tmp_path / "docs" / "notebooks" / "03_gone.ipynb").write_text("{}")  # a stale build
    assert link_problems(text, page, tmp_path) == ["notebooks/03_gone.ipynb: no such file"]


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_docs_link_only_existing_files_of_the_repository(doc):
    assert link_problems(doc.read_text(), doc) == []


def test_nothing_points_at_the_papers_folder_outside_the_repository():
    """The paper's folder and its errata file exist only beside this repository's
    working copies, never in a clone: cite the paper by title, link docs/paper-notes.md."""
    files = DOCS + sorted((ROOT / "geovs_drake").rglob("*.py"))
    files += sorted((ROOT / "notebooks").glob("*.ipynb"))
    for path in files:
        text = path.read_text()
        for needle in ("shared/paper", "ERRATA.md", "/work/"):
            assert needle not in text, (str(path.relative_to(ROOT)), needle)


def test_readme_links_the_paper_notes_and_cites_the_paper():
    readme = (ROOT / "README.md").read_text()
    assert "](docs/paper-notes.md)" in readme
    notes = NOTES.read_text()
    assert "N. J. Cowan and D. E. Chang, *Toward Geometric Visual" in notes


def test_paper_notes_name_functions_and_tests_that_exist():
    notes = NOTES.read_text()
    names = sorted(set(re.findall(r"`(geovs_drake(?:\.\w+)+)`", notes)))
    assert len(names) > 30
    for dotted in names:
        parts = dotted.split(".")
        # The longest importable module prefix, then attributes.
        for k in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:k]))
            except ImportError:
                continue
            for attr in parts[k:]:
                assert hasattr(obj, attr), dotted
                obj = getattr(obj, attr)
            break
        else:
            raise AssertionError(f"{dotted}: no such module")
    tests = sorted(set(re.findall(r"`(tests/\w+\.py)::(\w+)`", notes)))
    assert len(tests) > 30
    for file, name in tests:
        source = (ROOT / file).read_text()
        assert re.search(rf"^def {name}\(", source, re.M), f"{file}::{name}"


def test_readme_says_how_to_open_each_notebook_and_they_carry_no_outputs():
    """The README's notebooks section: the command that opens them (JupyterLab comes with
    the notebooks extra), one line per notebook, and the claim that they are committed
    without outputs."""
    import json
    import tomllib

    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Notebooks\n")[1].split("\n## ")[0]
    assert "jupyter lab notebooks/" in section
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    assert any(dep.startswith("jupyterlab") for dep in extras["notebooks"])
    listed = re.findall(r"^\* `(\w+\.ipynb)`: \S", section, re.M)
    notebooks = sorted(p.name for p in (ROOT / "notebooks").glob("*.ipynb"))
    assert listed == notebooks
    assert "committed without outputs" in section
    for name in notebooks:
        cells = json.loads((ROOT / "notebooks" / name).read_text())["cells"]
        for cell in cells:
            if cell["cell_type"] == "code":
                assert cell["outputs"] == [] and cell["execution_count"] is None, name


def test_docs_list_each_property_test_with_its_examples():
    """The testing page's table of hypothesis tests: every test of tests/test_properties.py, with
    the max_examples its settings give."""
    import ast

    source = (ROOT / "tests" / "test_properties.py").read_text()
    tree = ast.parse(source)
    default = None
    for node in tree.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "SETTINGS":
            default = next(k.value.value for k in node.value.keywords if k.arg == "max_examples")
    examples = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name.startswith("test_"):
            count = None
            for deco in node.decorator_list:
                if isinstance(deco, ast.Name) and deco.id == "SETTINGS":
                    count = default
                elif isinstance(deco, ast.Call) and getattr(deco.func, "id", "") == "settings":
                    count = next(k.value.value for k in deco.keywords if k.arg == "max_examples")
            examples[node.name] = count
    readme = (ROOT / "docs" / "testing.md").read_text()
    table = dict(re.findall(r"^\|[^|]*\| `(test_\w+)` \| (\d+) \|$", readme, re.M))
    assert {k: int(v) for k, v in table.items()} == examples


def test_the_performance_page_defines_every_baseline_its_records_use():
    """Each baseline named in benchmarks/results/*.json has its row in the performance
    page's table of baselines (what is timed: the integrator's accuracy, the loggers)."""
    import json

    page = (ROOT / "docs" / "performance.md").read_text()
    section = page.split("## The baselines\n")[1].split("\n## ")[0]
    defined = set(re.findall(r"^\| (.+?) \| .+ \|$", section, re.M)) - {"baseline", "---"}
    used = set()
    for record in (ROOT / "benchmarks" / "results").glob("*.json"):
        used |= {f["baseline"] for f in json.loads(record.read_text())["figures"]}
    assert used, "no benchmark records"
    assert used - defined == set(), "baselines the performance page does not define"
