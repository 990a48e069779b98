"""Blender images for bake results: create or reuse "<object>_AO", fill it, restore it, save it."""

import os

import bpy
import numpy as np

from . import corelink
from .jobs import folder_problem as output_dir_problem  # noqa: F401 (the operator checks its folder)


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


def save_pixels_with_blender(pixels, path, file_format, bits):
    """Write (H, W, 4) pixels to ``path`` in ``file_format`` (PNG, OPEN_EXR, TIFF) with Blender's writer.

    Used where this Python has no OpenImageIO module (mc_ao.jobs.write_outputs chooses). ``bits``
    8 writes an 8-bit file; any other value a float image, which Blender writes as a 16-bit PNG or
    TIFF, or a float EXR (Image.save() writes float EXR also for "half": checked with bpy 5.0.1).
    RGBA, no metadata.

    The pixels go into a temporary image (saving an image to a path turns that image into a file
    image) and from it into a temporary file beside ``path`` (core.atomicfile). Blender's PNG writer
    reports a file cut short by a full disk as saved, so the file is loaded back and compared with
    the pixels before it replaces anything at ``path``; a failure raises core.ImageWriteError and
    leaves ``path`` as it was.
    """
    core = corelink.load()
    atomicfile = corelink.load("atomicfile")
    pixels = np.ascontiguousarray(pixels, dtype=np.float32)
    h, w = pixels.shape[:2]

    def write(temp):
        image = bpy.data.images.new(".mc_ao_save", w, h, alpha=True, float_buffer=bits != 8, is_data=True)
        try:
            image.pixels.foreach_set(pixels.ravel())
            image.filepath_raw = os.fspath(temp)
            image.file_format = file_format
            try:
                image.save()
            except RuntimeError as exc:
                # "Error: Could not write image: No space left on device\nError: Image ... could not be saved"
                raise RuntimeError(str(exc).strip().splitlines()[0].removeprefix("Error: ")) from None
        finally:
            bpy.data.images.remove(image)

    atomicfile.write_file(
        path, write, verify=lambda temp: _reads_back(temp, pixels, file_format, bits),
        error=core.ImageWriteError,
    )


def _reads_back(temp, pixels, file_format, bits):
    """Raise ValueError unless Blender loads ``temp`` as ``pixels`` (within the file's precision)."""
    h, w, channels = pixels.shape
    image = bpy.data.images.load(os.fspath(temp), check_existing=False)
    try:
        image.colorspace_settings.name = "Non-Color"  # the values as stored, no colour transform
        if tuple(image.size) != (w, h):
            raise ValueError(f"it loads as {image.size[0]}x{image.size[1]}, not {w}x{h}")
        got = pixels_of(image)
    finally:
        bpy.data.images.remove(image)
    c = min(channels, got.shape[2])
    want = pixels[..., :c]
    if bits == 8:
        tolerance = 0.5 / 255
    elif file_format != "OPEN_EXR":
        tolerance = 0.5 / 65535
    elif bits == "half":
        tolerance = np.maximum(np.abs(want) * 2.0 ** -11, 2.0 ** -25)
    else:
        tolerance = 0.0
    if file_format != "OPEN_EXR":
        want = np.clip(want, 0.0, 1.0)
    off = np.abs(got[..., :c] - want) > tolerance + 1e-6
    off &= ~(np.isnan(got[..., :c]) & np.isnan(want))
    if off.any():
        raise ValueError(f"{int(off.sum())} of its values differ from those written")
