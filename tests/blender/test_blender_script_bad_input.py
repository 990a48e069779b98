"""Bad input to scripts/bake_ao.py: what a script user reads (stderr) and the exit status, files kept."""

import json
import os
import math
import re
import signal
import subprocess
import sys

import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene, old_file

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
PREVIOUS_PNG = old_file("x.png", "the previous bake")
FAST = ["--samples", "4", "--resolution", "16", "--threads", "1"]


def run_script(*args):
    return subprocess.run([sys.executable, SCRIPT, *map(str, args)], capture_output=True, text=True, timeout=120)


def save(bpy, path):
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


@pytest.fixture(scope="module")
def blends(bpy, tmp_path_factory):
    """mixed: Ground, Block, Flat (no UVs), Lamp; Ground, Flat and Lamp selected.
    unselected: the same with nothing selected. nan: Ground and Bad, whose first vertex is NaN."""
    folder = tmp_path_factory.mktemp("scenes")
    clean_scene(bpy)
    ground = add_plane(bpy, "Ground", size=4)
    block = add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    flat = add_plane(bpy, "Flat", size=1, location=(4, 0, 0))
    flat.data.uv_layers.remove(flat.data.uv_layers[0])
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 3))
    bpy.context.active_object.name = "Lamp"
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj.name in {"Ground", "Flat", "Lamp"})
    paths = {"mixed": save(bpy, folder / "mixed.blend")}
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    paths["unselected"] = save(bpy, folder / "unselected.blend")
    for obj in (block, flat, bpy.data.objects["Lamp"]):
        bpy.data.objects.remove(obj)
    bad = add_plane(bpy, "Bad", size=4, location=(6, 0, 0))
    bad.data.vertices[0].co = (float("nan"), 0.0, 0.0)
    paths["nan"] = save(bpy, folder / "nan.blend")
    bpy.data.objects.remove(bad)
    awry = add_plane(bpy, "Awry", size=4, location=(6, 0, 0))  # baked first: names sort before Ground
    for loop_uv in awry.data.uv_layers[0].data:
        loop_uv.uv = (loop_uv.uv[0] * 1e17, loop_uv.uv[1])
    paths["uvs"] = save(bpy, folder / "uvs.blend")
    assert ground.name == "Ground"
    clean_scene(bpy)
    return paths


@pytest.mark.parametrize("name, message", [
    ("Flat", "Flat has no UV map (unwrap it first: Edit Mode, U)"),
    ("Lamp", "Lamp is a light, not a mesh"),
])
def test_a_named_object_that_cannot_be_baked_exits_2(blends, tmp_path, name, message):
    proc = run_script(blends["mixed"], "--objects", "Ground", name, "--output", tmp_path, *FAST)
    assert proc.returncode == 2
    assert proc.stderr == f"bake_ao: error: {message}\n"
    assert not list(tmp_path.iterdir())


def test_selected_objects_that_cannot_be_baked_are_skipped_with_a_note(blends, tmp_path):
    proc = run_script(blends["mixed"], "--output", tmp_path, *FAST)
    assert proc.returncode == 0, proc.stderr
    assert "bake_ao: Flat: skipped, it has no UV map (unwrap it first: Edit Mode, U)\n" in proc.stderr
    assert "bake_ao: Lamp: skipped, it is a light, not a mesh\n" in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Ground_AO.png"]


def test_nothing_selected_bakes_every_mesh_with_uvs_and_says_so(blends, tmp_path):
    proc = run_script(blends["unselected"], "--output", tmp_path, *FAST)
    assert proc.returncode == 0, proc.stderr
    assert "bake_ao: nothing is selected; baking every mesh with a UV map: Block, Ground\n" in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Block_AO.png", "Ground_AO.png"]


def test_an_output_folder_under_a_file_exits_2_before_baking(blends, tmp_path):
    blocker = tmp_path / "afile"
    blocker.write_bytes(b"not a folder")
    folder = blocker / "sub"
    proc = run_script(blends["mixed"], "--objects", "Ground", "--output", folder, *FAST)
    assert proc.returncode == 2
    assert proc.stderr == (
        f"bake_ao: error: cannot write to the output folder '{folder}': '{blocker}' is a file, not a folder; "
        "nothing was baked\n"
    )
    assert "baking" not in proc.stdout
    assert blocker.read_bytes() == b"not a folder"


def test_a_core_error_fails_that_object_only(blends, tmp_path):
    (tmp_path / "Bad_AO.png").write_bytes(PREVIOUS_PNG)
    proc = run_script(blends["nan"], "--objects", "Bad", "Ground", "--occluders", "self", "--output", tmp_path, *FAST)
    assert proc.returncode == 1
    assert (
        "bake_ao: Bad: mesh 'Bad': positions contain 3 non-finite values (NaN first at index (0, 0))\n"
        in proc.stderr
    )
    assert "Traceback" not in proc.stderr
    assert "bake_ao: baked 1 of 2 objects, 1 failed" in proc.stdout
    assert (tmp_path / "Bad_AO.png").read_bytes() == PREVIOUS_PNG
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Bad_AO.png", "Ground_AO.png"]


# A fresh Python that puts SIGINT back to its default before it runs the script: a process started
# in the background by a non-interactive shell inherits SIGINT *ignored*, and the script, like any
# Unix program, keeps it so (that, not the machine's speed, made this test fail under a
# backgrounded `pytest &`).
WITH_SIGINT = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
               "os.execv(sys.executable, [sys.executable] + sys.argv[1:])")


def test_ctrl_c_during_a_bake_exits_130_and_writes_nothing(blends, tmp_path):
    """Ctrl-C once the bake traces rays (its first progress line, printed on the bake's first chunk)."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "Ground_AO.png").write_bytes(PREVIOUS_PNG)
    summary = tmp_path / "summary.json"
    # 65536 samples a texel at 256 x 256: hours of rays, cancelled within a chunk (one texel's rays).
    proc = subprocess.Popen(
        [sys.executable, "-c", WITH_SIGINT, SCRIPT, str(blends["mixed"]), "--objects", "Ground", "--output", str(out),
         "--samples", "65536", "--resolution", "256", "--threads", "1", "--summary-json", str(summary)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        seen = []
        for line in proc.stderr:  # the bake has traced its first chunk of rays
            seen.append(line)
            if re.fullmatch(r"bake_ao: \[1/1\] Ground: \d+%\n", line):
                break
        else:
            pytest.fail(f"no progress line: {''.join(seen)}")
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)  # a hang guard only: the cancel takes a chunk
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert err.endswith("bake_ao: cancelled; nothing of Ground was written (any file there is as it was)\n")
    assert (out / "Ground_AO.png").read_bytes() == PREVIOUS_PNG
    assert sorted(p.name for p in out.iterdir()) == ["Ground_AO.png"]
    record = json.loads(summary.read_text())
    assert record["exit_code"] == 130 and record["error"] == "cancelled (Ctrl-C)"
    assert record["objects"] == [{"object": "Ground", "status": "failed", "seconds": 0.0, "rays": 0,
                                  "samples_per_texel": 0.0, "files": [], "file_stats": {},
                                  "error": "not baked: cancelled (Ctrl-C)"}]


# Runs the script with SIGINT sent to itself right after its first image file is written: a Ctrl-C
# that lands between two files of one object.
CTRL_C_AFTER_FIRST_FILE = """
import os, runpy, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)
sys.path.insert(0, sys.argv[1])
import core.files.imageio as imageio
real = imageio.write_image
def write_image(*args, **kwargs):
    written = real(*args, **kwargs)
    if not getattr(write_image, "sent", False):
        write_image.sent = True
        os.kill(os.getpid(), signal.SIGINT)
    return written
imageio.write_image = write_image
sys.argv = sys.argv[2:]
runpy.run_path(sys.argv[0], run_name="__main__")
"""


def test_ctrl_c_between_an_objects_files_writes_all_of_them_and_says_so(blends, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    names = ["Ground_AO.png", "Ground_AO.exr", "Ground_AO.tif", "Block_AO.png"]
    for name in names:
        (out / name).write_bytes(old_file(name, "the previous bake"))
    proc = subprocess.run(
        [sys.executable, "-c", CTRL_C_AFTER_FIRST_FILE, str(ROOT), SCRIPT, str(blends["mixed"]), "--objects", "Ground",
         "Block", "--output", str(out), "--format", "png", "exr", "tif", *FAST],
        capture_output=True, text=True, timeout=300)
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.endswith("bake_ao: cancelled; every file of Ground is written; nothing of Block was written "
                                "(any file there is as it was)\n"), proc.stderr
    assert all((out / n).read_bytes() != old_file(n, "the previous bake") for n in names[:3])  # all of Ground's
    assert (out / "Block_AO.png").read_bytes() == PREVIOUS_PNG
    assert sorted(p.name for p in out.iterdir()) == sorted(names)


# Runs the script and kills it (SIGKILL: nothing of it runs after) once its first temporary file is
# written, before that file is checked and renamed.
KILLED_MID_WRITE = """
import os, runpy, signal, sys
sys.path.insert(0, sys.argv[1])
from core.files import atomicfile
def finish(self, verify=None):
    os.kill(os.getpid(), signal.SIGKILL)
atomicfile.PendingFile.finish = finish
sys.argv = sys.argv[2:]
runpy.run_path(sys.argv[0], run_name="__main__")
"""


def test_a_killed_run_keeps_the_old_files_and_the_next_run_removes_its_temporary_files(blends, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "Ground_AO.png").write_bytes(PREVIOUS_PNG)
    args = [str(blends["mixed"]), "--objects", "Ground", "--output", str(out), *FAST]
    proc = subprocess.run([sys.executable, "-c", KILLED_MID_WRITE, str(ROOT), SCRIPT, *args],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert (out / "Ground_AO.png").read_bytes() == PREVIOUS_PNG
    left = [p.name for p in out.iterdir() if p.name.startswith(".mc_ao-")]
    assert left, "the killed run left no temporary file: the test did not kill it mid-write"
    proc = subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["Ground_AO.png"]
    assert (out / "Ground_AO.png").read_bytes() != PREVIOUS_PNG


# -- every setting is checked before anything is baked: exit 2, once ------------------------------

INFINITY_MESSAGE = "must be a distance >= 0 (0 or inf = unlimited)"


@pytest.mark.parametrize("args, message", [
    (["--samples", "0"], "--samples must be from 1 to 1048576, not 0"),
    (["--samples", "-5"], "--samples must be from 1 to 1048576, not -5"),
    (["--samples", "1048577"], "--samples must be from 1 to 1048576, not 1048577"),
    (["--min-samples", "0"], "--min-samples must be from 1 to 1048576, not 0"),
    (["--max-distance", "-1"], f"--max-distance {INFINITY_MESSAGE}, not -1.0"),
    (["--max-distance", "nan"], f"--max-distance {INFINITY_MESSAGE}, not nan"),
    (["--max-distance=-inf"], f"--max-distance {INFINITY_MESSAGE}, not -inf"),
    (["--resolution", "65537"], "--resolution must be at most 65536 a side, not 65537x65537"),
    (["--resolution", "16x70000"], "--resolution must be at most 65536 a side, not 16x70000"),
    (["--margin", "-1"], "--margin must be from 0 to 65536, not -1"),
    (["--seed", "-1"], f"--seed must be from 0 to {2**64 - 1}, not -1"),
    (["--seed", str(10**30)], f"--seed must be from 0 to {2**64 - 1}, not {10**30}"),
    (["--threads", "-1"], "--threads must be from 0 to 1024 (0 = every core), not -1"),
    (["--target-error", "nan"], "--target-error must be a finite number >= 0 (0 = adaptive sampling off), not nan"),
    (["--target-error", "-0.1"], "--target-error must be a finite number >= 0 (0 = adaptive sampling off), not -0.1"),
    (["--target-error", "inf"], "--target-error must be a finite number >= 0 (0 = adaptive sampling off), not inf"),
    (["--bits", "8", "--format", "exr"], "--bits 8 cannot be written as exr: exr files take --bits half or float"),
    (["--bits", "float", "--format", "tif", "png"], "--bits float cannot be written as png: png files take --bits 8 or 16"),
    (["--image-name", "../{object}"], "--image-name '../{object}' is a path: give a name; files go into --output"),
    (["--objects", "Ground", "Nope"], "no object 'Nope' in the view layer; its meshes: Block, Flat, Ground"),
])
def test_a_bad_setting_exits_2_once_before_anything_is_baked(blends, tmp_path, args, message):
    summary = tmp_path / "summary.json"
    proc = run_script(blends["mixed"], "--objects", "Ground", "Block", "--output", tmp_path / "out",
                      "--summary-json", summary, *FAST, *args)
    assert proc.returncode == 2
    assert proc.stderr == f"bake_ao: error: {message}\n"  # said once, not once per object
    assert "baking" not in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]  # no output folder made
    record = json.loads(summary.read_text())
    assert record["exit_code"] == 2 and record["error"] == message
    assert record["settings"] == {} and record["objects"] == []
    assert record["blend"] == str(blends["mixed"])


def test_a_bad_argument_says_so_with_the_usage(blends, tmp_path):
    summary = tmp_path / "summary.json"
    proc = run_script(blends["mixed"], "--samples", "many", "--summary-json", summary)
    assert proc.returncode == 2
    assert proc.stderr.startswith("bake_ao: error: argument --samples: invalid int value: 'many'\nusage: bake_ao.py")
    assert json.loads(summary.read_text())["error"].startswith("argument --samples: invalid int value: 'many'")


def test_an_unwritable_summary_path_exits_2_before_baking(blends, tmp_path):
    proc = run_script(blends["mixed"], "--objects", "Ground", "--output", tmp_path / "out",
                      "--summary-json", tmp_path, *FAST)
    assert proc.returncode == 2
    assert proc.stderr == f"bake_ao: error: cannot write the summary '{tmp_path}': it is a folder; nothing was baked\n"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("distance", ["0", "inf"])
def test_zero_and_inf_max_distance_are_unlimited(blends, tmp_path, distance):
    from core.files import imageio

    proc = run_script(blends["mixed"], "--objects", "Ground", "--output", tmp_path, "--max-distance", distance,
                      "--summary-json", tmp_path / "s.json", *FAST)
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "s.json").read_text())["settings"]["max_distance"] == math.inf
    assert imageio.read_image(tmp_path / "Ground_AO.png")[1]["max_distance"] == math.inf


def test_a_too_long_image_name_becomes_a_shorter_file_name(blends, tmp_path):
    """A name too long for the file system is shortened before the bake, not refused after it ("File name too long")."""
    long_name = "L" * 300 + "{object}"
    proc = run_script(blends["mixed"], "--objects", "Ground", "--output", tmp_path / "out",
                      "--image-name", long_name, *FAST)
    assert proc.returncode == 0, proc.stderr
    (path,) = (tmp_path / "out").iterdir()
    # The file is named after the image, whose name Blender keeps to 255 bytes (5.0) or 63 (4.2 to 4.4).
    assert re.fullmatch(r"L{40,}-[0-9a-f]{8}\.png", path.name) and len(path.name.encode()) <= 255, path.name
    assert list(tmp_path.iterdir()) == [tmp_path / "out"]


def test_a_bad_uv_map_fails_that_object_and_the_others_are_baked(blends, tmp_path):
    summary = tmp_path / "summary.json"
    proc = run_script(blends["uvs"], "--objects", "Awry", "Ground", "--output", tmp_path / "out",
                      "--summary-json", summary, *FAST)
    assert proc.returncode == 1
    # The core's words (core.geometry.mesh), named by the object: "mesh 'Awry': 2 triangles have UV coordinates
    # beyond +-65536 (largest 1e+17, first at triangle 0); a UV map lies in [0, 1]: ..."
    assert re.search(r"^bake_ao: Awry: mesh 'Awry': .*UV coordinates.*1e\+17.*$", proc.stderr, re.M), proc.stderr
    assert "Traceback" not in proc.stderr
    assert "bake_ao: baked 1 of 2 objects, 1 failed" in proc.stdout
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["Ground_AO.png"]
    record = json.loads(summary.read_text())
    assert record["exit_code"] == 1 and record["error"] == "1 of 2 objects failed"
    awry, ground = record["objects"]
    assert awry["status"] == "failed" and awry["error"].startswith("mesh 'Awry': ")
    assert awry["files"] == [] and awry["rays"] == 0 and awry["seconds"] >= 0
    assert ground["status"] == "ok" and ground["error"] is None
    assert ground["files"] == [str(tmp_path / "out" / "Ground_AO.png")]


# -- the summary of a run that went well --------------------------------------------------------------

def test_the_summary_records_the_settings_every_file_carries(blends, tmp_path):
    from core.files import imageio
    from core._version import OUTPUT_VERSION, __version__

    summary = tmp_path / "summary.json"
    out = tmp_path / "out"
    proc = run_script(blends["unselected"], "--output", out, "--format", "png", "exr", "tif", "--stderr",
                      "--summary-json", summary, "--max-distance", "2.5", "--seed", "7", "--target-error", "0.05",
                      "--uv-map", "UVMap", *FAST)
    assert proc.returncode == 0, proc.stderr
    record = json.loads(summary.read_text())
    assert list(record) == ["mc_ao", "output_version", "blend", "exit_code", "error", "settings", "objects"]
    assert record["mc_ao"] == __version__ and record["exit_code"] == 0 and record["error"] is None
    assert record["output_version"] == OUTPUT_VERSION
    assert record["blend"] == str(blends["unselected"])
    assert record["settings"] == {
        "samples": 4, "min_samples": 4, "target_error": 0.05, "sample_source": "sobol", "distribution": "cosine",
        "seed": 7, "max_distance": 2.5, "margin": 16, "ignore_backfaces": False, "resolution": "16x16",
        "occluders": "visible", "uv_map": "UVMap", "replicates": 2,
    }
    assert [o["object"] for o in record["objects"]] == ["Block", "Ground"]
    for obj in record["objects"]:
        assert list(obj) == ["object", "status", "seconds", "rays", "samples_per_texel", "files", "file_stats",
                             "error", "parallel"]
        assert obj["file_stats"] == {os.path.basename(f): [os.stat(f).st_size, os.stat(f).st_mtime_ns]
                                     for f in obj["files"]}  # each file as the run left it
        assert obj["parallel"]["processes"] >= 1 and obj["parallel"]["threads"] >= 1 and obj["parallel"]["why"]
        assert obj["status"] == "ok" and obj["error"] is None and obj["seconds"] > 0
        assert obj["rays"] > 0 and 1 <= obj["samples_per_texel"] <= 4
        stem = out / f"{obj['object']}_AO"
        assert obj["files"] == [f"{stem}.png", f"{stem}_stderr.exr", f"{stem}.exr", f"{stem}.tif"]
        for path in obj["files"]:
            metadata = imageio.read_image(path)[1]
            assert {k: metadata[k] for k in record["settings"]} == record["settings"], path
            assert metadata["object"] == obj["object"]
            assert metadata["output_version"] == OUTPUT_VERSION, path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "summary.json"]
