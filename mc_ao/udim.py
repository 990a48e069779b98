"""UDIM bakes in Blender (scene.mc_ao.use_udim): one tiled image per object, one file per tile.

What the bpy API allows (checked on Blender 4.2 and 5.0; ``rna_Image_pixels_get/set``): ``Image.pixels``
reaches only a tiled image's first tile, and no API sets another tile's pixels. So a finished UDIM
bake goes into its image through files: every tile (the baked ones, and an existing image's other
tiles, kept as they were) is written to a temporary folder as ``tile.<number>.<ext>`` (float EXR for a
float image, else an 8-bit PNG of the linear values), the image is pointed at ``tile.<UDIM>.<ext>``
and reloaded (Blender finds every tile's file), then packed into the .blend file (or, with Save to
File and Link Image to File, pointed at the saved ``<name>.<UDIM>.<ext>`` files instead) and the
temporary folder removed. Nothing changes until the object's bake has finished: Esc and failures
leave the image as it was.

- A new image is created tiled (source 'TILED'), one tile per tile the UVs touch, each of the bake's
  size, Non-Color.
- An existing tiled image is filled tile by tile; its other tiles keep their pixels. A tile of
  another size than the bake's is refused before baking, naming the object, the image and the tile;
  so is an existing image that is not tiled (rename it, or choose another Image name).
- Files: ``<name>.<tile>.<ext>`` (Blender's ``<UDIM>`` token, Mari's and Substance's convention), and
  ``<name>_stderr.<tile>.exr`` for the standard errors.

Importing this module needs no bpy (the script and mc_ao.filewriter use its file names).
"""

import os
import shutil
import tempfile

import numpy as np

from . import corelink

UDIM_TOKEN = "<UDIM>"


def tile_path(path, tile):
    """``<stem>.<tile><ext>`` from ``<stem><ext>``."""
    stem, ext = os.path.splitext(path)
    return f"{stem}.{int(tile)}{ext}"


def token_path(path):
    """``<stem>.<UDIM><ext>``: the path Blender loads a tiled image's files from."""
    stem, ext = os.path.splitext(path)
    return f"{stem}.{UDIM_TOKEN}{ext}"


def tile_files(files, tile):
    """mc_ao.filewriter.OutputFile list of one tile: every path with ``.<tile>`` before its extension."""
    from dataclasses import replace

    return [replace(f, path=tile_path(f.path, tile),
                    stderr_path=tile_path(f.stderr_path, tile) if f.stderr_path else None) for f in files]


# -- checks before the bake (main thread) -------------------------------------------------------

def check_image(name, width, height):
    """Raise images.ImageError when the existing image ``name`` cannot take a UDIM bake of
    ``width`` x ``height`` tiles: it is not tiled, or one of its tiles has another size."""
    import bpy

    from .images import ImageError

    image = bpy.data.images.get(name)
    if image is None:
        return
    if image.source != "TILED":
        raise ImageError(
            f"image {name!r} is a {image.source.lower()} image, not a tiled (UDIM) one; a UDIM bake "
            "needs a tiled image: rename or remove it, or choose another Image name"
        )
    for tile in image.tiles:
        size = tuple(tile.size)
        if any(size) and size != (width, height):
            raise ImageError(
                f"tile {tile.number} of image {name!r} is {size[0]}x{size[1]}, the bake makes "
                f"{width}x{height} tiles; set Size to {size[0]}"
                + (f" and Height to {size[1]}" if size[1] != size[0] else "")
                + ", or choose another Image name"
            )


# -- reading and writing tiles (main thread) -----------------------------------------------------

def tile_pixels(image, numbers=None):
    """{tile number: (H, W, 4) float32 pixels as stored (no colour transform)} of a tiled image's
    tiles that hold pixels (all, or those in ``numbers``).

    Blender gives no tile's pixels but the first's; so the image is packed (its current buffers,
    painted pixels included, become its packed data, as File > Save would make them) and each tile's
    packed file is decoded. The image stays packed.
    """
    import bpy

    wanted = [t.number for t in image.tiles if any(t.size) and (numbers is None or t.number in numbers)]
    if not wanted:
        return {}
    if image.is_dirty or len(image.packed_files) < len(wanted):
        if not image.is_dirty and image.source == "TILED" and any(image.tiles[0].size):
            # Blender packs a clean generated image's tiles as nothing: its buffers count once dirty.
            first = np.empty(len(image.pixels), np.float32)
            image.pixels.foreach_get(first)
            image.pixels.foreach_set(first)
        image.pack()
    out = {}
    folder = tempfile.mkdtemp(prefix="mc_ao_tiles_")
    try:
        for packed in image.packed_files:
            if packed.tile_number not in wanted:
                continue
            data = bytes(packed.packed_file.data)
            path = os.path.join(folder, f"tile{packed.tile_number}")
            with open(path, "wb") as f:
                f.write(data)
            loaded = bpy.data.images.load(path, check_existing=False)
            try:
                loaded.colorspace_settings.name = "Non-Color"
                w, h = loaded.size
                px = np.empty(w * h * loaded.channels, np.float32)
                loaded.pixels.foreach_get(px)
                px = px.reshape(h, w, loaded.channels)
            finally:
                bpy.data.images.remove(loaded)
            out[packed.tile_number] = _rgba(px)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return out


def _rgba(px):
    h, w, c = px.shape
    out = np.ones((h, w, 4), np.float32)
    if c in (1, 2):
        out[..., :3] = px[..., :1]
        if c == 2:
            out[..., 3] = px[..., 1]
    else:
        out[..., :min(c, 4)] = px[..., :min(c, 4)]
    return out


def _write_tile(path, pixels, float_buffer):
    """One tile's (H, W, 4) pixels to ``path`` (EXR float or 8-bit PNG, linear), any writer."""
    from . import filewriter

    if filewriter.oiio_available():
        corelink.load("files.imageio").write_image(path, pixels, bits="float" if float_buffer else 8)
    else:
        from . import images

        images.save_pixels_with_blender(pixels, path, "OPEN_EXR" if float_buffer else "PNG",
                                        "float" if float_buffer else 8)


def fill(name, tiles, float_buffer, keep_others=True):
    """Put ``tiles`` ({number: (H, W, 4) float32}) into the tiled image ``name`` (created if missing),
    keeping its other tiles' pixels; pack it (all tiles). Returns the image.

    Raises images.ImageError when Blender does not load a tile back; the image is then put back as
    it was (a created one removed).
    """
    import bpy

    from .images import ImageError

    image = bpy.data.images.get(name)
    created = image is None
    previous = {} if created else tile_pixels(bpy.data.images[name])
    if not created and not keep_others:
        previous = {t: p for t, p in previous.items() if t in tiles}
    everything = {**previous, **tiles} if keep_others else dict(tiles)
    (h, w, _), = {p.shape for p in tiles.values()} or {(1, 1, 4)}
    if created:
        image = bpy.data.images.new(name, w, h, alpha=True, float_buffer=float_buffer, is_data=True, tiled=True)
    try:
        _load(image, everything, float_buffer)
        for number, pixels in tiles.items():
            tile = _tile(image, number)
            if tile is None or tuple(tile.size) != (pixels.shape[1], pixels.shape[0]):
                raise ImageError(f"Blender did not load tile {number} of image {name!r} back")
        image.use_fake_user = True
    except BaseException:
        if created:
            bpy.data.images.remove(image)
        else:
            try:
                _load(bpy.data.images[name], previous, float_buffer)
            except Exception:  # noqa: BLE001 - the first error is the one to report
                pass
        raise
    return image


def _tile(image, number):
    """The tile ``number`` of ``image`` or None (``tiles.get(1001)`` returns the first tile whatever its number)."""
    tile = image.tiles.get(number)
    return tile if tile is not None and tile.number == number else None


def _load(image, tiles, float_buffer):
    """Write ``tiles`` to a temporary folder, load them into ``image`` and pack it."""
    folder = tempfile.mkdtemp(prefix="mc_ao_udim_")
    ext = ".exr" if float_buffer else ".png"
    try:
        for number, pixels in tiles.items():
            _write_tile(os.path.join(folder, f"tile.{number}{ext}"), pixels, float_buffer)
        if image.source != "TILED":
            image.source = "TILED"
        if image.packed_file is not None or len(image.packed_files):
            image.unpack(method="REMOVE")
        image.filepath = os.path.join(folder, f"tile.{UDIM_TOKEN}{ext}")
        if image.colorspace_settings.name != "Non-Color":
            image.colorspace_settings.name = "Non-Color"
        image.reload()
        for number in tiles:
            if _tile(image, number) is None:
                image.tiles.new(tile_number=number)
        image.reload()
        for tile in image.tiles:
            tuple(tile.size)  # loads the tile: a tile never read is neither packed nor saved
        image.pack()
        image.filepath_raw = "//" + os.path.basename(image.filepath).replace("tile.", _safe(image.name) + ".", 1)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _safe(name):
    return corelink.load("files.filenames").safe_file_stem(name)


def link_files(name, path, relative):
    """Point the tiled image ``name`` at its saved tiles ``<stem>.<UDIM><ext>`` (``path`` is
    ``<stem><ext>``, the image's file without a tile) instead of its packed pixels, as Image > Save
    As would."""
    import bpy

    from .images import ImageError

    image = bpy.data.images[name]
    pattern = token_path(path)
    sizes = {t.number: tuple(t.size) for t in image.tiles}
    old = image.filepath
    if len(image.packed_files):
        image.unpack(method="REMOVE")
    image.filepath = bpy.path.relpath(pattern) if relative and bpy.data.filepath else pattern
    image.reload()
    got = {t.number: tuple(t.size) for t in image.tiles}
    if got != sizes:
        image.filepath = old
        raise ImageError(f"Blender could not read the saved files {pattern!r} into image {name!r}")
    image.use_fake_user = True
