"""UDIM tiles: their numbers, which tiles a UV layout touches, and a mesh's UVs moved onto one tile.

Numbering (Blender's ``BKE_image_get_tile_from_pos``): tile 1001 + u_tile + 10 v_tile covers
u in [u_tile, u_tile + 1), v in [v_tile, v_tile + 1), with u_tile in 0..9 and v_tile in 0..99 (tiles
1001 to 2000). Cycles bakes every tile of the target image with the UVs shifted by the tile's origin
and clipped to its square, and extends the margin per tile (``RE_bake_pixels_populate``,
``write_internal_bake_pixels`` in Blender's source). :func:`core.bake_udim` does the same with one
image bake per tile: the UVs minus the tile's origin (:func:`shifted`), each tile its own image of the
same size, margin and all.

A triangle belongs to every tile its UV triangle overlaps with positive area: clipped to each tile's
square, exactly (a triangle with an edge on a tile border is not in the tile across it; one that
crosses a border is baked in both tiles, each the part in its square). Texel centres never lie on a
border. The tiles a layout touches are those where this overlap covers some of a texel
(:data:`core.geometry.raster.MIN_FRAGMENT_AREA`, the rasteriser's own threshold).

Each tile draws its own random numbers: tile 1001 with the bake's seed (a UDIM bake of a layout
inside [0, 1] equals a plain bake), tile t with the seed plus (t - 1001) * 2^32 (:func:`tile_seed`), so
that tiles do not repeat one another's noise.
"""

import copy
from dataclasses import dataclass, field

import numpy as np

from ..base.errors import MeshError
from ..base.request import FIRST_TILE, LAST_TILE, check_resolution
from .raster import MIN_FRAGMENT_AREA, clip_polygons, prepare, rasterize_tile

U_TILES, V_TILES = 10, 100


def tile_origin(tile):
    """(u, v) of tile ``tile``'s lower left corner: ((t - 1001) % 10, (t - 1001) // 10)."""
    t = int(tile) - FIRST_TILE
    return t % U_TILES, t // U_TILES


def tile_of(u_tile, v_tile):
    return FIRST_TILE + int(u_tile) + U_TILES * int(v_tile)


def tile_seed(seed, tile):
    """The seed tile ``tile`` draws with (see the module docstring)."""
    return int(seed) + (int(tile) - FIRST_TILE) * (1 << 32)


@dataclass
class TileCoverage:
    """What :func:`covered_tiles` found: the tiles and how much of each the UVs cover.

    tiles : sorted tile numbers; area : {tile: UV area covered (sum over triangles, overlaps counted
    twice)}; outside : triangles with some of their UV area outside the tiles (u < 0, v < 0, u > 10
    or v > 100), whose part outside is not baked.
    """

    tiles: list
    area: dict = field(default_factory=dict)
    outside: int = 0


def covered_tiles(mesh, resolution=None):
    """The UDIM tiles the UV triangles of ``mesh`` overlap with positive area (see the module docstring).

    ``resolution`` (int or (W, H)): a tile counts when the rasteriser covers one of its texels at
    that size (an overlap of at least :data:`core.geometry.raster.MIN_FRAGMENT_AREA` of a texel: a tile whose
    overlap is smaller than a texel in all is rasterised to find out); None: any positive area.
    """
    if mesh.uvs is None:
        raise MeshError(f"mesh {mesh.name!r} has no UVs: the baker needs a UV map to know where each texel lies")
    w, h = check_resolution(resolution) if resolution is not None else (1, 1)
    threshold = MIN_FRAGMENT_AREA / (w * h) if resolution is not None else 0.0
    uv = mesh.uvs
    valid = prepare(mesh, 1, 1).valid
    idx = np.flatnonzero(valid)
    tri = uv[idx]
    lo = np.floor(tri.min(axis=1)).astype(np.int64)
    hi = np.ceil(tri.max(axis=1)).astype(np.int64)  # exclusive
    hi = np.maximum(hi, lo + 1)
    # Triangle area inside the tile grid, to find the ones reaching outside it.
    full = 0.5 * np.abs((tri[:, 1, 0] - tri[:, 0, 0]) * (tri[:, 2, 1] - tri[:, 0, 1])
                        - (tri[:, 1, 1] - tri[:, 0, 1]) * (tri[:, 2, 0] - tri[:, 0, 0]))
    glo = np.maximum(lo, 0)
    ghi = np.minimum(hi, [U_TILES, V_TILES])
    nx = np.maximum(ghi[:, 0] - glo[:, 0], 0)
    ny = np.maximum(ghi[:, 1] - glo[:, 1], 0)
    count = nx * ny
    rep = np.repeat(np.arange(len(idx)), count)
    k = np.arange(rep.size) - np.repeat(np.cumsum(count) - count, count)
    tu = glo[rep, 0] + k % np.maximum(nx[rep], 1)
    tv = glo[rep, 1] + k // np.maximum(nx[rep], 1)
    area = np.zeros(len(rep))
    for c0 in range(0, len(rep), 1 << 16):
        c = slice(c0, min(c0 + (1 << 16), len(rep)))
        area[c] = _overlap(tri[rep[c]], tu[c], tv[c])
    inside_total = np.bincount(rep, weights=area, minlength=len(idx))
    outside = int(np.count_nonzero(inside_total < full * (1.0 - 1e-9) - 1e-300))
    hit = area > threshold
    numbers = FIRST_TILE + tu[hit] + U_TILES * tv[hit]
    per_tile, members = {}, {}
    for t, a, i in zip(numbers.tolist(), area[hit].tolist(), idx[rep[hit]].tolist()):
        per_tile[t] = per_tile.get(t, 0.0) + a
        members.setdefault(t, []).append(i)
    if resolution is not None:
        for t in [t for t, a in per_tile.items() if a * w * h < 1.0]:
            if not _rasterises(mesh, t, np.array(members[t]), w, h):
                del per_tile[t]
    return TileCoverage(tiles=sorted(per_tile), area=per_tile, outside=outside)


def _rasterises(mesh, tile, tri_ids, w, h):
    """Whether the rasteriser covers a texel of tile ``tile`` with the triangles ``tri_ids``."""
    uvtris = prepare(shifted(mesh, tile), w, h)
    xy = uvtris.xy[tri_ids]
    x0, y0 = np.clip(np.floor(xy.min(axis=(0, 1))).astype(np.int64), 0, [w, h])
    x1, y1 = np.clip(np.ceil(xy.max(axis=(0, 1))).astype(np.int64), 0, [w, h])
    if x1 <= x0 or y1 <= y0:
        return False
    return len(rasterize_tile(uvtris, tri_ids, w, h, x0, y0, x1, y1).texels) > 0


def _overlap(tri, tu, tv):
    """Area of each UV triangle (n, 3, 2) inside the unit square at (tu, tv). Polygons are columns
    (vertex slots down, triangles across), as :func:`core.geometry.raster.clip_polygons` takes them."""
    n = len(tri)
    X, Y = np.zeros((8, n)), np.zeros((8, n))
    X[:3], Y[:3] = tri[:, :, 0].T, tri[:, :, 1].T
    cnt = np.full(n, 3)
    zero, one = np.zeros(n), np.ones(n)
    # x >= tu, x <= tu + 1, y >= tv, y <= tv + 1, as a x + b y + c >= 0.
    for a, b, c in ((one, zero, -tu), (-one, zero, tu + 1.0), (zero, one, -tv), (zero, -one, tv + 1.0)):
        k = X.shape[0] - 1
        cx, cy, cnt = clip_polygons(X[:k], Y[:k], cnt, a, b, c.astype(np.float64))
        X, Y = np.zeros((8, n)), np.zeros((8, n))
        X[:k + 1], Y[:k + 1] = cx, cy
    slot = np.arange(X.shape[0])[:, None]
    nxt = np.where(slot + 1 < cnt, slot + 1, 0)
    alive = slot < cnt
    xn = np.take_along_axis(X, nxt, axis=0)
    yn = np.take_along_axis(Y, nxt, axis=0)
    t = np.where(alive, X * yn - xn * Y, 0.0)
    # The shoelace terms added pairwise, as numpy sums 8 values along a row (the same bits as before).
    return 0.5 * np.abs(((t[0] + t[1]) + (t[2] + t[3])) + ((t[4] + t[5]) + (t[6] + t[7])))


def shifted(mesh, tile):
    """``mesh`` with its UVs moved by minus tile ``tile``'s origin (the tile's square onto [0, 1])."""
    du, dv = tile_origin(tile)
    out = copy.copy(mesh)
    out.uvs = mesh.uvs - np.array([du, dv], dtype=np.float64)
    return out


__all__ = ["covered_tiles", "TileCoverage", "tile_origin", "tile_of", "tile_seed", "shifted", "FIRST_TILE", "LAST_TILE",
           "U_TILES", "V_TILES"]
