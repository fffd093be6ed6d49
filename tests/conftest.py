"""The one CLI runner of the tests: ``run_cli(*argv)`` runs ``geovs-drake`` in this process
(``main``, argparse's own exits caught), ``run_cli(*argv, subprocess=True)`` through
``python -m geovs_drake.cli``; both give the exit code, stdout and stderr."""

from __future__ import annotations

import subprocess as _subprocess
import sys
from collections.abc import Callable
from typing import NamedTuple

import pytest


class CliRun(NamedTuple):
    """What one ``geovs-drake`` command did."""

    code: int
    out: str
    err: str


@pytest.fixture
def run_cli(capsys: pytest.CaptureFixture[str]) -> Callable[..., CliRun]:
    from geovs_drake.cli import main

    def run(*argv: str, subprocess: bool = False) -> CliRun:
        if subprocess:
            done = _subprocess.run(
                [sys.executable, "-m", "geovs_drake.cli", *argv], capture_output=True, text=True
            )
            return CliRun(done.returncode, done.stdout, done.stderr)
        capsys.readouterr()  # only this command's output
        try:
            code = main(list(argv))
        except SystemExit as e:  # argparse's own errors, --help, --version
            code = e.code
        out, err = capsys.readouterr()
        return CliRun(code, out, err)

    return run


#: Items that run longest, started first so that pytest-xdist's workers finish together
#: (longest first): the wheel check, then the notebooks.
def _start_order(item: pytest.Item) -> int:
    if item.get_closest_marker("wheel") is not None:
        return 0
    if item.nodeid.endswith(".ipynb") or ".ipynb::" in item.nodeid:
        return 1
    return 2


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Longest first (:func:`_start_order`), the rest in their usual order."""
    items.sort(key=_start_order)  # a stable sort: each group keeps its order
