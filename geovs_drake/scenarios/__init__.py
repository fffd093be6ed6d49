"""Scenario files shipped with the package, found with :mod:`importlib.resources`.

``default.yaml`` is the default scenario (every field of
:class:`~geovs_drake.scenario.ScenarioConfig` at its default), a template to copy
and edit; ``suite.yaml`` is the suite of scenarios that ``geovs-drake compare``
runs (:func:`geovs_drake.scenario.load_suite`)::

    python -c "import geovs_drake.scenarios as s; print(s.read_text('default'))" > my.yaml
    geovs-drake simulate --config my.yaml

Files are looked up inside the installed package, never relative to a checkout,
so they work the same from a wheel and from the repository.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

__all__ = ["names", "path", "read_text"]

_SUFFIX = ".yaml"


def names() -> list[str]:
    """The shipped scenario files' names, without ``.yaml``, sorted."""
    return sorted(
        entry.name.removesuffix(_SUFFIX)
        for entry in files(__name__).iterdir()
        if entry.name.endswith(_SUFFIX) and entry.is_file()
    )


def _resource(name: str):
    if name not in names():
        raise ValueError(f"no scenario file {name!r} in geovs_drake.scenarios: have {names()}")
    return files(__name__).joinpath(name + _SUFFIX)


def path(name: str) -> Path:
    """The file of scenario ``name`` (e.g. ``"default"``), for ``--config`` or
    :func:`~geovs_drake.scenario.load_scenario`. Raises ValueError for an unknown name.

    An installed package is a folder on disk (pip and uv unpack wheels), so this is a
    real path; :func:`read_text` also works where the package is imported from a zip.
    """
    return Path(str(_resource(name)))


def read_text(name: str) -> str:
    """The text of scenario ``name``; ``load_scenario(data=read_text(name))`` loads it."""
    return _resource(name).read_text(encoding="utf-8")
