"""template_system: pydrake's TemplateSystem, made without its stack search."""

from __future__ import annotations

import re
from pathlib import Path

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common import cpp_template
from pydrake.symbolic import Expression
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from geovs_drake.systems._template import template_system

PACKAGE = Path(__file__).resolve().parents[1] / "geovs_drake"


def _toy(T):
    class Impl(LeafSystem_[T]):
        def _construct(self, gain: float = 1.0, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.gain = gain
            self.DeclareVectorInputPort("u", 1)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.gain, converter=converter)

    return Impl


Searched = TemplateSystem.define("Searched_")(_toy)
Scoped = template_system("Scoped_")(_toy)


def test_a_scoped_template_is_the_template_pydrake_would_make():
    """Same module, names and scalar conversions as TemplateSystem.define's, and
    pydrake's own search is back in place after each instantiation."""
    for T in (float, AutoDiffXd, Expression):
        searched, scoped = Searched[T], Scoped[T]
        assert scoped.__module__ == searched.__module__ == __name__
        assert scoped.__name__ == searched.__name__.replace("Searched_", "Scoped_")
        assert scoped.ToScalarType.__module__ == searched.ToScalarType.__module__
    system = Scoped[None](gain=3.0)
    for converted in (system.ToAutoDiffXd(), system.ToSymbolic()):
        assert converted.gain == 3.0
        assert type(converted).__module__ == __name__
    assert cpp_template._get_module_from_stack.__module__ == cpp_template.__name__


def test_every_system_uses_the_scoped_template():
    """A template defined with TemplateSystem.define would bring the search back
    (1.5 s of each process's import, measured)."""
    define = re.compile(r"@TemplateSystem\.define\(")
    offenders = [
        p.relative_to(PACKAGE).as_posix()
        for p in PACKAGE.rglob("*.py")
        if p.name != "_template.py" and define.search(p.read_text())
    ]
    assert offenders == []
