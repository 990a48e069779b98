"""Nothing a user baked or had is lost, through Esc, undo, save and reopen.

- Esc during a bake into an existing image (generated or loaded from a file, painted or not, of
  another size than the bake) puts back its size and pixels; a later, unrelated undo step keeps them.
- A finished bake survives later undo and redo steps (and the undo and redo of the bake itself).
- A bake survives File > Save and reopening: packed, with a fake user; or, with Save to File and
  Link Image to File, as the file it was saved to.

Undo runs here as in the UI: ``bpy.ops.ed.undo_push`` makes the steps the UI would (an operator
with the UNDO flag called with ``undo=True`` pushes its own), and ``bpy.ops.ed.undo``/``redo`` step
through them; both work in background mode (bpy 4.2 and 5.0) once a first step is pushed.
"""

import numpy as np
import pytest

from blender_helpers import (
    add_cube, add_plane, new_session, pattern_image, select_only, tick_until,
)

pytestmark = pytest.mark.blender


def pixels(bpy, name):
    from mc_ao import images

    return images.pixels_of(bpy.data.images[name])


def state(bpy, name):
    """What a user would call the image's state: its size, pixels, and whether it has unsaved changes."""
    image = bpy.data.images[name]
    return tuple(image.size), pixels(bpy, name), image.is_dirty


def assert_state(bpy, name, expected):
    size, px, dirty = state(bpy, name)
    assert size == expected[0], f"{name} is {size}, was {expected[0]}"
    np.testing.assert_array_equal(px, expected[1])
    assert dirty == expected[2]


def unrelated_undo_step(bpy):
    """Add a cube (an undo step of its own, as in the UI), then undo it: Ctrl-Z after Shift-A."""
    bpy.ops.mesh.primitive_cube_add("EXEC_DEFAULT", True, size=0.5, location=(9, 9, 0))
    assert "Cube" in bpy.data.objects
    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert "Cube" not in bpy.data.objects


def file_image(bpy, tmp_path, name, width, height, float_buffer=False):
    """``name`` loaded from a file on disk (PNG, or OpenEXR for a float image) holding a pattern."""
    made = bpy.data.images.new("made", width, height, alpha=True, float_buffer=float_buffer)
    made.pixels.foreach_set(np.linspace(0, 1, width * height * 4, dtype=np.float32))
    path = tmp_path / (f"{name}.exr" if float_buffer else f"{name}.png")
    made.filepath_raw = str(path)
    made.file_format = "OPEN_EXR" if float_buffer else "PNG"
    made.save()
    bpy.data.images.remove(made)
    image = bpy.data.images.load(str(path))
    image.name = name
    return image, path


def paint(bpy, name):
    """Paint over part of an image, as a user with a brush would: its pixels now differ from any file."""
    from mc_ao import images

    image = bpy.data.images[name]
    px = images.pixels_of(image)
    px[: px.shape[0] // 2, :, :3] = 0.25
    images.set_pixels(image, px)


# The images a bake may find under its image's name, each of another size than the bake's 64 x 64.
def _generated_painted(bpy, tmp_path):
    pattern_image(bpy, "Ground_AO", 16, 8)  # sRGB, 8-bit: the bake changes both when it finishes


def _file_clean(bpy, tmp_path):
    file_image(bpy, tmp_path, "Ground_AO", 8, 4)


def _file_painted(bpy, tmp_path):
    file_image(bpy, tmp_path, "Ground_AO", 8, 4)
    paint(bpy, "Ground_AO")


def _file_scaled_and_painted(bpy, tmp_path):
    """Loaded from an 8 x 4 file, scaled to 16 x 8 and painted: neither size nor pixels are the file's."""
    image, _ = file_image(bpy, tmp_path, "Ground_AO", 8, 4, float_buffer=True)
    image.scale(16, 8)
    paint(bpy, "Ground_AO")


def _packed(bpy, tmp_path):
    pattern_image(bpy, "Ground_AO", 16, 8, float_buffer=True, is_data=True)
    bpy.data.images["Ground_AO"].pack()


EXISTING = {
    "generated, painted": _generated_painted,
    "file, clean": _file_clean,
    "file, painted": _file_painted,
    "file, scaled and painted": _file_scaled_and_painted,
    "packed": _packed,
}


@pytest.mark.parametrize("kind", EXISTING)
def test_esc_puts_an_image_back_and_a_later_undo_keeps_it(bpy, scene, tmp_path, hold_bake, kind):
    """Esc with the image resized and tiles drawn into it: its size and pixels come back; an unrelated
    undo step afterwards (add a cube, Ctrl-Z) does not reset it (blank, or reloaded from its file)."""
    ground = add_plane(bpy, "Ground", size=4)
    EXISTING[kind](bpy, tmp_path)
    files = {p: p.read_bytes() for p in tmp_path.iterdir()}
    before = state(bpy, "Ground_AO")
    scene.mc_ao.resolution = 64
    scene.mc_ao.threads = 1
    select_only(bpy, ground)
    bpy.ops.ed.undo_push(message="before the bake")
    held = hold_bake("Ground")

    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    tick_until(bpy, session, lambda: held.is_set() and not session.pending)
    size, live, _ = state(bpy, "Ground_AO")
    assert size == (64, 64) and not np.array_equal(live[..., 0], 0)  # resized, with a tile drawn in

    assert session.on_event(bpy.context, "ESC") == {"CANCELLED"}
    assert reports[-1] == ("WARNING", "AO bake cancelled; the images are as they were")
    assert_state(bpy, "Ground_AO", before)
    unrelated_undo_step(bpy)
    assert_state(bpy, "Ground_AO", before)
    assert {p: p.read_bytes() for p in tmp_path.iterdir()} == files  # no file touched


# The images a finished bake goes into: (image setup, 32-bit float bake).
TARGETS = {
    "created, float": (None, True),
    "created, 8-bit": (None, False),
    "reused generated, float": (_generated_painted, True),
    "reused generated, 8-bit": (_generated_painted, False),
    "reused file, float": (_file_painted, True),
    "reused file, 8-bit": (_file_painted, False),
}


def bake_with_undo(bpy, scene, tmp_path, kind):
    """Bake Ground as the UI does (one undo step) into the image ``kind`` describes; its pixels."""
    setup, float_buffer = TARGETS[kind]
    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0.3, 0, 0.8))
    if setup is not None:
        setup(bpy, tmp_path)
    scene.mc_ao.float_buffer = float_buffer
    select_only(bpy, ground)
    bpy.ops.ed.undo_push(message="scene")
    assert bpy.ops.object.mc_ao_bake("EXEC_DEFAULT", True) == {"FINISHED"}
    image = bpy.data.images["Ground_AO"]
    assert tuple(image.size) == (24, 24) and image.colorspace_settings.name == "Non-Color"
    baked = pixels(bpy, "Ground_AO")
    assert baked[..., 0].min() < 0.9  # the block shades the ground: a bake, not a blank image
    return baked


@pytest.mark.parametrize("kind", TARGETS)
def test_a_finished_bake_survives_later_undo_and_redo_steps(bpy, scene, tmp_path, kind):
    baked = bake_with_undo(bpy, scene, tmp_path, kind)

    unrelated_undo_step(bpy)  # Ctrl-Z of a later step
    np.testing.assert_array_equal(pixels(bpy, "Ground_AO"), baked)
    assert bpy.ops.ed.redo() == {"FINISHED"}  # Ctrl-Shift-Z: the cube is back
    assert "Cube" in bpy.data.objects
    np.testing.assert_array_equal(pixels(bpy, "Ground_AO"), baked)

    # A later operator re-run from its Adjust Last Operation panel: undo, then run it again.
    assert bpy.ops.ed.undo() == {"FINISHED"}
    bpy.ops.mesh.primitive_cube_add("EXEC_DEFAULT", True, size=2.0, location=(9, 9, 0))
    np.testing.assert_array_equal(pixels(bpy, "Ground_AO"), baked)

    # Undo back to before the bake and redo the bake: the image comes back baked, not blank.
    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert bpy.ops.ed.undo() == {"FINISHED"}
    if TARGETS[kind][0] is None:
        assert "Ground_AO" not in bpy.data.images
    assert bpy.ops.ed.redo() == {"FINISHED"}
    np.testing.assert_array_equal(pixels(bpy, "Ground_AO"), baked)


@pytest.mark.parametrize("kind", TARGETS)
def test_a_bake_survives_save_and_reopen(bpy, scene, tmp_path, kind):
    """File > Save, then File > Open: the image is there, with the bake's pixels (packed)."""
    baked = bake_with_undo(bpy, scene, tmp_path, kind)
    path = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))

    assert "Ground_AO" in bpy.data.images, "the image was dropped on save"
    image = bpy.data.images["Ground_AO"]
    assert tuple(image.size) == (24, 24) and image.colorspace_settings.name == "Non-Color"
    np.testing.assert_array_equal(pixels(bpy, "Ground_AO"), baked)
    assert image.use_fake_user and image.packed_file is not None  # how: packed, kept without users
    assert image.is_float == TARGETS[kind][1] or TARGETS[kind][0] is _file_painted  # a file's depth stays


@pytest.mark.parametrize("file_format, float_buffer", [("PNG", False), ("PNG", True), ("OPEN_EXR", True)])
def test_link_to_file_makes_the_image_the_saved_file(bpy, scene, tmp_path, file_format, float_buffer):
    """Save to File with Link Image to File: the image loads from the file it was saved to (relative
    to the .blend), is not packed, and reopens with the file's pixels; a later undo keeps them."""
    from core.files import imageio

    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))  # so that "//textures" is a folder
    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0.3, 0, 0.8))
    settings = scene.mc_ao
    settings.save_to_file = True
    settings.output_dir = "//textures"
    settings.file_format = file_format
    settings.float_buffer = float_buffer
    assert settings.link_to_file  # the default
    select_only(bpy, ground)
    bpy.ops.ed.undo_push(message="scene")
    assert bpy.ops.object.mc_ao_bake("EXEC_DEFAULT", True) == {"FINISHED"}

    image = bpy.data.images["Ground_AO"]
    ext = ".exr" if file_format == "OPEN_EXR" else ".png"
    assert image.source == "FILE" and image.packed_file is None and image.use_fake_user
    assert image.filepath == f"//textures/Ground_AO{ext}"
    assert image.colorspace_settings.name == "Non-Color" and not image.is_dirty
    on_disk, _ = imageio.read_image(tmp_path / "textures" / f"Ground_AO{ext}")
    linked = pixels(bpy, "Ground_AO")
    np.testing.assert_allclose(linked[..., 0], np.squeeze(on_disk), atol=1e-6)  # the file's pixels

    unrelated_undo_step(bpy)
    np.testing.assert_array_equal(pixels(bpy, "Ground_AO"), linked)
    bpy.ops.wm.save_mainfile()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    np.testing.assert_array_equal(pixels(bpy, "Ground_AO"), linked)


def test_without_link_to_file_the_saved_bake_is_packed_too(bpy, scene, tmp_path):
    ground = add_plane(bpy, "Ground", size=4)
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = str(tmp_path)
    scene.mc_ao.link_to_file = False
    select_only(bpy, ground)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    image = bpy.data.images["Ground_AO"]
    assert (tmp_path / "Ground_AO.png").is_file()
    assert image.packed_file is not None and image.filepath == "" and image.is_float


def test_a_saved_file_blender_cannot_read_leaves_the_bake_packed(bpy, scene, tmp_path, monkeypatch):
    """The file is written, but Blender reads nothing back from it: the bake is packed instead, said so."""
    from mc_ao import images

    ground = add_plane(bpy, "Ground", size=4)
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = str(tmp_path)
    select_only(bpy, ground)
    real = images.use_file

    def unreadable(image, path, relative):
        (tmp_path / "Ground_AO.png").write_bytes(b"not a PNG any more")
        return real(image, path, relative)

    monkeypatch.setattr(images, "use_file", unreadable)
    session, reports = new_session()
    assert session.start(bpy.context, live=False)
    assert tick_until(bpy, session, lambda: False) == {"FINISHED"}
    image = bpy.data.images["Ground_AO"]
    assert image.packed_file is not None and tuple(image.size) == (24, 24)
    assert pixels(bpy, "Ground_AO")[..., 0].max() > 0.5  # the bake, not an empty image
    assert (
        "WARNING",
        f"Ground: Blender could not read the saved file '{tmp_path / 'Ground_AO.png'}' into image "
        "'Ground_AO'; its pixels are packed into the .blend file instead",
    ) in reports


def test_a_packed_bake_linked_to_its_file_by_the_next_bake_is_unpacked(bpy, scene, tmp_path):
    """Bake (packed), then bake again with Save to File: the image now loads from the file, unpacked."""
    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, ground)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    assert bpy.data.images["Ground_AO"].packed_file is not None
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = str(tmp_path)
    scene.mc_ao.file_format = "OPEN_EXR"
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    image = bpy.data.images["Ground_AO"]
    assert image.packed_file is None and image.source == "FILE"
    assert image.filepath == str(tmp_path / "Ground_AO.exr")  # absolute, as the folder is
    assert tuple(image.size) == (24, 24) and pixels(bpy, "Ground_AO")[..., 0].max() > 0.5
