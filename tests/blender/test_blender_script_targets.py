"""The other targets in scripts/bake_ao.py and the batch: --udim, --bent-normals, --target vertex-colors
(PLY files, --save into a .blend file atomically, never the input unless asked), and the same
options passed through a batch manifest."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
FAST = ("--samples", "8", "--resolution", "16", "--threads", "2")


@pytest.fixture(scope="module")
def blend_file(bpy, tmp_path_factory):
    """Ground (UVs over tiles 1001 and 1002) with a block on it; Bare, a mesh without UVs."""
    clean_scene(bpy)
    ground = add_plane(bpy, "Ground", size=4)
    for d in ground.data.uv_layers.active.uv:
        d.vector = (2 * d.vector[0], d.vector[1])
    add_cube(bpy, "Block", size=1.0, location=(1.0, 0, 0.6))
    bare = add_plane(bpy, "Bare", size=1, location=(5, 0, 0))
    while bare.data.uv_layers:
        bare.data.uv_layers.remove(bare.data.uv_layers[0])
    path = tmp_path_factory.mktemp("scene") / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def run_script(*args):
    return subprocess.run([sys.executable, SCRIPT, *map(str, args)], capture_output=True, text=True, timeout=180)


def test_udim_and_bent_normals_write_one_file_per_tile_and_map(blend_file, tmp_path):
    from core.files import imageio

    out = tmp_path / "out"
    proc = run_script(blend_file, "--objects", "Ground", "--udim", "--bent-normals", "--format", "exr", "--stderr",
                      "--output", out, "--summary-json", tmp_path / "s.json", *FAST)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        "Ground_AO.1001.exr", "Ground_AO.1002.exr", "Ground_AO_stderr.1001.exr", "Ground_AO_stderr.1002.exr",
        "Ground_BentNormal.1001.exr", "Ground_BentNormal.1002.exr"]
    assert "16x16 x2 tiles" in proc.stdout
    right, meta = imageio.read_image(out / "Ground_AO.1002.exr")
    left, _ = imageio.read_image(out / "Ground_AO.1001.exr")
    assert meta["udim"] is True and meta["udim_tile"] == 1002 and meta["content"] == "ao"
    assert np.squeeze(right).mean() < np.squeeze(left).mean()  # the block stands over 1002
    bent, meta = imageio.read_image(out / "Ground_BentNormal.1002.exr")
    assert bent.shape == (16, 16, 3) and meta["content"] == "bent_normal" and meta["bent_space"] == "tangent"
    np.testing.assert_allclose(np.linalg.norm(bent * 2 - 1, axis=-1), 1.0, atol=2e-3)  # half-float EXR
    record = json.loads((tmp_path / "s.json").read_text())
    assert record["settings"]["udim"] is True and record["settings"]["bent_normals"] == "tangent"
    for f in record["objects"][0]["files"]:
        assert {k: imageio.read_image(f)[1][k] for k in record["settings"]} == record["settings"]


def test_vertex_colors_write_ply_files_and_save_the_attribute(blend_file, tmp_path, bpy):
    from core.files.plyio import read_ply

    out = tmp_path / "out"
    saved = tmp_path / "baked.blend"
    before = blend_file.read_bytes()
    proc = run_script(blend_file, "--objects", "Ground", "Block", "Bare", "--target", "vertex-colors",
                      "--domain", "corner", "--save", saved, "--output", out, *FAST)
    assert proc.returncode == 0, proc.stderr
    assert blend_file.read_bytes() == before  # the input is never written
    assert sorted(p.name for p in out.iterdir()) == ["Bare_AO.ply", "Block_AO.ply", "Ground_AO.ply"]
    positions, sizes, verts, ao, meta = read_ply(out / "Ground_AO.ply")
    assert len(positions) == 4 and sizes.tolist() == [4] and meta["domain"] == "corner"  # a vertex per corner
    assert meta["target"] == "vertex_colors" and meta["object"] == "Ground" and meta["content"] == "ao"
    assert read_ply(out / "Block_AO.ply")[3].min() < 0.9  # the block's bottom corners, near the ground
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    attr = bpy.data.objects["Ground"].data.color_attributes["AO"]
    assert (attr.data_type, attr.domain) == ("FLOAT_COLOR", "CORNER")
    got = np.array([d.color[0] for d in attr.data])
    loops = [p.loop_indices for p in bpy.data.objects["Ground"].data.polygons]
    np.testing.assert_allclose(got[np.concatenate(loops)], ao, atol=1e-6)
    assert bpy.data.objects["Bare"].data.color_attributes.get("AO") is not None  # no UV map needed


@pytest.mark.parametrize("args, message", [
    (["--target", "vertex-colors", "--format", "png"], "--target vertex-colors writes .ply files"),
    (["--format", "ply"], "--format ply is for --target vertex-colors"),
    (["--save", "x.blend"], "--save writes color attributes into a .blend file: it needs --target vertex-colors"),
    (["--target", "vertex-colors", "--udim"], "--udim bakes images"),
    (["--target", "vertex-colors", "--attribute", " "], "--attribute must name the color attribute"),
    (["--target", "vertex-colors", "--stderr"], "--stderr is for image textures"),
])
def test_bad_combinations_exit_2(blend_file, tmp_path, args, message):
    proc = run_script(blend_file, "--output", tmp_path / "out", *args, *FAST)
    assert proc.returncode == 2 and message in proc.stderr, proc.stderr
    assert not (tmp_path / "out").exists()


def test_save_never_replaces_the_input_unless_asked(blend_file, tmp_path):
    import shutil

    copy = tmp_path / "copy.blend"
    shutil.copy(blend_file, copy)
    before = copy.read_bytes()
    args = ("--objects", "Ground", "--target", "vertex-colors", "--output", tmp_path / "out", *FAST)
    proc = run_script(copy, *args, "--save", copy)
    assert proc.returncode == 2 and "is the .blend file being baked" in proc.stderr
    assert copy.read_bytes() == before
    proc = run_script(copy, *args, "--save", copy, "--overwrite-input")
    assert proc.returncode == 0, proc.stderr
    assert copy.read_bytes() != before and not list(tmp_path.glob(".mc_ao-*"))


def test_a_manifest_passes_the_new_options_through(blend_file, tmp_path):
    """A batch with one entry per new option: each task's files are the script's; a rerun finds them done."""
    manifest = tmp_path / "manifest.toml"
    (tmp_path / "a.blend").write_bytes(blend_file.read_bytes())
    (tmp_path / "b.blend").write_bytes(blend_file.read_bytes())
    manifest.write_text(
        '[defaults]\nsamples = 8\nresolution = 16\n\n'
        '[[bake]]\nblend = "a.blend"\nobjects = ["Ground"]\nudim = true\nbent_normals = true\n'
        'bent_space = "object"\nformat = ["exr"]\n\n'
        '[[bake]]\nblend = "b.blend"\nobjects = ["Ground"]\ntarget = "vertex-colors"\ndomain = "corner"\n'
    )
    out = tmp_path / "out"
    cmd = [sys.executable, str(ROOT / "scripts" / "bake_batch.py"), str(manifest), "--output", str(out),
           "--runner", "local", "--workers", "1", "--blender", "bpy"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert sorted(os.listdir(out / "a")) == ["Ground_AO.1001.exr", "Ground_AO.1002.exr",
                                             "Ground_BentNormal.1001.exr", "Ground_BentNormal.1002.exr"] + \
        sorted(n for n in os.listdir(out / "a") if not n.startswith("Ground_"))
    assert "Ground_AO.ply" in os.listdir(out / "b")
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0 and "0 baked, 2 already done" in again.stdout, again.stdout
    manifest.write_text('[[bake]]\nblend = "a.blend"\nsave = "x.blend"\n')
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "'save' cannot be set in a batch" in proc.stderr + proc.stdout
