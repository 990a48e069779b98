"""core's modules import each other in one direction only: the layers of core/README.md, bottom up, each
module importing modules of its own layer or of layers below (imports inside functions included), no
import cycle, no module over 700 lines, and no module reading another's private names. No numpy
needed: the imports are read from the source.

``python tests/test_core_layers.py`` prints the graph: each module, its layer, its lines, what it imports."""

import ast
from pathlib import Path

from importgraph import assert_no_cycle

CORE = Path(__file__).resolve().parent.parent / "core"
#: core/README.md's layers, bottom to top: a module imports modules of its own layer or below. The
#: package's own ``__init__`` (the public names) and ``demo`` (a command) are above them all.
LAYERS = ["base", "montecarlo", "files", "geometry", "tracing", "engine", "execution", "highpoly", "post", "targets",
          "pipeline", "top"]
TOP = {"__init__", "demo"}
MAX_LINES = 700


def module_name(path):
    parts = list(path.relative_to(CORE).with_suffix("").parts)
    if parts[-1] == "__init__" and len(parts) > 1:
        parts = parts[:-1]
    return ".".join(parts)


def modules():
    return {module_name(p): p for p in sorted(CORE.rglob("*.py"))}


def _package(name, path):
    """The package a module's relative imports start from."""
    if path.name == "__init__.py":
        return name.split(".") if name != "__init__" else []
    return name.split(".")[:-1]


def _resolve(base, names):
    """The core module a dotted name inside core stands for (a name inside a module: the module)."""
    target = ".".join(base)
    while target and target not in names:
        target = target.rpartition(".")[0]
    return target or "__init__"


def imports():
    """module -> {imported core module: [(line, names imported from it)]}: every relative import,
    at the top or inside functions; ``from . import x`` of a module counts as importing x."""
    found = modules()
    graph = {}
    for name, path in found.items():
        package = _package(name, path)
        edges = {}
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    assert not alias.name.split(".")[0] == "core", f"core.{name} imports {alias.name} absolutely"
            if not isinstance(node, ast.ImportFrom) or node.level == 0:
                continue
            base = package[:len(package) - (node.level - 1)] if node.level > 1 else list(package)
            if node.module:
                target = _resolve(base + node.module.split("."), found)
                edges.setdefault(target, []).append((node.lineno, [a.name for a in node.names]))
                for alias in node.names:  # from .pkg import module
                    sub = ".".join(base + node.module.split(".") + [alias.name])
                    if sub in found:
                        edges.setdefault(sub, []).append((node.lineno, []))
            else:
                for alias in node.names:
                    target = _resolve(base + [alias.name], found)
                    edges.setdefault(target, []).append((node.lineno, []))
        edges.pop(name, None)
        graph[name] = edges
    return graph


def layer_of(module):
    if module in TOP:
        return LAYERS.index("top")
    head = module.split(".")[0]
    assert head in LAYERS, f"core.{module} is in no layer of LAYERS (tests/test_core_layers.py, core/README.md)"
    return LAYERS.index(head)


def test_every_module_is_in_a_layer_folder():
    for name in modules():
        if name not in TOP | {"_version"}:
            assert "." in name or name in LAYERS, f"core/{name}.py lies outside the layer folders"
        layer_of(name) if name != "_version" else None


def test_the_graph_reads_every_kind_of_import():
    graph = imports()
    assert "base.errors" in graph["engine.settings"] or "base.machine" in graph["engine.settings"]
    assert "montecarlo.warps" in graph["engine.kernel"]  # from ..montecarlo import warps
    assert "post.denoise.guide" in graph["post.denoise.filter"]  # from .guide import RADIUS
    assert "geometry.raster" in graph["post.denoise.guide"]  # inside a function, and at the top


def test_no_import_cycle():
    assert_no_cycle(imports())


def test_nothing_imports_a_module_of_a_layer_above_its_own():
    for module, edges in imports().items():
        if module == "_version":
            continue
        for other, where in edges.items():
            if other == "_version":
                continue
            assert layer_of(other) <= layer_of(module), (
                f"core.{module} (layer {LAYERS[layer_of(module)]}) imports core.{other} (layer "
                f"{LAYERS[layer_of(other)]}, above it) at line {where[0][0]}")


def test_no_module_reads_another_modules_private_names():
    graph = imports()
    for module, edges in graph.items():
        for other, where in edges.items():
            for line, names in where:
                private = [n for n in names if n.startswith("_") and not n.startswith("__")]
                assert not private, f"core.{module} imports {private} from core.{other} (line {line})"
    found = modules()
    for module, path in found.items():
        tree = ast.parse(path.read_text())
        aliases = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level > 0:
                base = _package(module, path)
                base = base[:len(base) - (node.level - 1)] if node.level > 1 else list(base)
                for alias in node.names:
                    full = ".".join(base + (node.module.split(".") if node.module else []) + [alias.name])
                    if full in found:
                        aliases.add(alias.asname or alias.name)
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                raise AssertionError(f"core.{module} reads {node.value.id}.{node.attr} (line {node.lineno})")


def test_no_module_is_longer_than_700_lines():
    for name, path in modules().items():
        lines = len(path.read_text().splitlines())
        assert lines <= MAX_LINES, f"core/{path.relative_to(CORE)} has {lines} lines (at most {MAX_LINES})"


if __name__ == "__main__":
    found = modules()
    for module, edges in sorted(imports().items(), key=lambda kv: (layer_of(kv[0]) if kv[0] != "_version" else -1,
                                                                     kv[0])):
        lines = len(found[module].read_text().splitlines())
        layer = "-" if module == "_version" else LAYERS[layer_of(module)]
        print(f"{layer:10s} {module:28s} {lines:4d}  -> {', '.join(sorted(edges))}")
