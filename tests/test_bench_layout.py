"""The bench's layout: its modules import each other without a cycle, each folder imports only the
ones below it, and its two commands (python -m bench, python -m bench.device) start."""

import ast
import os
import subprocess
import sys
from pathlib import Path

from importgraph import assert_no_cycle

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
# A module may import from its own folder and from folders after its own in this order, never before:
# the sections use the comparators and the harness; the comparators use the harness; the harness imports
# the sections only where its command runs them (harness.run.main).
ORDER = ("prototypes", "sections", "comparators", "harness")


def _module(path):
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path):
    """The bench modules ``path`` imports, at the top or inside functions: (module, imported, lineno)."""
    name = _module(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            targets = [target] + [f"{target}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        else:
            continue
        for t in targets:
            where = ROOT / t.replace(".", "/")
            if t.split(".")[0] == "bench" and (where.with_suffix(".py").exists() or (where / "__init__.py").exists()):
                out.append((name, t, node.lineno))
    return out


def _graph():
    edges = {}
    for path in sorted(BENCH.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        edges.setdefault(_module(path), set())
        for src, dst, _ in _imports(path):
            if dst != src:
                edges[src].add(dst)
    return edges


def _folder(module):
    parts = module.split(".")
    return parts[1] if len(parts) > 2 else None


def test_no_import_cycles():
    edges = _graph()
    assert_no_cycle(edges)
    assert "bench.harness.run" in edges and "bench.sections.adaptive" in edges


def test_folders_import_only_downwards():
    wrong = []
    for path in sorted(BENCH.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        for src, dst, line in _imports(path):
            a, b = _folder(src), _folder(dst)
            if a in ORDER and b in ORDER and ORDER.index(b) < ORDER.index(a) and src != "bench.harness.run":
                wrong.append(f"{path.relative_to(ROOT)}:{line} imports {dst}")
    assert not wrong, wrong


def test_the_import_graph_sees_a_cycle(tmp_path, monkeypatch):
    """The check itself: two modules importing each other are reported."""
    for name, other in (("a", "b"), ("b", "a")):
        (tmp_path / "bench" / "sections").mkdir(parents=True, exist_ok=True)
        (tmp_path / "bench" / "sections" / f"{name}.py").write_text(f"def f():\n    from . import {other}\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    monkeypatch.setattr(sys.modules[__name__], "BENCH", tmp_path / "bench")
    try:
        test_no_import_cycles()
    except AssertionError as exc:
        assert "import cycle" in str(exc)
    else:
        raise AssertionError("the cycle a -> b -> a was not found")


def test_the_commands_start(tmp_path):
    env = dict(os.environ, TMPDIR=str(tmp_path))  # python -m bench makes Blender's user folder there
    for module in ("bench", "bench.device", "bench.sections.adaptive", "bench.sections.floor"):
        out = subprocess.run([sys.executable, "-m", module, "--help"], cwd=ROOT, env=env, capture_output=True,
                             text=True, timeout=120)
        assert out.returncode == 0 and "usage:" in out.stdout, (module, out.stdout + out.stderr)
