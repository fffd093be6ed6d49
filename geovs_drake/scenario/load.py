"""Loading a scenario: YAML files and fragments in layers, checked field by field,
then read by Drake's ``yaml_load_typed`` (the pattern of hardware_sim's loader)."""

import dataclasses
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml
from pydrake.common.yaml import yaml_load_typed

from geovs_drake.scenario.carriers import AUTO
from geovs_drake.scenario.schema import AXES, ScenarioConfig, variant_by_name

__all__ = ["load_scenario", "load_tagged_yaml", "variant_layer"]


def _describe(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _is_number(value: Any) -> bool:
    if isinstance(value, bool):
        return False
    if isinstance(value, int | float):
        return True
    if isinstance(value, str):  # PyYAML reads 1e-6 (no dot) as a string; Drake takes it
        try:
            float(value)
        except ValueError:
            return False
        return True
    return False


def _schema_fields(default: Any) -> dict[str, Any] | None:
    """Field name -> default value of a dataclass or a Drake-bound struct, else None."""
    if dataclasses.is_dataclass(default):
        hints = typing.get_type_hints(type(default))
        out = {}
        for f in dataclasses.fields(default):
            value = getattr(default, f.name)
            # An optional struct left unset (None): its shape is the struct's own.
            shape = [t for t in typing.get_args(hints[f.name]) if dataclasses.is_dataclass(t)]
            out[f.name] = shape[0]() if value is None and shape else value
        return out
    fields = getattr(type(default), "__fields__", None)
    if fields is not None:
        return {f.name: getattr(default, f.name) for f in fields}
    return None


#: The YAML tags of each axis's variants (``carrier: !Arm {...}``): axis -> tag -> class.
_TAGS: dict[str, dict[str, type]] = {
    axis: {f"!{kind.__name__}": kind for kind in typing.get_args(hint)}
    for axis, hint in typing.get_type_hints(ScenarioConfig).items()
    if axis in AXES
}
#: The tag of each union's first variant, which Drake's YAML leaves out.
_FIRST_TAG = {axis: next(iter(tags)) for axis, tags in _TAGS.items()}
#: The key under which a tagged mapping keeps its tag once read (as pydrake's loader does).
_TAG = "_tag"


class _TaggedLoader(yaml.SafeLoader):
    """PyYAML's safe loader that keeps a mapping's tag (a law variant) as ``_tag``."""


def variant_layer(kind: type, **fields: Any) -> dict:
    """A layer's value for a union field: the variant ``kind`` with ``fields`` (the rest
    the layers below give, if they chose the same variant, else its defaults), as a
    tagged YAML mapping reads; e.g. ``{"target_motion": variant_layer(Twist, twist=xi)}``
    in :func:`load_scenario`'s ``overrides``."""
    return {_TAG: f"!{kind.__name__}", **fields}


def _construct_tagged(loader: yaml.SafeLoader, suffix: str, node: yaml.Node) -> dict:
    tag = f"!{suffix}"
    if not isinstance(node, yaml.MappingNode):
        raise yaml.constructor.ConstructorError(
            None, None, f"the tag {tag} needs a mapping, e.g. {tag} {{}}", node.start_mark
        )
    return {_TAG: tag, **loader.construct_mapping(node, deep=True)}


_TaggedLoader.add_multi_constructor("!", _construct_tagged)


class _TaggedDumper(yaml.SafeDumper):
    """Writes a mapping with a ``_tag`` back as a tagged mapping, for Drake's loader."""


def _represent_dict(dumper: yaml.SafeDumper, data: dict) -> yaml.Node:
    if _TAG in data:
        body = {k: v for k, v in data.items() if k != _TAG}
        return dumper.represent_mapping(data[_TAG], body)
    return dumper.represent_dict(data)


_TaggedDumper.add_representer(dict, _represent_dict)


def load_tagged_yaml(text: str) -> Any:
    """YAML text as a tree; tagged mappings keep their tag (``_tag``)."""
    return yaml.load(text, Loader=_TaggedLoader)  # noqa: S506 - a SafeLoader subclass


def _dump_yaml(tree: Any) -> str:
    """A tree from :func:`load_tagged_yaml` back as YAML text, tags included."""
    return yaml.dump(tree, Dumper=_TaggedDumper)


def _check_fields(value: Any, default: Any, where: str) -> None:
    """``value`` as the mapping of a struct whose default is ``default``: known fields,
    each of its field's shape."""
    fields = _schema_fields(default)
    if not isinstance(value, dict):
        raise ValueError(f"{where}: expected a mapping of fields, got {_describe(value)}")
    unknown = [k for k in value if k not in fields]
    if unknown:
        # repr() for a key that is no identifier: it may hold a newline or be empty.
        key = unknown[0] if str(unknown[0]).isidentifier() else repr(unknown[0])
        raise ValueError(
            f"{where + '.' if where else ''}{key}: unknown field (known here: {', '.join(fields)})"
        )
    for key, item in value.items():
        _check_node(item, fields[key], f"{where}.{key}" if where else str(key))


def _check_untagged(fields: dict, axis: str) -> None:
    """An untagged mapping of ``axis`` is its first variant: where that variant lacks one
    of ``fields`` and another has them all, ValueError in one line naming that variant's
    tag, e.g. ``sensor: {latency_frames: 1}`` (read as ``!Exact``): write
    ``sensor: !Pinhole {latency_frames: 1}``."""
    tags = _TAGS[axis]
    first = _FIRST_TAG[axis]
    known = _schema_fields(tags[first]())
    if all(key in known for key in fields):
        return
    fitting = [
        tag for tag, kind in tags.items() if all(key in _schema_fields(kind()) for key in fields)
    ]
    if fitting:  # else _check_fields names the unknown field
        raise ValueError(
            f"{axis}: the {axis} is a tagged variant and an untagged mapping is {first} "
            f"({', '.join(known) or 'no fields'}): write {axis}: "
            f"{_tagged(fitting[0][1:], fields)}"
        )


def _check_node(value: Any, default: Any, where: str) -> None:
    """Raise ValueError ``where: expected ..., got ...`` if ``value`` cannot fill a field
    whose default is ``default`` (the defaults have the shapes the fields need)."""
    if where in _TAGS:
        # A variant, by its tag; its fields are checked against the variant. An
        # untagged mapping is the union's first variant, as Drake reads and writes it
        # (yaml_dump_typed leaves the default variant's tag out).
        tags = _TAGS[where]
        tag = value.get(_TAG, _FIRST_TAG[where]) if isinstance(value, dict) else None
        if tag not in tags:
            raise ValueError(
                f"{where}: expected a name ({', '.join(AXES[where])}) or a tagged "
                f"variant ({', '.join(tags)}), got {_describe(value)}"
            )
        fields = {k: v for k, v in value.items() if k != _TAG}
        if _TAG not in value:
            _check_untagged(fields, where)
        _check_fields(fields, tags[tag](), where)
        return
    if _schema_fields(default) is not None:
        _check_fields(value, default, where)
        return
    if isinstance(default, bool):
        ok, expected = isinstance(value, bool), "true or false"
    elif isinstance(default, float | int):
        ok, expected = _is_number(value), "a number"
    elif default == AUTO:  # a number, or auto (Arm.gain_scale)
        ok, expected = value == AUTO or _is_number(value), f"a number or {AUTO}"
    elif isinstance(default, str):
        ok, expected = isinstance(value, str), "a string"
    elif isinstance(default, list):
        # An empty default is a list whose length the model decides (an arm's joints):
        # its length is checked where the model is known.
        n = len(default)
        sized = n == 0 or (isinstance(value, list) and len(value) == n)
        ok = isinstance(value, list) and sized and all(_is_number(v) for v in value)
        expected = f"a list of {n} numbers" if n else "a list of numbers"
    else:  # not a shape this schema uses: Drake decides
        return
    if not ok:
        raise ValueError(f"{where}: expected {expected}, got {_describe(value)}")


#: The PoseConfig fields of a ScenarioConfig, as paths.
_POSE_FIELDS = (
    ("target",),
    ("goal",),
    ("initial",),
    ("carrier", "camera_offset"),
    ("carrier", "base_pose"),
)


def _complete_pose(tree: dict, path: tuple[str, ...]) -> None:
    """A pose the file gives is the whole pose: what it leaves out of xyz / rpy is zero.

    Why: Drake's loader fills a partial struct from the defaults, so a file giving
    only ``initial: {xyz: ...}`` would quietly keep the default start's 2 rad roll.
    """
    node = tree
    for key in path:
        if not isinstance(node, dict) or key not in node:
            return
        node = node[key]
    if isinstance(node, dict):
        node.setdefault("xyz", [0.0, 0.0, 0.0])
        node.setdefault("rpy", [0.0, 0.0, 0.0])


def _flow(value: Any) -> str:
    """A value as one line of flow YAML, or ``...`` if it is too odd to quote there."""
    shown = yaml.safe_dump(value, default_flow_style=True, width=10**6)
    shown = shown.strip().removesuffix("...").strip()
    return "..." if "\n" in shown or len(shown) > 80 else shown


def _tagged(kind: str, fields: Any) -> str:
    """``!Kind {fields}`` as a file writes it."""
    body = _flow(fields) if isinstance(fields, dict) and fields else "{}"
    return f"!{kind} {body}"


def _refuse_earlier_spelling(tree: dict) -> None:
    """The flat fields that the variants hold now (``camera``, ``arm``, ``rig``,
    ``mount``, ``control.ibvs_depth``, ``path``): refused in one line that writes the new
    spelling with the file's own values."""
    control = tree.get("control")
    if isinstance(control, dict) and "ibvs_depth" in control:
        new = _tagged("Ibvs", {"depth": control["ibvs_depth"]})
        raise ValueError(
            f"control.ibvs_depth: the law's fields are the law's own now: write controller: {new}"
        )
    if "path" in tree:
        new = _tagged("PathFollowing", tree["path"])
        raise ValueError(f"path: the law's fields are the law's own now: write controller: {new}")
    if "camera" in tree:
        camera = dict(tree["camera"]) if isinstance(tree["camera"], dict) else {}
        name = camera.pop("sensor", "exact")
        kind = AXES["sensor"].get(name, AXES["sensor"]["exact"]).__name__
        new = _tagged(kind, camera)
        raise ValueError(f"camera: the camera is the sensor's variant now: write sensor: {new}")
    for key, kind in (("arm", "Arm"), ("rig", None)):
        if key in tree:
            fixed = tree.get("mount") == "fixed"
            kind = kind or ("FixedCamera" if fixed else "FreeRig")
            fields = tree[key]
            if kind == "FixedCamera" and isinstance(fields, dict):
                fields = {k: v for k, v in fields.items() if k != "camera_offset"}
            new = _tagged(kind, fields)
            raise ValueError(f"{key}: its fields are the carrier's own now: write carrier: {new}")
    if "mount" in tree:
        new = "!FixedCamera {}" if tree["mount"] == "fixed" else "!FreeRig {} (or !Arm {...})"
        raise ValueError(f"mount: the mount is the carrier's variant now: write carrier: {new}")


def _read_variants(tree: dict) -> None:
    """A file's carrier, plant, sensor and controller as tagged variants: a bare name
    (``plant: kinematic``) is that variant with its defaults. The earlier, flat
    spelling is refused (:func:`_refuse_earlier_spelling`)."""
    _refuse_earlier_spelling(tree)
    for axis, variants in AXES.items():
        name = tree.get(axis)
        if isinstance(name, str):
            if name not in variants:
                raise ValueError(variant_by_name(axis, name))
            tree[axis] = {_TAG: f"!{variants[name].__name__}"}


def _layer_tree(name: str, fragment: str | Mapping[str, Any]) -> dict:
    """One layer as a checked tree of fields, its poses complete; errors start ``name: ``."""
    tree = fragment
    if isinstance(fragment, str):
        try:
            tree = load_tagged_yaml(fragment)
        except yaml.YAMLError as e:
            mark = getattr(e, "problem_mark", None)
            problem = getattr(e, "problem", None) or str(e).splitlines()[0]
            at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
            raise ValueError(f"{name}: malformed YAML{at}: {problem}") from None
    if tree is None:
        return {}
    if not isinstance(tree, Mapping):
        raise ValueError(
            f"{name}: expected a mapping of ScenarioConfig fields, got {_describe(tree)}"
        )
    tree = _plain(tree)  # a copy: the poses are completed in place
    try:
        _read_variants(tree)
        _check_node(tree, ScenarioConfig(), "")
    except ValueError as e:
        raise ValueError(f"{name}: {e}") from None
    for pose in _POSE_FIELDS:
        _complete_pose(tree, pose)
    return tree


def _plain(value: Any) -> Any:
    """``value`` with every mapping a new dict (and every list a new list)."""
    if isinstance(value, Mapping):
        return {key: _plain(item) for key, item in value.items()}
    return [_plain(item) for item in value] if isinstance(value, list) else value


def _merged(base: dict, over: Mapping[str, Any]) -> dict:
    """``over`` on ``base``: mappings merge key by key, anything else (a list too) replaces."""
    out = dict(base)
    for key, value in over.items():
        below = out.get(key)
        if (
            isinstance(value, Mapping)
            and isinstance(below, Mapping)
            and value.get(_TAG) == below.get(_TAG)  # another variant replaces, never merges
        ):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


def load_scenario(
    path: str | Path | None = None,
    data: str | None = None,
    *,
    overrides: Sequence[str | Mapping[str, Any] | tuple[str, str | Mapping[str, Any]]] = (),
) -> ScenarioConfig:
    """A ScenarioConfig from a YAML file or string; unspecified fields keep defaults.

    ``overrides`` are layered over the file in order, each a YAML text or a mapping of
    the same fields (or a pair ``(name, fragment)``, whose name its errors start
    with; else ``overrides[k]``): mappings merge key by key, anything else replaces.
    The command line passes ``--scenario-text`` and then each flag this way.

    A pose (``target``, ``goal``, ``initial``, a carrier's ``camera_offset`` or
    ``base_pose``) that the file or
    a layer gives is complete: its ``xyz`` or ``rpy``, if left out, is zero, not the
    default pose's nor a lower layer's.

    A missing file, malformed YAML, an unknown field or a value of the wrong type or
    length raises ValueError with one line naming the file (or the layer) and the
    field. The values themselves are checked by ``ScenarioConfig.validate``.
    """
    source = "scenario" if path is None else str(path)
    if path is not None:
        try:
            data = Path(path).read_text()
        except FileNotFoundError:
            raise ValueError(f"{source}: no such file") from None
        except (OSError, UnicodeDecodeError) as e:
            raise ValueError(f"{source}: cannot read: {e}") from None
    layers: list[tuple[str, str | Mapping[str, Any]]] = []
    if data is not None:
        layers.append((source, data))
    for k, item in enumerate(overrides):
        layers.append(item if isinstance(item, tuple) else (f"overrides[{k}]", item))
    tree: dict = {}
    for name, fragment in layers:
        tree = _merged(tree, _layer_tree(name, fragment))
    if not tree:
        return ScenarioConfig()
    try:
        return yaml_load_typed(
            schema=ScenarioConfig, data=_dump_yaml(tree), defaults=ScenarioConfig()
        )
    except (RuntimeError, ValueError, TypeError) as e:  # Drake's long messages: first line
        lines = str(e).strip().splitlines() or [type(e).__name__]
        raise ValueError(f"{source}: {lines[0]}") from None
