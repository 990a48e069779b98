"""scripts/bake_ao.py run by a plain Python with the bpy module, as a user runs it."""

import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")


@pytest.fixture(scope="module")
def blend_file(bpy, tmp_path_factory):
    clean_scene(bpy)
    add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    path = tmp_path_factory.mktemp("scene") / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def run_script(*args):
    return subprocess.run([sys.executable, SCRIPT, *map(str, args)], capture_output=True, text=True, timeout=120)


def test_bakes_each_object_into_files(blend_file, tmp_path):
    from core.files import imageio

    out = tmp_path / "out"
    proc = run_script(blend_file, "--objects", "Ground", "Block", "--samples", "8", "--resolution", "16x8",
                      "--output", out, "--format", "png", "exr", "--stderr", "--threads", "2")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        "Block_AO.exr", "Block_AO.png", "Block_AO_stderr.exr", "Ground_AO.exr", "Ground_AO.png",
        "Ground_AO_stderr.exr",
    ]
    assert "baked 2 of 2 objects" in proc.stdout
    assert "Ground" in proc.stdout and "Mrays/s" in proc.stdout
    ao, metadata = imageio.read_image(out / "Ground_AO.exr")
    ao = np.squeeze(ao)
    assert ao.shape == (8, 16) and ao.min() < 0.5 < ao.max()  # the block shades the ground
    assert metadata["object"] == "Ground" and metadata["content"] == "ao"
    png, _ = imageio.read_image(out / "Ground_AO.png")
    np.testing.assert_allclose(np.squeeze(png), ao, atol=0.5 / 255 + 1e-3)  # 8-bit of the same bake


@pytest.mark.parametrize("args, message", [
    (["--objects", "Nope"], "no object 'Nope' in the view layer; its meshes: Block, Ground"),
    (["--resolution", "0"], "is not a size"),
])
def test_bad_arguments_exit_2_with_a_message(blend_file, tmp_path, args, message):
    proc = run_script(blend_file, "--output", tmp_path, *args)
    assert proc.returncode == 2
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not list(tmp_path.glob("*.png"))


def test_missing_blend_file(tmp_path):
    proc = run_script(tmp_path / "missing.blend")
    assert proc.returncode == 2
    assert "no such .blend file" in proc.stderr
