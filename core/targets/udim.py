"""UDIM tiles: which tiles a UV layout touches, and a bake of each, as Cycles bakes a tiled image.

Numbering (Blender's ``BKE_image_get_tile_from_pos``): tile 1001 + u_tile + 10 v_tile covers
u in [u_tile, u_tile + 1), v in [v_tile, v_tile + 1), with u_tile in 0..9 and v_tile in 0..99 (tiles
1001 to 2000). Cycles bakes every tile of the target image with the UVs shifted by the tile's origin
and clipped to its square, and extends the margin per tile (``RE_bake_pixels_populate``,
``write_internal_bake_pixels`` in Blender's source). :func:`bake_udim` does the same with
one :func:`core.bake_ao` per tile: the UVs minus the tile's origin, each tile its own image of the
same size, margin and all.

A triangle belongs to every tile its UV triangle overlaps with positive area: clipped to each tile's
square, exactly (a triangle with an edge on a tile border is not in the tile across it; one that
crosses a border is baked in both tiles, each the part in its square). Texel centres never lie on a
border. The tiles a layout touches are those where this overlap covers some of a texel
(:data:`core.geometry.raster.MIN_FRAGMENT_AREA`, the rasteriser's own threshold).

Each tile draws its own random numbers: tile 1001 with the bake's seed (a UDIM bake of a layout
inside [0, 1] equals a plain bake), tile t with the seed plus (t - 1001) * 2^32, so that tiles do
not repeat one another's noise.
"""

import copy
from dataclasses import dataclass, field

import numpy as np

from ..pipeline.bake import BakeResult, bake_ao, empty_reason
from ..base.errors import MeshError, SettingsError
from ..geometry.mesh import Mesh
from ..geometry.raster import MIN_FRAGMENT_AREA, _clip, prepare, rasterize_tile
from ..engine.settings import _resolution

FIRST_TILE, LAST_TILE = 1001, 2000
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


def check_tiles(tiles):
    """The tile numbers, sorted and unique, after checking that each is a UDIM tile (1001 .. 2000)."""
    out = []
    for t in tiles:
        if isinstance(t, bool) or not isinstance(t, (int, np.integer)) or not FIRST_TILE <= t <= LAST_TILE:
            raise SettingsError(f"UDIM tile {t!r} does not exist: tiles are numbered {FIRST_TILE} to {LAST_TILE}")
        out.append(int(t))
    return sorted(set(out))


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
    w, h = _resolution(resolution) if resolution is not None else (1, 1)
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
    (vertex slots down, triangles across), as :func:`core.geometry.raster._clip` takes them."""
    n = len(tri)
    X, Y = np.zeros((8, n)), np.zeros((8, n))
    X[:3], Y[:3] = tri[:, :, 0].T, tri[:, :, 1].T
    cnt = np.full(n, 3)
    zero, one = np.zeros(n), np.ones(n)
    # x >= tu, x <= tu + 1, y >= tv, y <= tv + 1, as a x + b y + c >= 0.
    for a, b, c in ((one, zero, -tu), (-one, zero, tu + 1.0), (zero, one, -tv), (zero, -one, tv + 1.0)):
        k = X.shape[0] - 1
        cx, cy, cnt = _clip(X[:k], Y[:k], cnt, a, b, c.astype(np.float64))
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


#: The result of :func:`bake_udim`: :class:`core.BakeResult` with ``tiles``.
UdimResult = BakeResult


def _denoise_tiles(target, resolution, results, margin):
    """Denoise the tiles' maps together (:func:`core.post.denoise.denoise_udim`: across the seams between
    tiles too), keeping each tile's raw map (margin dilated) in ``raw_ao`` and ``raw_stderr``."""
    from ..post import denoise as _denoise
    from ..geometry.margin import dilate

    tiles = sorted(results)
    guide = _denoise.udim_guide(target, tiles, resolution)
    out = _denoise.denoise_udim({t: (results[t].ao, results[t].stderr, results[t].mask) for t in tiles}, guide,
                                margin=margin)
    for t in tiles:
        r = results[t]
        r.raw_ao, r.raw_stderr = r.ao, r.stderr
        if margin > 0:
            r.raw_ao = dilate(r.raw_ao.copy(), r.mask, margin)
        r.ao, r.stderr = out[t][0], out[t][1]
        r.metadata.update(denoise=True, margin=margin)


def shifted(mesh, tile):
    """``mesh`` with its UVs moved by minus tile ``tile``'s origin (the tile's square onto [0, 1])."""
    du, dv = tile_origin(tile)
    out = copy.copy(mesh)
    out.uvs = mesh.uvs - np.array([du, dv], dtype=np.float64)
    return out


def bake_udim(target, occluders=(), resolution=(1024, 1024), samples=256, *, tiles=None, seed=0, progress=None,
              cancel=None, on_tile=None, **kwargs):
    """Bake every UDIM tile the UVs of ``target`` touch (or the given ``tiles``), one image each.

    Parameters
    ----------
    tiles : None (the tiles :func:`covered_tiles` finds) or tile numbers; a listed tile the UVs do
        not touch is baked empty (nothing covered, all zero), as Cycles clears such a tile.
    on_tile : called as on_tile(tile, rows, cols, ao_block), as :func:`core.bake_ao`'s with the tile.
    progress : fraction of the whole bake, each tile weighed by the UV area it covers.
    The other parameters are :func:`core.bake_ao`'s, for every tile (the margin is per tile).

    Returns
    -------
    BakeResult with ``tiles`` (see :class:`core.BakeResult`)
    """
    quantity = kwargs.pop("quantity", "ao")
    return _bake_udim(target, occluders, resolution, samples, None, tiles, seed, progress, cancel, on_tile,
                      dict(kwargs, quantity=quantity))[None]


def bake_udim_maps(target, occluders=(), resolution=(1024, 1024), samples=256, *, quantities=("ao", "thickness"),
                   tiles=None, seed=0, progress=None, cancel=None, on_tile=None, **kwargs):
    """Several quantities of every UDIM tile in one pass per tile (:func:`core.bake_maps` per tile).

    ``quantities`` as for :func:`core.bake_maps`; ``on_tile`` is called as on_tile(quantity, tile,
    rows, cols, block); the others as for :func:`bake_udim`.

    Returns
    -------
    {quantity: BakeResult with ``tiles``}: each bit for bit :func:`bake_udim` of that quantity with the
    same settings.
    """
    from .maps import check_quantities

    return _bake_udim(target, occluders, resolution, samples, check_quantities(quantities), tiles, seed, progress,
                      cancel, on_tile, kwargs)


def _bake_udim(target, occluders, resolution, samples, quantities, tiles, seed, progress, cancel, on_tile, kwargs):
    """The UDIM bake of ``quantities`` (None: the one quantity of ``kwargs``, by :func:`core.bake_ao`;
    else by :func:`core.bake_maps`): {quantity (None for the one): BakeResult with ``tiles``}."""
    from ..pipeline.bake import bake_maps

    if not isinstance(target, Mesh):
        raise SettingsError(f"the target must be a core.Mesh, got {type(target).__name__}")
    # Denoised across the tiles' seams once every tile is baked (each tile alone would stop at its border).
    denoise = bool(kwargs.pop("denoise", False))
    if denoise and kwargs.get("replicates", 2) < 2:
        raise SettingsError("denoise needs replicates >= 2: the filter weighs each texel by its standard error, "
                            "which one replicate only bounds")
    margin = kwargs.get("margin", 16)
    tile_kwargs = dict(kwargs, margin=0) if denoise else kwargs
    coverage = covered_tiles(target, resolution)
    todo = coverage.tiles if tiles is None else check_tiles(tiles)
    weight = np.array([coverage.area.get(t, 0.0) for t in todo]) + 1e-12
    weight /= weight.sum()
    done = np.concatenate([[0.0], np.cumsum(weight)])
    names = [None] if quantities is None else list(quantities)
    results = {q: {} for q in names}
    for i, tile in enumerate(todo):
        def tile_progress(f, i=i):
            if progress is not None:
                progress(min(done[i] + weight[i] * f, 1.0))

        def tile_block(*args, tile=tile):
            if quantities is None:
                on_tile(tile, *args)
            else:
                on_tile(args[0], tile, *args[1:])

        common = dict(seed=tile_seed(seed, tile), progress=tile_progress, cancel=cancel,
                      on_tile=None if on_tile is None else tile_block, empty_ok=True)
        if quantities is None:
            baked = {None: bake_ao(shifted(target, tile), occluders, resolution, samples, **common, **tile_kwargs)}
        else:
            baked = bake_maps(shifted(target, tile), occluders, resolution, samples, quantities=quantities, **common,
                              **tile_kwargs)
        for q in names:
            results[q][tile] = baked[q]
    return {q: _assemble(target, resolution, results[q], todo, coverage, denoise, margin) for q in names}


def _assemble(target, resolution, results, todo, coverage, denoise, margin):
    """One quantity's UDIM result from its tiles' results."""
    if denoise and results:
        _denoise_tiles(target, resolution, results, margin)
    report = {}
    for r in results.values():
        for key, value in r.report.items():
            if key in ("degenerate_uv_triangles", "degenerate_triangles", "extrusion", "extrusion_served"):
                report[key] = value  # the same in every tile (the extrusion is measured on the whole mesh)
            elif key == "warnings":
                report[key] = report.get(key, []) + [w for w in value if w not in report.get(key, [])]
            elif key == "worker_memory":  # per process, the tile bake of its largest peak
                best = {e["process"]: e for e in report.get(key, [])}
                for e in value:
                    if ((best.get(e["process"]) or {}).get("peak") or 0) <= (e.get("peak") or 0):
                        best[e["process"]] = e
                report[key] = list(best.values())
            elif key != "uv_outside_triangles":
                report[key] = report.get(key, 0) + value
    report["uv_outside_udim_triangles"] = coverage.outside
    report["tiles"] = list(todo)
    parts = list(results.values())
    if not any(r.mask.any() for r in parts):
        reason = empty_reason(report.get("degenerate_triangles", 0), report.get("degenerate_uv_triangles", 0), 0,
                              coverage.outside)
        raise MeshError(f"mesh {target.name!r}: the bake covered no texel of the UDIM tiles "
                        f"{', '.join(map(str, todo))} ({reason}): nothing was written" if parts
                        else f"mesh {target.name!r}: the bake covered no texel (no UDIM tile): nothing was written")

    def stack(name):
        return np.stack([getattr(r, name) for r in parts])

    return BakeResult(ao=stack("ao"), mask=stack("mask"), stderr=stack("stderr"), samples=stack("samples"),
                      rays=sum(r.rays for r in parts), seconds=sum(r.seconds for r in parts),
                      trace_seconds=sum(r.trace_seconds for r in parts), threads=parts[0].threads,
                      trace_cpu_seconds=sum(r.trace_cpu_seconds for r in parts), metadata=dict(parts[0].metadata),
                      report=report, tiles=results,
                      bent=stack("bent") if parts[0].bent is not None else None,
                      raw_ao=stack("raw_ao") if parts[0].raw_ao is not None else None,
                      raw_stderr=stack("raw_stderr") if parts[0].raw_stderr is not None else None)


__all__ = ["bake_udim", "bake_udim_maps", "covered_tiles", "UdimResult", "TileCoverage", "tile_origin", "tile_of",
           "tile_seed", "check_tiles", "shifted", "FIRST_TILE", "LAST_TILE"]
