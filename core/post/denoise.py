"""Denoising a baked AO map over the surface, with an honest standard error after it.

What it builds on. The filter is a cross-bilateral (joint non-local) filter in the spirit of the
feature-guided, variance-aware Monte Carlo denoisers, with the per-texel filter selected by an
estimate of its mean squared error:

- Rousselle, Knaus and Zwicker, "Adaptive rendering with non-local means filtering" (SIGGRAPH Asia
  2012) and Rousselle, Manzi and Zwicker, "Robust denoising using feature and color information"
  (Pacific Graphics 2013): a set of candidate filters of increasing strength whose weights use
  features and the per-pixel variance, and a per-pixel choice among them by estimated error.
- Li, Wu and Chuang, "SURE-based optimization for adaptive sampling and reconstruction" (SIGGRAPH
  Asia 2012): choose per pixel the candidate whose estimated MSE is least.
- The bias of each candidate is estimated by double smoothing (the plug-in bias estimate of kernel
  regression, e.g. Hardle, "Applied nonparametric regression", 1990, ch. 5): for a linear smoother
  S, bias(S y) = S f - f, estimated by S (S y) - S y, whose noise is small because it smooths twice.

Where it departs from those image-space filters. A texel's neighbours are the texels near it on the
surface, not in the image: each texel has the surface point and normal at its centre, and the UV
island it lies on (:func:`surface_guide`). A neighbour in the image window counts only when it lies on
the same island; across a UV seam (a mesh edge shared in 3D, split in UV) the texels beyond the
island's border are replaced by the texels of the other side (a *halo*: the other island's chart
unfolded across the seam edge by the similarity that maps the edge onto itself). Weights are

    w_ij = exp(-|p_i - p_j|^2 / (2 h^2 s^2)) * exp(-beta (1 - n_i . n_j))
           * exp(-max(0, (g_i - g_j)^2 / (2 kappa^2 (v_i + v_j)) - flat))

with p the surface point, s^2 = (s_i^-2 + s_j^-2) / 2 from the world length s of each texel, n the
shading normal, g a pilot estimate of the AO (the same filter without the AO term, narrow) and v its
variance: the AO term keeps edges (a contact shadow) where the pilot shows a step larger than its
noise. All three factors are symmetric in i and j.

Error and selection. The raw estimates y_j have independent errors of variance sigma_j^2 (the
bake's standard error; each texel draws its own scrambled sample set). For candidate k,
F_k = sum_j w_ij y_j / W_i has variance V_k = sum_j w_ij^2 sigma_j^2 / W_i^2 (weights held fixed) and
estimated bias B_k = S_k F_k - F_k. Each texel takes the candidate with the least V_k + B_k^2, the
raw value (V = sigma_i^2, B = 0) among them, so a texel whose bias estimate exceeds what filtering
saves in noise is filtered less or not at all, and a texel with sigma_i = 0 (exactly open or fully
occluded: every sample and its neighbourhood agree) keeps its value and its zero error. The reported
standard error is sqrt(V_k + B_k^2) of the chosen candidate.

The same filter serves UDIM tiles together (:func:`udim_guide`, :func:`denoise_udim`: the tiles in
one canvas at their UDIM places) and AO baked at face corners (:func:`denoise_vertices`: the sample
points joined by the mesh's edges in place of an image window).

Cost: one pass of the pilot, one of the candidates, one of the bias, each over half of the window's
image offsets (the weights are symmetric), as numpy operations on bands of rows (the columns of
each band that hold covered texels); no loop over texels. In a bake the guide comes from the bake's
own tiles (:func:`tile_guide`). Measured (docs/denoise.md): 1.15 CPU seconds per megatexel for the
filter, 30-38% of a 64-sample bake at 4096^2 with the guide.
"""

import copy
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..base.errors import MeshError
from ..geometry.raster import prepare

#: Window radius in texels: (2 r + 1)^2 image offsets.
RADIUS = 3
#: Candidate bandwidths, in texels of world size (the raw value is a candidate too). A third between
#: them (1.77) changed neither RMSE nor z on the exact scenes and Suzanne, and cost a third more.
BANDWIDTHS = (1.25, 2.5)
#: Normal similarity: weight exp(-NORMAL_SHARPNESS (1 - n_i . n_j)).
NORMAL_SHARPNESS = 40.0
#: The AO term's scale kappa, in standard deviations of the pilot's difference, and how far (in units
#: of d^2 / (2 kappa^2 var)) it stays flat: the weight is 1 for differences within 2 sqrt(3) = 3.5
#: standard deviations, so noise alone hardly changes it (weights that follow the noise would make
#: the propagated variance too small), and falls off beyond, at a step such as a contact shadow.
RANGE_SIGMAS = 2.0
RANGE_FLAT = 3.0
#: Bandwidth (texels) of the pilot whose differences the AO term compares: narrow, so steps stay steep.
PILOT_BANDWIDTH = 1.0
#: Its window radius: 3 x 3 (weights 0.61 beside, 0.37 diagonally; 5 x 5 was dearer and no better:
#: RMSE on the exact scenes 0.0132 and 0.0106 against 0.0127 and 0.0105).
PILOT_RADIUS = 1
#: Factor on the double-smoothing bias estimate. S (S y) - S y is exact for a Gaussian kernel on a
#: locally quadratic AO; where edge-stopping weights and the window cut the kernel it may fall short.
#: Measured (z sd on the exact scenes at 64^2, 16 samples, six seeds; box on a plane, polygon over a
#: plane): window radius 3, factor 1: 1.00 and 0.98 (Suzanne at 256^2 against a 1024-sample
#: reference: 1.02-1.04); 1.25: 0.95 and 0.95; 1.5: 0.91 and 0.92. With radius 4 (a Gaussian of
#: 2.5 texels cut less) factor 1 fell short, 1.09 and 1.10, and took 1.5. No factor is needed here.
BIAS_SCALE = 1.0
#: Rows per band of the filter: bounds its working memory and orders its float32 additions (a
#: constant, so that the result is the same bits for any number of threads).
BAND_ROWS = 64
#: Columns without a covered texel that split a band into ranges filtered apart (at least
#: 2 radius + 1, see :meth:`_Features.segments`): the empty columns between islands are skipped,
#: and narrower gaps are not worth the calls of one more range.
SEGMENT_GAP = 16


# --- the guide ------------------------------------------------------------------------------------

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


def _resolution(resolution):
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
    a, b, c = xy[tri, 0], xy[tri, 1], xy[tri, 2]
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
    nd, nb = _point_triangle(c + 0.5, r + 0.5, xy[nk, 0], xy[nk, 1], xy[nk, 2])
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
    from ..geometry.raster import bin_triangles, rasterize_tile

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
    xy = uvtris.corners
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
    w, h = _resolution(resolution)
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


# --- the filter -----------------------------------------------------------------------------------

@dataclass
class DenoiseInfo:
    """What :func:`denoise` chose: ``choice`` (H, W) int8, the candidate each texel took (0: its raw
    value, k: bandwidth ``bandwidths[k - 1]``); ``variance`` and ``bias`` (H, W) float32, the parts of
    the reported error (stderr^2 = variance + bias^2)."""

    choice: np.ndarray
    variance: np.ndarray
    bias: np.ndarray
    bandwidths: tuple


class _Features:
    """The guide's per-texel features padded by the window radius, float32, one array per component;
    texels outside ``mask`` are off every island."""

    def __init__(self, guide, mask, r, image=False):
        pad = lambda a, v=0: np.pad(a, r, constant_values=v)  # noqa: E731
        self.r, self.h, self.w = r, guide.height, guide.width
        self.island = pad(np.where(mask, guide.island, -1).astype(np.int32), -1)
        self.p = [pad(guide.position[..., c].astype(np.float32)) for c in range(3)]
        self.n = [pad(guide.normal[..., c].astype(np.float32)) for c in range(3)]
        s64 = guide.scale.astype(np.float64)
        self.inv_s2 = pad(np.where(s64 > 0, 1.0 / np.maximum(s64, 1e-150) ** 2, 0.0).astype(np.float32))
        if image:  # the broken filter of the tests: image positions, one island, flat normals
            H, W = self.island.shape
            self.island = np.where(self.island >= 0, 0, -1).astype(np.int32)
            Y, X = np.mgrid[0:H, 0:W].astype(np.float32)
            self.p = [X, Y, np.zeros_like(X)]
            self.n = [np.zeros_like(X), np.zeros_like(X), np.ones_like(X)]
            self.inv_s2 = np.ones_like(X)

    def band(self, rows, dy, dx, cols=None):
        """(centre, neighbour) slices of the padded arrays for the band ``rows`` (its columns ``cols``,
        default all) and offset (dy, dx)."""
        r = self.r
        a, b = (0, self.w) if cols is None else cols
        c = (slice(rows.start + r, rows.stop + r), slice(r + a, r + b))
        o = (slice(rows.start + r + dy, rows.stop + r + dy), slice(r + a + dx, r + b + dx))
        return c, o

    def segments(self, rad):
        """Per band of :data:`BAND_ROWS` rows, the column ranges [a, b) that hold its covered texels:
        runs of columns with a covered texel in the band's rows, joined across gaps of fewer than
        ``max(2 rad + 1, SEGMENT_GAP)`` columns. A pair of texels counts only when both are covered,
        so the band's pairs all have their centre in a range, and with gaps of 2 rad + 1 or more no
        texel is within ``rad`` columns of two ranges: filtering each range alone adds the same
        terms to every texel in the same order as filtering the whole band (the same bits)."""
        h, w, r = self.h, self.w, self.r
        cov = self.island[r:r + h, r:r + w] >= 0
        starts = np.arange(0, h, BAND_ROWS)
        any_col = np.logical_or.reduceat(cov, starts, axis=0) if h else np.zeros((0, w), bool)
        gap = max(2 * rad + 1, SEGMENT_GAP)
        out = []
        for row in any_col:
            cols = np.flatnonzero(row)
            if not len(cols):
                out.append([])
                continue
            cut = np.flatnonzero(np.diff(cols) > gap) + 1
            lo = cols[np.concatenate([[0], cut])]
            hi = cols[np.concatenate([cut - 1, [len(cols) - 1]])] + 1
            out.append(list(zip(lo.tolist(), hi.tolist())))
        return out

    def direct(self, c, o):
        """Neighbours in the image window: on the centre's island, squared surface distance (in
        texels, the mean of both texels' squared inverse sizes) and normals' cosine; all symmetric in the pair."""
        valid = (self.island[o] == self.island[c]) & (self.island[c] >= 0)
        d2 = np.zeros(valid.shape, np.float32)
        for k in range(3):
            t = self.p[k][o] - self.p[k][c]
            d2 += t * t
        d2 *= self.inv_s2[c] + self.inv_s2[o]  # symmetric: the mean of both texels' scales, times 2
        d2 *= np.float32(0.5)
        dot = self.n[0][o] * self.n[0][c] + self.n[1][o] * self.n[1][c] + self.n[2][o] * self.n[2][c]
        return valid, d2, dot

    def pairs(self, rec, src):
        """The same for halo pairs (flat indices of the unpadded image): squared distance, cosine."""
        w, r = self.w, self.r
        wp = w + 2 * r
        ci = (rec // w + r) * wp + rec % w + r
        oi = (src // w + r) * wp + src % w + r
        d2 = np.zeros(len(rec), np.float32)
        for k in range(3):
            a = self.p[k].reshape(-1)
            t = np.take(a, oi) - np.take(a, ci)
            d2 += t * t
        d2 *= np.take(self.inv_s2.reshape(-1), ci)
        dot = sum(np.take(self.n[k].reshape(-1), oi) * np.take(self.n[k].reshape(-1), ci) for k in range(3))
        return d2, dot


def _offsets(r):
    return [(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)]


def _halo_pairs(guide, mask, r, F):
    """The halo entries that stand in for a texel's neighbours in its window (the receiver on the
    halo's island, both covered), every window offset at once, sorted by receiver (offsets in window
    order within one): (receiver flat index, source flat index, squared distance, cosine, Chebyshev
    length of the offset)."""
    h, w = guide.height, guide.width
    keep = mask.reshape(-1)[guide.halo_source]
    ty, tx = guide.halo_row[keep], guide.halo_col[keep]
    hisl, hsrc = guide.halo_island[keep], guide.halo_source[keep]
    # The islands padded by 2 r (-1 beyond the image): halo texels lie up to r beyond it, their
    # receivers up to r further, and every lookup stays inside without a bounds test.
    p = 2 * r
    wp = w + 2 * p
    isl = np.pad(np.where(mask, guide.island, -1).astype(np.int32), p, constant_values=-1).reshape(-1)
    at = (ty + p) * wp + (tx + p)
    recs, srcs, lens = [], [], []
    for dy, dx in _offsets(r):
        ok = np.flatnonzero(isl[at - (dy * wp + dx)] == hisl)
        recs.append((ty[ok] - dy) * w + (tx[ok] - dx))
        srcs.append(hsrc[ok])
        lens.append(np.full(len(ok), max(abs(dy), abs(dx)), np.int8))
    rec, src, cheb = np.concatenate(recs), np.concatenate(srcs), np.concatenate(lens)
    order = np.argsort(rec, kind="stable")
    rec, src, cheb = rec[order], src[order], cheb[order]
    return (rec, src) + F.pairs(rec, src) + (cheb,)


def _accumulate(acc, g, x, here, there, c, o, tmp, mirrored):
    """One offset's weights ``g`` of the texel pairs (c, o) into a band's sums: ``acc[here] += g``, or
    ``g * x[o]`` where a plane ``x`` is gathered; with ``mirrored`` (an offset other than zero) the
    pair's other texel too, ``acc[there] += g`` (or ``g * x[c]``). ``tmp`` takes the products."""
    if x is None:
        acc[here] += g
        if mirrored:
            acc[there] += g
    else:
        acc[here] += np.multiply(g, x[o], out=tmp)
        if mirrored:
            acc[there] += np.multiply(g, x[c], out=tmp)


def _filter(F, halo, weights, gathers, radius=None, threads=1):
    """sum_j w_ij x_j for every texel i, every candidate weight and every value x.

    ``weights(valid, d2, dot, c, o)`` gives the list of candidate weight arrays for neighbours in the
    image (``c``, ``o`` index padded images; for halo pairs ``valid`` is None and ``c``, ``o`` are
    flat indices of the unpadded image); ``gathers`` is a list of (candidate, padded array, power):
    each accumulates sum_j w_ij^power x_j (x None: the weights alone) over the offsets within
    ``radius`` (default: the features' radius).

    The weights in the image are symmetric (w_ij = w_ji), so each pair of texels is weighed once,
    at the offsets of one half-plane, and adds to both its texels: half the weights' work. Bands of
    rows are the outer loop and offsets the inner, so a band's accumulators (its rows and the
    ``radius`` rows either side that its pairs reach) stay in cache; bands go to ``threads`` threads
    (numpy releases the GIL in its loops) and are added into the image in their order, so the result
    does not depend on the threads.
    """
    h, w, r = F.h, F.w, F.r
    rad = r if radius is None else radius
    flat = [None if x is None else x[r:r + h, r:r + w].reshape(-1) for _, x, _ in gathers]
    segments = F.segments(rad)
    half = [(0, 0)] + [(dy, dx) for dy, dx in _offsets(rad) if dy > 0 or (dy == 0 and dx > 0)]

    def band(y0):
        rows = slice(y0, min(h, y0 + BAND_ROWS))
        n = rows.stop - rows.start
        out = []
        for a, b in segments[y0 // BAND_ROWS]:
            m = b - a
            loc = [np.zeros((n + 2 * rad, m + 2 * rad), np.float32) for _ in gathers]
            tmp = np.empty((n, m), np.float32)
            lc = (slice(rad, rad + n), slice(rad, rad + m))
            for dy, dx in half:
                c, o = F.band(rows, dy, dx, (a, b))
                ws = weights(*F.direct(c, o), c, o)
                lo = (slice(rad + dy, rad + dy + n), slice(rad + dx, rad + dx + m))
                sq = {}
                for acc, (k, x, power) in zip(loc, gathers):
                    if power == 1:
                        g = ws[k]
                    else:
                        if k not in sq:
                            sq[k] = np.multiply(ws[k], ws[k])
                        g = sq[k]
                    _accumulate(acc, g, x, lc, lo, c, o, tmp, dy or dx)
            out.append((a, loc))
        return out

    total = [np.zeros((h + 2 * rad, w + 2 * rad), np.float32) for _ in gathers]
    starts = list(range(0, h, BAND_ROWS))
    pool = ThreadPoolExecutor(threads) if threads > 1 and len(starts) > 1 else None
    try:
        for y0, parts in zip(starts, pool.map(band, starts) if pool else map(band, starts)):
            for a, loc in parts:
                for t, l in zip(total, loc):
                    t[y0:y0 + l.shape[0], a:a + l.shape[1]] += l
    finally:
        if pool:
            pool.shutdown()
    out = [t[rad:rad + h, rad:rad + w].copy() for t in total]
    if halo and len(halo[0]):
        rec, src, d2, dot, cheb = halo
        if rad < F.r:
            sel = cheb <= rad
            rec, src, d2, dot = rec[sel], src[sel], d2[sel], dot[sel]
        if len(rec):
            # Each receiver's halo terms summed in their order (reduceat over the sorted receivers),
            # then added once.
            starts = np.flatnonzero(np.r_[True, rec[1:] != rec[:-1]])
            urec = rec[starts]
            ws = weights(None, d2, dot, rec, src)
            for acc, fx, (k, x, power) in zip(out, flat, gathers):
                g = ws[k] if power == 1 else ws[k] * ws[k]
                v = g if fx is None else g * np.take(fx, src)
                acc.reshape(-1)[urec] += np.add.reduceat(v, starts)
    return out


def _candidates_and_bias(F, halo, weights, K, yp, vp, y, var, threads=1, bias=True):
    """The candidates' sums and their bias pass in one sweep over the bands, with each band's weights
    kept between the two (the same weights serve both): W_k, Y_k, V_k (sum w, w y, w^2 sigma^2),
    F_k = Y_k / W_k (y where W_k = 0) and S_k = sum w F_k (None without ``bias``), each (H, W).

    With symmetric weights at the offsets of a half-plane (dy >= 0), a band's pairs reach the
    ``radius`` rows below it only, so once a band's sums are added, every row above its last is
    final: the bias pass of a band runs as soon as the next band's sums are in. Halo terms (whose
    sources may be anywhere) are added before the bands (sums) and after them (bias). Bands go to
    ``threads`` threads a few at a time and are added in their order: the same bits for any count.
    """
    h, w, r = F.h, F.w, F.r
    half = [(0, 0)] + [(dy, dx) for dy, dx in _offsets(r) if dy > 0 or (dy == 0 and dx > 0)]
    segments = F.segments(r)
    tot = [np.zeros((h + 2 * r, w + 2 * r), np.float32) for _ in range(3 * K)]  # W, Y, V per candidate
    S = [np.zeros((h + 2 * r, w + 2 * r), np.float32) for _ in range(K)] if bias else None
    Fp = [np.zeros((h + 2 * r, w + 2 * r), np.float32) for _ in range(K)]
    inner = (slice(r, r + h), slice(r, r + w))
    yf, vf = yp[inner].reshape(-1), vp[inner].reshape(-1)

    hal = None
    if halo and len(halo[0]):
        rec, src, d2, dot, _ = halo
        starts = np.flatnonzero(np.r_[True, rec[1:] != rec[:-1]])
        urec = rec[starts]
        ws = weights(None, d2, dot, rec, src)
        ys, vs = np.take(yf, src), np.take(vf, src)
        for k in range(K):
            for j, v in enumerate((ws[k], ws[k] * ys, ws[k] * ws[k] * vs)):
                part = np.zeros(h * w, np.float32)  # (a padded image's inner block is no flat view)
                part[urec] = np.add.reduceat(v, starts)
                tot[3 * k + j][inner] += part.reshape(h, w)
        hal = (src, starts, urec, ws)

    def sums(y0):
        rows = slice(y0, min(h, y0 + BAND_ROWS))
        n = rows.stop - rows.start
        out = []
        for a, b in segments[y0 // BAND_ROWS]:
            m = b - a
            loc = [np.zeros((n + 2 * r, m + 2 * r), np.float32) for _ in range(3 * K)]
            tmp = np.empty((n, m), np.float32)
            g2 = np.empty((n, m), np.float32)
            lc = (slice(r, r + n), slice(r, r + m))
            cache = []
            for dy, dx in half:
                c, o = F.band(rows, dy, dx, (a, b))
                ws = weights(*F.direct(c, o), c, o)
                cache.append(ws)
                lo = (slice(r + dy, r + dy + n), slice(r + dx, r + dx + m))
                for k in range(K):
                    g = ws[k]
                    np.multiply(g, g, out=g2)
                    for j, (gg, x) in enumerate(((g, None), (g, yp), (g2, vp))):
                        _accumulate(loc[3 * k + j], gg, x, lc, lo, c, o, tmp, dy or dx)
            out.append((a, loc, cache))
        return out

    def smooth(y0, parts):
        rows = slice(y0, min(h, y0 + BAND_ROWS))
        n = rows.stop - rows.start
        out = []
        for a, _, cache in parts:
            b = a + cache[0][0].shape[1]
            m = b - a
            loc = [np.zeros((n + 2 * r, m + 2 * r), np.float32) for _ in range(K)]
            tmp = np.empty((n, m), np.float32)
            lc = (slice(r, r + n), slice(r, r + m))
            for (dy, dx), ws in zip(half, cache):
                c, o = F.band(rows, dy, dx, (a, b))
                lo = (slice(r + dy, r + dy + n), slice(r + dx, r + dx + m))
                for k in range(K):
                    loc[k][lc] += np.multiply(ws[k], Fp[k][o], out=tmp)
                    if dy or dx:
                        loc[k][lo] += np.multiply(ws[k], Fp[k][c], out=tmp)
            out.append((a, loc))
        return out

    done = [0]  # rows whose F_k are final

    def finalize(upto):
        a, b = done[0], min(h, upto)
        if b <= a:
            return
        for k in range(K):
            W_, Y_ = tot[3 * k][r + a:r + b, r:r + w], tot[3 * k + 1][r + a:r + b, r:r + w]
            with np.errstate(invalid="ignore", divide="ignore"):
                Fp[k][r + a:r + b, r:r + w] = np.where(W_ > 0, Y_ / W_, y[a:b])
        done[0] = b

    def add_smooth(y0, parts):
        for a, loc in parts:
            for t, l in zip(S, loc):
                t[y0:y0 + l.shape[0], a:a + l.shape[1]] += l

    starts = list(range(0, h, BAND_ROWS))
    pool = ThreadPoolExecutor(threads) if threads > 1 and len(starts) > 1 else None
    try:
        ahead = max(1, threads)
        futures = {}

        def submit(i):
            if i < len(starts) and i not in futures:
                futures[i] = pool.submit(sums, starts[i]) if pool else None

        for i in range(ahead):
            submit(i)
        previous = None
        for i, y0 in enumerate(starts):
            parts = futures.pop(i).result() if pool else sums(y0)
            submit(i + ahead)
            for a, loc, _ in parts:
                for t, l in zip(tot, loc):
                    t[y0:y0 + l.shape[0], a:a + l.shape[1]] += l
            finalize(y0 + BAND_ROWS)
            if bias and previous is not None:
                add_smooth(previous[0], smooth(*previous))
            previous = (y0, parts)
        finalize(h)
        if bias and previous is not None:
            add_smooth(previous[0], smooth(*previous))
    finally:
        if pool:
            pool.shutdown()
    if bias and hal is not None:
        src, starts_, urec, ws = hal
        for k in range(K):
            Fk_flat = Fp[k][inner].reshape(-1)
            part = np.zeros(h * w, np.float32)
            part[urec] = np.add.reduceat(ws[k] * np.take(Fk_flat, src), starts_)
            S[k][inner] += part.reshape(h, w)
    out = [t[inner] for t in tot]  # views of the padded sums: no copies
    Fk = [f[inner] for f in Fp]
    return out[0::3], out[1::3], out[2::3], Fk, (None if S is None else [t[inner] for t in S])


def _trusted_zeros(F, var, r=2):
    """The variance of texels whose error is 0 (every sample and every texel of the bake's pooling
    window agreed) raised to the mean variance of the texels within ``r`` (Chebyshev, same island)
    whose error is not 0: the bake's window stops at its 16 x 16 blocks, so a texel at a block's
    edge beside a varying region may report 0 though its value is not exact. Zero stays zero only
    where the whole neighbourhood agrees."""
    h, w, R = F.h, F.w, F.r
    wp = w + 2 * R
    vp = np.pad(var, R).reshape(-1)
    isl = F.island.reshape(-1)
    # Only the covered texels whose error is 0 (a gather over their windows: usually few of them).
    idx = np.flatnonzero((var == 0) & (F.island[R:R + h, R:R + w] >= 0))
    pi = (idx // w + R) * wp + idx % w + R
    total = np.zeros(len(idx), np.float32)
    count = np.zeros(len(idx), np.float32)
    own = isl[pi]
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            po = pi + dy * wp + dx
            v = vp[po]
            ok = (isl[po] == own) & (v > 0)
            total += np.where(ok, v, 0)
            count += ok
    out = var.astype(np.float32, copy=True)
    flat = out.reshape(-1)
    flat[idx] = np.where(count > 0, total / np.maximum(count, 1), flat[idx])
    return out


def denoise(ao, stderr, mask, guide, *, bandwidths=BANDWIDTHS, radius=RADIUS, normal_sharpness=NORMAL_SHARPNESS,
            range_sigmas=RANGE_SIGMAS, range_flat=RANGE_FLAT, pilot_bandwidth=PILOT_BANDWIDTH,
            bias_scale=BIAS_SCALE, margin=0, threads=2, neighbours="surface", use_error=True, use_bias=True):
    """Denoise a baked AO map over the surface; return it with its standard error.

    Parameters
    ----------
    ao, stderr : (H, W) the bake's estimate and its standard error (:class:`core.BakeResult`).
    mask : (H, W) bool, the covered texels (only these are filtered and used).
    guide : :class:`SurfaceGuide` of the same resolution (:func:`surface_guide`), built with a halo
        radius of at least ``radius``.
    bandwidths : candidate filter widths, in texels of each texel's world size.
    radius : window radius in texels (image offsets -radius..radius).
    normal_sharpness : beta of the normal weight exp(-beta (1 - n_i . n_j)).
    range_sigmas, range_flat : the AO term exp(-max(0, d^2 / (2 kappa^2 (v_i + v_j)) - flat)) of the
        pilot's difference d: flat (weight 1) up to sqrt(2 flat) kappa standard deviations, so that
        noise alone hardly moves the weights; kappa = range_sigmas.
    pilot_bandwidth : bandwidth of the pilot (geometry only) that the AO term compares.
    bias_scale : factor on the double-smoothing bias estimate (see the module docstring).
    margin : re-dilate this many texels around the covered ones (as the bake does); 0: texels outside
        the mask keep their input value.
    threads : bands of rows filtered at the same time (numpy releases the GIL in its loops); the
        result does not depend on it (bands are added in their order).
    neighbours : 'surface' (the filter); 'image' only for the tests that break it on purpose: the
        image window's texels whatever their island, by image distance, nothing across seams.
    use_error, use_bias : off only in the tests that break the filter on purpose: without the error
        every texel takes the widest candidate whatever its standard error; without the bias the
        reported error is the propagated variance alone.

    Returns
    -------
    (ao, stderr, info): (H, W) float32 denoised AO in [0, 1] and its standard error (0 outside the
    mask), and a :class:`DenoiseInfo`. Deterministic: no randomness, the same bits for any
    ``threads``; each texel depends only on the texels within a few window radii and their halo.
    """
    ao = np.asarray(ao)
    h, w = ao.shape
    if (guide.height, guide.width) != (h, w):
        raise ValueError(f"the guide is {guide.width} x {guide.height}, the map {w} x {h}")
    r = int(radius)
    if r < 2:
        raise ValueError(f"the window radius must be at least 2 texels, got {radius}")
    if neighbours not in ("surface", "image"):
        raise ValueError(f"neighbours must be 'surface' or 'image', got {neighbours!r}")
    use_halo = neighbours == "surface"
    if use_halo and r > guide.halo_radius:
        raise ValueError(f"the window radius {r} exceeds the guide's halo radius {guide.halo_radius}")
    mask = np.asarray(mask, bool) & guide.covered
    F = _Features(guide, mask, r, image=not use_halo)
    halo = _halo_pairs(guide, mask, r, F) if use_halo else ()
    y = np.where(mask, ao, 0).astype(np.float32)
    var = np.where(mask, np.asarray(stderr, np.float32) ** 2, 0).astype(np.float32)
    exact = var == 0
    var = _trusted_zeros(F, var) if use_error else var
    exact &= var == 0
    bws = [float(b) for b in bandwidths]
    K = len(bws)
    inv2h2 = [np.float32(0.5 / (b * b)) for b in bws]
    halving = all(abs(bws[k + 1] / bws[k] - math.sqrt(2)) < 1e-3 for k in range(K - 1))
    pilot = np.float32(0.5 / float(pilot_bandwidth) ** 2)
    beta = np.float32(normal_sharpness)
    zero = np.float32(0)
    P = lambda a: np.pad(a, r)  # noqa: E731
    yp, vp = P(y), P(var)

    def geometric(valid, d2, dot, c, o):
        g = np.exp(-(d2 * pilot + beta * (1.0 - dot)))
        return [g if valid is None else np.where(valid, g, zero)]

    # The pilot (geometry only, narrow): what the AO term compares, and its variance.
    Wg, Yg, Vg = _filter(F, halo, geometric, [(0, None, 1), (0, yp, 1), (0, vp, 2)], radius=min(r, PILOT_RADIUS),
                         threads=threads)
    with np.errstate(invalid="ignore", divide="ignore"):
        G = P(np.where(Wg > 0, Yg / Wg, 0).astype(np.float32))
        vG = P(np.where(Wg > 0, Vg / (Wg * Wg), 0).astype(np.float32))
    Gf, vGf = G[r:r + h, r:r + w].reshape(-1), vG[r:r + h, r:r + w].reshape(-1)
    k2 = np.float32(2.0 * range_sigmas ** 2)
    flat, eps = np.float32(range_flat), np.float32(1e-12)

    def candidates(valid, d2, dot, c, o):
        if valid is None:
            gi, gj, vi, vj = Gf[c], Gf[o], vGf[c], vGf[o]
        else:
            gi, gj, vi, vj = G[c], G[o], vG[c], vG[o]
        base = beta * (1.0 - dot) + np.maximum((gi - gj) ** 2 / (k2 * (vi + vj) + eps) - flat, zero)
        if valid is not None:
            base = np.where(valid, base, np.float32(np.inf))  # exp(-inf) = 0: not a neighbour
        if not halving:
            return [np.exp(-(d2 * inv + base)) for inv in inv2h2]
        # Bandwidths a factor sqrt(2) apart: exp(-d2 inv_k) is the widest's factor E raised to
        # 1, 2, 4, ...: two exponentials for every candidate.
        E = np.exp(-(d2 * inv2h2[-1]))
        g = np.exp(-base)
        g *= E
        out = [g]
        for _ in range(K - 1):
            g = g * E
            out.append(g)
            E = E * E
        return out[::-1]

    # The candidates F_k = S_k y, their variance, then their bias S_k F_k - F_k (same weights).
    Wk, Yk, Vk, Fk, Sk = _candidates_and_bias(F, halo, candidates, K, yp, vp, y, var, threads=threads,
                                              bias=bool(use_bias))
    with np.errstate(invalid="ignore", divide="ignore"):
        Vark = [np.where(Wk[k] > 0, Vk[k] / (Wk[k] * Wk[k]), var).astype(np.float32) for k in range(K)]
    if use_bias:
        with np.errstate(invalid="ignore", divide="ignore"):
            Bk = [(np.float32(bias_scale) * np.where(Wk[k] > 0, Sk[k] / Wk[k] - Fk[k], 0)).astype(np.float32)
                  for k in range(K)]
    else:
        Bk = [np.zeros((h, w), np.float32) for _ in range(K)]

    # Each texel takes the least V + B^2, its raw value (sigma^2, 0) among the candidates.
    if use_error:
        best, choice = var.copy(), np.zeros((h, w), np.int8)
        for k in range(K):
            m = Vark[k] + Bk[k] * Bk[k]
            take = m < best
            best = np.where(take, m, best)
            choice[take] = k + 1
        choice[exact] = 0
    else:
        choice = np.full((h, w), K, np.int8)
    out, varo, bias = y.copy(), var.copy(), np.zeros((h, w), np.float32)
    for k in range(K):
        take = choice == k + 1
        out[take], varo[take], bias[take] = Fk[k][take], Vark[k][take], Bk[k][take]
    out = np.clip(out, 0.0, 1.0)
    se = np.sqrt(varo + bias * bias)
    res = np.where(mask, out, np.asarray(ao, np.float32)).astype(np.float32)
    se = np.where(mask, se, 0).astype(np.float32)
    if margin:
        from ..geometry.margin import dilate
        dilate(res, mask, int(margin), threads=threads, out=res)
    info = DenoiseInfo(choice=np.where(mask, choice, 0).astype(np.int8),
                       variance=np.where(mask, varo, 0).astype(np.float32),
                       bias=np.where(mask, bias, 0).astype(np.float32), bandwidths=tuple(bws))
    return res, se, info


# --- colour attributes (values at vertices) -------------------------------------------------------

#: Candidate bandwidths of the vertex filter, in lengths of the edges around each sample point.
VERTEX_BANDWIDTHS = (1.0, 1.4, 2.0)


def _two_ring(a, b, n):
    """The pairs (sorted by first, then second; both directions; no self pair) of points joined by
    one or two of the pairs (a, b) (both directions already, sorted by a)."""
    count = np.bincount(a, minlength=n)
    start = np.concatenate([[0], np.cumsum(count)])
    reps = count[b]
    first = np.repeat(a, reps)
    offs = np.arange(int(reps.sum())) - np.repeat(np.cumsum(reps) - reps, reps)
    third = b[np.repeat(start[b], reps) + offs]
    aa, cc = np.concatenate([a, first]), np.concatenate([b, third])
    keep = aa != cc
    pair = np.unique(np.stack([aa[keep], cc[keep]], axis=1), axis=0)
    return pair[:, 0], pair[:, 1]


def denoise_vertices(mesh, ao, stderr, unit, corners=None, *, bandwidths=VERTEX_BANDWIDTHS,
                     normal_sharpness=NORMAL_SHARPNESS, range_sigmas=RANGE_SIGMAS, range_flat=RANGE_FLAT,
                     use_error=True, use_bias=True):
    """Denoise AO baked at face corners (:func:`core.bake_vertex_ao`) over the mesh's vertex
    neighbours: the same filter as :func:`denoise`, with the sample points joined by the mesh's edges
    (up to two edges away) in place of an image window.

    Parameters
    ----------
    mesh : the baked core.Mesh; ao, stderr, unit : per corner, as :class:`core.VertexBakeResult`
        holds them; corners : the (C, 2) corners baked (None: every triangle corner).
    bandwidths : candidate widths in lengths of the edges around each point (their mean).
    The others as :func:`denoise`.

    Returns
    -------
    (ao, stderr, info) per corner (float32), info a :class:`DenoiseInfo` per corner.
    """
    from ..targets.corners import all_corners, unit_pairs

    corners = all_corners(mesh) if corners is None else np.asarray(corners, np.int64)
    unit = np.asarray(unit, np.int64)
    n = int(unit.max()) + 1 if len(unit) else 0
    _, first = np.unique(unit, return_index=True)
    tri, k = corners[first, 0], corners[first, 1]
    vert = mesh.triangles[tri, k]
    p = mesh.positions[vert]
    nrm = mesh.normals[tri, k]
    y = np.asarray(ao, np.float64)[first]
    var = np.asarray(stderr, np.float64)[first] ** 2
    a1, b1 = unit_pairs(mesh, vert)
    d1 = np.linalg.norm(p[a1] - p[b1], axis=1)
    apart = d1 > 0
    length = np.bincount(a1[apart], d1[apart], minlength=n) / np.maximum(np.bincount(a1[apart], minlength=n), 1)
    length = np.where(length > 0, length, 1.0)
    beta = float(normal_sharpness)

    def geometry(a, b):
        d2 = np.sum((p[a] - p[b]) ** 2, axis=1) / (length[a] * length[b])
        return d2, np.sum(nrm[a] * nrm[b], axis=1)

    def sums(a, w, x):
        return np.bincount(a, w * x, minlength=n)

    a2, b2 = _two_ring(a1, b1, n)
    exact = var == 0
    if use_error and len(a2):
        # Trusted zeros, as _trusted_zeros: the bake pools a point's error over its vertex's 1-ring
        # only, so all 16 samples of 7 points may agree where the AO is 0.97; a zero is trusted
        # where the 2-ring agrees too.
        nz = var[b2] > 0
        cnt = np.bincount(a2[nz], minlength=n)
        mean = np.bincount(a2[nz], var[b2][nz], minlength=n) / np.maximum(cnt, 1)
        var = np.where(exact & (cnt > 0), mean, var)
        exact &= var == 0
    # Pilot: geometry only, the 1-ring, the narrowest bandwidth.
    d2, dot = geometry(a1, b1)
    g = np.exp(-(d2 * (0.5 / bandwidths[0] ** 2) + beta * (1.0 - dot)))
    Wg = 1.0 + np.bincount(a1, g, minlength=n)
    G = (y + sums(a1, g, y[b1])) / Wg
    vG = (var + sums(a1, g * g, var[b1])) / Wg ** 2
    # Candidates over the 2-ring.
    d2, dot = geometry(a2, b2)
    rng = np.maximum((G[a2] - G[b2]) ** 2 / (2 * range_sigmas ** 2 * (vG[a2] + vG[b2]) + 1e-12) - range_flat, 0.0)
    base = beta * (1.0 - dot) + rng
    F, V, B = [], [], []
    for h in bandwidths:
        w = np.exp(-(d2 * (0.5 / h ** 2) + base))
        W = 1.0 + np.bincount(a2, w, minlength=n)
        f = (y + sums(a2, w, y[b2])) / W
        F.append(f)
        V.append((var + sums(a2, w * w, var[b2])) / W ** 2)
        B.append((f + sums(a2, w, f[b2])) / W - f if use_bias else np.zeros(n))
    if use_error:
        best, choice = var.copy(), np.zeros(n, np.int8)
        for i in range(len(bandwidths)):
            m = V[i] + B[i] ** 2
            take = m < best
            best = np.where(take, m, best)
            choice[take] = i + 1
        choice[exact] = 0
    else:
        choice = np.full(n, len(bandwidths), np.int8)
    out, vo, bo = y.copy(), var.copy(), np.zeros(n)
    for i in range(len(bandwidths)):
        take = choice == i + 1
        out[take], vo[take], bo[take] = F[i][take], V[i][take], B[i][take]
    se = np.sqrt(vo + bo * bo)
    info = DenoiseInfo(choice=choice[unit], variance=vo[unit].astype(np.float32), bias=bo[unit].astype(np.float32),
                       bandwidths=tuple(float(b) for b in bandwidths))
    return np.clip(out, 0.0, 1.0)[unit].astype(np.float32), se[unit].astype(np.float32), info


# --- UDIM ----------------------------------------------------------------------------------------

def udim_canvas(tiles):
    """The layout of UDIM ``tiles`` (numbers) in one image: (u0, v0, nu, nv), the least tile
    column and row and how many tile columns and rows the tiles span. Tiles keep their places in
    UDIM space, so texels of neighbouring tiles stay neighbours and triangles that cross a tile's
    border are whole."""
    from ..targets.udim import tile_origin

    origins = np.array([tile_origin(t) for t in tiles])
    u0, v0 = origins.min(axis=0)
    nu, nv = origins.max(axis=0) - (u0, v0) + 1
    return int(u0), int(v0), int(nu), int(nv)


def udim_guide(mesh, tiles, resolution, radius=RADIUS):
    """:func:`surface_guide` of UDIM ``tiles`` (each ``resolution``, as :func:`core.bake_udim`
    bakes them) laid out in one image (:func:`udim_canvas`): seams between tiles are linked as seams
    within one."""
    w, h = _resolution(resolution)
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
    from ..geometry.margin import dilate
    from ..targets.udim import tile_origin

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
                           bandwidths=info.bandwidths)
        result[t] = (a, err[b].copy(), part)
    return result


__all__ = ["surface_guide", "tile_guide", "SurfaceGuide", "denoise", "DenoiseInfo", "BANDWIDTHS", "RADIUS", "udim_canvas",
           "udim_guide", "denoise_udim", "denoise_vertices", "VERTEX_BANDWIDTHS"]
