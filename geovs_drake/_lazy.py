"""Lazy re-exports for a package's ``__init__`` (PEP 562, as in Scientific Python's SPEC 1).

``geovs_drake.loop``, ``.systems`` and ``.simulation`` re-export their modules'
names so users write ``from geovs_drake.loop import build_loop``. Imported eagerly,
that made any module of the package pull in all of them: the sweep's workers, which
need the batch engine and ``loop.state`` only, spent 2.8 s importing every Drake
system before their first start. With :func:`attach` a name's module is imported on
first use of the name, and ``import geovs_drake.loop.state`` imports just that.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

__all__ = ["attach"]


def attach(
    package: str, exports: dict[str, tuple[str, ...]]
) -> tuple[Callable[[str], object], Callable[[], list[str]], list[str]]:
    """``(__getattr__, __dir__, __all__)`` for ``package``, which re-exports each name of
    ``exports[module]`` from ``package.module`` (or from ``module`` itself where it is a
    full name, ``geovs_drake....``)."""
    where = {name: module for module, names in exports.items() for name in names}

    def __getattr__(name: str) -> object:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        full = module if module.startswith("geovs_drake.") else f"{package}.{module}"
        return getattr(importlib.import_module(full), name)

    def __dir__() -> list[str]:
        return sorted(where)

    return __getattr__, __dir__, sorted(where)
