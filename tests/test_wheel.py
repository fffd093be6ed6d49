"""The wheel as a user installs it (tools/check_wheel.py): about 50 s, so it is marked
``wheel``: ``make test`` runs it as ``make wheel-check``, from the start, beside the
kernels' compile and then the other tests (it overlaps them on another core)."""

from __future__ import annotations

import importlib.util
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

CHECK = Path(__file__).resolve().parents[1] / "tools" / "check_wheel.py"


def _load_check():
    spec = importlib.util.spec_from_file_location("check_wheel", CHECK)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.mark.wheel
def test_installed_wheel_runs_every_command_without_a_traceback():
    """Fresh environments outside the checkout, with no extras and with [all]: each
    command works, or (no extras) prints the one line naming its extra with exit 2;
    no command prints a traceback; the package data is installed and found."""
    check = _load_check()
    tmp = Path(tempfile.mkdtemp(prefix="geovs-wheel-check-"))
    try:
        report = check.check(tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print("\n".join(report.lines))  # shown with -s or -rA: sizes and timings
    assert not report.failures, "\n".join(report.failures)
    assert any("needs dask[distributed]" in line for line in report.lines)
    assert report.wheel_bytes > 0


def test_the_missing_extra_pattern_matches_the_library_message():
    """The check recognises exactly the line the command line prints."""
    from geovs_drake._optional import MissingExtra

    line = MissingExtra("dask[distributed]", "sweep", "x").message("geovs-drake sweep")
    match = _load_check().MISSING_EXTRA.match(line)
    assert match and match.groups() == ("sweep", "dask[distributed]", "sweep")
    assert not _load_check().MISSING_EXTRA.match("geovs-drake: --duration must be > 0")
