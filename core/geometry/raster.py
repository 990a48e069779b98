"""UV rasterisation: which surface every texel covers, and how its samples find it.

Texel space: x = u * W, y = v * H, texel (row i, column j) is the unit square [j, j+1) x [i, i+1).
A texel is covered when a UV triangle overlaps its square with positive area, however little (so
texels cut by a triangle's edge are covered, conservatively). Every covered texel is one of three
kinds, found without clipping anything:

- **inside one triangle** (``full_tri >= 0``): the whole square lies in one triangle and nothing
  else overlaps it. Most texels of meshes whose triangles are larger than texels.
- **located** (``full_tri == LOCATED``): triangles cover the square exactly once between them, with
  no island border or overlap crossing it (triangles smaller than texels, or texels on the edges
  between triangles of one island). Its samples are spread uniformly over the whole square, and each
  sample finds the triangle it lies in among the texel's candidates (``loc_*``): exact, with no
  clipping and no sharing of samples among pieces.
- **split** (``full_tri == -1``): an island's border or overlapping islands cross the square. It is
  clipped by each triangle (Sutherland-Hodgman) into sub-triangles, and its samples are shared among
  them by area (:mod:`core.geometry.surface`).

How the kinds are found: each triangle is scanned row by row of texels; in each row the columns its
area overlaps and the columns it contains entirely are two intervals, from its edges in closed form,
so the work grows with the triangles' perimeters (in texels) and their count, never with pairs of
texels and triangles classified one by one. A texel whose only overlapping triangles cross it
(partial pairs) is covered exactly once when no *border* half-edge crosses it (a half-edge without a
twin: the same two UV points in the other direction, in another triangle; shared edges of an island
cancel, so the number of layers covering a point changes only across border edges) and one triangle
contains a probe point inside it.

Work is organised by tiles of texels: triangles are binned to the tiles their UV bounding boxes
touch, and each tile is rasterised on its own (in the worker thread that bakes it), which bounds the
memory of any bake to a tile's worth of fragments. Everything a texel gets depends only on the
texel and the triangles that overlap it, never on the tiling.
"""

import functools
from dataclasses import dataclass

import numpy as np

#: Clipped overlaps smaller than this (in texel areas) are dropped as numerical slivers.
MIN_FRAGMENT_AREA = 1e-9
#: Coverage above 1 + this (in texel areas) counts as overlapping UV islands in the bake's report;
#: UV unwrappers leave slivers of 1e-6 to 1e-4 texels where islands touch, which are not worth a word.
OVERLAP_REPORT_AREA = 1e-3
#: ``full_tri`` of a located texel (see the module docstring); -1 marks a split texel.
LOCATED = -2
#: Where in a texel the layers covering it are counted (texel-local; irrational, so it rarely lies on
#: an edge; a texel whose probe point lies within ON_EDGE texels of an edge is split instead).
PROBE = (0.3183098861837907, 0.5772156649015329)
ON_EDGE = 1e-9
#: Overlaps thinner than this (texels) do not count: a triangle touching a texel's side or corner up
#: to rounding neither covers it nor splits it (clipping drops such slivers as well).
TOUCH = 1e-9


#: Triangles prepared at a time (:func:`prepare`): the temporaries stay a slice's, whatever the mesh.
SLICE = 1 << 18


class UVTriangles:
    """Per-triangle data of the target in texel space, shared by every tile.

    corners32 : (T, 3, 2) float32 corners in texel coordinates, in the mesh's order (float32 as
    Blender's UVs are: half the bytes a triangle, every worker holds them; :meth:`corners_of` and
    :attr:`corners` read them as float64, the precision every computation on them takes); valid : (T,) bool, positive
    UV area and area in space (others are skipped); cw : (T,) bool, corners clockwise in texel space;
    degenerate : number of triangles with zero UV area (skipped); degenerate_space : number of
    triangles with UV area but zero area in space (skipped); outside : number of valid triangles
    with some UV outside [0, 1].

    The counter-clockwise corners and the edge functions are computed for the triangles a tile asks
    for (:meth:`xy_of`, :meth:`edges_of`: 120 bytes a triangle not held), or for all of them when
    :attr:`xy` or :attr:`edges` is asked for (then kept); the same bits either way.
    """

    def __init__(self, corners32, valid, cw, degenerate, degenerate_space, outside):
        self.corners32 = np.asarray(corners32, np.float32)
        self.valid, self.cw = valid, cw
        self.degenerate, self.degenerate_space, self.outside = degenerate, degenerate_space, outside

    @property
    def corners(self):
        """(T, 3, 2) float64 corners of every triangle (a copy: for passes over the whole mesh)."""
        return self.corners32.astype(np.float64)

    def corners_of(self, tri):
        """(n, 3, 2) float64 corners of triangles ``tri`` (indices, or a slice), in the mesh's order."""
        if isinstance(tri, slice):
            return self.corners32[tri].astype(np.float64)
        return np.take(self.corners32, tri, axis=0).astype(np.float64)

    def xy_of(self, tri):
        """(n, 3, 2) corners of triangles ``tri`` (indices), counter-clockwise: every edge function is
        positive inside."""
        if "xy" in self.__dict__:
            return self.xy[tri]
        xy = self.corners_of(tri)
        cw = self.cw[tri]
        if cw.any():
            xy[cw, 1], xy[cw, 2] = xy[cw, 2], xy[cw, 1]
        return xy

    def edges_of(self, tri, xy=None):
        """(n, 3, 3) edge functions of triangles ``tri``: edge k (corner k -> k + 1 of :meth:`xy_of`) as
        (a, b, c), a x + b y + c the signed distance in texels from its line, positive inside
        (``xy``: their :meth:`xy_of`, when already at hand)."""
        if "edges" in self.__dict__:
            return self.edges[tri]
        xy = self.xy_of(tri) if xy is None else xy
        ea, eb, ec = _edges(xy)
        norm = np.hypot(ea, eb)
        norm[~(norm > 0)] = 1.0
        norm[~self.valid[tri]] = 1.0
        edges = np.empty(ea.shape + (3,))
        ef, nf = edges.reshape(-1, 3), norm.reshape(-1)
        for j, e in enumerate((ea, eb, ec)):
            np.divide(e.reshape(-1), nf, out=ef[:, j])
        return edges

    @functools.cached_property
    def xy(self):
        """(T, 3, 2) :meth:`xy_of` every triangle (kept once asked for)."""
        out = np.empty(self.corners32.shape)
        for lo in range(0, len(out), SLICE):
            out[lo:lo + SLICE] = self.xy_of(np.arange(lo, min(lo + SLICE, len(out))))
        return out

    @functools.cached_property
    def edges(self):
        """(T, 3, 3) :meth:`edges_of` every triangle (kept once asked for)."""
        out = np.empty(self.corners32.shape[:2] + (3,))
        for lo in range(0, len(out), SLICE):
            out[lo:lo + SLICE] = self.edges_of(np.arange(lo, min(lo + SLICE, len(out))))
        return out


def prepare(mesh, width, height):
    """Texel-space corners of every triangle, which of them can be baked, and counts of the others.

    The surface each texel point lies on (position and normal as affine maps of texel space) is
    :class:`core.geometry.surface.SurfaceTable`'s business. Arrays of a few values per triangle are worked
    column by column (see :func:`core.geometry.mesh.face_geometry`), with the same operations and bits, and
    :data:`SLICE` triangles at a time (the same bits: every operation is per triangle).
    """
    uv = mesh.uvs
    T = len(uv)
    xy32 = np.empty((T, 3, 2), np.float32)
    valid = np.empty(T, bool)
    cw = np.empty(T, bool)
    flat_valid = outside = 0
    for lo in range(0, T, SLICE):
        hi = min(lo + SLICE, T)
        part = np.empty((hi - lo, 3, 2))
        xf, uf = part.reshape(-1, 2), uv[lo:hi].reshape(-1, 2)
        np.multiply(uf[:, 0], np.float64(width), out=xf[:, 0])
        np.multiply(uf[:, 1], np.float64(height), out=xf[:, 1])
        # Kept in float32; everything below (and every later use) reads the kept values, in float64.
        xy32[lo:hi] = part
        part[...] = xy32[lo:hi]
        e1x, e1y = part[:, 1, 0] - part[:, 0, 0], part[:, 1, 1] - part[:, 0, 1]
        e2x, e2y = part[:, 2, 0] - part[:, 0, 0], part[:, 2, 1] - part[:, 0, 1]
        det = e1x * e2y - e1y * e2x  # twice the signed UV area, in texels
        scale = np.maximum(np.maximum(np.abs(e1x), np.abs(e1y)), np.maximum(np.abs(e2x), np.abs(e2y)))
        v = valid[lo:hi]
        np.greater(np.abs(det), 1e-12 * np.maximum(scale * scale, 1e-300), out=v)
        v &= np.abs(det) > 0
        # A triangle with no area in space has no surface (and no normal) to bake.
        flat = ~(mesh.face_geometry_of(np.arange(lo, hi))[0] > 0)
        flat_valid += int((v & flat).sum())
        v &= ~flat
        # Counter-clockwise corners make every edge function positive inside (UVTriangles.xy_of).
        np.less(det, 0, out=cw[lo:hi])
        out_uv = (uv[lo:hi] < 0) | (uv[lo:hi] > 1)
        of = out_uv.reshape(hi - lo, 6)
        any_out = of[:, 0] | of[:, 1]
        for j in range(2, 6):
            any_out |= of[:, j]
        outside += int((v & any_out).sum())
    return UVTriangles(xy32, valid, cw, degenerate=int((~valid).sum()) - flat_valid, degenerate_space=flat_valid,
                       outside=outside)


def _corner_bounds(xy):
    """Per triangle of ``xy`` (T, 3, 2), the least and greatest (x, y) of its corners, each (T, 2):
    elementwise over the three corners, coordinate by coordinate (numpy's reductions over an axis
    of 3, and its loops over an inner axis of 2, are several times slower)."""
    lo, hi = np.empty((len(xy), 2), xy.dtype), np.empty((len(xy), 2), xy.dtype)
    for k in range(2):
        np.minimum(np.minimum(xy[:, 0, k], xy[:, 1, k]), xy[:, 2, k], out=lo[:, k])
        np.maximum(np.maximum(xy[:, 0, k], xy[:, 1, k]), xy[:, 2, k], out=hi[:, k])
    return lo, hi


def uv_centres(tris):
    """(2, n): the texel-space centres (x row, y row) of the valid triangles of ``tris``."""
    idx = np.flatnonzero(tris.valid)
    out = np.empty((2, len(idx)))
    for lo in range(0, len(idx), SLICE):
        xy = tris.xy_of(idx[lo:lo + SLICE])
        for k in range(2):
            out[k, lo:lo + SLICE] = (xy[:, 0, k] + xy[:, 1, k] + xy[:, 2, k]) / 3.0
    return out


def bin_triangles(tris, width, height, tile):
    """Triangle indices per tile: a dict (tile_row, tile_col) -> int64 array (ascending), for tiles
    touched; ``tile`` the side of square tiles or (columns, rows). Binned :data:`SLICE` triangles
    at a time (the temporaries stay a slice's), each tile's parts joined in order."""
    tile = np.broadcast_to(np.asarray(tile, dtype=np.int64), (2,))
    valid = np.flatnonzero(tris.valid)
    tiles_x = -(-width // int(tile[0]))
    parts = {}
    for s0 in range(0, len(valid), SLICE):
        idx = valid[s0:s0 + SLICE]
        # The corners in the mesh's order: the same bounds as counter-clockwise (min and max are exact).
        lo, hi = _corner_bounds(tris.corners_of(idx))
        lo = np.maximum(np.floor(lo).astype(np.int64), 0)
        hi = np.ceil(hi).astype(np.int64) - 1  # last texel the bbox reaches
        # Column by column (numpy is slow over an inner axis of 2).
        np.minimum(hi[:, 0], width - 1, out=hi[:, 0])
        np.minimum(hi[:, 1], height - 1, out=hi[:, 1])
        ok = np.flatnonzero((hi[:, 0] >= lo[:, 0]) & (hi[:, 1] >= lo[:, 1]))
        idx, lo, hi = idx[ok], lo[ok], hi[ok]
        lx, ly = lo[:, 0] // tile[0], lo[:, 1] // tile[1]  # (x, y) tile coordinates
        nx = hi[:, 0] // tile[0] - lx + 1
        ny = hi[:, 1] // tile[1] - ly + 1
        count = nx * ny
        rep = np.repeat(np.arange(len(idx)), count)
        k = np.arange(rep.size) - np.repeat(np.cumsum(count) - count, count)
        nr = nx[rep]
        tx = lx[rep] + k % nr
        ty = ly[rep] + k // nr
        key = ty * tiles_x + tx
        order = np.argsort(key, kind="stable")
        key, tri = key[order], idx[rep[order]]
        bounds = np.flatnonzero(np.diff(key)) + 1
        for part_key, part in zip(np.split(key, bounds), np.split(tri, bounds)):
            if part_key.size:
                parts.setdefault((int(part_key[0] // tiles_x), int(part_key[0] % tiles_x)), []).append(part)
    # Each tile's triangles ascending: its parts come slice by slice, each ascending.
    return {key: p[0] if len(p) == 1 else np.concatenate(p) for key, p in sorted(parts.items(),
                                                                               key=lambda item: item[0][0] * tiles_x
                                                                               + item[0][1])}


def clip_polygons(X, Y, count, a, b, c):
    """Clip convex polygons by a*x + b*y + c >= 0 (vectorised); the polygons are columns: vertex k
    of polygon p at (X[k, p], Y[k, p]) (K, P), ``count`` (P,) vertices each.

    Returns the clipped polygons' (X, Y) (K + 1, P), slots past their count zero, and their counts.
    Each vertex is kept if inside, and each edge that crosses the line adds its crossing point, in
    order. Polygons are columns, not rows, so that every operation runs along the P polygons (numpy
    is several times slower over a short inner axis of K slots).
    """
    K, P = X.shape
    cols = np.arange(P)
    last = np.maximum(count, 1) - 1

    def following(v):
        """Each slot's next vertex: the slot after it, the first for the last vertex."""
        w = np.empty_like(v)
        w[:-1] = v[1:]
        w[-1] = v[0]
        w[last, cols] = v[0]
        return w

    dv = a * X + b * Y + c
    dw = following(dv)
    alive = np.arange(K)[:, None] < count
    inside_v = dv >= 0
    keep = alive & inside_v
    cross = alive & (inside_v != (dw >= 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, dv / (dv - dw), 0.0)
    # Emit per slot: the vertex if kept, then the crossing point if the edge crosses; each emitted
    # point goes to the slot after the points emitted before it in its polygon.
    emit = np.empty((2 * K, P), bool)
    emit[0::2] = keep
    emit[1::2] = cross
    slot = np.empty((2 * K, P), np.int64)  # running count of emitted points, row by row
    slot[0] = emit[0]
    for i in range(1, 2 * K):
        np.add(slot[i - 1], emit[i], out=slot[i])
    src = np.flatnonzero(emit)
    col = src % P
    dst = (np.take(slot, src) - 1) * P + col
    out = []
    pts = np.empty((2 * K, P))
    for v in (X, Y):
        pts[0::2] = v
        pts[1::2] = v + t * (following(v) - v)
        o = np.zeros((K + 1, P))
        o.reshape(-1)[dst] = np.take(pts, src)
        out.append(o)
    return out[0], out[1], slot[-1].copy()


@dataclass
class TileFragments:
    """What one tile's texels cover.

    ``texels``: (n,) flat texel indices (row * W + col) of covered texels, sorted.
    ``full_tri``: (n,) the triangle covering the whole texel, -1 for a split texel, :data:`LOCATED`
    for a located one.
    Sub-triangles of split texels (fans of the clipped polygons), grouped by texel:
    ``sub_texel`` (m,) index into ``texels``, ``sub_tri`` (m,) parent triangle, ``sub_xy`` (m, 3, 2)
    corners in texel space, ``sub_cdf`` (m,) the texel's cumulative area fraction up to and including
    this sub-triangle, ``sub_start`` (n + 1,) offsets of each texel's run.
    Candidates of located texels, grouped by texel in ascending triangle order: ``loc_tri`` (c,)
    the triangles overlapping the texel, ``loc_start`` (n + 1,) offsets of each texel's run (empty
    for other texels), ``loc_edges`` (c, 3, 3) each candidate's edge functions (a, b, c) in
    texel-local coordinates (the texel's corner at 0), positive inside.
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
    loc_tri: np.ndarray = None
    loc_start: np.ndarray = None
    loc_edges: np.ndarray = None


def _edges(xy):
    """Edge functions E_k(x, y) = a_k x + b_k y + c_k >= 0 inside, for CCW triangles (..., 3, 2)."""
    ea, eb, ec = (np.empty(xy.shape[:-1], np.result_type(xy, np.float64)) for _ in range(3))
    for k in range(3):  # edge k: corner k -> corner k + 1 (no rolled copy of the corners)
        c0, c1 = xy[..., k, :], xy[..., (k + 1) % 3, :]
        a, b = ea[..., k], eb[..., k]
        np.subtract(c0[..., 1], c1[..., 1], out=a)
        np.subtract(c1[..., 0], c0[..., 0], out=b)
        np.multiply(a, c0[..., 0], out=ec[..., k])
        ec[..., k] += b * c0[..., 1]
        np.negative(ec[..., k], out=ec[..., k])
    return ea, eb, ec


def _runs(lo, hi):
    """Expand half-open integer runs [lo, hi) (n,): returns (run index, value) of every element."""
    count = np.maximum(hi - lo, 0)
    rep = np.repeat(np.arange(len(lo)), count)
    return rep, lo[rep] + (np.arange(rep.size) - np.repeat(np.cumsum(count) - count, count))


class _Spans:
    """Triangles (n, 3, 2) as their x-extent along horizontal lines: corners sorted by y (low,
    middle, high) and the inverse slopes of the long edge (low -> high) and the two short ones."""

    def __init__(self, xy):
        order = np.argsort(xy[:, :, 1], axis=1, kind="stable")
        # The sorted corners column by column (numpy is slow over an inner axis of 2 or 3).
        at = order + 3 * np.arange(len(xy))[:, None]
        flat = xy.reshape(-1, 2)
        X, Y = np.ascontiguousarray(flat[:, 0]), np.ascontiguousarray(flat[:, 1])
        (self.xl, self.yl), (self.xm, self.ym), (self.xh, self.yh) = (
            (np.take(X, at[:, k]), np.take(Y, at[:, k])) for k in range(3))
        with np.errstate(divide="ignore", invalid="ignore"):
            self.s_long = (self.xh - self.xl) / (self.yh - self.yl)
            self.s_low = np.where(self.ym > self.yl, (self.xm - self.xl) / (self.ym - self.yl), 0.0)
            self.s_high = np.where(self.yh > self.ym, (self.xh - self.xm) / (self.yh - self.ym), 0.0)

    def extent(self, i, y):
        """[lo, hi] of triangles ``i`` along the lines ``y`` (each within its triangle's y-range)."""
        yl, ym = self.yl[i], self.ym[i]
        x_long = self.xl[i] + (y - yl) * self.s_long[i]
        low = y < ym
        x_short = np.where(low, self.xl[i] + (y - yl) * self.s_low[i], self.xm[i] + (y - ym) * self.s_high[i])
        return np.minimum(x_long, x_short), np.maximum(x_long, x_short)


def _scan(spans, x0, y0, x1, y1):
    """Per triangle of ``spans``, the texels of the window [x0, x1) x [y0, y1) it overlaps with
    positive area, as runs along rows: returns (owner, row, overlap lo, overlap hi, full lo, full hi),
    the full run [full lo, full hi) the texels it contains entirely (inside the overlap run; empty
    when full lo >= full hi)."""
    ymin, ymax = spans.yl, spans.yh
    r_lo = np.maximum(np.floor(ymin + TOUCH), y0).astype(np.int64)
    r_hi = np.minimum(np.ceil(ymax - TOUCH), y1).astype(np.int64)  # rows r with r < ymax and r + 1 > ymin
    own, r = _runs(r_lo, r_hi)
    rf = r.astype(np.float64)
    ylo, yhi = ymin[own], ymax[own]
    ya = np.maximum(rf, ylo)
    yb = np.minimum(rf + 1.0, yhi)
    lo_a, hi_a = spans.extent(own, ya)
    lo_b, hi_b = spans.extent(own, yb)
    # The middle corner strictly inside the strip can stick out further than the strip's two lines.
    xm, ym = spans.xm[own], spans.ym[own]
    mid = (ym > ya) & (ym < yb)
    xmin = np.minimum(np.minimum(lo_a, lo_b), np.where(mid, xm, np.inf))
    xmax = np.maximum(np.maximum(hi_a, hi_b), np.where(mid, xm, -np.inf))
    ov_lo = np.maximum(np.floor(xmin + TOUCH), x0).astype(np.int64)
    ov_hi = np.minimum(np.ceil(xmax - TOUCH), x1).astype(np.int64)
    # Texels whose four corners are inside (the triangle is convex): the strip lies within its
    # y-range, and [j, j + 1] within its extent along both lines.
    inside = (ya <= rf + TOUCH) & (yb >= rf + 1.0 - TOUCH)
    f_lo = np.maximum(np.ceil(np.maximum(lo_a, lo_b) - TOUCH), ov_lo).astype(np.int64)
    f_hi = np.minimum(np.floor(np.minimum(hi_a, hi_b) + TOUCH), ov_hi).astype(np.int64)
    f_hi = np.where(inside, np.maximum(f_hi, f_lo), f_lo)
    return own, r, ov_lo, ov_hi, f_lo, f_hi


def _border_half_edges(xy):
    """(n, 3) bool: half-edges of the triangles ``xy`` (n, 3, 2), CCW, that have no twin among them
    (the same two points in the other direction, in exactly one other half-edge): island borders,
    seams, folds and edges shared by more than two triangles."""
    # Column by column over the flat (triangle, corner) order (numpy is slow over an inner axis of
    # 2 or 3): half-edge e = 3 t + k goes from corner k to corner k + 1 of triangle t.
    n = len(xy)
    flat = xy.reshape(-1, 2)
    ax, ay = flat[:, 0] + 0.0, flat[:, 1] + 0.0  # -0.0 -> 0.0, so equal points have equal bits
    nxt = np.arange(1, 3 * n + 1)
    nxt[2::3] -= 3
    bx, by = np.take(ax, nxt), np.take(ay, nxt)
    swap = (ax > bx) | ((ax == bx) & (ay > by))
    px, py = np.where(swap, bx, ax), np.where(swap, by, ay)
    qx, qy = np.where(swap, ax, bx), np.where(swap, ay, by)
    border = np.ones(3 * n, bool)
    if n == 0:
        return border.reshape(n, 3)
    bits = [v.view(np.uint64) for v in (px, py, qx, qy)]
    h = np.full(3 * n, 0x9E3779B97F4A7C15, np.uint64)
    with np.errstate(over="ignore"):
        for v in bits:  # splitmix64's finaliser after each coordinate
            h ^= v
            h ^= h >> np.uint64(30)
            h *= np.uint64(0xBF58476D1CE4E5B9)
            h ^= h >> np.uint64(27)
            h *= np.uint64(0x94D049BB133111EB)
            h ^= h >> np.uint64(31)
    m = 3 * n
    ib = max(1, int(m - 1).bit_length())
    packed = np.sort(((h >> np.uint64(ib)) << np.uint64(ib)) | np.arange(m, dtype=np.uint64))
    idx = (packed & np.uint64((1 << ib) - 1)).astype(np.int64)
    key = packed >> np.uint64(ib)
    same = key[1:] == key[:-1]
    start = np.ones(m, bool)
    start[1:] = ~same
    first = np.flatnonzero(start)
    size = np.diff(np.concatenate([first, [m]]))
    # Pairs with equal hashes: twins when the points are equal and the directions opposite.
    two = first[size == 2]
    i, j = idx[two], idx[two + 1]
    twin = swap[i] != swap[j]
    for v in bits:  # equal bits: equal points (no -0.0, NaN)
        twin &= np.take(v, i) == np.take(v, j)
    border[i[twin]] = False
    border[j[twin]] = False
    # Larger groups (hash collisions or edges shared by more than two triangles): exactly, by points.
    for f, sz in zip(first[size > 2], size[size > 2]):
        members = idx[f:f + int(sz)]
        groups = {}
        for e in members:
            groups.setdefault((px[e], py[e], qx[e], qy[e]), []).append(e)
        for g in groups.values():
            if len(g) == 2 and swap[g[0]] != swap[g[1]]:
                border[g] = False
    return border.reshape(n, 3)


def _crosses(xa, ya, xb, yb, px, py):
    """Whether segments (xa, ya) -> (xb, yb) meet the open unit squares with lower corners (px, py)."""
    box = ((np.minimum(xa, xb) < px + 1) & (np.maximum(xa, xb) > px)
           & (np.minimum(ya, yb) < py + 1) & (np.maximum(ya, yb) > py))
    dx, dy = xb - xa, yb - ya
    lo = np.full(len(xa), np.inf)
    hi = np.full(len(xa), -np.inf)
    for cx, cy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        s = dx * (py + cy - ya) - dy * (px + cx - xa)
        lo, hi = np.minimum(lo, s), np.maximum(hi, s)
    return box & (lo < 0) & (hi > 0)


def _run_bins(r, lo, hi, y0, x0, tw):
    """Where the runs [lo, hi) of rows ``r`` start and end in a tile's difference array
    (:func:`_row_sums`), texel (row, column) of the tile at row * tw + column: the start bins, the
    end bins of the runs that end inside their row, and which runs those are (a run reaching the
    row's last texel needs no end: each row's running sum starts afresh)."""
    base = (r - y0) * tw - x0
    inside = hi - x0 < tw
    return base + lo, (base + hi)[inside], inside


def _row_sums(bins, weight, th, tw):
    """Per texel of the tile's (th, tw) grid, the sum of ``weight`` (None: 1; else integers) over
    the runs whose bins :func:`_run_bins` gave that cover it (a difference array along each row,
    then a running sum along each row), int64. The sums are integers: bincount's float64 sums of
    integer weights are exact (below 2^53), and the running sum is taken in int64, 5 times as fast
    as float64's (its additions wait on each other: 0.18 against 0.89 ms over a 512^2 tile)."""
    start, end, inside = bins
    n = th * tw
    if weight is None:
        d = np.bincount(start, minlength=n)
        d -= np.bincount(end, minlength=n)
    else:
        w = np.asarray(weight, np.float64)
        f = np.bincount(start, weights=w, minlength=n)
        f -= np.bincount(end, weights=w[inside], minlength=n)
        d = f.astype(np.int64)
    return np.cumsum(d.reshape(th, tw), axis=1).reshape(n)


def rasterize_tile(tris, tri_ids, width, height, x0, y0, x1, y1, locate=True):
    """Fragments of the texels [x0, x1) x [y0, y1) covered by the triangles ``tri_ids`` (ascending).

    ``locate=False`` splits every texel that is not inside one triangle (the reference the tests
    compare located texels against).
    """
    tri_ids = np.asarray(tri_ids, dtype=np.int64)
    xy = tris.xy_of(tri_ids)
    E = tris.edges_of(tri_ids, xy)
    tw, th = x1 - x0, y1 - y0
    spans = _Spans(xy)
    own, r, ov_lo, ov_hi, f_lo, f_hi = _scan(spans, x0, y0, x1, y1)
    has_full = f_hi > f_lo
    # Partial runs: the overlap less the full run (two runs when there is one, else the overlap).
    p_lo = np.concatenate([ov_lo, np.where(has_full, f_hi, ov_hi)])
    p_hi = np.concatenate([np.where(has_full, f_lo, ov_hi), ov_hi])
    p_own, p_r = np.concatenate([own, own]), np.concatenate([r, r])
    live = np.flatnonzero(p_hi > p_lo)
    live = live[np.argsort(p_own[live], kind="stable")]  # triangle by triangle: candidates come ascending
    p_lo, p_hi, p_own, p_r = p_lo[live], p_hi[live], p_own[live], p_r[live]
    # Counts per texel without listing the texels of full runs (most of a texture): how many
    # triangles contain it, the sum of their indices (the triangle when there is one), how many cross it.
    # All three are integers, exact (indices < 2^53).
    fsel = np.flatnonzero(has_full)
    f_bins = _run_bins(r[fsel], f_lo[fsel], f_hi[fsel], y0, x0, tw)
    n_full = _row_sums(f_bins, None, th, tw)
    id_sum = _row_sums(f_bins, own[fsel], th, tw)
    n_part = _row_sums(_run_bins(p_r, p_lo, p_hi, y0, x0, tw), None, th, tw)
    kind = np.full(tw * th, -1, np.int64)  # per local texel: triangle, -1 split, LOCATED
    simple = (n_full == 1) & (n_part == 0)
    kind[simple] = tri_ids[id_sum[simple]]

    # Partial pairs, texel by texel of each run.
    pr, p_x = _runs(p_lo, p_hi)
    p_tri, p_y = p_own[pr], p_r[pr]
    part_local = (p_y - y0) * tw + (p_x - x0)

    # Located texels: only partial pairs, covered exactly once (no border half-edge crosses them and
    # exactly one triangle contains the probe point).
    cand = (n_full == 0) & (n_part > 0)
    loc_pair = np.zeros(len(p_tri), bool)
    if locate and cand.any():
        sel = np.flatnonzero(cand[part_local])
        st, sx, sy, sl = p_tri[sel], p_x[sel], p_y[sel], part_local[sel]
        ok = np.ones(tw * th, bool)
        border = _border_half_edges(xy)
        bsel = np.flatnonzero(border.any(axis=1)[st])
        if len(bsel):
            hit = np.zeros(len(bsel), bool)
            xb = xy[st[bsel]]
            for k in range(3):
                a_, b_ = xb[:, k], xb[:, (k + 1) % 3]
                hit |= border[st[bsel], k] & _crosses(a_[:, 0], a_[:, 1], b_[:, 0], b_[:, 1], sx[bsel], sy[bsel])
            ok[sl[bsel[hit]]] = False
        # Layers at the probe point: triangles containing it (and none within ON_EDGE of it).
        qx, qy = sx + PROBE[0], sy + PROBE[1]
        yq = np.clip(qy, spans.yl[st], spans.yh[st])
        lo, hi = spans.extent(st, yq)
        d = np.minimum(np.minimum(qx - lo, hi - qx), np.minimum(qy - spans.yl[st], spans.yh[st] - qy))
        inside = np.bincount(sl, weights=d > ON_EDGE, minlength=tw * th)
        near = np.bincount(sl, weights=np.abs(d) <= ON_EDGE, minlength=tw * th)
        located = cand & ok & (inside == 1) & (near == 0)
        kind[located] = LOCATED
        loc_pair[sel] = located[sl]

    # Split texels: their partial pairs are clipped; a texel full for a triangle that also meets
    # others (overlapping UVs) takes that triangle's square as two sub-triangles.
    covered_any = (n_full + n_part) > 0
    split = covered_any & (kind == -1)
    clip = np.flatnonzero(split[part_local])
    ctri, cx_, cy_ = p_tri[clip], p_x[clip], p_y[clip]
    sub_xy, sub_area, sub_t, sub_pair = _clip_pairs(xy, E, ctri, cx_, cy_)
    sub_tri = tri_ids[sub_t]
    sub_local = (cy_[sub_pair] - y0) * tw + (cx_[sub_pair] - x0)
    if split.any() and len(fsel):
        # Full runs reaching a split texel (texels of overlapping islands): their texels there.
        row_split = np.cumsum(np.concatenate([np.zeros((th, 1), np.int64), split.reshape(th, tw)], axis=1), axis=1)
        rr = r[fsel] - y0
        reach = row_split[rr, f_hi[fsel] - x0] > row_split[rr, f_lo[fsel] - x0]
        fr, f_x = _runs(f_lo[fsel[reach]], f_hi[fsel[reach]])
        f_tri, f_y = own[fsel[reach]][fr], r[fsel[reach]][fr]
        f_local = (f_y - y0) * tw + (f_x - x0)
        keep = split[f_local]
        f_tri, f_local = f_tri[keep], f_local[keep]
        fx, fy = (f_local % tw + x0).astype(float), (f_local // tw + y0).astype(float)
        sq_a = np.stack([fx, fy], 1)
        sq_b = np.stack([fx + 1, fy], 1)
        sq_c = np.stack([fx + 1, fy + 1], 1)
        sq_d = np.stack([fx, fy + 1], 1)
        sub_xy = np.concatenate([sub_xy, np.stack([sq_a, sq_b, sq_c], 1), np.stack([sq_a, sq_c, sq_d], 1)])
        extra_tri = tri_ids[f_tri]
        sub_tri = np.concatenate([sub_tri, extra_tri, extra_tri])
        sub_area = np.concatenate([sub_area, np.full(2 * len(extra_tri), 0.5)])
        sub_local = np.concatenate([sub_local, f_local, f_local])
    # Clipping can find nothing of a texel whose overlap is a sliver: it is not covered then.
    has_sub = np.zeros(tw * th, bool)
    has_sub[sub_local] = True
    covered = np.flatnonzero(covered_any & (~split | has_sub))
    compact = np.full(tw * th, -1, np.int64)
    compact[covered] = np.arange(len(covered))
    texels = (covered // tw + y0) * width + (covered % tw + x0)
    n = len(covered)

    sub_tex = compact[sub_local]
    order = np.argsort(sub_tex, kind="stable")
    sub_tex, sub_tri, sub_xy, sub_area = sub_tex[order], sub_tri[order], sub_xy[order], sub_area[order]
    full_of = kind[covered]
    coverage = np.bincount(sub_tex, weights=sub_area, minlength=n)
    coverage[full_of != -1] = 1.0
    sub_start = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(sub_tex, minlength=n), out=sub_start[1:])
    csum = np.cumsum(sub_area)
    run_base = np.concatenate([[0.0], csum])[sub_start[:-1]]
    with np.errstate(invalid="ignore", divide="ignore"):
        sub_cdf = (csum - run_base[sub_tex]) / coverage[sub_tex]
    if len(sub_cdf):
        last = sub_start[1:][sub_start[1:] > sub_start[:-1]] - 1
        sub_cdf[last] = 1.0

    # Candidates of located texels, by texel, in ascending triangle order (pairs come triangle by
    # triangle, and the tile's triangles are ascending).
    li = np.flatnonzero(loc_pair)
    loc_tex = compact[part_local[li]]
    order = np.argsort(loc_tex, kind="stable")
    li, loc_tex = li[order], loc_tex[order]
    lt = p_tri[li]
    e = np.take(E, lt, axis=0)
    ef = e.reshape(-1, 3)  # each edge's (a, b, c), column by column
    ef[:, 2] += ef[:, 0] * np.repeat(p_x[li], 3) + ef[:, 1] * np.repeat(p_y[li], 3)
    loc_start = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(loc_tex, minlength=n), out=loc_start[1:])
    return TileFragments(texels, full_of, sub_tex, sub_tri, sub_xy, sub_cdf, sub_start, coverage,
                         loc_tri=tri_ids[lt], loc_start=loc_start, loc_edges=e)


def _clip_pairs(xy, E, tri, px, py):
    """Clip texel squares (lower corners ``px``, ``py``) by the triangles ``xy[tri]``: fan
    sub-triangles (m, 3, 2), their areas, and the pair each came from (index into ``tri``).
    Polygons are worked as columns (see :func:`clip_polygons`)."""
    n = len(tri)
    X, Y = np.zeros((7, n)), np.zeros((7, n))
    sq_x, sq_y = [px + d for d in (0.0, 1.0, 1.0, 0.0)], [py + d for d in (0.0, 0.0, 1.0, 1.0)]
    for j in range(4):
        X[j], Y[j] = sq_x[j], sq_y[j]
    cnt = np.full(n, 4)
    # A triangle inside the texel is its own fragment (meshes with triangles smaller than texels).
    txy = np.take(xy, tri, axis=0)
    lo, hi = _corner_bounds(txy)
    within = (lo[:, 0] >= px) & (hi[:, 0] <= px + 1) & (lo[:, 1] >= py) & (hi[:, 1] <= py + 1)
    w = np.flatnonzero(within)
    for k in range(3):
        X[k, w], Y[k, w] = txy[w, k, 0], txy[w, k, 1]
    cnt[w] = 3
    et = np.take(E, tri, axis=0)
    for e in range(3):
        a_e, b_e, c_e = et[:, e, 0], et[:, e, 1], et[:, e, 2]
        # Only the edges that cut a texel clip it (usually one): each pass takes the pairs it cuts.
        cut = a_e * sq_x[0] + b_e * sq_y[0] + c_e < 0
        for j in range(1, 4):
            cut |= a_e * sq_x[j] + b_e * sq_y[j] + c_e < 0
        cuts = np.flatnonzero(cut & ~within)
        if not len(cuts):
            continue
        slots = int(cnt[cuts].max())
        cx, cy, cnt[cuts] = clip_polygons(X[:slots, cuts], Y[:slots, cuts], cnt[cuts], a_e[cuts], b_e[cuts], c_e[cuts])
        X[:slots + 1, cuts], Y[:slots + 1, cuts] = cx, cy
        X[slots + 1:, cuts] = 0.0
        Y[slots + 1:, cuts] = 0.0
    K = max(int(cnt.max()) if len(cnt) else 3, 3)
    X, Y = X[:K], Y[:K]
    # Fan triangulation around vertex 0: sub-triangles (0, k, k+1), k = 1 .. cnt - 2.
    ks = np.arange(1, K - 1)
    fan_ok = ks[:, None] < (cnt - 1)
    ax, ay = X[0], Y[0]
    bx, by, cx, cy = X[1:K - 1], Y[1:K - 1], X[2:K], Y[2:K]
    fan_area = 0.5 * ((bx - ax) * (cy - ay) - (by - ay) * (cx - ax))
    fan_area = np.where(fan_ok, np.abs(fan_area), 0.0)
    ip = np.flatnonzero(fan_area.sum(axis=0) > MIN_FRAGMENT_AREA)
    fan_ok, fan_area = fan_ok[:, ip], fan_area[:, ip]
    fan_ok &= fan_area > 0
    rr, kk = np.nonzero(fan_ok.T)  # pair by pair, each pair's fan in order
    p = ip[rr]
    sub_xy = np.empty((len(rr), 3, 2))
    for corner, (vx, vy) in enumerate(((ax[p], ay[p]), (bx[kk, p], by[kk, p]), (cx[kk, p], cy[kk, p]))):
        sub_xy[:, corner, 0], sub_xy[:, corner, 1] = vx, vy
    return sub_xy, fan_area[kk, rr], tri[p], p
