"""What a script bake prints: its own lines only (none of Blender's log lines: the file it read, the
temporary copy it saved), and objects counted as objects (one baked for AO and thickness is one).
Run on bpy 4.2 and 5.0 (scripts/test_bpy42.sh): their log lines differ."""

import ctypes
import os
import re
import subprocess
import sys

import pytest

from blender_helpers import ROOT, add_cube, add_plane, new_session, select_only, tick_until

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
SUZANNE = str(ROOT / "sample_scenes" / "suzanne.blend")
#: What Blender itself writes when it opens or saves a file, in 4.2 and 5.0.
BLENDER_LINES = re.compile(r"Read blend|Saved copy as|Saved \"|\.tmp\.blend|Total files")


def script(*args, cwd):
    return subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True, timeout=600, cwd=cwd)


def test_a_script_bake_prints_no_blender_log_line(tmp_path):
    """A colour-attribute bake saved with --save: Blender opens one file and saves another, and says
    neither; the script says what it saved."""
    proc = script(SUZANNE, "--objects", "Suzanne", "--target", "vertex-colors", "--samples", "4",
                  "--save", str(tmp_path / "baked.blend"), "--output", str(tmp_path), "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert not BLENDER_LINES.search(proc.stdout + proc.stderr), proc.stdout + proc.stderr
    assert f"bake_ao: saved {tmp_path / 'baked.blend'} with the color attribute 'AO' of Suzanne" in proc.stdout
    assert proc.stdout.splitlines()[0] == "bake_ao: [1/1] baking Suzanne"


def test_blenders_other_lines_still_get_through(capfd):
    """Only Blender's routine lines go: whatever else its C code writes while a file is opened (a
    warning about the file) is passed on, in order."""
    from mc_ao.cli.blenderlog import blender_output

    libc = ctypes.CDLL(None)
    with blender_output():
        os.write(1, b'00:00.511  blend            | Read blend: "/x/scene.blend"\n')
        libc.printf(b"Warning: the file was saved by a newer Blender\n")  # C stdio, buffered
        libc.printf(b'Info: Saved copy as ".mc_ao-1.tmp.blend"\n')
    assert capfd.readouterr().out == "Warning: the file was saved by a newer Blender\n"


def test_one_object_with_two_quantities_is_one_object(tmp_path):
    proc = script(SUZANNE, "--objects", "Suzanne", "--quantity", "ao", "thickness", "--max-distance", "0.5",
                  "--resolution", "16", "--samples", "4", "--output", str(tmp_path), "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "bake_ao: [1/1] baking Suzanne (AO and thickness)" in proc.stdout
    assert "[2/" not in proc.stdout + proc.stderr
    assert proc.stdout.rstrip().endswith("bake_ao: baked 1 of 1 objects")
    rows = [line.split()[:2] for line in proc.stdout.splitlines() if line.startswith("Suzanne")]
    assert rows == [["Suzanne:", "AO"], ["Suzanne:", "thickness"]]


def test_the_operator_counts_an_object_with_two_quantities_once(bpy, scene):
    """The panel's last line after AO and thickness of two objects: "2 objects (AO and thickness)", and
    after one object's: "1 object (AO and thickness)"."""
    from mc_ao import operators

    ground = add_plane(bpy, "Ground", size=4)
    block = add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    scene.mc_ao.quantity = {"AO", "THICKNESS"}
    scene.mc_ao.max_distance = 1.0
    for objects, words in (((ground, block), "2 objects"), ((block,), "1 object")):
        select_only(bpy, *objects)
        session, reports = new_session()
        assert session.start(bpy.context, live=False)
        assert tick_until(bpy, session, lambda: False) == {"FINISHED"}
        kind, text = reports[-1]
        assert kind == "INFO" and text.startswith(f"AO bake: {words} (AO and thickness) in "), text
        assert operators.last_outcome == reports[-1]


def test_a_thickness_map_at_its_defaults_says_its_distance(tmp_path):
    proc = script(SUZANNE, "--objects", "Suzanne", "--quantity", "thickness", "--resolution", "16", "--samples", "4",
                  "--output", str(tmp_path), "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"bake_ao: Suzanne: thickness map: rays into the mesh up to [0-9.]+ cm \(a twentieth of its "
                     r"size: set --max-distance for another\)", proc.stderr), proc.stderr
