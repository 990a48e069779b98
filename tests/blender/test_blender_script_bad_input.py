"""Issue 8 for scripts/bake_ao.py: what a script user reads (stderr) and the exit status, files kept."""

import signal
import subprocess
import sys

import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
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
    (tmp_path / "Bad_AO.png").write_bytes(b"the previous bake")
    proc = run_script(blends["nan"], "--objects", "Bad", "Ground", "--occluders", "self", "--output", tmp_path, *FAST)
    assert proc.returncode == 1
    assert (
        "bake_ao: Bad: mesh 'Bad': positions contain 3 non-finite values (NaN first at index (0, 0))\n"
        in proc.stderr
    )
    assert "Traceback" not in proc.stderr
    assert "bake_ao: baked 1 of 2 objects, 1 failed" in proc.stdout
    assert (tmp_path / "Bad_AO.png").read_bytes() == b"the previous bake"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Bad_AO.png", "Ground_AO.png"]


def test_ctrl_c_during_a_bake_exits_130_and_writes_nothing(blends, tmp_path):
    (tmp_path / "Ground_AO.png").write_bytes(b"the previous bake")
    proc = subprocess.Popen(
        [sys.executable, SCRIPT, str(blends["mixed"]), "--objects", "Ground", "--output", str(tmp_path),
         "--samples", "4096", "--resolution", "256", "--threads", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        for line in proc.stdout:  # wait until the bake is under way
            if "baking Ground" in line:
                break
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert err.endswith(
        "bake_ao: cancelled; the files of finished objects are written, nothing of the cancelled one was\n"
    )
    assert (tmp_path / "Ground_AO.png").read_bytes() == b"the previous bake"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Ground_AO.png"]
