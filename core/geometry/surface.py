"""Surface sampling: where on the target each texel's samples lie, with which normals.

The rasteriser (:mod:`core.geometry.raster`) says which parts of which triangles each texel covers. This
module turns that into *sample units*, each a piece of one triangle with a map from the sample's
position coordinates to the triangle's texel space:

    (x, y) = (A0 + A1 u + A2 v,  B0 + B1 u + B2 v)        (texel units, from the triangle's first corner)

- a texel inside one triangle is one unit, a square: (u, v) in [0, 1)^2 is the point's position in
  the texel (u2, u3 of the sample pattern), and the map is a translation to the texel's corner;
- a located texel (covered exactly once by several triangles, :data:`core.geometry.raster.LOCATED`) is one
  unit too, a square whose samples each find their own triangle: the candidate whose edge functions
  at (u, v) are least negative (the one containing the point), and then that triangle's translation
  to the texel's corner (``cand_*``);
- a texel split among triangles (an island's border or overlapping islands cross it) has one unit per
  piece of triangle inside it (the rasteriser's sub-triangles): (u, v) are the weights of the
  piece's corners 0 and 1 from Heitz's square-to-triangle map of (u2, u3)
  (:func:`core.montecarlo.warps.square_to_triangle`), corner 2 the origin.

The surface itself is per triangle (:class:`SurfaceTable`): position and interpolated shading
normal are affine in texel space, so every sample's point and normal are exact. The kernel
(:mod:`core.engine.kernel`) turns each triangle's maps into one matrix.

A split texel's samples are shared among its units by systematic sampling: sample r of a block of
``count`` goes to the unit whose cumulative area fraction first exceeds (r + phi) / count, phi a
per-texel random number. Every sample lands in a unit with probability proportional to its area
(the estimate stays unbiased), each unit gets its area's share of samples to within one, and the
samples of a unit are consecutive indices, traced together in power-of-two pieces (a texel of one
unit traces a block of samples as one piece).
"""

from dataclasses import dataclass

import numpy as np

from .mesh import SLICE, corner_positions
from ..montecarlo.hashing import hash_uniform

SQUARE, TRIANGLE, LOCATED = 0, 1, 2
#: Located texels with more candidates than this have their runs padded to a power of two.
CANDIDATE_PAD = 4
#: A padding candidate's edge functions: below any real one's at any point of the texel.
NEVER = np.float32(3e38)
_TAG_ALLOCATE = 21
#: The surface table's and the UV triangles' storage type (:class:`SurfaceTable`).
DTYPE = np.float32


def _smooth(mesh, N, FN):
    """Per triangle, whether its corner normals ``N`` (n, 3, 3) differ from each other or from its
    face normal ``FN`` (n, 3)."""
    out = np.zeros(len(N), bool)
    if not mesh.has_corner_normals:
        return out
    for c in range(3):
        out |= N[:, 1, c] != N[:, 0, c]
        out |= N[:, 2, c] != N[:, 0, c]
        out |= np.abs(N[:, 0, c] - FN[:, c]) > 1e-7
    return out


@dataclass
class SurfaceTable:
    """Affine maps from texel space (x, y) to the surface, per triangle, anchored at its first corner.

    position(x, y) = P0 + (x - ox) Px + (y - oy) Py; normal(x, y) = N0 + (x - ox) Nx + (y - oy) Ny
    (the interpolated corner normals, unnormalised); FN the unit face normal.

    Kept in float32 (:data:`DTYPE`), as Blender's and Embree's geometry is: half the bytes a triangle
    in every process that bakes. Each map is computed in float64 and rounded once; whoever computes
    with the table reads its rows in float64 (:meth:`take`), so no arithmetic runs in float32 by
    accident (numpy 1.26 and 2.x promote float32 arrays with float64 scalars differently).
    """

    origin: np.ndarray
    P0: np.ndarray
    Px: np.ndarray
    Py: np.ndarray
    N0: np.ndarray
    Nx: np.ndarray
    Ny: np.ndarray
    FN: np.ndarray
    corners: np.ndarray = None  # (T, 3, 3) the corners' positions, or None: from positions and triangles
    smooth: np.ndarray = None   # (T,) bool: the shading normal is not the face normal everywhere
    corners_xy: np.ndarray = None  # (T, 3, 2) the corners in texel space
    positions: np.ndarray = None   # the mesh's (V, 3) positions and (T, 3) triangles, where ``corners``
    triangles: np.ndarray = None   # is None (72 bytes a triangle not held)

    def take(self, field, tri):
        """Rows ``tri`` of the table's ``field`` ('P0', 'Px', ..., 'FN', 'origin'), in float64."""
        return np.take(getattr(self, field), tri, axis=0, mode="clip").astype(np.float64)

    def corners_of(self, tri):
        """(n, 3, 3) corner positions of triangles ``tri``."""
        if self.corners is not None:
            return np.take(self.corners, tri, axis=0, mode="clip")
        return corner_positions(self.positions, np.take(self.triangles, tri, axis=0, mode="clip"))

    @classmethod
    def build(cls, mesh, uvtris):
        """The table of ``mesh`` over its UV triangles ``uvtris`` (:func:`core.geometry.raster.prepare`), built
        :data:`SLICE` triangles at a time: the temporaries (the corner normals, the barycentric
        gradients) stay a slice's whatever the mesh, and the values are the same bits as in one go."""
        xy = uvtris.corners32
        T = len(xy)
        maps = {"P": tuple(np.empty((T, 3), DTYPE) for _ in range(3))}
        FN32 = np.empty((T, 3), DTYPE)
        flat = not mesh.has_corner_normals
        if flat:
            # Flat: the corner normals are the face normal, N0 is the table's FN itself (not a copy),
            # and the normal does not change across a triangle: Nx = Ny = 0, one read-only row of
            # zeros seen as (T, 3) (24 bytes a triangle not held).
            zeros = np.broadcast_to(np.zeros(3, DTYPE), (T, 3))
            normal = (FN32, zeros, zeros)
        else:
            maps["N"] = normal = tuple(np.empty((T, 3), DTYPE) for _ in range(3))
        smooth = np.empty(T, bool)
        for lo in range(0, T, SLICE):
            hi = min(lo + SLICE, T)
            tri = np.arange(lo, hi)
            # The face normals of the slice (row by row: the mesh keeps none it did not have).
            FN = mesh.face_geometry_of(tri)[1]
            FN32[lo:hi] = FN
            N = None if flat else mesh.corner_normals(tri)
            smooth[lo:hi] = False if flat else _smooth(mesh, N, FN)
            cls._slice(uvtris.corners_of(slice(lo, hi)), uvtris.valid[lo:hi],
                       corner_positions(mesh.positions, mesh.triangles[lo:hi]), N, maps, lo, hi)
        # origin: the first corners, a view of the corners the UV triangles keep (not a copy).
        return cls(origin=xy[:, 0], P0=maps["P"][0], corners_xy=xy, Px=maps["P"][1], Py=maps["P"][2],
                   N0=normal[0], Nx=normal[1], Ny=normal[2], FN=FN32, smooth=smooth,
                   positions=mesh.positions, triangles=mesh.triangles)

    @staticmethod
    def _slice(xy, valid, P, N, maps, lo, hi):
        # Column by column (see core.geometry.mesh.face_geometry: numpy is slow over an inner axis of 2 or 3);
        # the same operations as the (T, 2) and (T, 3) forms, so the same bits. In float64 (``xy``,
        # ``P``, ``N`` are), each map rounded once into the float32 table.
        x0, y0 = xy[:, 0, 0], xy[:, 0, 1]
        e1x, e1y = xy[:, 1, 0] - x0, xy[:, 1, 1] - y0
        e2x, e2y = xy[:, 2, 0] - x0, xy[:, 2, 1] - y0
        det = e1x * e2y - e1y * e2x
        safe = np.where(valid, det, 1.0)
        # Barycentric weights b1, b2 of corners 1, 2 as linear functions of (x - x0, y - y0).
        d1x, d1y = e2y / safe, -e2x / safe   # d b1 / d(x, y)
        d2x, d2y = -e1y / safe, e1x / safe   # d b2 / d(x, y)
        for name, V in (("P", P), ("N", N)):
            if name not in maps:
                continue  # a flat mesh's normal maps are constant (SurfaceTable.build)
            v0_out, vx_out, vy_out = maps[name]
            if v0_out is not None:
                v0_out[lo:hi] = V[:, 0]
            vx, vy = np.empty((hi - lo, 3)), np.empty((hi - lo, 3))
            for c in range(3):
                v0 = V[:, 0, c]
                dv1, dv2 = V[:, 1, c] - v0, V[:, 2, c] - v0
                np.multiply(d1x, dv1, out=vx[:, c])
                vx[:, c] += d2x * dv2
                np.multiply(d1y, dv1, out=vy[:, c])
                vy[:, c] += d2y * dv2
            vx_out[lo:hi] = vx
            vy_out[lo:hi] = vy

    def position(self, tri, x, y):
        return self._affine(tri, x, y, self.P0, self.Px, self.Py)

    def normal(self, tri, x, y):
        return self._affine(tri, x, y, self.N0, self.Nx, self.Ny)

    def _affine(self, tri, x, y, v0, vx, vy):
        # np.take: numpy's fancy indexing of these (T, 3) arrays is 2-3 times slower.
        origin = np.take(self.origin, tri, axis=0, mode="clip").astype(np.float64)  # ids of the table: in range
        dx, dy = np.asarray(x, np.float64) - origin[:, 0], np.asarray(y, np.float64) - origin[:, 1]
        g0, gx, gy = (np.take(v, tri, axis=0, mode="clip").astype(np.float64) for v in (v0, vx, vy))
        out = np.empty(g0.shape)
        for c in range(g0.shape[1]):  # column by column (numpy is slow over an inner axis of 3)
            np.multiply(dx, gx[:, c], out=out[:, c])
            out[:, c] += g0[:, c]
            out[:, c] += dy * gy[:, c]
        return out


@dataclass
class Units:
    """The sample units of one tile, sorted by texel (see the module docstring).

    kind : SQUARE, TRIANGLE or LOCATED; texel : the unit's texel, as an index into the tile's texel
    list; tri : its triangle (a located unit's first candidate); first : (n_texels + 1,) units of
    texel k are first[k]:first[k + 1]; cdf : cumulative area fraction of the texel's covered area up
    to and including the unit; coef : (U, 6) float64, (A0, A1, A2, B0, B1, B2) of the map above
    (from build_units: a view of (6, U) planes).
    Candidates of located units: cand_first (U + 1,) offsets (empty runs for other units), cand_tri
    (c,) triangles, cand_edges (c, 3, 3) float32 edge functions (a, b, c) in texel-local
    coordinates, cand_coef (c, 2) float32 the translation (A0, B0) to each candidate's texel space;
    runs of more than :data:`CANDIDATE_PAD` end in padding candidates that never contain a point.
    """

    kind: np.ndarray
    texel: np.ndarray
    tri: np.ndarray
    first: np.ndarray
    cdf: np.ndarray
    coef: np.ndarray
    cand_first: np.ndarray = None
    cand_tri: np.ndarray = None
    cand_edges: np.ndarray = None
    cand_coef: np.ndarray = None

    def __len__(self):
        return len(self.kind)


def point_table(p, n, gn, corners, smooth=None):
    """A :class:`SurfaceTable` of one constant 'triangle' per point (position ``p``, shading normal
    ``n``, geometric normal ``gn``, (m, 3) each; ``corners`` (m, 3, 3) the triangle each lies on,
    which sets its ray offset): the units of sample points that are not texels (mesh vertices, the
    high-poly points a selected-to-active bake matched). ``smooth``: None (a point whose normals
    differ takes the smooth form), or one bool for all."""
    m = len(p)
    zeros = np.zeros((m, 3), DTYPE)
    if smooth is None:
        smooth = np.any(np.abs(n - gn) > 1e-7, axis=1)
    else:
        smooth = np.full(m, bool(smooth))
    return SurfaceTable(origin=np.zeros((m, 2), DTYPE), P0=np.asarray(p, DTYPE), Px=zeros, Py=zeros,
                        N0=np.asarray(n, DTYPE), Nx=zeros, Ny=zeros, FN=np.asarray(gn, DTYPE),
                        corners=corners, smooth=smooth, corners_xy=np.zeros((m, 3, 2), DTYPE))


def point_units(tri, texel):
    """The units of points: one square each (a map of nothing), point ``tri`` (a row of its
    :func:`point_table`) standing for texel ``texel`` (an index into the tile's texel list; one
    point per texel, or several in texel order)."""
    m = len(tri)
    coef = np.zeros((m, 6))
    coef[:, 1] = coef[:, 5] = 1.0
    texel = np.asarray(texel, np.int64)
    first = np.searchsorted(texel, np.arange(int(texel[-1]) + 2 if m else 1))
    return Units(kind=np.full(m, SQUARE, np.int8), texel=texel, tri=np.asarray(tri, np.int64),
                 first=first.astype(np.int64), cdf=np.ones(m), coef=coef,
                 cand_first=np.zeros(m + 1, np.int64), cand_tri=np.zeros(0, np.int64),
                 cand_edges=np.zeros((0, 3, 3), np.float32), cand_coef=np.zeros((0, 2), np.float32))


def build_units(frag, table, width):
    """The units of a tile's fragments, in texel order (a split texel's sub-triangles in theirs)."""
    from .raster import LOCATED as _LOCATED

    n = len(frag.texels)
    full = frag.full_tri
    # Units per texel: one for a texel inside one triangle or located, its sub-triangles' count else.
    per = np.where(full != -1, 1, np.diff(frag.sub_start))
    first = np.zeros(n + 1, np.int64)
    np.cumsum(per, out=first[1:])
    U = int(first[-1])
    kind = np.empty(U, np.int8)
    tri = np.empty(U, np.int64)
    cdf = np.ones(U)
    # The maps as planes (6, U), one contiguous row per coefficient: the writes below run along a
    # plane, and the kernel's float32 planes are one conversion of them (TileContext). ``coef`` is
    # their (U, 6) view.
    # A1 and B2 are 1 for every square (and located texel's square); sub-triangles write theirs.
    planes = np.zeros((6, U))
    planes[1].fill(1.0)
    planes[5].fill(1.0)
    simple = np.flatnonzero(full >= 0)
    at = first[simple]
    tri_s = full[simple]
    tex = frag.texels[simple]
    # Squares: a translation to the texel's corner.
    kind[at] = SQUARE
    tri[at] = tri_s
    origin_x, origin_y = table.origin[:, 0], table.origin[:, 1]  # float32 views; read in float64
    planes[0, at] = (tex % width) - np.take(origin_x, tri_s).astype(np.float64)  # np.take: origin[tri_s, 0] costs twice
    planes[3, at] = (tex // width) - np.take(origin_y, tri_s).astype(np.float64)
    # Located texels: a square each; its candidates' translations.
    loc = np.flatnonzero(full == _LOCATED)
    loc_start = frag.loc_start if frag.loc_start is not None else np.zeros(n + 1, np.int64)
    cand_tri = frag.loc_tri if frag.loc_tri is not None else np.zeros(0, np.int64)
    per_c = loc_start[loc + 1] - loc_start[loc]
    # Runs of more than CANDIDATE_PAD candidates are padded to a power of two with candidates that
    # never contain a point (edge functions -BIG everywhere, the first candidate's triangle): the
    # kernel traces located texels with equal candidate counts together, and a few counts make few
    # calls (an adaptive bake's rounds each made a call per count, most of a few rays).
    padded = np.where(per_c <= CANDIDATE_PAD, per_c, 1 << np.ceil(np.log2(np.maximum(per_c, 1))).astype(np.int64))
    j = np.arange(int(padded.sum())) - np.repeat(np.cumsum(padded) - padded, padded)
    real = j < np.repeat(per_c, padded)
    src = np.repeat(loc_start[loc], padded) + np.where(real, j, 0)
    cand_tri = cand_tri[src]
    per_c = padded
    cand_tex = np.repeat(frag.texels[loc], per_c)
    cand_coef = np.empty((len(cand_tri), 2), np.float32)  # column by column (see SurfaceTable.build)
    cand_coef[:, 0] = (cand_tex % width) - np.take(origin_x, cand_tri).astype(np.float64)
    cand_coef[:, 1] = (cand_tex // width) - np.take(origin_y, cand_tri).astype(np.float64)
    at = first[loc]
    kind[at] = LOCATED
    tri[at] = cand_tri[loc_start[loc]] if len(loc) else 0
    # Sub-triangles: corner 2 plus the weights of corners 0 and 1 times the edges to them.
    tri_t = frag.sub_tri
    at = first[frag.sub_texel] + (np.arange(len(tri_t)) - frag.sub_start[frag.sub_texel])
    c = np.asarray(frag.sub_xy, np.float64) - table.take("origin", tri_t)[:, None, :]
    kind[at] = TRIANGLE
    tri[at] = tri_t
    cdf[at] = frag.sub_cdf
    for k in range(2):
        planes[3 * k, at] = c[:, 2, k]
        planes[3 * k + 1, at] = c[:, 0, k] - c[:, 2, k]
        planes[3 * k + 2, at] = c[:, 1, k] - c[:, 2, k]
    texel = np.arange(n) if U == n else np.repeat(np.arange(n), per)
    # Candidate runs follow the units: located units in texel order are the fragments' runs.
    cand_count = np.zeros(U, np.int64)
    cand_count[first[loc]] = per_c
    cand_first = np.zeros(U + 1, np.int64)
    np.cumsum(cand_count, out=cand_first[1:])
    loc_edges = frag.loc_edges if frag.loc_edges is not None else np.zeros((0, 3, 3))
    edges = np.take(loc_edges, src, axis=0, mode="clip").astype(np.float32)  # src: the fragments' own rows
    pad = np.flatnonzero(~real)
    if len(pad):
        edges.reshape(-1, 9)[pad] = np.array([0.0, 0.0, -NEVER] * 3, np.float32)
    return Units(kind=kind, texel=texel, tri=tri, first=first, cdf=cdf, coef=planes.T, cand_first=cand_first,
                 cand_tri=cand_tri, cand_edges=edges, cand_coef=cand_coef)


def allocate(units, texels, start, count, seed, texel_ids):
    """Pieces of samples [start, start + count) of the tile's ``texels`` (indices into its texel
    list; ``texel_ids`` the global texel numbers of the whole list): which unit takes which samples.
    ``start`` and ``count`` are one number for all the texels or one per texel (an adaptive round,
    where each texel goes from its own count to its own next count).

    Returns (unit, piece start, piece size) arrays (the kernel traces equal pieces together). A texel
    of one unit (inside one triangle, or located) takes the whole block as one piece; the units of a
    split texel share it, each share cut into pieces whose sizes are powers of two.
    """
    texels = np.asarray(texels, dtype=np.int64)
    start = np.broadcast_to(np.asarray(start, dtype=np.int64), texels.shape)
    count = np.broadcast_to(np.asarray(count, dtype=np.int64), texels.shape)
    lo = units.first[texels]
    per = units.first[texels + 1] - lo
    one = (per == 1) & (count > 0)
    single, s_start, s_count = lo[one], start[one], count[one]
    multi = (per > 1) & (count > 0)
    mt = texels[multi]
    if len(mt):
        lo_m, per_m = lo[multi], per[multi]
        unit = np.repeat(lo_m, per_m) + (np.arange(per_m.sum()) - np.repeat(np.cumsum(per_m) - per_m, per_m))
        owner = np.repeat(mt, per_m)
        first, cnt = np.repeat(start[multi], per_m), np.repeat(count[multi], per_m)
        # Systematic sampling among a split texel's units: the first sample past each unit's cumulative share.
        phi = hash_uniform(seed, texel_ids[owner], first.astype(np.uint64), _TAG_ALLOCATE)
        edge = np.clip(np.ceil(units.cdf[unit] * cnt - phi), 0, cnt).astype(np.int64)
        new_texel = np.ones(len(unit), bool)
        new_texel[1:] = owner[1:] != owner[:-1]
        last = np.ones(len(unit), bool)
        last[:-1] = new_texel[1:]
        edge[last] = cnt[last]
        before = np.zeros(len(unit), np.int64)
        before[1:] = edge[:-1]
        before[new_texel] = 0
        size = edge - before
        keep = size > 0
        unit, size, offset = unit[keep], size[keep], before[keep] + first[keep]
    else:
        unit = size = offset = np.zeros(0, np.int64)
    # A texel of a single unit takes its whole block as one piece, whatever its size and start: an
    # adaptive round from 8 to 64 samples is one piece of 56, not pieces of 8, 16 and 32 (short
    # pieces cost the kernel more per ray). The units of split texels get shares of any size, cut
    # below into pieces whose sizes are powers of two, so that they fall into few kernel calls.
    pu, ps, pz = aligned_pieces(unit, offset, size)
    return np.concatenate([single, pu]), np.concatenate([s_start, ps]), np.concatenate([s_count, pz])


def aligned_pieces(owner, start, count):
    """Samples [start, start + count) of each entry cut into power-of-two pieces, each aligned to its
    own size (the kernel gathers an aligned block of a xor-ordered pattern as whole rows): from each
    piece's start, the largest power of two that divides it and still fits. From 0 that is largest
    first (120 samples from 0: 64, 32, 16, 8); from an adaptive round's start it climbs (samples 8 to
    128: 8, 16, 32, 64). Returns (owner, piece start, piece size), the entries' first pieces, then
    their second pieces, and so on."""
    pu, ps, pz = [], [], []
    pos, left = np.asarray(start, np.int64).copy(), np.asarray(count, np.int64).copy()
    while len(left):
        low = np.where(pos > 0, pos & -pos, 1 << 62)  # the largest power of two dividing pos
        high = np.left_shift(1, np.floor(np.log2(np.maximum(left, 1))).astype(np.int64))  # the largest that fits
        piece = np.minimum(low, high)
        pu.append(owner)
        ps.append(pos.copy())
        pz.append(piece)
        pos = pos + piece
        left = left - piece
        more = left > 0
        owner, pos, left = owner[more], pos[more], left[more]
    if not pu:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(pu), np.concatenate(ps), np.concatenate(pz)


def contact_texels(frag, table, width, tracer, samples):
    """Per texel, whether another object's surface touches this one somewhere in the texel.

    Probes (see :class:`core.tracing.tracer.Tracer`) at the corners and centre of texels inside one
    triangle, and at the corners and centroid of every sub-triangle of split texels: contact is a
    property of the position, not of the direction, so texels that no probe finds in contact skip
    the per-sample probes. Contact smaller than these probe points are apart can go unnoticed.
    """
    n_tex = len(frag.texels)
    if not tracer.touches or n_tex == 0:
        return np.zeros(n_tex, bool)
    # The tile's triangles, ascending: marked in a table of every triangle (a tile's texels name
    # them a hundred thousand times over at 4096^2, where sorting them cost more than the probes).
    inside = frag.full_tri >= 0
    full_tri = frag.full_tri[inside]
    loc_tri = frag.loc_tri if frag.loc_tri is not None else np.zeros(0, np.int64)
    seen = np.zeros(len(table.P0), bool)
    seen[full_tri] = True
    seen[frag.sub_tri] = True
    seen[loc_tri] = True
    tris = np.flatnonzero(seen)
    # Only triangles whose bounding box, grown by twice the largest offset, meets an occluder's can
    # touch one: the probes go to their texels alone.
    corners3 = table.corners_of(tris)
    grow = 2.0 * tracer.offset(np.abs(corners3).max(axis=(1, 2)))[:, None]
    near = np.zeros(len(table.P0), bool)
    near[tris] = tracer.near_occluders(corners3.min(axis=1) - grow, corners3.max(axis=1) + grow)
    candidates = np.zeros(n_tex, bool)
    candidates[inside] = near[full_tri]
    candidates[frag.sub_texel[near[frag.sub_tri]]] = True
    # A located texel's samples may lie on any of its candidates: each sample is probed (its own
    # triangle's normal) when one of them is near an occluder.
    located = np.zeros(n_tex, bool)
    if len(loc_tri):
        owner = np.repeat(np.arange(n_tex), np.diff(frag.loc_start))
        located[owner[near[loc_tri]]] = True
        candidates |= located
    if not candidates.any():
        return candidates
    if samples <= 8:
        return candidates  # as few samples as probe points: probe the samples themselves
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0.5, 0.5]])
    simple = np.flatnonzero(inside & candidates)
    tex = frag.texels[simple]
    xy_s = (np.stack([tex % width, tex // width], 1)[:, None, :] + corners[None]).reshape(-1, 2)
    tri_s = np.repeat(frag.full_tri[simple], len(corners))
    own_s = np.repeat(simple, len(corners))
    sub = np.flatnonzero(near[frag.sub_tri])
    c3 = frag.sub_xy[sub]
    xy_p = np.concatenate([c3, c3.mean(axis=1, keepdims=True)], axis=1).reshape(-1, 2)
    tri_p = np.repeat(frag.sub_tri[sub], 4)
    own_p = np.repeat(frag.sub_texel[sub], 4)
    xy = np.concatenate([xy_s, xy_p]).astype(np.float64)
    tri = np.concatenate([tri_s, tri_p])
    own = np.concatenate([own_s, own_p])
    pos = table.position(tri, xy[:, 0], xy[:, 1])
    hit = tracer.contact(pos, table.take("FN", tri))
    return (np.bincount(own[hit], minlength=n_tex) > 0) | located


__all__ = ["SQUARE", "TRIANGLE", "LOCATED", "SurfaceTable", "Units", "build_units", "allocate", "aligned_pieces",
           "contact_texels"]
