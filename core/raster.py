"""UV rasterisation: which surface every texel covers, as exact pieces of triangles.

Texel space: x = u * W, y = v * H, texel (row i, column j) is the unit square [j, j+1) x [i, i+1).
A texel is covered when a UV triangle overlaps its square with positive area, however little (so
texels cut by a triangle's edge are covered, conservatively). Each (texel, triangle) overlap is the
texel square clipped by the triangle (Sutherland-Hodgman), split into a fan of sub-triangles, so that
sample positions can be drawn uniformly over exactly the covered part of the texel and always lie on
the surface. Texels entirely inside one triangle, the common case, are flagged and skip the clipping.

Work is organised by tiles of texels: triangles are binned to the tiles their UV bounding boxes
touch, and each tile is rasterised on its own (in the worker thread that bakes it), which bounds the
memory of any bake to a tile's worth of fragments.
"""

from dataclasses import dataclass

import numpy as np

#: Clipped overlaps smaller than this (in texel areas) are dropped as numerical slivers.
MIN_FRAGMENT_AREA = 1e-9
#: Coverage above 1 + this (in texel areas) counts as overlapping UV islands in the bake's report;
#: UV unwrappers leave slivers of 1e-6 to 1e-4 texels where islands touch, which are not worth a word.
OVERLAP_REPORT_AREA = 1e-3


@dataclass
class UVTriangles:
    """Per-triangle data of the target in texel space, shared by every tile."""

    xy: np.ndarray         # (T, 3, 2) corners in texel coordinates, counter-clockwise
    corners: np.ndarray    # (T, 3, 2) corners in texel coordinates, in the mesh's order
    valid: np.ndarray      # (T,) bool: positive UV area and area in space (others are skipped)
    degenerate: int        # number of triangles with zero UV area (skipped)
    degenerate_space: int  # number of triangles with UV area but zero area in space (skipped)
    outside: int           # number of valid triangles with some UV outside [0, 1]


def prepare(mesh, width, height):
    """Texel-space corners of every triangle, which of them can be baked, and counts of the others.

    The surface each texel point lies on (position and normal as affine maps of texel space) is
    :class:`core.surface.SurfaceTable`'s business.
    """
    xy = mesh.uvs * np.array([width, height], dtype=np.float64)
    e1 = xy[:, 1] - xy[:, 0]
    e2 = xy[:, 2] - xy[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]  # twice the signed UV area, in texels
    scale = np.maximum(np.abs(e1).max(axis=1), np.abs(e2).max(axis=1))
    valid = np.abs(det) > 1e-12 * np.maximum(scale * scale, 1e-300)
    valid &= np.abs(det) > 0
    # A triangle with no area in space has no surface (and no normal) to bake.
    flat = ~(mesh.areas > 0)
    degenerate_space = int((valid & flat).sum())
    valid &= ~flat
    # Counter-clockwise corners make every edge function positive inside.
    cw = det < 0
    xy_ccw = xy.copy()
    xy_ccw[cw, 1], xy_ccw[cw, 2] = xy[cw, 2], xy[cw, 1]
    uv = mesh.uvs
    outside = int((valid & np.any((uv < 0) | (uv > 1), axis=(1, 2))).sum())
    return UVTriangles(xy_ccw, xy, valid, degenerate=int((~valid).sum()) - degenerate_space,
                       degenerate_space=degenerate_space, outside=outside)


def bin_triangles(tris, width, height, tile):
    """Triangle indices per tile: a dict (tile_row, tile_col) -> int64 array, for tiles touched."""
    idx = np.flatnonzero(tris.valid)
    xy = tris.xy[idx]
    lo = np.floor(xy.min(axis=1)).astype(np.int64)
    hi = np.ceil(xy.max(axis=1)).astype(np.int64) - 1  # last texel the bbox reaches
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [width - 1, height - 1])
    ok = np.all(hi >= lo, axis=1)
    idx, lo, hi = idx[ok], lo[ok], hi[ok]
    t_lo, t_hi = lo // tile, hi // tile  # (x, y) tile coordinates
    nx = t_hi[:, 0] - t_lo[:, 0] + 1
    ny = t_hi[:, 1] - t_lo[:, 1] + 1
    count = nx * ny
    rep = np.repeat(np.arange(len(idx)), count)
    k = np.arange(rep.size) - np.repeat(np.cumsum(count) - count, count)
    tx = t_lo[rep, 0] + k % nx[rep]
    ty = t_lo[rep, 1] + k // nx[rep]
    tiles_x = -(-width // tile)
    key = ty * tiles_x + tx
    order = np.argsort(key, kind="stable")
    key, tri = key[order], idx[rep[order]]
    bounds = np.flatnonzero(np.diff(key)) + 1
    out = {}
    for part_key, part in zip(np.split(key, bounds), np.split(tri, bounds)):
        if part_key.size:
            out[(int(part_key[0] // tiles_x), int(part_key[0] % tiles_x))] = part
    return out


def _clip(poly, count, a, b, c):
    """Clip convex polygons (P, K, 2) with ``count`` vertices by a*x + b*y + c >= 0 (vectorised)."""
    P, K, _ = poly.shape
    slot = np.arange(K)
    alive = slot[None, :] < count[:, None]
    nxt = (slot[None, :] + 1) % np.maximum(count[:, None], 1)
    v = poly
    w = np.take_along_axis(poly, nxt[..., None], axis=1)
    dv = a[:, None] * v[..., 0] + b[:, None] * v[..., 1] + c[:, None]
    dw = a[:, None] * w[..., 0] + b[:, None] * w[..., 1] + c[:, None]
    inside_v = dv >= 0
    inside_w = dw >= 0
    keep = alive & inside_v
    cross = alive & (inside_v != inside_w)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, dv / (dv - dw), 0.0)
    x = v + t[..., None] * (w - v)
    # Emit per slot: the vertex if kept, then the crossing point if the edge crosses.
    emit = np.stack([keep, cross], axis=2).reshape(P, 2 * K)
    pts = np.stack([v, x], axis=2).reshape(P, 2 * K, 2)
    pos = np.cumsum(emit, axis=1) - 1
    new_count = emit.sum(axis=1)
    out = np.zeros((P, K + 1, 2))
    r, s = np.nonzero(emit)
    out[r, pos[r, s]] = pts[r, s]
    return out, new_count


@dataclass
class TileFragments:
    """What one tile's texels cover.

    ``texels``: (n,) flat texel indices (row * W + col) of covered texels, sorted.
    ``full_tri``: (n,) the triangle covering the whole texel, or -1 when the texel is split.
    Sub-triangles of split texels (fans of the clipped polygons), grouped by texel:
    ``sub_texel`` (m,) index into ``texels``, ``sub_tri`` (m,) parent triangle, ``sub_xy`` (m, 3, 2)
    corners in texel space, ``sub_cdf`` (m,) the texel's cumulative area fraction up to and including
    this sub-triangle, ``sub_start`` (n + 1,) offsets of each texel's run.
    ``coverage``: (n,) covered area of each texel in texel units (above 1 where UV islands overlap).
    """

    texels: np.ndarray
    full_tri: np.ndarray
    sub_texel: np.ndarray
    sub_tri: np.ndarray
    sub_xy: np.ndarray
    sub_cdf: np.ndarray
    sub_start: np.ndarray
    coverage: np.ndarray


def _edges(xy):
    """Edge functions E_k(x, y) = a_k x + b_k y + c_k >= 0 inside, for CCW triangles (..., 3, 2)."""
    c0, c1 = xy, np.roll(xy, -1, axis=-2)
    ea = -(c1[..., 1] - c0[..., 1])
    eb = c1[..., 0] - c0[..., 0]
    ec = -(ea * c0[..., 0] + eb * c0[..., 1])
    return ea, eb, ec


def _cells(lo, hi, size):
    """Enumerate, per row of lo/hi (n, 2) (exclusive hi, in units of ``size``), its grid cells:
    returns (owner row, cell x, cell y) flattened."""
    nx = np.maximum(hi[:, 0] - lo[:, 0], 0)
    ny = np.maximum(hi[:, 1] - lo[:, 1], 0)
    count = nx * ny
    rep = np.repeat(np.arange(len(lo)), count)
    k = np.arange(rep.size) - np.repeat(np.cumsum(count) - count, count)
    return rep, lo[rep, 0] + k % nx[rep], lo[rep, 1] + k // nx[rep]


def _classify(ea, eb, ec, x, y, size):
    """Squares [x, x + size] x [y, y + size] against triangles: (inside, outside) masks."""
    cx = x[:, None] + np.array([0, size, size, 0])
    cy = y[:, None] + np.array([0, 0, size, size])
    E = ea[:, :, None] * cx[:, None, :] + eb[:, :, None] * cy[:, None, :] + ec[:, :, None]
    full = np.all(E >= 0, axis=(1, 2))
    return full, np.any(np.all(E <= 0, axis=2), axis=1) & ~full


#: Side of the blocks of texels classified before single texels: whole blocks inside a triangle
#: skip per-texel work, which is most of a texture for meshes with triangles larger than texels.
BLOCK = 8


def rasterize_tile(tris, tri_ids, width, height, x0, y0, x1, y1):
    """Fragments of the texels [x0, x1) x [y0, y1) covered by the triangles ``tri_ids``."""
    xy = tris.xy[tri_ids]
    ea_t, eb_t, ec_t = _edges(xy)
    lo = np.maximum(np.floor(xy.min(axis=1)).astype(np.int64), [x0, y0])
    hi = np.minimum(np.ceil(xy.max(axis=1)).astype(np.int64), [x1, y1])  # exclusive

    # Level 1: blocks of BLOCK x BLOCK texels (clipped to each triangle's texel bounding box).
    blo = (lo - [x0, y0]) // BLOCK
    bhi = -(-(hi - [x0, y0]) // BLOCK)
    owner, bx, by = _cells(blo, bhi, 1)
    bx, by = x0 + bx * BLOCK, y0 + by * BLOCK
    b_full, b_out = _classify(ea_t[owner], eb_t[owner], ec_t[owner], bx.astype(float), by.astype(float), BLOCK)
    # Texels of full blocks are full; texels of partial blocks are classified one by one.
    def texels_of(sel):
        o = owner[sel]
        t_lo = np.maximum(np.stack([bx[sel], by[sel]], 1), lo[o])
        t_hi = np.minimum(np.stack([bx[sel], by[sel]], 1) + BLOCK, hi[o])
        r, px, py = _cells(t_lo, t_hi, 1)
        return o[r], px, py

    f_tri, f_x, f_y = texels_of(b_full)
    p_tri, px, py = texels_of(~b_full & ~b_out)
    ea, eb, ec = ea_t[p_tri], eb_t[p_tri], ec_t[p_tri]
    full, out = _classify(ea, eb, ec, px.astype(float), py.astype(float), 1)
    part = ~full & ~out
    f_tri = np.concatenate([f_tri, p_tri[full]])
    f_x = np.concatenate([f_x, px[full]])
    f_y = np.concatenate([f_y, py[full]])

    # Clip the texel square by the three edges for the partial pairs.
    # Only the edges that cut a texel clip it (usually one): each pass takes the pairs it cuts.
    ip = np.flatnonzero(part)
    poly = np.zeros((len(ip), 7, 2))
    cx = px[ip, None] + np.array([0.0, 1.0, 1.0, 0.0])
    cy = py[ip, None] + np.array([0.0, 0.0, 1.0, 1.0])
    poly[:, :4, 0], poly[:, :4, 1] = cx, cy
    cnt = np.full(len(ip), 4)
    # A triangle inside the texel is its own fragment (meshes with triangles smaller than texels).
    txy = tris.xy[tri_ids[p_tri[ip]]]
    within = np.all((txy.min(axis=1) >= np.stack([px[ip], py[ip]], 1))
                    & (txy.max(axis=1) <= np.stack([px[ip], py[ip]], 1) + 1), axis=1)
    poly[within, :3] = txy[within]
    cnt[within] = 3
    for e in range(3):
        a_e, b_e, c_e = ea[ip, e], eb[ip, e], ec[ip, e]
        cuts = np.flatnonzero(~within & np.any(a_e[:, None] * cx + b_e[:, None] * cy + c_e[:, None] < 0, axis=1))
        if not len(cuts):
            continue
        slots = int(cnt[cuts].max())
        clipped, cnt[cuts] = _clip(poly[cuts, :slots], cnt[cuts], a_e[cuts], b_e[cuts], c_e[cuts])
        poly[cuts, :slots + 1] = clipped
        poly[cuts, slots + 1:] = 0.0
    poly = poly[:, :max(int(cnt.max()) if len(cnt) else 3, 3)]
    # Fan triangulation around vertex 0: sub-triangles (0, k, k+1), k = 1 .. cnt - 2.
    K = poly.shape[1]
    ks = np.arange(1, K - 1)
    fan_ok = ks[None, :] < (cnt[:, None] - 1)
    a = poly[:, :1, :]
    b = poly[:, 1:K - 1, :]
    c = poly[:, 2:K, :]
    fan_area = 0.5 * ((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                      - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))
    fan_area = np.where(fan_ok, np.abs(fan_area), 0.0)
    real = fan_area.sum(axis=1) > MIN_FRAGMENT_AREA
    ip, fan_ok, fan_area, b, c, a = ip[real], fan_ok[real], fan_area[real], b[real], c[real], a[real]
    fan_ok &= fan_area > 0
    rr, kk = np.nonzero(fan_ok)
    sub_xy = np.stack([a[rr, 0], b[rr, kk], c[rr, kk]], axis=1)
    sub_area = fan_area[rr, kk]
    sub_tri = tri_ids[p_tri[ip[rr]]]
    sub_local = (py[ip[rr]] - y0) * (x1 - x0) + (px[ip[rr]] - x0)

    # Compact the tile's texels without sorting: count fragments per local texel index.
    tw, th = x1 - x0, y1 - y0
    full_local = (f_y - y0) * tw + (f_x - x0)
    n_full = np.bincount(full_local, minlength=tw * th)
    n_sub = np.bincount(sub_local, minlength=tw * th) if len(sub_local) else np.zeros(tw * th, np.int64)
    covered = np.flatnonzero(n_full + n_sub)
    compact = np.full(tw * th, -1, np.int64)
    compact[covered] = np.arange(len(covered))
    texels = (covered // tw + y0) * width + (covered % tw + x0)

    # A texel with exactly one full fragment and nothing else keeps the fast path; a texel that is
    # full for one triangle and touched by others (overlapping UVs) is split into sub-triangles.
    simple_local = (n_full == 1) & (n_sub == 0)
    full_of = np.full(len(covered), -1, dtype=np.int64)
    fs = simple_local[full_local]
    full_of[compact[full_local[fs]]] = tri_ids[f_tri[fs]]
    sub_tex = compact[sub_local]
    nf = ~fs
    if nf.any():
        fx, fy = f_x[nf].astype(float), f_y[nf].astype(float)
        sq_a = np.stack([fx, fy], 1)
        sq_b = np.stack([fx + 1, fy], 1)
        sq_c = np.stack([fx + 1, fy + 1], 1)
        sq_d = np.stack([fx, fy + 1], 1)
        sub_xy = np.concatenate([sub_xy, np.stack([sq_a, sq_b, sq_c], 1), np.stack([sq_a, sq_c, sq_d], 1)])
        extra_tri = tri_ids[f_tri[nf]]
        sub_tri = np.concatenate([sub_tri, extra_tri, extra_tri])
        sub_area = np.concatenate([sub_area, np.full(2 * len(extra_tri), 0.5)])
        extra_tex = compact[full_local[nf]]
        sub_tex = np.concatenate([sub_tex, extra_tex, extra_tex])

    order = np.argsort(sub_tex, kind="stable")
    sub_tex, sub_tri, sub_xy, sub_area = sub_tex[order], sub_tri[order], sub_xy[order], sub_area[order]
    coverage = np.bincount(sub_tex, weights=sub_area, minlength=len(covered))
    coverage[full_of >= 0] = 1.0
    sub_start = np.searchsorted(sub_tex, np.arange(len(covered) + 1))
    csum = np.cumsum(sub_area)
    run_base = np.concatenate([[0.0], csum])[sub_start[:-1]]
    with np.errstate(invalid="ignore", divide="ignore"):
        sub_cdf = (csum - run_base[sub_tex]) / coverage[sub_tex]
    if len(sub_cdf):
        last = sub_start[1:][sub_start[1:] > sub_start[:-1]] - 1
        sub_cdf[last] = 1.0
    return TileFragments(texels, full_of, sub_tex, sub_tri, sub_xy, sub_cdf, sub_start, coverage)
