"""The denoiser's guide: each texel's surface point, normal, world size and UV island, and the links and the
halo across UV seams."""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ...base.errors import MeshError
from ...geometry.raster import prepare


#: Window radius in texels: (2 r + 1)^2 image offsets.
RADIUS = 3


@dataclass
class SurfaceGuide:
    """Per texel of a (H, W) map: where on the surface its centre lies, and its seam links.

    covered : (H, W) bool, the texels the bake covers (its rasteriser's, :mod:`core.geometry.raster`: the bake's mask).
    triangle : (H, W) int32, the lowest triangle that holds the texel's centre, else the nearest of
        those that overlap the texel (-1 where not covered).
    position, normal : (H, W, 3) float32, the surface point at the centre (the nearest point of the
        triangle) and its unit shading normal.
    scale : (H, W) float32, world length of one texel there (sqrt of the 3D area per texel area).
    island : (H, W) int32, the UV island (triangles joined by edges shared in UV), -1 where not covered.
    halo_island, halo_row, halo_col, halo_source : (m,) one entry per texel just outside an island
        across a UV seam (within ``halo_radius`` texels of the seam edge): the island it extends, its
        row and column in that island's chart (possibly beyond the image), and the flat index
        (row * W + column) of the texel on the other side of the seam that stands in for it.
    links : (k, 2) int64 flat indices of texel pairs that are neighbours on the surface across a UV
        seam (each within about a texel of the seam edge, one on each side).
    """

    width: int
    height: int
    covered: np.ndarray
    triangle: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    scale: np.ndarray
    island: np.ndarray
    halo_island: np.ndarray
    halo_row: np.ndarray
    halo_col: np.ndarray
    halo_source: np.ndarray
    links: np.ndarray
    halo_radius: int


def resolution_pair(resolution):
    """(width, height) of a resolution given as one side or a pair."""
    if np.isscalar(resolution):
        return int(resolution), int(resolution)
    w, h = resolution
    return int(w), int(h)


def _ranges(lo, hi):
    """For per-item integer ranges [lo, hi) (lo <= hi): (item of each element, value of each element)."""
    n = np.maximum(hi - lo, 0)
    item = np.repeat(np.arange(len(n)), n)
    start = np.cumsum(n) - n
    value = np.arange(int(n.sum()), dtype=np.int64) - np.repeat(start, n) + np.repeat(lo, n)
    return item, value


def _barycentrics(qx, qy, a, b, c):
    """Barycentrics (n, 3) of points q in triangles (a, b, c) (each (n, 2))."""
    e1, e2 = b - a, c - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    dx, dy = qx - a[:, 0], qy - a[:, 1]
    b1 = (dx * e2[:, 1] - dy * e2[:, 0]) / det
    b2 = (e1[:, 0] * dy - e1[:, 1] * dx) / det
    return np.stack([1.0 - b1 - b2, b1, b2], axis=1)


def _point_triangle(qx, qy, a, b, c):
    """Distance (texels) from points q to triangles (a, b, c) (each (n, 2)), and the barycentrics
    (n, 3) of the nearest point of each triangle."""
    corners = (a, b, c)
    bary = _barycentrics(qx, qy, a, b, c)
    inside = (bary >= 0).all(axis=1)
    best = np.where(inside, 0.0, np.inf)
    out = bary.copy()
    for k in range(3):
        p0, p1 = corners[k], corners[(k + 1) % 3]
        ex, ey = p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1]
        L2 = ex * ex + ey * ey
        t = np.clip(((qx - p0[:, 0]) * ex + (qy - p0[:, 1]) * ey) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
        d = np.hypot(qx - p0[:, 0] - t * ex, qy - p0[:, 1] - t * ey)
        take = ~inside & (d < best)
        best = np.where(take, d, best)
        if take.any():
            nb = np.zeros((int(take.sum()), 3))
            nb[:, k] = 1.0 - t[take]
            nb[:, (k + 1) % 3] = t[take]
            out[take] = nb
    return best, out


def _interpolate(mesh, tri, bary):
    """Surface point and unit shading normal (each (n, 3) float32) at barycentrics ``bary`` (n, 3)
    of triangles ``tri``: the corners' sum written out, so that any subset of texels gets the same
    bits as the whole (the guide from the bake's tiles and the one computed here agree exactly)."""
    P = mesh.positions[mesh.triangles[tri]]
    N = mesh.normals[tri]
    b0, b1, b2 = bary[:, 0:1], bary[:, 1:2], bary[:, 2:3]
    pos = b0 * P[:, 0] + b1 * P[:, 1] + b2 * P[:, 2]
    n = b0 * N[:, 0] + b1 * N[:, 1] + b2 * N[:, 2]
    length = np.sqrt(n[:, 0] * n[:, 0] + n[:, 1] * n[:, 1] + n[:, 2] * n[:, 2])
    n /= np.maximum(length, 1e-30)[:, None]
    return pos.astype(np.float32), n.astype(np.float32)


def _centre_barycentrics(xy, texel, tri, width):
    """Barycentrics (n, 3) of the nearest point of triangle ``tri`` to each texel's centre (the
    centre's own where it lies inside): :func:`_point_triangle`, measured only where needed."""
    row, col = np.divmod(texel, width)
    cx, cy = col + 0.5, row + 0.5
    a, b, c = (np.asarray(xy[tri, k], np.float64) for k in range(3))  # float32 corners, read in float64
    bary = _barycentrics(cx, cy, a, b, c)
    out = ~(bary >= 0).all(axis=1)
    if out.any():
        bary[out] = _point_triangle(cx[out], cy[out], a[out], b[out], c[out])[1]
    return bary


def _choose(xy, uvtris, texel, tri, width):
    """For candidate pairs (texel, triangle), sorted by texel: each texel's triangle by the guide's
    rule (the lowest triangle whose edge functions all hold at the centre; where none does, the
    nearest to the centre, ties the lowest). The edge functions are those of the candidates'
    triangles only (``uvtris.edges_of``). Returns (texels, triangles, barycentrics)."""
    if not len(texel):
        return texel, tri, np.zeros((0, 3))
    row, col = np.divmod(texel, width)
    cx, cy = col + 0.5, row + 0.5
    ids, which = np.unique(tri, return_inverse=True)
    edges = uvtris.edges_of(ids)
    m = None
    for j in range(3):
        v = np.take(np.ascontiguousarray(edges[:, j, 0]), which) * cx
        v += np.take(np.ascontiguousarray(edges[:, j, 1]), which) * cy
        v += np.take(np.ascontiguousarray(edges[:, j, 2]), which)
        m = v if m is None else np.minimum(m, v, out=m)
    ins = m >= 0
    it, ik = texel[ins], tri[ins]
    order = np.lexsort((ik, it))
    it, ik = it[order], ik[order]
    first = np.ones(len(it), bool)
    first[1:] = it[1:] != it[:-1]
    it, ik = it[first], ik[first]
    out = ~np.isin(texel, it)
    nt, nk = texel[out], tri[out]
    r, c = np.divmod(nt, width)
    nd, nb = _point_triangle(c + 0.5, r + 0.5, *(np.asarray(xy[nk, k], np.float64) for k in range(3)))
    order = np.lexsort((nk, nd, nt))
    nt, nk, nb = nt[order], nk[order], nb[order]
    first = np.ones(len(nt), bool)
    first[1:] = nt[1:] != nt[:-1]
    texel = np.concatenate([it, nt[first]])
    tri = np.concatenate([ik, nk[first]])
    bary = np.concatenate([_centre_barycentrics(xy, it, ik, width), nb[first]])
    return texel, tri, bary


#: Tiles (texels a side) in which :func:`surface_guide` rasterises a map when no bake gives it the texels.
GUIDE_TILE = 256


def _tile_guides(mesh, tris, w, h, threads=1):
    """Per texel (triangle, position, normal) as :func:`surface_guide` takes them: the bake's
    rasteriser and :func:`tile_guide` over tiles, as a bake finds them (the same texels as its mask)."""
    from ...geometry.raster import bin_triangles, rasterize_tile

    triangle = np.full(h * w, -1, np.int32)
    position = np.zeros((h * w, 3), np.float32)
    normal = np.zeros((h * w, 3), np.float32)
    bins = bin_triangles(tris, w, h, GUIDE_TILE)

    def one(key):
        (ty, tx), t = key, GUIDE_TILE
        frag = rasterize_tile(tris, bins[key], w, h, tx * t, ty * t, min(tx * t + t, w), min(ty * t + t, h))
        if len(frag.texels):
            out = tile_guide(frag, tris, mesh, w)
            for a, v in zip((triangle, position, normal), out):
                a[frag.texels] = v

    keys = sorted(bins)
    if threads > 1 and len(keys) > 1:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(one, keys))
    else:
        for key in keys:
            one(key)
    return triangle, position, normal


def tile_guide(frag, uvtris, mesh, width):
    """The guide's texels of one tile of the bake (:func:`core.geometry.raster.rasterize_tile`'s fragments
    ``frag``): per covered texel its triangle, surface point and shading normal, by the same rule as
    :func:`surface_guide` (the same bits), from what the rasteriser already found: a texel inside one
    triangle takes it; a texel that several triangles cross takes the lowest that holds its centre,
    else the nearest, among the triangles the rasteriser found overlapping it.

    Returns (triangle (n,) int32, position (n, 3), normal (n, 3) float32), aligned with ``frag.texels``.
    """
    texels = frag.texels
    n = len(texels)
    xy = uvtris.corners32  # gathered per texel below, in float64 (not a whole-mesh copy per tile)
    tri = np.asarray(frag.full_tri, np.int64).copy()
    bary = np.zeros((n, 3))
    full = np.flatnonzero(tri >= 0)
    bary[full] = _centre_barycentrics(xy, texels[full], tri[full], width)
    rest = np.flatnonzero(tri < 0)
    if len(rest):
        # Candidates: the located texels' triangles, the split texels' pieces' triangles.
        ls = frag.loc_start if frag.loc_start is not None else np.zeros(n + 1, np.int64)
        cnt = np.diff(ls)
        idx = [np.repeat(np.arange(n), cnt), frag.sub_texel]
        cand = [frag.loc_tri if frag.loc_tri is not None else np.zeros(0, np.int64), frag.sub_tri]
        ci, ct = np.concatenate(idx).astype(np.int64), np.concatenate(cand).astype(np.int64)
        keep = tri[ci] < 0
        ci, ct = ci[keep], ct[keep]
        order = np.lexsort((ct, ci))
        ci, ct = ci[order], ct[order]
        ct_t, ct_k, ct_b = _choose(xy, uvtris, texels[ci], ct, width)
        pos = np.searchsorted(texels, ct_t)
        tri[pos] = ct_k
        bary[pos] = ct_b
    position, normal = _interpolate(mesh, tri, bary)
    return tri.astype(np.int32), position, normal


def _components(n, a, b):
    """Connected components of n nodes joined by edges (a, b): the least node index of each one's
    component (label propagation with pointer jumping; vectorised, O(log n) rounds in practice)."""
    label = np.arange(n)
    if len(a) == 0:
        return label
    while True:
        la, lb = label[a], label[b]
        m = np.minimum(la, lb)
        new = label.copy()
        np.minimum.at(new, la, m)
        np.minimum.at(new, lb, m)
        while True:  # pointer jumping
            nxt = new[new]
            if np.array_equal(nxt, new):
                break
            new = nxt
        if np.array_equal(new, label):
            return label
        label = new


def _weld(mesh):
    """Per vertex, one index per distinct position (meshes split at UV seams or sharp edges still
    join there)."""
    return np.unique(mesh.positions, axis=0, return_inverse=True)[1].reshape(-1)


def _edges(mesh, valid, weld):
    """Edges of the valid triangles: (triangle, corner k (edge k -> k + 1), welded vertex pair
    (lo, hi) and whether the edge runs lo -> hi), ``weld`` the vertices' welded indices."""
    tri = np.flatnonzero(valid)
    v = weld[mesh.triangles[tri]]
    t = np.repeat(tri, 3)
    k = np.tile(np.arange(3), len(tri))
    va, vb = v.reshape(-1), v[:, [1, 2, 0]].reshape(-1)
    return t, k, np.minimum(va, vb), np.maximum(va, vb), va < vb


def _islands_and_seams(mesh, valid, weld):
    """(island of every triangle (T,), -1 for invalid ones; seam pairs (s, 4): triangle A, its edge
    corner, triangle B, its edge corner, for edges shared in 3D by exactly two triangles whose UVs
    differ along them)."""
    T = len(mesh.triangles)
    t, k, lo, hi, forward = _edges(mesh, valid, weld)
    uv = mesh.uvs
    ua, ub = uv[t, k], uv[t, (k + 1) % 3]
    ulo = np.where(forward[:, None], ua, ub)
    uhi = np.where(forward[:, None], ub, ua)
    # Group by the 3D edge (one integer key), then, within the groups of more than two (non-manifold
    # edges: rare), by the edge's UVs; a group of two needs no order to compare its UVs.
    key = lo.astype(np.int64) * (int(weld.max()) + 1 if len(weld) else 1) + hi
    order = np.argsort(key, kind="stable")
    t, k, key, ulo, uhi = t[order], k[order], key[order], ulo[order], uhi[order]
    same3d = key[1:] == key[:-1]
    start = np.ones(len(t), bool)
    start[1:] = ~same3d
    gid = np.cumsum(start) - 1
    size = np.bincount(gid)
    big = np.flatnonzero(size[gid] > 2)
    if len(big):
        perm = big[np.lexsort((uhi[big, 1], uhi[big, 0], ulo[big, 1], ulo[big, 0], key[big]))]
        t[big], k[big], ulo[big], uhi[big] = t[perm], k[perm], ulo[perm], uhi[perm]
    sameuv = same3d & (ulo[1:] == ulo[:-1]).all(axis=1) & (uhi[1:] == uhi[:-1]).all(axis=1)
    label = _components(T, t[:-1][sameuv], t[1:][sameuv])
    _, island = np.unique(label, return_inverse=True)
    island = island.reshape(-1).astype(np.int32)
    island[~valid] = -1
    # Edges shared in 3D by exactly two triangles with different UVs: seams.
    two = size[gid] == 2
    first = start & two
    i = np.flatnonzero(first)
    i = i[i + 1 < len(t)]
    seam = i[~sameuv[i]]
    seam = seam[t[seam] != t[seam + 1]]
    pairs = np.stack([t[seam], k[seam], t[seam + 1], k[seam + 1]], axis=1)
    return island, pairs


def _seam_maps(xy, mesh, pairs, weld):
    """For every seam pair, both directions (host, other): the similarity of texel space that takes
    the host's chart to the other's across the shared edge, unfolded so that the host's interior
    maps away from the other's. Returns a dict of (n,) arrays: host, other triangles; h0, h1 (n, 2)
    the edge in the host chart; hc (n, 2) the host's third corner; the map z -> o0 + q (z - h0) or,
    where ``mirror`` (the charts have opposite orientations), o0 + q conj(z - h0) (complex numbers).
    Edges shared by more than two triangles are no seams here (non-manifold: no unfolding)."""
    tA, kA, tB, kB = pairs.T
    host = np.concatenate([tA, tB])
    hk = np.concatenate([kA, kB])
    other = np.concatenate([tB, tA])
    ok = np.concatenate([kB, kA])
    h0, h1 = xy[host, hk], xy[host, (hk + 1) % 3]
    hc = xy[host, (hk + 2) % 3]
    o0, o1 = xy[other, ok], xy[other, (ok + 1) % 3]
    oc = xy[other, (ok + 2) % 3]
    # Match the edge's ends by welded vertex: the host's corner hk is the other's corner ok or ok + 1.
    same = weld[mesh.triangles[host, hk]] == weld[mesh.triangles[other, ok]]
    o0, o1 = np.where(same[:, None], o0, o1), np.where(same[:, None], o1, o0)
    z = lambda p: p[:, 0] + 1j * p[:, 1]  # noqa: E731
    H0, H1, HC, O0, O1, OC = map(z, (h0, h1, hc, o0, o1, oc))
    q = (O1 - O0) / (H1 - H0)
    mapped_c = O0 + q * (HC - H0)
    # The host's third corner must land on the far side of the edge from the other's.
    side = lambda p: ((O1 - O0).conjugate() * (p - O0)).imag  # noqa: E731
    mirror = np.sign(side(mapped_c)) == np.sign(side(OC))
    qm = (O1 - O0) / (H1 - H0).conjugate()
    q = np.where(mirror, qm, q)
    return dict(host=host, other=other, h0=h0, h1=h1, hc=hc, o0=o0, q=q, mirror=mirror)


def _apply_map(m, idx, px, py):
    d = (px - m["h0"][idx, 0]) + 1j * (py - m["h0"][idx, 1])
    d = np.where(m["mirror"][idx], d.conjugate(), d)
    w = m["o0"][idx, 0] + 1j * m["o0"][idx, 1] + m["q"][idx] * d
    return w.real, w.imag


def surface_guide(mesh, resolution, radius=RADIUS, texels=None, threads=1, tris=None):
    """Where every texel of a ``resolution`` map of ``mesh``'s UVs lies on the surface, and its
    neighbours across UV seams.

    Parameters
    ----------
    mesh : core.Mesh with UVs (world space; corner normals used if it has them).
    resolution : int or (width, height), as :func:`core.bake_ao` takes it.
    radius : how far (texels) the halo across seams reaches; the filter's window radius.
    texels : None, or what the bake's tiles found (:func:`tile_guide`) laid out per texel:
        (triangle (H * W,) int32, -1 where not covered; position, normal (H * W, 3) float32), used
        (not copied) instead of finding every texel's triangle again. The same guide, bit for bit.
    threads : tiles rasterised at the same time (the result does not depend on it).
    tris : the bake's :func:`core.geometry.raster.prepare` of ``mesh`` at this resolution, if it has it.

    Returns
    -------
    SurfaceGuide
    """
    if mesh.uvs is None:
        raise MeshError(f"mesh {mesh.name!r} has no UVs: the denoiser's guide needs the UV map the bake used")
    w, h = resolution_pair(resolution)
    tris = prepare(mesh, w, h) if tris is None else tris
    xy = tris.corners
    valid = tris.valid
    ids = np.flatnonzero(valid)
    weld = _weld(mesh)
    island_t, pairs = _islands_and_seams(mesh, valid, weld)
    # World length of a texel per triangle: sqrt(area in space / area in texels).
    det = np.abs((xy[:, 1, 0] - xy[:, 0, 0]) * (xy[:, 2, 1] - xy[:, 0, 1])
                 - (xy[:, 1, 1] - xy[:, 0, 1]) * (xy[:, 2, 0] - xy[:, 0, 0]))
    tscale = np.sqrt(mesh.areas / np.where(det > 0, det / 2.0, 1.0)).astype(np.float32)
    if texels is not None:
        triangle, position, normal = texels
        covered = triangle >= 0
    else:
        triangle, position, normal = _tile_guides(mesh, tris, w, h, threads)
        covered = triangle >= 0
    # Per texel from its triangle (-1 reads the appended entry: 0 scale, no island).
    scale = np.append(tscale, np.float32(0))[triangle]
    island = np.append(island_t, np.int32(-1))[triangle]
    halo, links = _halo(xy, mesh, pairs, island_t, island, w, h, radius, weld)
    return SurfaceGuide(width=w, height=h, covered=covered.reshape(h, w), triangle=triangle.reshape(h, w),
                        position=position.reshape(h, w, 3), normal=normal.reshape(h, w, 3),
                        scale=scale.reshape(h, w), island=island.reshape(h, w),
                        halo_island=halo[0], halo_row=halo[1], halo_col=halo[2], halo_source=halo[3],
                        links=links, halo_radius=int(radius))


def _near_segments(h0, h1, lo, hi, radius):
    """The texels of the boxes [lo, hi) (per segment, (n, 2) each, columns then rows) whose centre
    lies within ``radius`` of the segment h0 -> h1 (and a few more: the centres in the segment's
    rectangle, ``radius`` either side and beyond its ends): (segment, column, row) of each, found
    row by row in closed form, so a long slanted segment costs its rectangle, not its bounding box."""
    ny = np.maximum(hi[:, 1] - lo[:, 1], 0)
    seg, row = _ranges(lo[:, 1], lo[:, 1] + ny)
    d = h1 - h0
    L = np.hypot(d[:, 0], d[:, 1])
    ux, uy = d[:, 0] / np.where(L > 0, L, 1.0), d[:, 1] / np.where(L > 0, L, 1.0)
    eps = 1e-6
    # Along the segment s = (p - h0) . u in [-R, L + R], across it q = (p - h0) . (-uy, ux) in [-R, R];
    # on the row's centre line both are a x + b in the centre's x.
    y = row + 0.5 - h0[seg, 1]
    xlo = np.full(len(seg), -np.inf)
    xhi = np.full(len(seg), np.inf)
    for a, b, low, high in ((ux[seg], y * uy[seg], -radius - eps, L[seg] + radius + eps),
                            (-uy[seg], y * ux[seg], -radius - eps, radius + eps)):
        flat = np.abs(a) < 1e-12
        safe = np.where(flat, 1.0, a)
        x1, x2 = (low - b) / safe, (high - b) / safe
        xlo = np.where(flat, np.where((b >= low) & (b <= high), xlo, np.inf), np.maximum(xlo, np.minimum(x1, x2)))
        xhi = np.where(flat, np.where((b >= low) & (b <= high), xhi, -np.inf), np.minimum(xhi, np.maximum(x1, x2)))
    x0 = h0[seg, 0]
    with np.errstate(invalid="ignore"):
        c0 = np.maximum(np.ceil(x0 + xlo - 0.5 - eps), lo[seg, 0])
        c1 = np.minimum(np.floor(x0 + xhi - 0.5 + eps) + 1, hi[seg, 0])
    keep = c1 > c0
    seg, row, c0, c1 = seg[keep], row[keep], c0[keep].astype(np.int64), c1[keep].astype(np.int64)
    part, col = _ranges(c0, c1)
    return seg[part], col, row[part]


def _halo(xy, mesh, pairs, island_t, island, w, h, radius, weld):
    empty = np.zeros(0, np.int64)
    if len(pairs) == 0:
        return (empty.astype(np.int32), empty, empty, empty), np.zeros((0, 2), np.int64)
    m = _seam_maps(xy, mesh, pairs, weld)
    h0, h1 = m["h0"], m["h1"]
    seg = np.stack([h0, h1, m["hc"]], axis=1)  # enumerate texels near each host edge via its bbox
    # Halo texels may lie beyond the image (an island on its border has neighbours there too).
    lo = np.floor(np.minimum(h0, h1) - radius - 0.5).astype(np.int64) + 1
    hi = np.floor(np.maximum(h0, h1) + radius - 0.5).astype(np.int64) + 1
    lo = np.clip(lo, -radius, [w + radius, h + radius])
    hi = np.clip(hi, -radius, [w + radius, h + radius])
    item, col, row = _near_segments(h0, h1, lo, hi, radius)
    cx, cy = col + 0.5, row + 0.5
    ex, ey = h1[item, 0] - h0[item, 0], h1[item, 1] - h0[item, 1]
    L2 = ex * ex + ey * ey
    t = np.clip(((cx - h0[item, 0]) * ex + (cy - h0[item, 1]) * ey) / L2, 0.0, 1.0)
    dist = np.hypot(cx - h0[item, 0] - t * ex, cy - h0[item, 1] - t * ey)
    cross = lambda px, py: ex * (py - h0[item, 1]) - ey * (px - h0[item, 0])  # noqa: E731
    inner = np.sign(cross(seg[item, 2, 0], seg[item, 2, 1]))
    outside = np.sign(cross(cx, cy)) != inner
    inside_image = (row >= 0) & (row < h) & (col >= 0) & (col < w)
    texel = np.where(inside_image, row * w + col, 0)
    own = inside_image & (island[texel] == island_t[m["host"][item]])
    host_island = island_t[m["host"][item]]
    other_island = island_t[m["other"][item]]

    # Halo: texels outside the host's island across the edge, within the radius, stand in by the
    # texel their centre maps to on the other side.
    sel = outside & (dist <= radius) & ~own
    sx, sy = _apply_map(m, item[sel], cx[sel], cy[sel])
    sc, sr = np.floor(sx).astype(np.int64), np.floor(sy).astype(np.int64)
    inb = (sc >= 0) & (sc < w) & (sr >= 0) & (sr < h)
    src = np.where(inb, sr * w + np.clip(sc, 0, w - 1), 0)
    good = inb & (island[src] == other_island[sel])
    # Keyed by padded flat index (texels beyond the image included), nearest edge first.
    key = (row[sel][good] + radius) * (w + 2 * radius) + col[sel][good] + radius
    hi_, hs, hd = host_island[sel][good], src[good], dist[sel][good]
    order = np.lexsort((hs, hd, key, hi_))
    hi_, key, hs = hi_[order], key[order], hs[order]
    first = np.ones(len(key), bool)
    first[1:] = (key[1:] != key[:-1]) | (hi_[1:] != hi_[:-1])
    hr, hc = np.divmod(key[first], w + 2 * radius)
    halo = (hi_[first].astype(np.int32), hr - radius, hc - radius, hs[first])

    # Links: the host's own texels within a texel of the edge, and the texel at their mirror image
    # across the edge, mapped to the other side.
    sel = ~outside & (dist <= 1.0) & own
    fx = cx[sel] - 2 * (cx[sel] - (h0[item[sel], 0] + t[sel] * ex[sel]))
    fy = cy[sel] - 2 * (cy[sel] - (h0[item[sel], 1] + t[sel] * ey[sel]))
    sx, sy = _apply_map(m, item[sel], fx, fy)
    sc, sr = np.floor(sx).astype(np.int64), np.floor(sy).astype(np.int64)
    inb = (sc >= 0) & (sc < w) & (sr >= 0) & (sr < h)
    src = np.where(inb, sr * w + np.clip(sc, 0, w - 1), 0)
    good = inb & (island[src] == other_island[sel])
    a, b = texel[sel][good], src[good]
    pair = np.unique(np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1), axis=0)
    return halo, pair.reshape(-1, 2).astype(np.int64)


__all__ = ["RADIUS", "SurfaceGuide", "resolution_pair", "GUIDE_TILE", "tile_guide", "surface_guide"]
