"""Blender images for bake results: create or reuse "<object>_AO", fill it, restore it, save it."""

import os

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
    if ao.ndim == 3:  # (H, W, 3) colours (a bent-normal map): RGB as given, or their first channel
        out = np.ones(ao.shape[:2] + (channels,), dtype=np.float32)
        colour = 1 if channels == 2 else min(channels, 3)
        out[..., :colour] = ao[..., :colour]
        return out
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
    """What an image was before a bake wrote into it, to put it back when the bake does not finish.

    A bake that creates its image removes it again. One that reuses an image changes only the
    image's pixel buffer while it runs (its size, through Image.scale, and its pixels), never the
    datablock's settings: Blender's memfile undo keeps the pixel buffer of an image whose datablock
    did not change, but drops it (and regenerates a generated image blank, or reloads a file image
    from disk) for one whose settings changed. So a cancelled bake leaves nothing for a later undo
    step to lose. Putting back: an image whose pixels Blender can bring back itself (a clean
    generated image, a clean packed one, a clean file image whose file has not changed since) gets
    its buffers freed, so that Blender brings it back and it stays clean; any other image (painted,
    baked before and not saved) gets its size and pixels back from the copy kept here.
    """

    def __init__(self, image, created):
        self.name = image.name
        self.created = created
        if created:
            return
        self.source = image.source
        self.generated_state = (image.generated_width, image.generated_height, image.use_generated_float)
        self.colorspace = image.colorspace_settings.name
        # image.has_data is False for a file image until its pixels are first read; size loads it.
        self.size = tuple(image.size)
        self.dirty = image.is_dirty
        self.packed = image.packed_file is not None
        self.file_stat = _file_stat(image)
        self.pixels = pixels_of(image) if all(self.size) else None

    def _comes_back_by_itself(self, image):
        """Whether freeing the image's buffers brings back exactly the pixels it had.

        True for an image that was clean (no painted or unsaved pixels): Blender then regenerates a
        generated image, decodes a packed one from its packed data, and reads a file image from its
        file, which must not have changed since.
        """
        if self.dirty or image.source != self.source:
            return False
        if self.source == "GENERATED":
            return True
        if self.packed:
            return image.packed_file is not None
        return self.file_stat is not None and _file_stat(image) == self.file_stat

    def restore(self):
        image = bpy.data.images.get(self.name)
        if image is None:
            return
        if self.created:
            bpy.data.images.remove(image)
            return
        # Settings that finish_image() may have changed before it failed; each reloads the image.
        if image.colorspace_settings.name != self.colorspace:
            image.colorspace_settings.name = self.colorspace
        if self.source == "GENERATED" and (
            image.generated_width, image.generated_height, image.use_generated_float
        ) != self.generated_state:
            image.generated_width, image.generated_height, image.use_generated_float = self.generated_state
        if self._comes_back_by_itself(image):
            # Not Image.reload(): on a packed image it re-packs the file on disk, if there is one.
            image.buffers_free()
            _redraw_image(image)
            if tuple(image.size) == self.size:
                return
        if tuple(image.size) != self.size and all(self.size):
            image.scale(*self.size)
        if self.pixels is not None and tuple(image.size) == self.size:
            set_pixels(image, self.pixels)


def _file_stat(image):
    """(size, modification time) of an unpacked file image's file, or None (generated, packed, missing)."""
    if image.source != "FILE" or image.packed_file is not None or not image.filepath:
        return None
    try:
        st = os.stat(bpy.path.abspath(image.filepath, library=image.library))
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns


def _redraw_image(image):
    """Let viewers show an image whose buffers were freed or reloaded (the 3D Viewport follows the tag)."""
    image.update_tag()


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
    """Create the image ``name``, or give an existing one's pixel buffer the bake's size.

    Returns (image, Snapshot).

    A new image is Non-Color and float when asked. An existing image of another size is resized,
    not refused (the operator's tooltip says so), through its pixel buffer only (Image.scale): its
    settings (colour space, a generated image's size and depth) stay as they were until the bake
    finishes, when finish_image() settles them, so that a bake that does not finish leaves nothing
    that Blender's undo would later reset (see Snapshot). The Snapshot puts the image back if the
    bake does not finish.
    """
    image = bpy.data.images.get(name)
    if image is None:
        image = bpy.data.images.new(name, width, height, alpha=True, float_buffer=float_buffer, is_data=True)
        return image, Snapshot(image, created=True)
    reason = unusable_reason(image)
    if reason is not None:
        raise ImageError(reason)
    snapshot = Snapshot(image, created=False)
    if tuple(image.size) != (width, height):
        image.scale(width, height)
    if tuple(image.size) != (width, height):
        snapshot.restore()
        raise ImageError(
            f"image {name!r} could not be resized from {image.size[0]}x{image.size[1]} to {width}x{height}"
        )
    return image, snapshot


def finish_image(name, ao, float_buffer):
    """Give the image ``name`` a finished bake for good: settings, size and pixels; return the image.

    Its colour space becomes Non-Color (AO is data; any other colour space would transform it); a
    generated image gets the bake's size and depth (a file image keeps its file's depth); then the
    pixels. The settings first, since changing them reloads or regenerates the pixel buffer.
    """
    image = bpy.data.images.get(name)
    if image is None:
        raise ImageError(f"image {name!r} is gone")
    h, w = ao.shape[:2]
    if image.colorspace_settings.name != "Non-Color":
        image.colorspace_settings.name = "Non-Color"
    if image.source == "GENERATED" and (
        image.generated_width, image.generated_height, image.use_generated_float
    ) != (w, h, float_buffer):
        image.generated_width, image.generated_height = w, h
        image.use_generated_float = float_buffer
    if tuple(image.size) != (w, h):
        image.scale(w, h)
    set_pixels(image, rgba(ao, image.channels))
    return image


#: Colour spaces whose stored values are the linear values themselves (data, or linear light).
_LINEAR_SPACES = {"Non-Color", "Raw", "Generic Data", "Linear", "Linear Rec.709", "Linear CIE-XYZ E",
                  "Linear FilmLight E-Gamut", "Linear Rec.2020", "ACEScg", "ACES2065-1"}
#: Colour spaces whose byte values are the sRGB encoding of the linear values.
_SRGB_SPACES = {"sRGB", "sRGB 2.1", "Rec.709"}


def encoding_of(image):
    """How a bake's linear values go into ``image``'s pixels, as Cycles' bake stores them: "linear"
    (a float image, whose buffer is linear whatever its colour space, or a byte image in a data or
    linear colour space), "srgb" (a byte image in sRGB: the values' sRGB encoding), or None for a
    byte image in a colour space this add-on does not encode (it is refused before baking)."""
    space = image.colorspace_settings.name
    if image.is_float or getattr(image.colorspace_settings, "is_data", False) or space in _LINEAR_SPACES:
        return "linear"
    if space in _SRGB_SPACES:
        return "srgb"
    return None


def srgb_encode(values):
    """The sRGB encoding (IEC 61966-2-1, OpenColorIO's "sRGB" of Blender's config) of linear values."""
    v = np.clip(np.asarray(values, np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1.0 / 2.4) - 0.055).astype(np.float32)


def describe(image):
    """"2048x2048, 8-bit, sRGB": what a shared image keeps."""
    depth = "float" if image.is_float else "8-bit"
    return f"{image.size[0]}x{image.size[1]}, {depth}, {image.colorspace_settings.name}"


def check_shared(name):
    """Raise ImageError when the existing image ``name`` cannot take a bake into its own pixels (a
    UDIM, movie or render image; a byte image in a colour space the add-on does not encode)."""
    image = bpy.data.images.get(name)
    if image is None:
        return
    reason = unusable_reason(image)
    if reason is None and encoding_of(image) is None:
        reason = (f"image {name!r} is an 8-bit image in colour space {image.colorspace_settings.name!r}; the bake "
                  "stores its values into Non-Color, linear or sRGB images: change its colour space, or bake into a "
                  "float image")
    if reason is not None:
        raise ImageError(reason)


def store_shared(name, plane, texels):
    """Write a shared image's bake into the existing image ``name`` as Cycles' bake does: only the
    ``texels`` (H, W) bool it baked (its objects' covered and margin texels), every other pixel as it
    was; the image keeps its size, depth and colour space (an 8-bit sRGB image gets the sRGB encoding
    of the values, which Blender's shaders decode back to them). Returns the image."""
    image = bpy.data.images.get(name)
    if image is None:
        raise ImageError(f"image {name!r} is gone")
    h, w = plane.shape[:2]
    if tuple(image.size) != (w, h):
        raise ImageError(f"image {name!r} is {image.size[0]}x{image.size[1]}, not the bake's {w}x{h}: it changed "
                         "during the bake")
    encoding = encoding_of(image)
    values = plane if encoding == "linear" else srgb_encode(plane)
    pixels = pixels_of(image)
    channels = pixels.shape[2]
    colour = 1 if channels == 2 else min(channels, 3)
    sel = np.asarray(texels, bool)
    if values.ndim == 3:
        pixels[sel, :colour] = values[sel][:, :colour]
    else:
        pixels[sel, :colour] = values[sel][:, None]
    if channels in (2, 4):
        pixels[sel, channels - 1] = 1.0
    set_pixels(image, pixels)
    return image


#: The custom property of a Blender image that holds the record of the atlas baked into it
#: (core.files.atlasrecord: its objects, their fingerprints and texels; mc_ao.atlas reads it).
RECORD_PROPERTY = "mc_ao_atlas"


def keep_record(name, data):
    """Keep an atlas's record (bytes) on the image ``name``, where its next bake finds it: as base64
    text (Blender keeps ID property strings as C strings, and an undo step cut raw bytes at their
    first zero byte)."""
    import base64

    image = bpy.data.images.get(name)
    if image is not None:
        image[RECORD_PROPERTY] = base64.b64encode(bytes(data)).decode("ascii")


def record_bytes(image):
    """The record bytes :func:`keep_record` kept on ``image``, or None."""
    import base64
    import binascii

    text = image.get(RECORD_PROPERTY)
    if text is None:
        return None
    try:
        return base64.b64decode(text if isinstance(text, (str, bytes)) else str(text), validate=True)
    except (binascii.Error, ValueError):
        return b""  # not a record: the caller says so


def pack(image):
    """Keep a baked image's pixels inside the .blend file: packed, with a fake user.

    Packed pixels are written into the .blend by File > Save, and into every undo step, so the bake
    survives saving and reopening, and undo and redo, which keep no pixels of an unpacked image
    whose datablock changed. The fake user keeps an image that no material uses yet from being
    dropped on save. A float image is packed as a float OpenEXR, an 8-bit one as a PNG (Blender's
    choice; both exact). An image loaded from a file is packed too: the file on disk is left as it
    was (Image > Unpack writes the bake there).

    Raises ImageError when Blender cannot pack it.
    """
    image.use_fake_user = True
    try:
        image.pack()
    except RuntimeError as exc:
        raise ImageError(f"image {image.name!r} could not be packed into the .blend file: {exc}") from None


def use_file(image, path, relative):
    """Make ``image`` the image file at ``path`` (as Image > Save As does); its pixels become the file's.

    ``relative``: store the path relative to the .blend file ("//..."), where it is saved. The
    image gets a fake user (kept on save even when no material uses it); packed pixels from an
    earlier bake are dropped, since the file now holds the bake.

    Raises ImageError when Blender cannot read the file back; the image is then a generated image
    again, whose pixels the caller puts back.
    """
    size = tuple(image.size)
    image.use_fake_user = True
    image.filepath = bpy.path.relpath(path) if relative and bpy.data.filepath else path
    if image.source != "FILE":
        image.source = "FILE"
    if image.packed_file is not None:
        image.unpack(method="REMOVE")
    if image.colorspace_settings.name != "Non-Color":
        image.colorspace_settings.name = "Non-Color"
    image.reload()  # not packed (any more): reads the file
    _redraw_image(image)
    if tuple(image.size) != size:
        image.filepath = ""
        image.source = "GENERATED"
        raise ImageError(f"Blender could not read the saved file {path!r} into image {image.name!r}")


def save_pixels_with_blender(pixels, path, file_format, bits):
    """Write (H, W, 4) pixels to ``path`` in ``file_format`` (PNG, OPEN_EXR, TIFF) with Blender's writer.

    Used where this Python has no OpenImageIO module (mc_ao.outputs.maps chooses). ``bits``
    8 writes an 8-bit file; any other value a float image, which Blender writes as a 16-bit PNG or
    TIFF, or a float EXR (Image.save() writes float EXR also for "half": checked with bpy 5.0.1).
    RGBA, no metadata.

    The pixels go into a temporary image (saving an image to a path turns that image into a file
    image) and from it into a temporary file beside ``path`` (core.files.atomicfile). Blender's PNG writer
    reports a file cut short by a full disk as saved, so the file is loaded back and compared with
    the pixels before it replaces anything at ``path``; a failure raises core.ImageWriteError and
    leaves ``path`` as it was.
    """
    core = corelink.load()
    atomicfile = corelink.load("files.atomicfile")
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
