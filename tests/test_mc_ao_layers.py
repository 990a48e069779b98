"""mc_ao's modules import each other in one direction only: no import cycle (also through imports
inside functions), and nothing below the operator imports the operator, the panel or the preview.
No bpy needed: the imports are read from the source."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "mc_ao"
# The Blender UI: only register() (mc_ao/__init__.py) and each other may import these.
UI = {"operators", "panel", "preview", "properties"}


def imports():
    """module -> the mc_ao modules it imports (relative imports anywhere in it)."""
    graph = {}
    for path in sorted(PACKAGE.glob("*.py")):
        name = path.stem
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                if node.module:
                    found.add(node.module.split(".")[0])
                else:
                    found.update(alias.name for alias in node.names)
        graph[name] = found - {name}
    return graph


def test_no_import_cycle():
    graph = imports()
    state = {}

    def visit(module, stack):
        if state.get(module) == "done":
            return
        if state.get(module) == "open":
            cycle = stack[stack.index(module):] + [module]
            raise AssertionError("import cycle: " + " -> ".join(cycle))
        state[module] = "open"
        for other in sorted(graph.get(module, ())):
            visit(other, stack + [module])
        state[module] = "done"

    for module in graph:
        visit(module, [])


def test_nothing_below_the_ui_imports_it():
    for module, imported in imports().items():
        if module not in UI and module != "__init__":
            assert not imported & UI, f"mc_ao.{module} imports {sorted(imported & UI)}"


def test_names_say_purpose_not_history():
    for path in PACKAGE.glob("*.py"):
        text = path.read_text().lower()
        for word in ("issue 1", "issue1", "round 1", "issue14"):
            assert word not in text, f"{path.name} says {word!r}"
