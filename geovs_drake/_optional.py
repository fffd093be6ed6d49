"""Optional dependencies: one place that imports them and names the extra to install.

A plain ``pip install geovs-drake`` has what ``geovs-drake simulate`` and
``demo`` and the library's core need (matplotlib included: Drake's
``pydrake.visualization`` imports it). Sweeps on Dask and the vision features
come with extras (``pip install "geovs-drake[sweep]"``, ``[vision]``, ``[all]``).
Code that needs one calls :func:`require` where it imports it; a missing module
raises :class:`MissingExtra`, whose message is one line naming the extra, and
which the command line turns into that line and exit code 2.
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["MissingExtra", "require"]


class MissingExtra(ImportError):
    """An optional dependency is not installed.

    Attributes:
        package: the distribution to install, e.g. ``"dask[distributed]"``.
        extra: the extra of geovs-drake that brings it, e.g. ``"sweep"``.
        needed_by: what needs it, e.g. ``"geovs-drake sweep"`` or ``"run_sweep on Dask"``.
    """

    def __init__(self, package: str, extra: str, needed_by: str) -> None:
        self.package, self.extra, self.needed_by = package, extra, needed_by
        super().__init__(self.message(needed_by))

    def message(self, needed_by: str) -> str:
        """The one line: ``<needed_by> needs <package>: pip install "geovs-drake[<extra>]"``."""
        return f'{needed_by} needs {self.package}: pip install "geovs-drake[{self.extra}]"'


def require(module: str, extra: str, needed_by: str, package: str | None = None) -> ModuleType:
    """Import ``module`` and return it, or raise :class:`MissingExtra` naming ``extra``.

    Args:
        module: the module to import, e.g. ``"distributed"`` or ``"cv2"``.
        extra: the extra of geovs-drake that installs it (``sweep``, ``vision``).
        needed_by: what needs it, for the message.
        package: the distribution's name if it differs from the module's, e.g.
            ``"opencv-python-headless"`` for ``cv2``.

    Only a missing module is turned into :class:`MissingExtra`; an installed module
    that fails while importing raises its own error.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        top = module.split(".")[0]
        if e.name is not None and e.name.split(".")[0] != top:
            raise  # the module is there but one of *its* imports is missing
        raise MissingExtra(package or top, extra, needed_by) from None
