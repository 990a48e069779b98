"""Blender images for bake results: create or reuse "<object>_AO", fill it, restore it, save it."""

import importlib.util
import os
import tempfile

import bpy
import numpy as np

from . import corelink


class ImageError(ValueError):
    """An existing image cannot take the bake (a UDIM image, for one)."""


def rgba(ao, channels=4):
    """(H, W) AO -> (H, W, channels) float32 pixels: AO in the colour channels, alpha 1 everywhere.

    Alpha stays 1 outside the UV islands too, so that the map looks the same in every viewer; the
    bake's coverage mask is in the result, not in the image. ``channels`` is the image's (4 for any
    image a bake creates; an image loaded from a file may have 1 to 4).
    """
    out = np.ones(ao.shape + (channels,), dtype=np.float32)
    colour = 1 if channels == 2 else min(channels, 3)  # 2 channels = grey + alpha
    out[..., :colour] = ao[..., None]
    return out


def pixels_of(image):
    """The image's pixels as an (H, W, channels) float32 array (a copy)."""
    w, h = image.size
    buf = np.empty(w * h * image.channels, dtype=np.float32)
    image.pixels.foreach_get(buf)
    return buf.reshape(h, w, image.channels)


def set_pixels(image, pixels):
    """Write (H, W, channels) float pixels into the image (same size) and let viewers redraw it."""
    h, w, channels = pixels.shape
    if (tuple(image.size), image.channels) != ((w, h), channels):
        raise ImageError(
            f"image {image.name!r} is {image.size[0]}x{image.size[1]} with {image.channels} channels, "
            f"not {w}x{h} with {channels}: it changed during the bake"
        )
    image.pixels.foreach_set(np.ascontiguousarray(pixels, dtype=np.float32).ravel())
    image.update()
    # The 3D Viewport's texture of the image follows only a depsgraph tag (checked in Blender 4.3:
    # with update() and a redraw alone, textured solid shading kept showing the old pixels).
    image.update_tag()


class Snapshot:
    """What an image was before a bake changed it, to put it back when the bake is cancelled.

    A bake that creates its image removes it again; one that reuses an image restores its size,
    depth, colour space and pixels.
    """

    def __init__(self, image, created):
        self.name = image.name
        self.created = created
        if created:
            return
        self.generated = image.source == "GENERATED"
        self.generated_state = (image.generated_width, image.generated_height, image.use_generated_float)
        self.size = tuple(image.size)
        self.colorspace = image.colorspace_settings.name
        # image.has_data is False for a file image until its pixels are first read; size loads it.
        self.pixels = pixels_of(image) if all(self.size) else None

    def restore(self):
        image = bpy.data.images.get(self.name)
        if image is None:
            return
        if self.created:
            bpy.data.images.remove(image)
            return
        if self.generated:
            image.generated_width, image.generated_height, image.use_generated_float = self.generated_state
        elif tuple(image.size) != self.size and all(self.size):
            image.scale(*self.size)
        image.colorspace_settings.name = self.colorspace
        if self.pixels is not None and tuple(image.size) == self.size:
            set_pixels(image, self.pixels)


def unusable_reason(image):
    """Why an existing image cannot take a bake (a UDIM, movie or render image), or None."""
    if image.source not in {"GENERATED", "FILE"}:
        return f"image {image.name!r} is a {image.source.lower()} image; bake into a plain image"
    return None


def check_target(name):
    """Raise ImageError when an existing image ``name`` cannot take a bake (checked before baking)."""
    image = bpy.data.images.get(name)
    reason = None if image is None else unusable_reason(image)
    if reason is not None:
        raise ImageError(reason)


def prepare_image(name, width, height, float_buffer):
    """Create the image ``name`` or make an existing one fit the bake; return (image, Snapshot).

    A new image is Non-Color and float when asked. An existing image of another size is resized,
    not refused (the operator's tooltip says so): a generated image gets the bake's size and depth,
    an image from a file is scaled to the size (its depth is the file's; the file on disk is not
    touched). Either way its colour space becomes Non-Color: AO is data, and any other colour space
    would transform it. The Snapshot puts all of that back if the bake does not finish.
    """
    image = bpy.data.images.get(name)
    if image is None:
        image = bpy.data.images.new(name, width, height, alpha=True, float_buffer=float_buffer, is_data=True)
        return image, Snapshot(image, created=True)
    reason = unusable_reason(image)
    if reason is not None:
        raise ImageError(reason)
    snapshot = Snapshot(image, created=False)
    # The colour space first: changing it reloads an image from its file, which would undo a resize.
    # Only when it differs: setting it, even to the same name, also wipes a generated image's pixels
    # (Blender regenerates them), and a live bake shows its tiles over the previous pixels.
    if image.colorspace_settings.name != "Non-Color":
        image.colorspace_settings.name = "Non-Color"
    if image.source == "GENERATED":
        if (image.generated_width, image.generated_height, image.use_generated_float) != (
            width, height, float_buffer,
        ):
            image.generated_width, image.generated_height = width, height
            image.use_generated_float = float_buffer
    elif tuple(image.size) != (width, height):
        image.scale(width, height)
    if tuple(image.size) != (width, height):
        snapshot.restore()
        raise ImageError(
            f"image {name!r} could not be resized from {image.size[0]}x{image.size[1]} to {width}x{height}"
        )
    return image, snapshot


def output_dir_problem(folder):
    """Why image files cannot be written into ``folder``, or None when they can.

    A folder that does not exist yet is fine where it can be created (the writers create it): what
    counts is its nearest existing ancestor, which must be a folder that this process may write.
    Checked before a bake, so that a typo in the folder does not cost the bake; a write can still
    fail later (a full disk), and then the existing file is left as it was.
    """
    path = os.path.abspath(folder)
    existing = path
    while not os.path.exists(existing):
        parent = os.path.dirname(existing)
        if parent == existing:
            break
        existing = parent
    if not os.path.isdir(existing):
        return "it is a file, not a folder" if existing == path else f"{existing!r} is a file, not a folder"
    if not os.access(existing, os.W_OK | os.X_OK):
        return "it is not writable" if existing == path else f"{existing!r} is not writable"
    return None


def oiio_available():
    """Whether core.imageio can write files here (it needs the OpenImageIO Python module)."""
    return importlib.util.find_spec("OpenImageIO") is not None


def save(result, path, settings, metadata=None):
    """Write a bake result to ``path`` in ``settings.file_format``; return how it was written.

    The core's OpenImageIO writer is used where OpenImageIO is importable (Blender's official builds
    ship it): an atomic write, one grey channel, the bake's metadata. Where it is missing (Debian's
    Blender, for one), the pixels go through Blender's own writer instead: RGBA, the format's
    default depth for the image's depth (8 or 16-bit PNG, half or float EXR), no metadata.

    Returns
    -------
    str
        "OpenImageIO" or "Blender".
    """
    if oiio_available():
        imageio = corelink.load("imageio")
        imageio.write_ao(path, result, bits=settings.file_bits, metadata=metadata, make_dirs=True)
        return "OpenImageIO"
    save_pixels_with_blender(rgba(result.ao), path, settings.file_format, settings.float_buffer)
    return "Blender"


def save_pixels_with_blender(pixels, path, file_format, float_buffer):
    """Write (H, W, 4) pixels to ``path`` in ``file_format`` (PNG, OPEN_EXR, TIFF) through a temporary image.

    A temporary image, because saving an image to a path turns that image into a file image. The
    file is written beside ``path`` under a temporary name and then renamed over it, so that a failed
    write leaves an existing file at ``path`` as it was.
    """
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    stem, ext = os.path.splitext(os.path.basename(path))
    fd, temp_path = tempfile.mkstemp(prefix=f".{stem}.tmp", suffix=ext, dir=directory)
    os.close(fd)
    h, w = pixels.shape[:2]
    temp = bpy.data.images.new(".mc_ao_save", w, h, alpha=True, float_buffer=float_buffer, is_data=True)
    try:
        temp.pixels.foreach_set(np.ascontiguousarray(pixels, dtype=np.float32).ravel())
        temp.filepath_raw = temp_path
        temp.file_format = file_format
        temp.save()
        os.replace(temp_path, path)
    finally:
        bpy.data.images.remove(temp)
        if os.path.exists(temp_path):
            os.remove(temp_path)
