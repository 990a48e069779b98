"""UDIM tiles: how a map goes into a tiled image and its files, one per tile (mc_ao.udim does the
Blender side). Every map kind (mc_ao.outputs.maps.MapOutput) uses this when the bake is a UDIM bake:
its plane per tile, files ``<stem>.<tile><ext>``, the tiled image filled with every tile at once and
packed, or pointed at its saved tiles with Link to File."""

import os


def split(results, quantity, settings):
    """[(tile or None, {quantity: that tile's result})]: one entry (None) for a plain bake; for a UDIM
    bake one per tile of ``results[quantity]``, in tile order."""
    if not settings.use_udim:
        return [(None, results)]
    tiles = sorted(results[quantity].tiles)
    return [(t, {q: r.tiles[t] for q, r in results.items() if getattr(r, "tiles", None) and t in r.tiles})
            for t in tiles]


def tile_entries(entries, tile):
    """The planned files (mc_ao.filewriter.OutputFile) of one tile: ``.<tile>`` before each extension."""
    from .. import udim

    return entries if tile is None else udim.tile_files(entries, tile)


def check(name, width, height):
    """Raise images.ImageError when the existing image ``name`` cannot take tiles of this size."""
    from .. import udim

    udim.check_image(name, width, height)


def store(run, name, planes, float_buffer):
    """Fill the tiled image ``name`` with ``planes`` ({tile: plane}); its other tiles kept; packed."""
    from .. import images, udim

    udim.fill(name, {t: images.rgba(p) for t, p in planes.items()}, float_buffer)


def keep(run, job, name, result, path):
    """With Link to File and saved tiles (``path``: the image's file without its tile number): point
    the image at them, where the bake wrote every tile it has; else it stays packed (said so)."""
    import bpy

    from .. import images, udim

    if path is None or not run.settings.link_to_file:
        return
    image = bpy.data.images.get(name)
    if image is None:
        return
    if {t.number for t in image.tiles} - set(result.tiles):
        run.warn(f"image {name!r} has tiles the bake did not write; its pixels are "
                 "packed into the .blend file instead of loading from the saved files")
        return
    try:
        udim.link_files(name, path, run.link_relative)
    except (images.ImageError, RuntimeError) as exc:
        run.warn(f"{exc}; its pixels are packed into the .blend file instead")


def untiled(path, tile):
    """``<stem><ext>`` from the tile's ``<stem>.<tile><ext>``."""
    stem, ext = os.path.splitext(path)
    suffix = f".{int(tile)}"
    return (stem[:-len(suffix)] if stem.endswith(suffix) else stem) + ext
