"""The layers show in the imports: geometry imports nothing of ours above it,
systems only geometry, and no module imports itself back through another
(function-level imports included)."""

import ast
from pathlib import Path

import geovs_drake

ROOT = Path(geovs_drake.__file__).parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports() -> dict[str, set[str]]:
    """Every module of the package -> the package modules it imports, anywhere in it."""
    modules = {_module_name(p): p for p in ROOT.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            found |= {t for t in targets if t in modules and t != name}
        graph[name] = found
    return graph


#: Below every layer: modules that import nothing of ours (the optional-import helper,
#: the canonical order of spectra).
BASE = ("geovs_drake._optional", "geovs_drake._lazy", "geovs_drake._json", "geovs_drake.spectrum")


def test_geometry_and_systems_import_only_the_layers_below():
    graph = _imports()
    for name in BASE:
        assert not graph[name], (name, graph[name])
    for name, deps in graph.items():
        if name.startswith("geovs_drake.geometry"):
            allowed = ("geovs_drake.geometry", *BASE)
            assert all(d.startswith(allowed) for d in deps), (name, deps)
        if name.startswith("geovs_drake.systems"):
            allowed = ("geovs_drake.geometry", "geovs_drake.systems", *BASE)
            assert all(d.startswith(allowed) for d in deps), (name, deps)


def test_no_import_cycles():
    graph = _imports()
    # A package's __init__ re-exports its children; an edge child -> package
    # is the only way back, and counts like any other.
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for dep in sorted(graph[node]):
            if state.get(dep) == 1:
                cycle = path[path.index(dep) :] + [dep] if dep in path else [node, dep]
                raise AssertionError(f"import cycle: {' -> '.join(cycle)}")
            if dep not in state:
                visit(dep, path + [dep])
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])


#: The layers from the bottom up (as docs/python.md lists them): a module imports its own
#: layer's and the layers' below, never one above. Each entry is a module or a package
#: (its modules with it).
LAYERS: tuple[tuple[str, ...], ...] = (
    BASE,
    ("geovs_drake.geometry", "geovs_drake.sampling", "geovs_drake.progress"),
    ("geovs_drake.systems",),
    ("geovs_drake.scenario", "geovs_drake.scenarios", "geovs_drake.models"),
    ("geovs_drake.goal", "geovs_drake.planning", "geovs_drake.visualization"),
    ("geovs_drake.loop",),
    ("geovs_drake.simulation",),
    # The Panda over LCM (issue 34): the loop's parts and simulate's tolerances, behind a bus.
    ("geovs_drake.hardware",),
    ("geovs_drake.batch", "geovs_drake.plotting"),
    ("geovs_drake.analysis._pool", "geovs_drake.analysis.linear"),
    ("geovs_drake.analysis.studies", "geovs_drake.analysis.sweep", "geovs_drake.analysis"),
    ("geovs_drake.demo",),
    ("geovs_drake.cli",),
)


def _layer_of(module: str) -> int:
    """The index in LAYERS of the longest entry that is ``module`` or holds it."""
    best, where = -1, None
    for index, entries in enumerate(LAYERS):
        for entry in entries:
            if (module == entry or module.startswith(entry + ".")) and len(entry) > best:
                best, where = len(entry), index
    assert where is not None, f"{module} is in no layer: add it to LAYERS"
    return where


def test_every_module_imports_only_its_layer_and_the_layers_below():
    graph = _imports()
    upward = [
        (name, dep, _layer_of(name), _layer_of(dep))
        for name, deps in graph.items()
        if name != "geovs_drake"  # the package's root, which re-exports the version
        for dep in deps
        if dep != "geovs_drake" and _layer_of(dep) > _layer_of(name)
    ]
    assert not upward, "imports that go up a layer (module, import, layers): " + repr(upward)


#: The largest module and hand-written function the package keeps (issue 41): past these a
#: module holds several jobs and a function several steps, each of which wants a name.
MAX_MODULE_LINES, MAX_FUNCTION_LINES = 650, 100


def _template_factory(node: ast.FunctionDef) -> bool:
    """A TemplateSystem factory (``@template_system(...)``): one system's whole class,
    its ports and calculations, exempt from the function size like generated code; and
    a batch integrator's loop over its starts (``@njit(parallel=True)``, or
    ``@batch_kernel``, which ``geovs_drake.batch._threads.over_starts`` runs on threads),
    kept whole: the batch engine's integrator with its Bogacki-Shampine step as a kernel
    of its own ran the kinematic 10^4 starts 1.6 times slower (2.65 s against 4.18 s in
    _integrate alone, measured here; inline="always" did not recover it)."""
    return any(
        ast.unparse(d) == "batch_kernel"
        or ast.unparse(d).startswith("template_system")
        or "parallel=True" in ast.unparse(d)
        for d in node.decorator_list
    )


def test_no_module_over_650_lines_and_no_function_over_100():
    too_long = []
    for path in ROOT.rglob("*.py"):
        if "_generated" in path.parts:
            continue
        text = path.read_text()
        if text.count("\n") > MAX_MODULE_LINES:
            too_long.append(f"{path.relative_to(ROOT)}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef) and not _template_factory(node):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    too_long.append(f"{path.relative_to(ROOT)}:{node.name}: {length} lines")
    assert not too_long, too_long


def test_a_variants_type_is_asked_only_in_the_scenario():
    """The package asks a variant's traits (geovs_drake.scenario.traits), not its type:
    outside scenario/ no isinstance names a variant class (issue 41)."""
    import geovs_drake.scenario as scenario

    variants = {kind.__name__ for axis in scenario.AXES.values() for kind in axis.values()}
    variants |= {"CameraModel", "RigidBodyConfig"}
    asked = []
    for path in ROOT.rglob("*.py"):
        if path.relative_to(ROOT).parts[0] == "scenario":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "isinstance":
                names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                if names & variants:
                    asked.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}")
    assert not asked, asked
