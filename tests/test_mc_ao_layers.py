"""mc_ao's modules import each other in one direction only: no import cycle (also through imports
inside functions), nothing imports a module of a layer above its own (the layers of mc_ao/README.md),
nothing below the operator imports the operator, the panel or the preview, and no module is over
MAX_LINES lines (mc_ao_batch's neither). Subpackages (mc_ao/outputs/) count module by module. No bpy needed: the imports are read from the source.

``python tests/test_mc_ao_layers.py`` prints the graph: each module, its lines, what it imports."""

import ast
from pathlib import Path

from importgraph import assert_no_cycle

PACKAGE = Path(__file__).resolve().parent.parent / "mc_ao"
MAX_LINES = 700
# The Blender UI: only register() (mc_ao/__init__.py) and each other may import these.
UI = {"operators", "panel", "preview", "properties"}
# mc_ao/README.md's layers, top to bottom: a module imports modules of its own layer or below.
LAYERS = [
    {"__init__"} | UI,
    {"cli", "cli.*"},
    {"service"},
    {"outputs", "outputs.*"},
    {"precheck", "choose", "selected_to_active", "baking", "occluders", "atlas"},
    {"udim", "vertex_colors", "bent"},
    {"bakerun", "filewriter", "filecheck", "summaries"},
    {"images", "undo_images"},
    {"schema", "settings", "rules"},
    {"extract", "corelink", "terminal", "interrupts"},
]


def module_name(path):
    parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
    if parts[-1] == "__init__" and len(parts) > 1:
        parts = parts[:-1]
    return ".".join(parts)


def imports():
    """module -> the mc_ao modules it imports (relative imports anywhere in it, imports inside
    functions included); a subpackage's modules are named "outputs.maps", its __init__ "outputs"."""
    paths = sorted(PACKAGE.rglob("*.py"))
    names = {module_name(p) for p in paths}
    graph = {}
    for path in paths:
        name = module_name(path)
        if name == "__init__":
            package = []
        elif path.name == "__init__.py":
            package = name.split(".")
        else:
            package = name.split(".")[:-1]
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom) or node.level == 0:
                continue
            base = package[:len(package) - (node.level - 1)]
            if node.module:
                target = ".".join(base + node.module.split("."))
                while target and target not in names:  # a name inside a module: the module
                    target = target.rpartition(".")[0]
                if target:
                    found.add(target)
            else:
                for alias in node.names:
                    target = ".".join(base + [alias.name])
                    found.add(target if target in names else ".".join(base) or "__init__")
        graph[name] = found - {name}
    return graph


def layer_of(module):
    for k, layer in enumerate(LAYERS):
        if module in layer or ("." in module and module.partition(".")[0] + ".*" in layer):
            return k
    raise AssertionError(f"mc_ao.{module} is in no layer of LAYERS (tests/test_mc_ao_layers.py, mc_ao/README.md)")


def test_the_graph_reads_subpackages():
    graph = imports()
    assert "outputs.base" in graph["outputs.maps"]  # from .base import ...
    assert "outputs.udim_tiles" in graph["outputs.maps"]  # from . import udim_tiles
    assert "corelink" in graph["outputs.base"]  # from .. import corelink
    assert "outputs" in graph["service"]


def test_no_import_cycle():
    assert_no_cycle(imports())


def test_nothing_imports_a_module_above_it():
    for module, imported in imports().items():
        for other in imported:
            assert layer_of(other) >= layer_of(module), f"mc_ao.{module} imports mc_ao.{other}, a layer above it"


def test_nothing_below_the_ui_imports_it():
    for module, imported in imports().items():
        if module not in UI and module != "__init__":
            assert not imported & UI, f"mc_ao.{module} imports {sorted(imported & UI)}"


def test_no_module_is_over_the_line_limit():
    paths = sorted(PACKAGE.rglob("*.py")) + sorted((PACKAGE.parent / "mc_ao_batch").rglob("*.py"))
    long = {str(p.relative_to(PACKAGE.parent)): n for p in paths if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


if __name__ == "__main__":
    for module, imported in sorted(imports().items()):
        path = PACKAGE / (module.replace(".", "/") + ".py")
        if not path.exists():
            path = PACKAGE / module.replace(".", "/") / "__init__.py"
        lines = len(path.read_text().splitlines())
        print(f"{module:26s} {lines:4d}  -> {', '.join(sorted(imported))}")
