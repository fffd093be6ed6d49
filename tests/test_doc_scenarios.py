"""Every scenario the docs and the README write loads and validates as written: each
``--scenario-text "..."`` and each fenced YAML block (issue 30: the YAML examples keep
working after the typed variants; the shipped default scenario is held in
test_distribution.py)."""

import re
from pathlib import Path

import pytest

from geovs_drake.scenario import ScenarioConfig, load_scenario

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([*(ROOT / "docs").glob("*.md"), *(ROOT / "docs").glob("*.rst"), ROOT / "README.md"])
SCENARIO_TEXT = re.compile(r'--scenario-text\s+"((?:[^"\\]|\\.)*)"', re.S)
YAML_BLOCK = re.compile(r"```yaml\n(.*?)```", re.S)


def _examples() -> list[tuple[str, str]]:
    out = []
    for page in PAGES:
        text = page.read_text()
        for k, m in enumerate([*SCENARIO_TEXT.finditer(text), *YAML_BLOCK.finditer(text)]):
            out.append((f"{page.name}[{k}]", " ".join(m.group(1).split("\n"))))
    return out


EXAMPLES = _examples()


def test_the_docs_have_scenario_examples():
    assert len(EXAMPLES) >= 4, EXAMPLES  # the pages that show --scenario-text


@pytest.mark.parametrize("where, text", EXAMPLES, ids=[w for w, _ in EXAMPLES])
def test_a_scenario_the_docs_write_loads_and_validates(where: str, text: str):
    config = load_scenario(data=text)
    config.validate()
    assert config != ScenarioConfig(), f"{where} changes nothing: {text}"
