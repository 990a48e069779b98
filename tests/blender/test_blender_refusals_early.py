"""Refusals that come before any work, saying what to change, and SIGTERM ending the script as Ctrl-C
does: a dangling symlink as the output folder (exit 2 up front, naming the link), --denoise with one
sample (naming --samples, not an internal setting), and SIGTERM mid-bake (exit 143, the summary says so)."""

import json
import os
import signal
import subprocess
import sys
import threading

import pytest

from blender_helpers import ROOT, add_plane, clean_scene, select_only

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")


@pytest.fixture(scope="module")
def blend_file(bpy, addon, tmp_path_factory):
    scene = clean_scene(bpy)
    floor = add_plane(bpy, "Floor", size=4)
    add_plane(bpy, "Lid", size=2, location=(0, 0, 0.3))
    select_only(bpy, floor)
    scene.mc_ao.processes = 1
    path = tmp_path_factory.mktemp("blend") / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def script(blend_file, *args, **kw):
    return subprocess.run([sys.executable, SCRIPT, str(blend_file), "--objects", "Floor", "--threads", "1",
                           "--processes", "1", *map(str, args)], capture_output=True, text=True, timeout=300, **kw)


def test_a_dangling_symlink_as_the_output_folder_is_refused_before_baking(blend_file, tmp_path):
    os.symlink(tmp_path / "gone", tmp_path / "out")
    p = script(blend_file, "--resolution", "16", "--samples", "4", "--output", tmp_path / "out",
               "--summary-json", tmp_path / "s.json")
    assert p.returncode == 2, p.stdout + p.stderr
    assert f"it is a link to '{tmp_path / 'gone'}', which does not exist" in p.stderr and "nothing was baked" in p.stderr
    assert "baking Floor" not in p.stdout  # before any work
    assert json.loads((tmp_path / "s.json").read_text())["exit_code"] == 2
    # Deeper: a folder inside the dangling link.
    p = script(blend_file, "--resolution", "16", "--samples", "4", "--output", tmp_path / "out" / "textures")
    assert p.returncode == 2 and f"'{tmp_path / 'out'}' is a link to" in p.stderr, p.stdout + p.stderr


def test_denoise_with_one_sample_names_the_samples_to_raise(blend_file, tmp_path):
    p = script(blend_file, "--resolution", "16", "--samples", "1", "--denoise", "--output", tmp_path / "out")
    assert p.returncode == 2, p.stdout + p.stderr
    assert "--samples must be at least 2 with --denoise" in p.stderr and "replicates" not in p.stderr, p.stderr
    assert not (tmp_path / "out").exists()


def _default_signals():
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def test_sigterm_ends_the_script_with_its_summary(blend_file, tmp_path):
    """The script is frozen when it says it bakes, sent SIGTERM, thawed: it stops as Ctrl-C stops it."""
    summary = tmp_path / "s.json"
    proc = subprocess.Popen([sys.executable, SCRIPT, str(blend_file), "--objects", "Floor", "--threads", "1",
                             "--processes", "1", "--resolution", "256", "--samples", "1024", "--output",
                             str(tmp_path / "out"), "--summary-json", str(summary)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_signals)
    watchdog = threading.Timer(300, proc.kill)
    watchdog.start()
    try:
        for line in proc.stdout:
            if "baking Floor" in line:
                proc.send_signal(signal.SIGSTOP)
                proc.send_signal(signal.SIGTERM)
                proc.send_signal(signal.SIGCONT)
                break
        out, err = proc.communicate()
    finally:
        watchdog.cancel()
    assert proc.returncode == 143, out + err
    assert "terminated (SIGTERM); nothing of Floor was written" in err
    data = json.loads(summary.read_text())
    assert data["exit_code"] == 143 and data["error"] == "terminated (SIGTERM)"
    assert data["objects"] == [dict(data["objects"][0], object="Floor", status="failed",
                                    error="not baked: terminated (SIGTERM)")]
    assert not (tmp_path / "out" / "Floor_AO.png").exists()
