"""The operator, the script and the batch give the same files, byte for byte, for the same settings,
where OpenImageIO writes them (Blender's official builds).

Where this Python has no OpenImageIO module, all three fall back to Blender's own image writer
(mc_ao.filewriter), and its files differ from OpenImageIO's (measured on bpy 5.0, 8 x 8 random AO):
other bytes (headers, compression), no mc_ao metadata (so the batch cannot tell such a file is done
and bakes it again), 8-bit PNG pixels equal, half EXR values up to 2.4e-4 apart (Blender rounds to
half precision its own way, and writes RGBA instead of one channel)."""

import subprocess
import sys

import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene, select_only

pytestmark = pytest.mark.blender

FILES = ["Block_AO.exr", "Block_AO.png", "Ground_AO.exr", "Ground_AO.png"]
# with the error map and bent normals on
MORE_FILES = ["Block_AO_stderr.exr", "Block_BentNormal.exr", "Ground_AO_stderr.exr", "Ground_BentNormal.exr"]


@pytest.fixture
def scene_file(bpy, addon, tmp_path):
    clean_scene(bpy)
    ground = add_plane(bpy, "Ground", size=4)
    block = add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    select_only(bpy, ground, block)
    path = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))  # the operator's file is this one, as a user's is
    return path, ground, block


def test_the_operator_the_script_and_the_batch_write_the_same_bytes(bpy, scene_file, tmp_path):
    pytest.importorskip("OpenImageIO")
    path, ground, block = scene_file
    settings = bpy.context.scene.mc_ao
    settings.resolution, settings.samples, settings.margin, settings.seed = 16, 8, 2, 3
    settings.float_buffer = False  # 8-bit PNG, half EXR: the script's default depths
    settings.save_to_file = True
    by_operator = tmp_path / "operator"
    settings.output_dir = str(by_operator)
    for file_format in ("PNG", "OPEN_EXR"):
        settings.file_format = file_format
        assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    common = ["--objects", "Ground", "Block", "--resolution", "16", "--samples", "8", "--margin", "2", "--seed", "3",
              "--format", "png", "exr", "--threads", "2", "--quiet"]
    by_script = tmp_path / "script"
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "bake_ao.py"), str(path), *common, "--output",
                           str(by_script)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    manifest = tmp_path / "m.toml"
    manifest.write_text("[[bake]]\nblend = 'scene.blend'\nobjects = ['Ground', 'Block']\nresolution = 16\n"
                        "samples = 8\nmargin = 2\nseed = 3\nformat = ['png', 'exr']\n")
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "bake_batch.py"), str(manifest), "--output",
                           str(tmp_path / "batch"), "--blender", "bpy"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    by_batch = tmp_path / "batch" / "scene"
    for name in FILES:
        operator_bytes = (by_operator / name).read_bytes()
        assert (by_script / name).read_bytes() == operator_bytes, f"{name}: the script's differs from the operator's"
        assert (by_batch / name).read_bytes() == operator_bytes, f"{name}: the batch's differs from the operator's"
    clean_scene(bpy)


def test_the_error_map_and_bent_normals_are_the_same_bytes_too(bpy, scene_file, tmp_path):
    pytest.importorskip("OpenImageIO")
    path, ground, block = scene_file
    settings = bpy.context.scene.mc_ao
    settings.resolution, settings.samples, settings.margin, settings.seed = 16, 8, 2, 3
    settings.float_buffer = False
    settings.error_map = settings.bent_normals = True
    settings.save_to_file, settings.file_format = True, "OPEN_EXR"
    by_operator = tmp_path / "operator"
    settings.output_dir = str(by_operator)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    by_script = tmp_path / "script"
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "bake_ao.py"), str(path), "--objects", "Ground",
                           "Block", "--resolution", "16", "--samples", "8", "--margin", "2", "--seed", "3", "--format",
                           "exr", "--stderr", "--bent-normals", "--threads", "2", "--quiet", "--output", str(by_script)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    for name in MORE_FILES + ["Block_AO.exr", "Ground_AO.exr"]:
        assert (by_script / name).read_bytes() == (by_operator / name).read_bytes(), name
    clean_scene(bpy)
