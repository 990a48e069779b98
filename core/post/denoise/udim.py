"""The denoiser on UDIM tiles together: the tiles in one canvas at their UDIM places, across the seams between tiles."""

import copy

import numpy as np

from ...base.errors import MeshError
from .guide import RADIUS, resolution_pair, surface_guide
from .filter import DenoiseInfo, denoise


def udim_canvas(tiles):
    """The layout of UDIM ``tiles`` (numbers) in one image: (u0, v0, nu, nv), the least tile
    column and row and how many tile columns and rows the tiles span. Tiles keep their places in
    UDIM space, so texels of neighbouring tiles stay neighbours and triangles that cross a tile's
    border are whole."""
    from ...geometry.uvtiles import tile_origin

    origins = np.array([tile_origin(t) for t in tiles])
    u0, v0 = origins.min(axis=0)
    nu, nv = origins.max(axis=0) - (u0, v0) + 1
    return int(u0), int(v0), int(nu), int(nv)


def udim_guide(mesh, tiles, resolution, radius=RADIUS):
    """:func:`surface_guide` of UDIM ``tiles`` (each ``resolution``, as :func:`core.bake_udim`
    bakes them) laid out in one image (:func:`udim_canvas`): seams between tiles are linked as seams
    within one."""
    w, h = resolution_pair(resolution)
    u0, v0, nu, nv = udim_canvas(tiles)
    if mesh.uvs is None:
        raise MeshError(f"mesh {mesh.name!r} has no UVs: the denoiser's guide needs the UV map the bake used")
    canvas = copy.copy(mesh)
    canvas.uvs = (mesh.uvs - np.array([u0, v0], np.float64)) / np.array([nu, nv], np.float64)
    return surface_guide(canvas, (nu * w, nv * h), radius=radius)


def denoise_udim(tile_maps, guide, margin=0, **kw):
    """Denoise UDIM tiles together, across the seams between them.

    Parameters
    ----------
    tile_maps : {tile: (ao, stderr, mask)} (H, W) each, as :func:`core.bake_udim`'s results hold them.
    guide : :func:`udim_guide` of the same tiles and resolution.
    margin : re-dilate this many texels per tile (as the bake does), 0: outside texels keep their value.
    kw : :func:`denoise`'s other arguments.

    Returns
    -------
    {tile: (ao, stderr, info)} as :func:`denoise` returns them, one per tile.
    """
    from ...geometry.margin import dilate
    from ...geometry.uvtiles import tile_origin

    tiles = sorted(tile_maps)
    u0, v0, nu, nv = udim_canvas(tiles)
    h, w = np.asarray(tile_maps[tiles[0]][0]).shape
    if (guide.height, guide.width) != (nv * h, nu * w):
        raise ValueError(f"the guide is {guide.width} x {guide.height}, the tiles' canvas {nu * w} x {nv * h}")
    ao = np.zeros((nv * h, nu * w), np.float32)
    se = np.zeros_like(ao)
    mask = np.zeros(ao.shape, bool)
    blocks = {}
    for t in tiles:
        tu, tv = tile_origin(t)
        b = (slice((tv - v0) * h, (tv - v0 + 1) * h), slice((tu - u0) * w, (tu - u0 + 1) * w))
        blocks[t] = b
        a, s, m = (np.asarray(x) for x in tile_maps[t])
        ao[b], se[b], mask[b] = a, s, m
    out, err, info = denoise(ao, se, mask, guide, margin=0, **kw)
    result = {}
    for t in tiles:
        b = blocks[t]
        a = np.where(mask[b], out[b], np.asarray(tile_maps[t][0], np.float32)).astype(np.float32)
        if margin:
            dilate(a, mask[b], int(margin), out=a)
        part = DenoiseInfo(choice=info.choice[b].copy(), variance=info.variance[b].copy(), bias=info.bias[b].copy(),
                           bandwidths=info.bandwidths, shapes=info.shapes)
        result[t] = (a, err[b].copy(), part)
    return result


__all__ = ["udim_canvas", "udim_guide", "denoise_udim"]
