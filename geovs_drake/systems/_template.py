"""``TemplateSystem.define`` without pydrake's stack search.

pydrake finds the module a template belongs to with
``inspect.getmodule(inspect.stack()[2][0])``: ``inspect.stack()`` reads the source
context of every frame on the stack, and ``getmodule`` scans ``sys.modules`` for each.
It does so once in ``define`` (unless given ``scope``) and twice more per
instantiation (the ``ToScalarType`` and ``ToScalarTypeMaybe`` methods it adds). For the
package's 18 templates that was 54 searches: measured 1.5 s of the 2.8 s import of the
loop (``python -c "import geovs_drake.loop.build"`` under cProfile: 3.8 of 6.0 s) and
16 s of the docs build, whose autodoc imports run under a deep docutils stack. Every
process pays it (each test worker, each CLI command, each notebook kernel).

So :func:`template_system` passes the defining module as ``scope``, and while an
instantiation adds those methods, pydrake's search reads the module from the frame's
globals: the same answer, without reading any source.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from types import ModuleType

from pydrake.common import cpp_template
from pydrake.systems.scalar_conversion import TemplateSystem

__all__ = ["ScopedTemplateSystem", "template_system"]


def _module_of_frame(frame: int = 2) -> ModuleType | None:
    """What ``cpp_template._get_module_from_stack`` returns (the module of the frame
    ``frame`` levels up, counting itself as 0), from that frame's globals."""
    return sys.modules.get(sys._getframe(frame).f_globals.get("__name__", ""))


@contextlib.contextmanager
def _fast_module_lookup() -> Iterator[None]:
    searched = cpp_template._get_module_from_stack
    cpp_template._get_module_from_stack = _module_of_frame
    try:
        yield
    finally:
        cpp_template._get_module_from_stack = searched


class ScopedTemplateSystem(TemplateSystem):
    """A ``TemplateSystem`` whose instantiations (made lazily, on first use of
    ``Foo_[T]``) add their scalar-conversion methods without the stack search."""

    def _on_add(self, param, cls, skip_rename):
        with _fast_module_lookup():
            return super()._on_add(param, cls, skip_rename)


def template_system(name: str, T_list: list | None = None) -> Callable:
    """``@TemplateSystem.define(name, T_list)`` scoped to the calling module: the same
    template (name, instantiations, scalar conversions), made without the stack search."""
    module = sys.modules[sys._getframe(1).f_globals["__name__"]]
    return ScopedTemplateSystem.define(name, T_list=T_list, scope=module)
