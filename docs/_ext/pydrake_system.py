"""Sphinx directive ``.. pydrake_system::``: a LeafSystem's ports as a block diagram.

Drake documents each system's ports in its docstring with a YAML block::

    .. pydrake_system::

        name: SphericalCamera
        input_ports:
        - body_pose
        output_ports:
        - image_features

Drake's own Sphinx extension that draws it is not shipped with the ``drake`` wheel,
so this one renders the block as a three-column table: the input ports (arrows in)
on the left, the system's name in a box in the middle, the output ports (arrows
out) on the right. It is a plain docutils table, so every builder shows it; the
HTML theme gets a stylesheet that draws the box (``_static/pydrake_system.css``).
"""

from __future__ import annotations

import yaml
from docutils import nodes
from docutils.parsers.rst import Directive
from sphinx.application import Sphinx
from sphinx.util.typing import ExtensionMetadata

__all__ = ["PydrakeSystem", "parse_block", "setup"]

_KEYS = {"name", "input_ports", "output_ports"}


def parse_block(text: str) -> tuple[str, list[str], list[str]]:
    """(name, input ports, output ports) of a ``pydrake_system`` block's YAML.

    Raises ValueError naming the problem: not a mapping, unknown keys, no name, or
    ports that are not a list of names.
    """
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise ValueError(f"malformed YAML: {str(e).splitlines()[0]}") from None
    if not isinstance(data, dict):
        raise ValueError(f"expected a mapping with {sorted(_KEYS)}, got {data!r}")
    unknown = set(data) - _KEYS
    if unknown:
        raise ValueError(f"unknown keys {sorted(unknown)} (known: {sorted(_KEYS)})")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise ValueError(f"'name' must be the system's name, got {name!r}")
    ports = []
    for key in ("input_ports", "output_ports"):
        value = data.get(key) or []
        if not isinstance(value, list) or not all(isinstance(p, str) for p in value):
            raise ValueError(f"{key!r} must be a list of port names, got {value!r}")
        ports.append(value)
    return name, ports[0], ports[1]


def _cell(text: str, classes: list[str], morerows: int = 0) -> nodes.entry:
    entry = nodes.entry(classes=classes, morerows=morerows)
    if text:
        entry += nodes.paragraph("", "", nodes.literal(text, text))
    return entry


class PydrakeSystem(Directive):
    """``.. pydrake_system::`` with a YAML body: a table drawn as a block diagram."""

    has_content = True

    def run(self) -> list[nodes.Node]:
        try:
            name, inputs, outputs = parse_block("\n".join(self.content))
        except ValueError as e:
            raise self.error(f"pydrake_system: {e}") from None
        rows = max(len(inputs), len(outputs), 1)
        table = nodes.table(classes=["pydrake-system"])
        group = nodes.tgroup(cols=3)
        table += group
        for width in (3, 2, 3):
            group += nodes.colspec(colwidth=width)
        body = nodes.tbody()
        group += body
        for i in range(rows):
            row = nodes.row()
            port = f"{inputs[i]} \u2192" if i < len(inputs) else ""
            row += _cell(port, ["pydrake-system-input"])
            if i == 0:
                box = nodes.entry(classes=["pydrake-system-name"], morerows=rows - 1)
                box += nodes.paragraph("", "", nodes.strong(name, name))
                row += box
            port = f"\u2192 {outputs[i]}" if i < len(outputs) else ""
            row += _cell(port, ["pydrake-system-output"])
            body += row
        caption = f"{name}: {len(inputs)} input port(s), {len(outputs)} output port(s)"
        table["ids"] = []
        table.insert(0, nodes.title(caption, caption))
        return [table]


def setup(app: Sphinx) -> ExtensionMetadata:
    app.add_directive("pydrake_system", PydrakeSystem)
    app.add_css_file("pydrake_system.css")
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
