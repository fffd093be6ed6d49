"""What a plain install holds: core dependencies cover every import, optional ones go
through one helper that names the extra, and the scenario files ship as package data.
(The installed wheel itself is exercised by tests/test_wheel.py.)"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from pathlib import Path

import pytest

import geovs_drake
from geovs_drake import cli
from geovs_drake._optional import MissingExtra, require

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = Path(geovs_drake.__file__).parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
#: Import name -> distribution, for the third-party modules the package imports.
DISTRIBUTION = {
    "pydrake": "drake",
    "drake": "drake",  # the LCM message types (lcmt_*) the drake wheel ships
    "numpy": "numpy",
    "yaml": "pyyaml",
    "numba": "numba",
    "matplotlib": "matplotlib",
    "tqdm": "tqdm",
    "distributed": "dask",
    "dask": "dask",
    "pyarrow": "pyarrow",
    "pandas": "pandas",
    "cv2": "opencv-python-headless",
    "sympy": "sympy",
}


def _name(requirement: str) -> str:
    return re.split(r"[\[<>=!~ ;@]", requirement, maxsplit=1)[0].lower()


def _imports_and_requires(path: Path) -> tuple[set[str], set[str]]:
    """Top-level names of the third-party modules ``path`` imports (anywhere), and the
    modules it passes to require()."""
    imported, required = set(), set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            imported |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            imported.add(node.module.split(".")[0])
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "id", None) == "require"
            and isinstance(node.args[0], ast.Constant)
        ):
            required.add(node.args[0].value.split(".")[0])
    third_party = imported - set(sys.stdlib_module_names) - {"geovs_drake", "__future__"}
    return third_party, required


def test_core_dependencies_cover_every_import_and_optional_ones_use_require():
    """A module may import a non-core package only where it also calls require() for it,
    so a plain install never fails with a bare ModuleNotFoundError."""
    core = {_name(r) for r in PYPROJECT["dependencies"]}
    extras = PYPROJECT["optional-dependencies"]
    for path in sorted(PACKAGE.rglob("*.py")):
        imported, required = _imports_and_requires(path)
        for module in sorted(imported):
            assert module in DISTRIBUTION, f"{path}: unknown third-party import {module!r}"
            if DISTRIBUTION[module] in core:
                continue
            if path.name == "_codegen.py":  # the maintainers' generator: the test extra
                assert DISTRIBUTION[module] in {_name(r) for r in extras["test"]}, module
                continue
            assert module in required, f"{path}: imports {module} without require()"


def test_every_require_names_an_extra_that_installs_it():
    extras = PYPROJECT["optional-dependencies"]
    calls = []
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "require":
                calls.append((path, [ast.literal_eval(a) for a in node.args[:2]]))
    assert calls, "no optional import found: the sweep's Dask import should use require()"
    for path, (module, extra) in calls:
        assert extra in extras, f"{path}: require({module!r}, {extra!r}): no such extra"
        names = {_name(r) for r in extras[extra]}
        assert DISTRIBUTION[module.split(".")[0]] in names, (path, module, extra)
        assert _name(extras["all"][0]) == "geovs-drake" and extra in extras["all"][0]


def test_all_and_test_extras_include_the_user_extras():
    extras = PYPROJECT["optional-dependencies"]
    users = set(extras) - {"all", "test", "docs"}
    assert extras["all"] == [f"geovs-drake[{','.join(sorted(users, key=list(extras).index))}]"]
    assert "geovs-drake[all]" in extras["test"]


def test_require_names_the_extra_and_only_for_the_missing_module(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    with pytest.raises(MissingExtra) as e:
        require("distributed", "sweep", "run_sweep on Dask", package="dask[distributed]")
    assert (
        str(e.value)
        == 'run_sweep on Dask needs dask[distributed]: pip install "geovs-drake[sweep]"'
    )
    assert isinstance(e.value, ImportError)
    # An installed module whose own import is missing is a real error, not an extra.
    (tmp_path / "geovs_probe_pkg.py").write_text("import geovs_no_such_module_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ModuleNotFoundError) as e:
        require("geovs_probe_pkg", "sweep", "probe")
    assert not isinstance(e.value, MissingExtra) and e.value.name == "geovs_no_such_module_xyz"


def test_sweep_without_dask_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    """The sweep's default, a local Dask cluster, names the extra before anything runs
    or is written."""
    monkeypatch.setitem(sys.modules, "distributed", None)
    out = tmp_path / "sweep"
    argv = ["sweep", "--starts", "2", "--duration", "0.2", "--engine", "drake", "--out", str(out)]
    code = cli.main(argv)
    err = capsys.readouterr().err
    assert code == cli.EXIT_BAD_INPUT
    assert err.strip() == (
        'geovs-drake sweep needs dask[distributed]: pip install "geovs-drake[sweep]"'
    )
    assert not out.exists()


def test_default_scenario_file_is_the_default_scenario():
    """default.yaml, found through importlib.resources, loads to ScenarioConfig()."""
    from pydrake.common.yaml import yaml_dump_typed

    from geovs_drake import scenarios
    from geovs_drake.scenario import ScenarioConfig, load_scenario

    assert "default" in scenarios.names()
    path = scenarios.path("default")
    assert path.is_file() and path.parent == PACKAGE / "scenarios"
    loaded = load_scenario(path)
    assert yaml_dump_typed(loaded) == yaml_dump_typed(ScenarioConfig()), (
        "geovs_drake/scenarios/default.yaml differs from ScenarioConfig()'s defaults: "
        "rewrite its body with pydrake.common.yaml.yaml_dump_typed(ScenarioConfig())"
    )
    text = yaml_dump_typed(load_scenario(data=scenarios.read_text("default")))
    assert text == yaml_dump_typed(ScenarioConfig())
    with pytest.raises(ValueError, match=r"no scenario file 'nope' .*'default'"):
        scenarios.path("nope")


def test_scenario_files_are_package_data():
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "*.yaml" in data["package-data"]["geovs_drake.scenarios"]
    assert (PACKAGE / "scenarios" / "__init__.py").is_file()  # a package: resources work


def test_no_build_or_test_file_pins_the_blas_kernel():
    """OPENBLAS_CORETYPE (and OPENBLAS_L2_SIZE) are the machine's: some machines set them
    for their processor, and the suite's verdict must hold whatever they say. A file that
    set them would hide a test that depends on the kernel (see geovs_drake.spectrum)."""
    files = [ROOT / "Makefile", ROOT / "pyproject.toml", *sorted((ROOT / ".ci").glob("*"))]
    files += sorted((ROOT / "tests").glob("*.py")) + sorted((ROOT / "notebooks").glob("*.ipynb"))
    files += sorted((ROOT / "docs" / "_ext").glob("*.py")) + [ROOT / "docs" / "conf.py"]
    setting = re.compile(
        r"OPENBLAS_(?:CORETYPE|L2_SIZE)['\"]?\]?\s*[=:]|(?:setenv|setdefault)\(\s*['\"]OPENBLAS"
    )
    assert setting.search('env["OPENBLAS_CORETYPE"] = "Haswell"')  # the check can fail
    assert setting.search("OPENBLAS_CORETYPE=Zen pytest") and setting.search(
        'monkeypatch.setenv("OPENBLAS_CORETYPE", "Zen")'
    )
    for path in files:
        if path.resolve() != Path(__file__).resolve():  # this test's own examples
            assert not setting.search(path.read_text()), path.relative_to(ROOT)


def test_the_configs_defaults_are_the_geometrys_written_once():
    """DomainConfig and NavigationGainsConfig read their defaults from SafeDomain and
    NavigationGains: the default scenario's D and NF are the geometry's, the degrees of
    the field of view exactly 35."""
    from geovs_drake.geometry.domain import SafeDomain
    from geovs_drake.geometry.navigation import NavigationGains
    from geovs_drake.scenario import DomainConfig, NavigationGainsConfig

    assert DomainConfig().to_domain() == SafeDomain()
    assert NavigationGainsConfig().to_gains() == NavigationGains()
    assert DomainConfig().fov_half_angle_deg == 35.0
