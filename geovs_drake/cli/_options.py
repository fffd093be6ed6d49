"""What every ``geovs-drake`` command shares: the exit codes, the one-line parser, the
help formatter, the argument types and the options defined once for all commands.

A flag that sets a scenario field (:func:`add_field`) is a config layer: parsing it
appends ``(flag, {field: value})`` to ``args.layers``, and :func:`load_config` layers
``--config``, then ``--scenario-text``, then the flags in command-line order, with
:func:`~geovs_drake.scenario.load_scenario`. Its help shows the dataclass default.
A flag that sets a field of one variant (:func:`add_variant_field`, e.g. ``--ibvs-depth``
of ``!Ibvs``, ``--camera-rate`` of a camera sensor) applies to the variant the layers
chose, last; with another variant it is one line's error.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from geovs_drake.scenario import AUTO, AXES, ScenarioConfig, load_scenario, variant_name

if TYPE_CHECKING:  # the command line starts without the loop's modules
    from geovs_drake.loop.resolved import ResolvedScenario

EXIT_CONVERGED = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141

#: The exit codes of every command, in one place (``--help`` and the README show them).
EXIT_CODES: dict[int, str] = {
    EXIT_CONVERGED: "ran and converged (simulate, demo); the table finished (sweep, compare,\n"
    "robustness, camera-accuracy, linearize)",
    EXIT_BAD_INPUT: "bad input: an argument, the --config file or --scenario-text, a start\n"
    "outside D, or a missing extra (one line on stderr, nothing run)",
    EXIT_NOT_CONVERGED: "ran and did not converge (simulate, demo): status not_converged,\n"
    "left_domain, lost_visibility, feature_lost, joint_limit or non_finite",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C)",
    EXIT_BROKEN_PIPE: "the reader of stdout went away (e.g. | head), as a shell reports SIGPIPE",
}


def exit_code_of(status: str) -> int:
    """The exit code of a run that finished with ``status``: 0 converged, else 3."""
    return EXIT_CONVERGED if status == "converged" else EXIT_NOT_CONVERGED


def exit_codes_epilog() -> str:
    """The exit-code table of every ``--help``."""
    lines = ["exit codes:"]
    for code, text in EXIT_CODES.items():
        first, *rest = text.splitlines()
        lines.append(f"  {code:<4} {first}")
        lines += [f"       {line}" for line in rest]
    return "\n".join(lines)


class OneLineParser(argparse.ArgumentParser):
    """Bad arguments in one line on stderr (exit code 2), without argparse's usage block."""

    def error(self, message: str) -> NoReturn:
        if message.endswith("expected one argument"):  # most often a value "-0.1,..."
            message += " (write a value that starts with '-' as --option=-0.1,...)"
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class EpilogTableFormatter(argparse.HelpFormatter):
    """Keeps the exit-code table's lines, and never breaks a word at its hyphen (an
    option such as ``--initial-velocity=-0.1,...`` stays whole, ready to copy)."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if text.startswith("exit codes:"):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        text = " ".join(text.split())
        return "\n".join(
            textwrap.wrap(
                text,
                width,
                initial_indent=indent,
                subsequent_indent=indent,
                break_on_hyphens=False,
            )
        )

    def _split_lines(self, text: str, width: int) -> list[str]:
        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)


def add_command(
    sub: argparse._SubParsersAction, name: str, summary: str, description: str
) -> argparse.ArgumentParser:
    """A subcommand with the one-line errors, the formatter and the exit-code table."""
    return sub.add_parser(
        name,
        help=summary,
        description=description,
        epilog=exit_codes_epilog(),
        formatter_class=EpilogTableFormatter,
    )


# ---- argument types
def _six_numbers(text: str, names: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"expected 6 numbers {names}: {text!r}") from e
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected 6 finite numbers {names}, got {text!r}")
    return values


def pose_arg(text: str) -> dict[str, list[float]]:
    """``x,y,z,roll,pitch,yaw`` as a pose's fields ``{xyz: [...], rpy: [...]}``."""
    values = _six_numbers(text, "x,y,z,roll,pitch,yaw")
    return {"xyz": values[:3], "rpy": values[3:]}


def twist_arg(text: str) -> list[float]:
    """``wx,wy,wz,vx,vy,vz`` as 6 finite numbers."""
    return _six_numbers(text, "wx,wy,wz,vx,vy,vz")


def joints_arg(text: str) -> list[float]:
    """``q1,q2,...``: finite numbers, one per joint; ``none`` for none (the default)."""
    if text.strip().lower() == "none":
        return []
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"expected numbers q1,q2,...: {text!r}") from e
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected finite numbers q1,q2,..., got {text!r}")
    return values


def gain_scale_arg(text: str) -> float | str:
    """A finite number > 0, or ``auto`` (the arm's ``gain_scale``)."""
    if text.strip().lower() == AUTO:
        return AUTO
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a number > 0 or {AUTO}, got {text!r}")
    return value


def resolution_arg(text: str) -> list[int]:
    """``WxH`` as two integers >= 16."""
    parts = text.lower().split("x")
    try:
        size = [int(v) for v in parts]
    except ValueError:
        size = []
    if len(size) != 2 or min(size) < 16:
        raise argparse.ArgumentTypeError(
            f"expected WxH, two integers >= 16 such as 320x240, got {text!r}"
        )
    return size


def numbers(values: Sequence[float]) -> str:
    """``1,0.5,-2``: numbers as the command line writes them."""
    return ",".join(f"{v:g}" for v in values)


# ---- flags that set a scenario field: config layers
def field_default(path: Sequence[str]) -> Any:
    """The default of the scenario field at ``path`` (e.g. ``("control", "potential_gain")``)."""
    node: Any = ScenarioConfig()
    for key in path:
        node = getattr(node, key)
    return node


def _shown(value: Any) -> str:
    """A default as the flag takes it: a pose or a list as numbers, a number as %g."""
    if hasattr(value, "xyz"):
        return numbers(list(value.xyz) + list(value.rpy))
    if isinstance(value, list):
        return numbers(value)
    if any(type(value) in variants.values() for variants in AXES.values()):
        return variant_name(value)
    return f"{value:g}" if isinstance(value, float) else str(value)


class _ScenarioFlag(argparse.Action):
    """A flag that sets a scenario field; ``positive``: the unit of a number that must be
    finite and > 0, checked as it is parsed (one line, exit 2)."""

    def __init__(self, *args: Any, positive: str | None = None, **kwargs: Any):
        self.positive = positive
        super().__init__(*args, **kwargs)

    def _check(self, parser, value, option_string) -> None:
        if self.positive is not None and not (math.isfinite(value) and value > 0):
            parser.error(f"{option_string} must be finite and > 0 [{self.positive}]: {value}")


class _Layer(_ScenarioFlag):
    """Appends ``(flag, {path: value})`` to ``args.layers``, in command-line order."""

    def __init__(self, *args: Any, path: tuple[str, ...], **kwargs: Any):
        self.path = path
        super().__init__(*args, **kwargs)

    def __call__(self, parser, namespace, value, option_string=None) -> None:
        self._check(parser, value, option_string)
        fragment: Any = value
        for key in reversed(self.path):
            fragment = {key: fragment}
        namespace.layers = [*(getattr(namespace, "layers", None) or []), (self.dest, fragment)]


def add_field(
    p: argparse.ArgumentParser,
    flag: str,
    path: Sequence[str],
    help: str,
    *,
    shown: str | None = None,
    positive: str | None = None,
    **kwargs: Any,
) -> None:
    """``flag`` as a layer setting the scenario field at ``path``; its help ends with the
    field's default (``shown`` in place of the value, if given). ``positive``: the unit of
    a number that must be finite and > 0, checked as it is parsed."""
    default = shown if shown is not None else _shown(field_default(path))
    p.add_argument(
        flag,
        action=_Layer,
        path=tuple(path),
        positive=positive,
        dest=flag,  # the layer's name in errors
        default=argparse.SUPPRESS,
        help=f"{help} (default: the config's, else {default})",
        **kwargs,
    )


def add_goal(p: argparse.ArgumentParser) -> None:
    """``--goal``: the goal camera pose X_BC* (``goal``), as a pose."""
    add_field(
        p,
        "--goal",
        ("goal",),
        "goal camera pose X_BC* in the target frame [m, rad]",
        type=pose_arg,
        metavar="x,y,z,roll,pitch,yaw",
    )


class _VariantField(_ScenarioFlag):
    """Appends ``(flag, apply, value)`` to ``args.variant_fields``, in command-line order."""

    def __init__(self, *args: Any, apply: Any, **kwargs: Any):
        self.apply = apply
        super().__init__(*args, **kwargs)

    def __call__(self, parser, namespace, value, option_string=None) -> None:
        self._check(parser, value, option_string)
        entry = (option_string, self.apply, value)
        namespace.variant_fields = [*(getattr(namespace, "variant_fields", None) or []), entry]


def _set_variant_field(axis: str, names: tuple[str, ...], field: str):
    """How a variant flag applies: ``field`` of the ``axis`` variant the layers chose, if
    it is one of ``names`` (ValueError in one line where it is another)."""
    kinds = tuple(AXES[axis][name] for name in names)

    def apply(config: ScenarioConfig, flag: str, value: Any) -> None:
        variant = getattr(config, axis)
        if not isinstance(variant, kinds):  # the axis's variants by name, not a capability
            raise ValueError(
                f"{flag} applies to --{axis} {'|'.join(names)}, the {axis} here is "
                f"{variant_name(variant)}: add --{axis} {names[0]} (or {axis}: "
                f"!{kinds[0].__name__} {{...}} in the scenario)"
            )
        setattr(config, axis, dataclasses.replace(variant, **{field: value}))

    return apply


def add_variant_field(
    p: argparse.ArgumentParser,
    flag: str,
    axis: str,
    names: tuple[str, ...],
    field: str,
    help: str,
    **kwargs: Any,
) -> None:
    """``flag`` sets the field ``field`` of the ``axis`` variant (``carrier``, ``sensor``,
    ``controller``) whichever layer chose it, if it is one of ``names``
    (:data:`~geovs_drake.scenario.AXES`' names, e.g. ``("pinhole", "rendered")``); its
    help ends with the first variant's default."""
    default = kwargs.pop("shown", None) or _shown(getattr(AXES[axis][names[0]](), field))
    p.add_argument(
        flag,
        action=_VariantField,
        apply=_set_variant_field(axis, names, field),
        dest=flag,
        default=argparse.SUPPRESS,
        help=f"with --{axis} {'|'.join(names)}: {help} (default: the config's, else {default})",
        **kwargs,
    )


def add_variant_flag(
    p: argparse.ArgumentParser, flag: str, apply: Any, help: str, **kwargs: Any
) -> None:
    """``flag`` runs ``apply(config, flag, value)`` on the loaded scenario, after the
    layers and in command-line order among such flags (a flag that maps onto a union in
    its own way, as ``--mount`` does)."""
    p.add_argument(
        flag,
        action=_VariantField,
        apply=apply,
        dest=flag,
        default=argparse.SUPPRESS,
        help=help,
        **kwargs,
    )


def _apply_variant_fields(config: ScenarioConfig, fields: Sequence[tuple]) -> None:
    """Each variant flag on the loaded scenario (ValueError in one line where its variant
    is not the scenario's)."""
    for flag, apply, value in fields:
        apply(config, flag, value)


def add_config(p: argparse.ArgumentParser) -> None:
    """``--config FILE`` and ``--scenario-text YAML``, the two lowest layers."""
    p.add_argument(
        "--config",
        metavar="FILE",
        help="scenario YAML (fields of ScenarioConfig; --scenario-text and the options "
        "below override it) (default: none, the built-in scenario)",
    )
    p.add_argument(
        "--scenario-text",
        metavar="YAML",
        help="a YAML mapping of ScenarioConfig fields layered over --config and under the "
        'options, e.g. --scenario-text "{plant: !Kinematic {}, control: {kinematic_gain: 2}}" '
        "(default: none)",
    )
    p.set_defaults(layers=None, variant_fields=None)


def load_layers(args: argparse.Namespace) -> ScenarioConfig:
    """The scenario of ``args`` as the user gave it: ``--config``, ``--scenario-text``, then
    each flag, loaded once (ValueError: one line naming the layer or the field), not yet
    resolved: what a study varies before it resolves (the arm's gains stay unscaled)."""
    layers: list[tuple[str, Any]] = []
    if args.scenario_text is not None:
        layers.append(("--scenario-text", args.scenario_text))
    layers += args.layers or []
    config = load_scenario(args.config, overrides=layers)
    _apply_variant_fields(config, args.variant_fields or [])
    return config


def load_resolved(args: argparse.Namespace, effort: bool = False) -> ResolvedScenario:
    """The scenario of ``args`` (:func:`load_layers`), validated and resolved once (the
    arm's ``gain_scale: auto`` fitted there; ``effort``: with the dynamic arm's effort
    check, for a warning line). What is built from it trusts it."""
    # Here, not at the top: the command line starts without the loop's modules.
    from geovs_drake.loop.resolver import resolve

    return resolve(load_layers(args), effort=effort)


def load_config(args: argparse.Namespace) -> ScenarioConfig:
    """The validated scenario of ``args`` (:func:`load_resolved`), as a config to vary."""
    return load_resolved(args).config


#: The axes of :data:`~geovs_drake.scenario.AXES` whose variant is no bare name: a flag
#: gives its values (the target's twist, its trajectory file), so the command adds those
#: flags itself; every other axis gets ``--AXIS NAME`` from :func:`add_axes`.
VALUE_AXES: dict[str, tuple[str, ...]] = {
    "target_motion": ("--target-twist", "--target-trajectory"),
}


def _first_sentence(kind: type) -> str:
    """A variant's docstring's first sentence, as plain text: what a variant that a
    command describes in no words of its own shows in the help."""
    text = " ".join((kind.__doc__ or kind.__name__).split()).replace("``", "")
    return text.split(". ")[0].rstrip(".")


def add_axis(
    p: argparse.ArgumentParser,
    axis: str,
    what: str,
    described: dict[str, str] | None = None,
    *,
    names: Sequence[str] | None = None,
    after: str = "",
) -> None:
    """``--AXIS NAME``, a layer choosing the variant of ``axis`` by its name in
    :data:`~geovs_drake.scenario.AXES` (``--carrier arm`` is ``{carrier: !Arm {}}``).
    Its choices are ``names``, default every variant of the axis: a variant added to the
    axis is a choice with no edit here. Its help is ``what``, then each name with its
    text in ``described``, else its class's first sentence, then ``after``."""
    names = tuple(AXES[axis]) if names is None else tuple(names)
    described = described or {}
    each = "; ".join(
        f"{name}: {described.get(name) or _first_sentence(AXES[axis][name])}" for name in names
    )
    add_field(
        p,
        f"--{axis.replace('_', '-')}",
        (axis,),
        f"{what}: {each}{after}",
        choices=names,
    )


def add_axes(p: argparse.ArgumentParser, helps: dict[str, tuple[str, dict[str, str]]]) -> None:
    """``--AXIS NAME`` (:func:`add_axis`) for every axis of
    :data:`~geovs_drake.scenario.AXES` but :data:`VALUE_AXES`, in AXES' order; ``helps``:
    axis -> (what it is, a text per variant), where a command has words of its own."""
    for axis in AXES:
        if axis not in VALUE_AXES:
            what, described = helps.get(axis, (f"the {axis.replace('_', ' ')}", {}))
            add_axis(p, axis, what, described)


#: What ``--plant``'s names say, in every command that takes it.
PLANT_HELP: dict[str, str] = {
    "dynamic": "the MultibodyPlant free body driven by a wrench",
    "kinematic": "the camera's twist is commanded",
}


def add_plant(p: argparse.ArgumentParser, dynamic_detail: str = "") -> None:
    """``--plant dynamic|kinematic``, a layer (:func:`add_axis`)."""
    described = dict(PLANT_HELP, dynamic=PLANT_HELP["dynamic"] + dynamic_detail)
    add_axis(p, "plant", "how the carrier is driven", described)


def frames_arg(text: str) -> int:
    """A whole number of frames >= 0."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number of frames >= 0, got {text!r}")
    return value


def add_latency_frames(p: argparse.ArgumentParser) -> None:
    """``--latency-frames N``: the camera sensor's ``latency_frames`` (Pinhole or
    Rendered); under the exact sensor, one line naming ``--sensor pinhole``."""
    add_variant_field(
        p,
        "--latency-frames",
        "sensor",
        ("pinhole", "rendered"),
        "latency_frames",
        "the camera's latency: the law acts on the frame taken N periods ago",
        type=frames_arg,
        metavar="N",
    )


# ---- options with the same meaning in every command
def add_duration(p: argparse.ArgumentParser, what: str, default: float | None, shown: str) -> None:
    """``--duration T`` [s] that is not the scenario's field (sweep, compare, demo, ...)."""
    p.add_argument(
        "--duration",
        type=float,
        default=default,
        metavar="T",
        help=f"{what} [s] (default: {shown})",
    )


def add_out(p: argparse.ArgumentParser, default: str, contents: str) -> None:
    """``--out DIR``, the output folder."""
    p.add_argument("--out", default=default, metavar="DIR", help=f"{contents} (default: {default})")


def add_json(p: argparse.ArgumentParser, what: str = "one JSON object") -> None:
    """``--json``: stdout is JSON, not a line of text."""
    p.add_argument("--json", action="store_true", help=f"print {what} (default: one line of text)")


def add_workers(
    p: argparse.ArgumentParser, default: int, what: str = "worker processes", shown: str = ""
) -> None:
    """``--workers K``, processes; 1 runs in this process."""
    p.add_argument(
        "--workers",
        type=int,
        default=default,
        metavar="K",
        help=f"{what}; 1 runs in this process (default: {shown or default})",
    )


# ---- checks before anything runs (one line, exit code 2)
def check_at_least_1(args: argparse.Namespace, *names: str) -> None:
    """ValueError ``--name must be >= 1: --name value`` for the first count below 1."""
    for name in names:
        value = getattr(args, name)
        flag = "--" + name.replace("_", "-")
        if value < 1:
            raise ValueError(f"{flag} must be >= 1: {flag} {value}")


def check_duration(value: float, flag: str = "--duration") -> None:
    """ValueError unless ``value`` [s] is finite and > 0."""
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{flag} must be finite and > 0 [s]: {flag} {value}")


def check_out(out: str | Path) -> None:
    """ValueError if the output folder ``out`` exists and is not a directory."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a directory")
