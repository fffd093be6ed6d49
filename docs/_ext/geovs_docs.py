"""Local Sphinx helpers for the geovs_drake reference.

* ``.. optional-include:: FILE``: include a Markdown file when it exists (the paper
  notes), else a short note saying it is not written yet.
* ``.. benchmark-tables::``: the benchmarks' latest figures, from
  ``benchmarks/results/*.json`` (``benchmarks/_record.py``).
* ``.. cli-help:: [COMMAND]``: the ``--help`` text of ``geovs-drake [COMMAND]``,
  from the parser itself (:func:`geovs_drake.cli.build_parser`).
* napoleon reads Google-style sections everywhere but in attribute, data and
  property docstrings, whose first line is prose here, not ``type: text``.
* The reference stays complete: a public function, class, method or property
  without a docstring, or a public module that no page documents, is a warning
  (an error under ``-W``).
* The systems' framework members (``Calc*`` callbacks, ``ToScalarType`` and
  friends) and the ``Foo_`` TemplateSystem objects are left out of the member
  lists; each system page says what ``Foo_`` is.
* ``.. leafsystem:: module.Foo``: a TemplateSystem's default instantiation
  (``SphericalCamera`` is ``SphericalCamera_[float]``) as the class it is, where
  autodoc would write "alias of"; a system that no such entry documents is a warning.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import pkgutil
import re
import textwrap
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import directives
from pydrake.systems.scalar_conversion import TemplateSystem
from sphinx.application import Sphinx
from sphinx.directives.other import Include
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective
from sphinx.util.typing import ExtensionMetadata

logger = logging.getLogger(__name__)

#: Members of the systems that are the framework's plumbing, not the API.
_FRAMEWORK = re.compile(r"^(Calc[A-Z]|DoCalc|ToScalarType|ToAutoDiffXd|ToSymbolic)|𝓣")


class OptionalInclude(SphinxDirective):
    """Include a Markdown file (parsed with MyST) if it exists; else say it is missing."""

    required_arguments = 1
    option_spec = {"title": directives.unchanged}

    def run(self) -> list[nodes.Node]:
        relative = self.arguments[0]
        path = Path(self.env.srcdir) / relative
        self.env.note_dependency(str(path))  # rebuild when it appears or changes
        if path.is_file():
            include = Include(
                "include",
                [relative],
                {"parser": directives.parser_name("myst_parser.sphinx_")},
                self.content,
                self.lineno,
                self.content_offset,
                self.block_text,
                self.state,
                self.state_machine,
            )
            return include.run()
        title = self.options.get("title", relative)
        section = nodes.section(ids=[nodes.make_id(title)])
        section += nodes.title(title, title)
        text = f"docs/{relative} is not written yet; this page includes it once it is."
        section += nodes.paragraph(text, text)
        return [section]


class CliHelp(SphinxDirective):
    """The ``--help`` of ``geovs-drake`` or of one of its commands, as a literal block."""

    optional_arguments = 1

    def run(self) -> list[nodes.Node]:
        from geovs_drake.cli import help_text

        text = help_text(self.arguments[0] if self.arguments else None, columns=88)
        return [nodes.literal_block(text, text, language="text")]


def _number(value: float | None) -> str:
    """A figure as the table shows it: 3 significant digits, no exponent under 10^5."""
    if value is None:
        return ""
    return f"{value:.3g}" if abs(value) < 1e5 else f"{value:.3e}"


def _table(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> nodes.table:
    """A docutils table of plain-text cells (whatever parser the page uses)."""
    table = nodes.table()
    group = nodes.tgroup(cols=len(header))
    table += group
    group += [nodes.colspec(colwidth=1) for _ in header]

    def row(cells: tuple[str, ...]) -> nodes.row:
        out = nodes.row()
        for cell in cells:
            out += nodes.entry("", nodes.paragraph(text=cell))
        return out

    group += nodes.thead("", row(header))
    group += nodes.tbody("", *(row(r) for r in rows))
    return table


class BenchmarkTables(SphinxDirective):
    """One table per ``benchmarks/results/*.json`` file (``benchmarks/_record.py``): each
    figure beside its baseline from the same run, then the run's machine, date, commit
    and command. A file that does not parse is a warning (an error under ``-W``)."""

    def run(self) -> list[nodes.Node]:
        import json

        folder = Path(self.env.srcdir).parent / "benchmarks" / "results"
        out: list[nodes.Node] = []
        for path in sorted(folder.glob("*.json")):
            self.env.note_dependency(str(path))
            try:
                data = json.loads(path.read_text())
                figures, machine = data["figures"], data["machine"]
            except (ValueError, KeyError) as e:
                logger.warning(f"{path.name}: not a benchmark record ({e})")
                continue
            rows = []
            for f in figures:
                baseline = f["baseline"]
                if f.get("baseline_value") is not None:
                    baseline += f": {_number(f['baseline_value'])} {f['unit']}"
                rows.append((f["name"], f"{_number(f['value'])} {f['unit']}", baseline,
                             _number(f.get("ratio")), f.get("target", "")))  # fmt: skip
            load = machine.get("load_average_at_end")
            where = (
                f"{data['command']}, {data['date']}, commit {data['commit']}; "
                f"{machine['cores']} cores ({machine['cpu']}), {machine['numba_threads']} numba "
                f"threads, Python {machine['python']}, Drake {machine['drake']}"
                + ("" if load is None else f", load average {load:.1f} at the end")
                + "."
            )
            section = nodes.rubric(text=data["title"])
            header = ("figure", "value", "baseline (same run)", "value / baseline", "target")
            out += [section, _table(header, rows), nodes.paragraph(text=where)]
            if data.get("note"):
                out.append(nodes.paragraph(text=data["note"]))
        if not out:
            logger.warning(f"no benchmark records in {folder}")
        return out


def _is_template_instantiation(obj) -> bool:
    """A class made by a pydrake TemplateSystem (``Foo_[float]``, whose ``__name__`` is
    ``Foo_𝓣float𝓤``)."""
    return inspect.isclass(obj) and "𝓣" in obj.__name__ and hasattr(obj, "_construct")


def _constructor_signature(construct) -> str:
    """``(radius: float = 0.1, domain: SafeDomain = DEFAULT_DOMAIN, ...)``: the arguments
    of ``_construct`` less self and the converter, defaults as written in the source."""
    defaults = {}
    tree = ast.parse(textwrap.dedent(inspect.getsource(construct)))
    arguments = tree.body[0].args
    positional = arguments.posonlyargs + arguments.args
    for arg, default in zip(positional[len(positional) - len(arguments.defaults) :],
                            arguments.defaults, strict=True):  # fmt: skip
        defaults[arg.arg] = ast.unparse(default)
    for arg, default in zip(arguments.kwonlyargs, arguments.kw_defaults, strict=True):
        if default is not None:
            defaults[arg.arg] = ast.unparse(default)
    out = []
    for name, parameter in inspect.signature(construct).parameters.items():
        if name in ("self", "converter"):
            continue
        text = name
        if parameter.annotation is not inspect.Parameter.empty:
            annotation = parameter.annotation
            text += f": {annotation if isinstance(annotation, str) else annotation.__name__}"
        if name in defaults:
            text += f" = {defaults[name]}"
        out.append(text)
    return f"({', '.join(out)})"


class LeafSystemDirective(SphinxDirective):
    """``.. leafsystem:: module.Foo``: a TemplateSystem's default instantiation as a class.

    autodoc documents ``Foo = Foo_[None]`` as "alias of Foo_[float]" without its
    docstring or methods (the class's ``__name__`` is not ``Foo``), so this directive
    writes the class entry itself: the constructor's arguments (``_construct``'s,
    less the converter), the docstring through napoleon (with its
    ``pydrake_system`` block) and the public methods through autodoc.
    """

    required_arguments = 1

    def run(self) -> list[nodes.Node]:
        from docutils.statemachine import StringList
        from sphinx.ext.napoleon.docstring import GoogleDocstring

        path = self.arguments[0]
        module_name, _, attr = path.rpartition(".")
        obj = getattr(importlib.import_module(module_name), attr)
        if not _is_template_instantiation(obj):
            raise self.error(f"leafsystem: {path} is not a TemplateSystem's instantiation")
        self.env.domaindata.setdefault("geovs", {}).setdefault("systems", set()).add(path)
        args = _constructor_signature(obj._construct)
        doc = inspect.getdoc(obj) or ""
        if not doc.strip():
            logger.warning(f"{path} has no docstring", type="geovs", subtype="undocumented")
        lines = GoogleDocstring(doc, self.config, self.env.app, "class", path, obj).lines()
        rst = [f".. py:class:: {attr}{args}", f"   :module: {module_name}", ""]
        rst += [f"   {line}" if line else "" for line in lines] + [""]
        for name, member in vars(obj).items():
            if name.startswith("_") or _FRAMEWORK.search(name):
                continue
            kind = "autoproperty" if isinstance(member, property) else "automethod"
            if callable(member) or isinstance(member, property):
                rst += [f"   .. {kind}:: {path}.{name}", ""]
        node = nodes.container()
        self.state.nested_parse(StringList(rst, source=path), self.content_offset, node)
        return node.children


def _skip_member(app, what, name, obj, skip, options):
    if _FRAMEWORK.search(name):
        return True
    if _is_template_instantiation(obj):  # documented by ``.. leafsystem::``
        app.env.domaindata.setdefault("geovs", {}).setdefault("skipped", set()).add(
            f"{obj.__module__}.{name}"
        )
        return True
    module = getattr(obj, "__module__", "") or ""
    if isinstance(obj, TemplateSystem) or (
        name.endswith("_") and module.startswith("geovs_drake.systems")
    ):
        return True
    return None


def _check_docstring(app, what, name, obj, options, lines):
    if what not in ("function", "class", "method", "property", "exception", "leafsystem"):
        return
    if name.rsplit(".", 1)[-1].startswith("_"):
        return
    text = "\n".join(lines).strip()
    generated = (
        dataclasses.is_dataclass(obj)
        and inspect.isclass(obj)
        and text.startswith(f"{obj.__name__}(")
    )
    if not text or generated:
        logger.warning(f"{name} has no docstring", type="geovs", subtype="undocumented")


def _public_modules() -> set[str]:
    import geovs_drake

    names = {"geovs_drake"}
    for info in pkgutil.walk_packages(geovs_drake.__path__, "geovs_drake."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.add(info.name)
    for name in list(names):  # a module that fails to import is the page's problem
        importlib.import_module(name)
    return names


def _check_modules(app: Sphinx, env) -> None:
    documented = set(env.domaindata["py"]["modules"])
    for name in sorted(_public_modules() - documented):
        logger.warning(f"module {name} is on no page", type="geovs", subtype="undocumented")
    ours = env.domaindata.get("geovs", {})
    for name in sorted(ours.get("skipped", set()) - ours.get("systems", set())):
        message = f"LeafSystem {name} has no '.. leafsystem::' entry"
        logger.warning(message, type="geovs", subtype="undocumented")


def _merge(app: Sphinx, env, docnames, other) -> None:
    """Parallel reading: the sets of systems seen by the other process."""
    ours = env.domaindata.setdefault("geovs", {})
    for key, values in other.domaindata.get("geovs", {}).items():
        ours.setdefault(key, set()).update(values)


def _napoleon_except_attributes(app, what, name, obj, options, lines) -> None:
    """napoleon, except on attributes, data and properties: it reads their first line
    ``X: text`` as "type X" (``q1: Q's first column`` would show type q1); ours are
    prose."""
    from sphinx.ext.napoleon import _process_docstring

    if what not in ("attribute", "data", "property"):
        _process_docstring(app, what, name, obj, options, lines)


def _reroute_napoleon(app: Sphinx) -> None:
    from sphinx.errors import ExtensionError
    from sphinx.ext.napoleon import _process_docstring

    listeners = app.events.listeners.get("autodoc-process-docstring", [])
    ours = [listener for listener in listeners if listener.handler is _process_docstring]
    if len(ours) != 1:
        raise ExtensionError("geovs_docs: napoleon's docstring handler not found")
    app.disconnect(ours[0].id)
    app.connect("autodoc-process-docstring", _napoleon_except_attributes)


def setup(app: Sphinx) -> ExtensionMetadata:
    app.setup_extension("sphinx.ext.autodoc")
    app.setup_extension("sphinx.ext.napoleon")
    _reroute_napoleon(app)
    app.add_directive("optional-include", OptionalInclude)
    app.add_directive("cli-help", CliHelp)
    app.add_directive("benchmark-tables", BenchmarkTables)
    app.add_directive("leafsystem", LeafSystemDirective)
    app.connect("autodoc-skip-member", _skip_member)
    app.connect("autodoc-process-docstring", _check_docstring)
    app.connect("env-check-consistency", _check_modules)
    app.connect("env-merge-info", _merge)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
