"""Paths compared by the file they reach, in the real bpy: an output folder that is a link to the Into file's
folder never overwrites the Into file; the Into image and the object's own image are never one file or one
image; --save through a link to the .blend file being baked is refused. Each refusal comes before any work,
and the files already there keep their bytes."""

import os
import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_plane, clean_scene, pattern_image, run_bake, select_only

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")


@pytest.fixture(scope="module")
def blend_file(bpy, addon, tmp_path_factory):
    scene = clean_scene(bpy)
    s = scene.mc_ao
    s.max_distance, s.margin, s.processes = 1.0, 0, 1
    floor = add_plane(bpy, "Floor", size=4)
    add_plane(bpy, "Lid", size=2, location=(0, 0, 0.3))
    select_only(bpy, floor)
    path = tmp_path_factory.mktemp("blend") / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def script(blend_file, *args):
    return subprocess.run([sys.executable, SCRIPT, str(blend_file), "--objects", "Floor", "--resolution", "16",
                           "--samples", "4", "--max-distance", "1", "--threads", "1", "--processes", "1",
                           *map(str, args)], capture_output=True, text=True, timeout=300)


def orm_file(path):
    from core.files import imageio

    imageio.write_image(str(path), np.random.default_rng(4).random((16, 16, 4)).astype(np.float32), bits=8)
    return path.read_bytes()


def test_an_output_folder_linked_to_the_into_files_folder_never_overwrites_it(blend_file, tmp_path):
    textures = tmp_path / "textures"
    textures.mkdir()
    old = orm_file(textures / "orm.png")
    os.symlink(textures, tmp_path / "out")  # --output reaches the Into file's folder through a link
    p = script(blend_file, "--output", tmp_path / "out", "--channel", "R", "--into", textures / "orm.png")
    assert p.returncode == 2, p.stdout + p.stderr
    assert "is the Into image's own file" in p.stderr and "nothing was baked" in p.stderr, p.stderr
    assert (textures / "orm.png").read_bytes() == old
    assert sorted(os.listdir(textures)) == ["orm.png"]  # not even the object's own image


def test_the_into_file_and_the_objects_own_image_are_never_one_file(blend_file, tmp_path):
    """--into .../Floor_AO.png: the copy of the Into file and Floor's own image would both be
    OUTPUT/Floor_AO.png (one result lost, exit 0, the path listed twice in the summary)."""
    old = orm_file(tmp_path / "Floor_AO.png")
    out = tmp_path / "out"
    p = script(blend_file, "--output", out, "--channel", "G", "--into", tmp_path / "Floor_AO.png")
    assert p.returncode == 2, p.stdout + p.stderr
    assert "Floor: its own image and its copy of the Into image would both be saved as 'Floor_AO'" in p.stderr
    assert (tmp_path / "Floor_AO.png").read_bytes() == old and not out.exists()
    # The same file in the output folder itself.
    p = script(blend_file, "--output", tmp_path, "--channel", "G", "--into", tmp_path / "Floor_AO.png")
    assert p.returncode == 2 and "would both be saved as" in p.stderr, p.stdout + p.stderr
    assert (tmp_path / "Floor_AO.png").read_bytes() == old
    # Names that differ in case only (one file on Windows' and macOS's disks): two files apart.
    os.rename(tmp_path / "Floor_AO.png", tmp_path / "FLOOR_ao.png")
    p = script(blend_file, "--output", out, "--channel", "G", "--into", tmp_path / "FLOOR_ao.png")
    assert p.returncode == 0, p.stdout + p.stderr
    files = sorted(f.name.casefold() for f in out.iterdir() if f.suffix == ".png")
    assert len(set(files)) == 2 and (tmp_path / "FLOOR_ao.png").read_bytes() == old


def test_an_into_image_that_is_the_objects_own_image_is_refused(bpy, scene, capfd):
    from mc_ao import images

    clean_scene(bpy)
    s = scene.mc_ao
    s.max_distance, s.margin, s.processes, s.resolution, s.samples = 1.0, 0, 1, 16, 4
    floor = add_plane(bpy, "Floor", size=4)
    add_plane(bpy, "Lid", size=2, location=(0, 0, 0.3))
    select_only(bpy, floor)
    before = pattern_image(bpy, "ORM", 16, 16)
    s.channel, s.into, s.image_name = "R", bpy.data.images["ORM"], "ORM"
    result, error, out = run_bake(bpy, capfd)
    assert result is None and "is both Floor's own image and the Into image" in error, (result, error, out)
    assert images.pixels_of(bpy.data.images["ORM"]).tobytes() == before.tobytes()


def test_save_through_a_link_to_the_blend_being_baked_is_refused(bpy, blend_file, tmp_path):
    os.symlink(blend_file.parent, tmp_path / "link")
    old = blend_file.read_bytes()
    p = script(blend_file, "--output", tmp_path / "out", "--target", "vertex-colors",
               "--save", tmp_path / "link" / blend_file.name)
    assert p.returncode == 2 and "is the .blend file being baked" in p.stderr, p.stdout + p.stderr
    assert blend_file.read_bytes() == old
