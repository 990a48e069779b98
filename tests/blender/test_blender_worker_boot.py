"""The script's worker processes, in the real bpy: a json.py and a numpy.py beside the user's .blend (the
working folder) never run in a worker, the bake uses its worker processes (no fall back to threads);
--processes 1000 on this machine starts at most a process a core and says so."""

import json
import subprocess
import sys
import textwrap

import pytest

from blender_helpers import ROOT, add_plane, clean_scene, select_only

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
SABOTAGE = textwrap.dedent("""
    import os, sys
    open(os.path.join(os.path.dirname(os.path.abspath(__file__)), __name__ + ".ran"), "w").close()
    sys.exit("{name}.py from the working folder ran")
""")


@pytest.fixture(scope="module")
def folder(bpy, addon, tmp_path_factory):
    """A user's folder: the .blend file, and a json.py and a numpy.py that must never run."""
    scene = clean_scene(bpy)
    floor = add_plane(bpy, "Floor", size=4)
    add_plane(bpy, "Lid", size=2, location=(0, 0, 0.3))
    select_only(bpy, floor)
    scene.mc_ao.processes = 1
    folder = tmp_path_factory.mktemp("assets")
    bpy.ops.wm.save_as_mainfile(filepath=str(folder / "scene.blend"), copy=True)
    for name in ("json", "numpy"):
        (folder / f"{name}.py").write_text(SABOTAGE.format(name=name))
    return folder


def bake(folder, processes, tmp_path):
    summary = tmp_path / "summary.json"
    proc = subprocess.run([sys.executable, SCRIPT, "scene.blend", "--objects", "Floor", "--resolution", "32",
                           "--samples", "8", "--threads", "1", "--processes", str(processes), "--output",
                           str(tmp_path / "out"), "--summary-json", str(summary)],
                          cwd=folder, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc, json.loads(summary.read_text())


def test_a_json_and_a_numpy_beside_the_blend_never_run_in_a_worker(folder, tmp_path):
    proc, _ = bake(folder, 2, tmp_path)
    assert not list(folder.glob("*.ran")), proc.stderr
    assert "worker process" not in proc.stderr and "threads of this process" not in proc.stderr, proc.stderr


def test_a_thousand_processes_start_at_most_a_process_a_core_and_say_so(folder, tmp_path):
    from core.base.machine import cpu_count

    proc, _ = bake(folder, 1000, tmp_path)
    assert f"asked for 1000 worker processes, baked on {cpu_count()}" in proc.stderr or \
        "asked for 1000 worker processes, baked on" in proc.stderr and "memory for" in proc.stderr, proc.stderr
