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
