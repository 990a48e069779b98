"""mc_ao.undo_images in the bpy module: what the undo_post / redo_post handler does with an image whose
restored bake token is not its pixels'. The real Ctrl-Z is tests/gui/undo.sh's (Blender's undo takes
another path in background mode); here the token is set back by hand, as undo sets it back."""

import numpy as np
import pytest

pytestmark = pytest.mark.blender


def fill(bpy, image, value):
    px = np.full(len(image.pixels), value, np.float32)
    image.pixels.foreach_set(px)
    image.update()


def red(image):
    px = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(-1, 4)[:, 0]


def test_a_packed_image_is_read_again_from_its_packed_data(bpy, addon):
    from mc_ao import undo_images

    undo_images.forget()
    image = bpy.data.images.new("undo packed", 8, 8)
    fill(bpy, image, 0.25)
    image.pack()
    undo_images.record(image)
    first = image[undo_images.PROPERTY]
    fill(bpy, image, 0.75)  # what a second bake left in the buffer, its packed data not (as after Ctrl-Z)
    image[undo_images.PROPERTY] = first + "x"  # the undo step's token is another bake's
    undo_images.after_undo()
    assert np.allclose(red(image), 0.25, atol=1 / 255)  # the packed pixels, read again
    bpy.data.images.remove(image)


def test_a_file_image_gets_the_pixels_of_the_bake_the_undo_came_to(bpy, addon, tmp_path):
    from mc_ao import undo_images

    undo_images.forget()
    path = str(tmp_path / "ao.png")

    def bake(value):
        made = bpy.data.images.new("made", 8, 8)
        fill(bpy, made, value)
        made.filepath_raw, made.file_format = path, "PNG"
        made.save()
        bpy.data.images.remove(made)

    bake(0.25)
    image = bpy.data.images.load(path)
    undo_images.record(image)
    first, a = image[undo_images.PROPERTY], red(image)
    bake(0.75)  # the second bake overwrites the file the image loads from
    image.reload()
    undo_images.record(image)
    second, b = image[undo_images.PROPERTY], red(image)
    assert a.max() < b.min()

    image[undo_images.PROPERTY] = first  # Ctrl-Z
    undo_images.after_undo()
    assert np.array_equal(red(image), a) and image.is_dirty  # the kept pixels; the file holds the second bake
    image[undo_images.PROPERTY] = second  # Ctrl-Shift-Z
    undo_images.after_undo()
    assert np.array_equal(red(image), b)  # read from its file again
    del image[undo_images.PROPERTY]  # undone to before the first bake: what the file holds
    undo_images.after_undo()
    assert np.array_equal(red(image), b)
    bpy.data.images.remove(image)


def test_a_new_image_under_a_baked_ones_name_keeps_its_pixels(bpy, addon):
    """A baked image deleted, another made under its name and painted: an undo does not touch it (its
    pixels are in no file; the handler once took it for the baked one and freed them)."""
    from mc_ao import undo_images

    undo_images.forget()
    image = bpy.data.images.new("undo reused name", 8, 8)
    fill(bpy, image, 0.25)
    image.pack()
    undo_images.record(image)
    bpy.data.images.remove(image)
    fresh = bpy.data.images.new("undo reused name", 8, 8)
    fill(bpy, fresh, 0.6)  # painted, not packed, no file
    painted = red(fresh)
    undo_images.after_undo()
    assert np.array_equal(red(fresh), painted) and painted.min() > 0.5
    bpy.data.images.remove(fresh)


def test_undone_to_before_the_first_bake_a_generated_image_keeps_the_bakes_pixels(bpy, addon):
    """Its pixels before the bake were never stored (a painted generated image): freeing its buffer
    would give a blank image, not those pixels; it keeps the bake's."""
    from mc_ao import undo_images

    undo_images.forget()
    image = bpy.data.images.new("undo generated", 8, 8)
    fill(bpy, image, 0.3)
    baked = red(image)
    undo_images.record(image)  # (as if baked and left unpacked)
    del image[undo_images.PROPERTY]
    undo_images.after_undo()
    assert np.array_equal(red(image), baked) and baked.min() > 0.25
    bpy.data.images.remove(image)
