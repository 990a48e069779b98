"""Channel and Into (mc_ao.outputs.channel) and AO with thickness from one bake, in the real bpy: the map in
one channel of a Blender image with the other channels' pixels exactly as they were; a copy of the image's
file in the output folder, its other channels byte-identical and the file itself untouched; an image of
another size refused before any work; the script's --into FILE; --quantity ao thickness baked as one
core bake (metadata 'quantities')."""

import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_plane, pattern_image, run_bake as run, select_only

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")


def floor_under_lid(bpy, scene):
    """A 4 x 4 floor under a 2 x 2 lid 0.3 above its middle: AO dark under the lid, open around it."""
    for image in list(bpy.data.images):
        bpy.data.images.remove(image)
    s = scene.mc_ao
    s.max_distance, s.margin, s.processes = 1.0, 0, 1
    floor = add_plane(bpy, "Floor", size=4)
    add_plane(bpy, "Lid", size=2, location=(0, 0, 0.3))
    select_only(bpy, floor)
    return floor


def stored(path):
    import OpenImageIO as oiio

    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    spec = inp.spec()
    data = np.asarray(inp.read_image(str(spec.format))).reshape(spec.height, spec.width, spec.nchannels)
    inp.close()
    return data


def test_the_ao_goes_into_one_channel_of_a_blender_image(bpy, scene, capfd):
    from mc_ao import images

    floor_under_lid(bpy, scene)
    s = scene.mc_ao
    w, h = s.resolution, s.resolution
    before = pattern_image(bpy, "ORM", w, h, float_buffer=True)
    s.channel, s.into = "R", bpy.data.images["ORM"]
    result, error, out = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None), out
    after = images.pixels_of(bpy.data.images["ORM"])
    assert after[:, :, 1:].tobytes() == before[:, :, 1:].tobytes()  # G, B and A exactly as they were
    ao = images.pixels_of(bpy.data.images["Floor_AO"])[:, :, 0]
    np.testing.assert_array_equal(after[:, :, 0], ao)
    assert ao.min() < 0.8 and ao.max() > 0.95  # the lid's shadow and the open floor: a real map
    assert bpy.data.images["ORM"].packed_file is not None  # a generated image: kept in the .blend file


def test_an_image_of_another_size_is_refused_before_any_work(bpy, scene, capfd):
    floor_under_lid(bpy, scene)
    s = scene.mc_ao
    before = pattern_image(bpy, "Small", 8, 8)
    s.channel, s.into = "G", bpy.data.images["Small"]
    result, error, out = run(bpy, capfd)
    assert result is None and "image 'Small' is 8x8, not the bake's" in error, error
    assert "Floor_AO" not in bpy.data.images
    from blender_helpers import assert_unchanged

    assert_unchanged(bpy, "Small", before)


def test_a_file_image_gets_a_copy_of_its_file_in_the_output_folder(bpy, scene, capfd, tmp_path):
    from core.files import imageio
    from mc_ao import images

    floor_under_lid(bpy, scene)
    s = scene.mc_ao
    w = s.resolution
    rng = np.random.default_rng(5)
    source = tmp_path / "crate_orm.png"
    imageio.write_image(str(source), rng.random((w, w, 4)).astype(np.float32), bits=8)
    old = source.read_bytes()
    image = bpy.data.images.load(str(source))
    s.channel, s.into = "B", image
    s.output_dir = str(tmp_path / "out")
    s.save_to_file = True
    try:
        result, error, out = run(bpy, capfd)
    finally:
        s.save_to_file = False
        s.output_dir = ""
    assert (result, error) == ({"FINISHED"}, None), out
    assert source.read_bytes() == old  # the image's own file is never written
    copy = tmp_path / "out" / "crate_orm.png"
    assert copy.is_file()
    a, b = stored(source), stored(copy)
    assert b[:, :, [0, 1, 3]].tobytes() == a[:, :, [0, 1, 3]].tobytes()
    ao = images.pixels_of(bpy.data.images["Floor_AO"])[:, :, 0]
    assert np.abs(b[::-1, :, 2] / 255.0 - ao).max() <= 0.5 / 255 + 1e-6
    # In Blender the image holds the map too, and is left for the user to save.
    np.testing.assert_allclose(images.pixels_of(bpy.data.images[image.name])[:, :, 2], ao, atol=0.5 / 255 + 1e-6)


@pytest.fixture(scope="module")
def blend_file(bpy, addon, tmp_path_factory):
    from blender_helpers import clean_scene

    scene = clean_scene(bpy)
    floor_under_lid(bpy, scene)
    path = tmp_path_factory.mktemp("blend") / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def script(blend_file, *args):
    return subprocess.run([sys.executable, SCRIPT, str(blend_file), "--objects", "Floor", "--resolution",
                           "16", "--samples", "8", "--max-distance", "1", "--threads", "2", "--processes", "1",
                           *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def test_the_script_writes_into_a_copy_of_the_into_file_and_bakes_both_quantities_at_once(blend_file, tmp_path):
    from core.files import imageio

    source = tmp_path / "orm.exr"
    imageio.write_image(str(source), np.random.default_rng(2).random((16, 16, 4)).astype(np.float32), bits="half")
    old = source.read_bytes()
    out = tmp_path / "out"
    p = script(blend_file, "--output", out, "--format", "exr", "--bits", "half", "--channel", "R", "--into", source)
    assert p.returncode == 0, p.stderr
    assert sorted(f.name for f in out.iterdir() if f.suffix == ".exr") == ["Floor_AO.exr", "orm.exr"]
    assert source.read_bytes() == old
    a, b = stored(source), stored(out / "orm.exr")
    assert b[:, :, 1:].tobytes() == a[:, :, 1:].tobytes()
    ao, _ = imageio.read_image(str(out / "Floor_AO.exr"))
    np.testing.assert_array_equal(b[::-1, :, 0], ao.astype(np.float16))
    # AO and thickness come from one core bake (core.bake_maps), each in its own file.
    both = tmp_path / "both"
    p = script(blend_file, "--output", both, "--format", "exr", "--quantity", "ao", "thickness")
    assert p.returncode == 0, p.stderr
    for name in ("Floor_AO.exr", "Floor_Thickness.exr"):
        assert imageio.read_image(str(both / name))[1]["quantities"] == "ao,thickness"
    # A channel the file does not have: refused naming the file, nothing written.
    rgb = tmp_path / "rgb.png"
    imageio.write_image(str(rgb), np.zeros((16, 16, 3), np.float32), bits=8)
    p = script(blend_file, "--output", str(tmp_path / "none"), "--channel", "A", "--into", str(rgb))
    assert p.returncode == 2 and "rgb.png' has no channel A" in p.stderr, p.stderr
    assert not (tmp_path / "none").exists() or not list((tmp_path / "none").iterdir())
