"""The sampling kernel: pieces of sample units -> rays -> per-piece sums, one matrix product per chunk.

A piece is ``K`` consecutive samples (see :func:`core.geometry.surface.allocate`) of one unit, a piece of one
triangle. Each sample's pattern point (:mod:`core.engine.patterns`) comes as a feature row

    x = [a, b, 1, f0, f1, f2]

(a, b: the sample's position in the triangle's texel space, from u2, u3 after the texel's shift,
through Heitz's map for a unit that is a piece of triangle, and the unit's map; f: the direction
features of u0, u1, lifted once for the whole pool, turned by the texel's own angle about the
normal), and everything a ray needs is linear in x, so one product Y = X M per piece, with one
matrix M per triangle, gives every ray's origin and direction:

- flat-shaded triangles (the shading normal is the face normal): f = Malley's polar map of (u0, u1)
  in the triangle's tangent frame; M maps x to [origin (3), direction (3)];
- smooth-shaded triangles: f = v, the sphere point of (u0, u1) (:func:`core.montecarlo.warps.cosine_sphere_point`);
  M maps x to [origin, interpolated normal n(a, b), v in world space, n . gn, v . gn], and each
  sample's direction is normalize(n) + v: cosine-distributed about the sample's own shading normal,
  with no per-sample frame (or v folded onto n's side, for uniform directions).

The kernel holds X and Y as planes, one contiguous (n,) array per feature and per output column:
numpy's passes over a column of (n, 6) rows cost 2-4 times as much as over a plane, a piece's
(6, k) planes are one matrix for BLAS (rows n apart), and Embree reads origins and directions as
(n, 3) views of the planes (embreex takes any strides).

Thickness (:mod:`core.engine.thickness`) is the same kernel with the direction stage flipped: a tile
built ``inward`` pushes its origins off the surface to the inside and negates every direction.

Turning each texel's directions by its own random angle (:meth:`core.engine.patterns.TexelPattern.keys`)
means texels that share a pool pattern trace different directions. Directions below the geometric
surface are not traced (tfar 0) and count as occluded.

Where to extend it: a stage that moves sample points elsewhere (onto a high-poly surface) can take
the origins and the interpolated normals the smooth path computes (planes 0:3 and 3:6 of Y), replace
them per sample, and form directions as normalize(n) + v exactly as that path does (the sphere form
needs no frame, so any per-sample normal works); a miss mask joins ``below``. Points that are not
texels (mesh vertices) are units of a degenerate triangle (position and normal constant, Px = Py =
Nx = Ny = 0). Bent normals are the sum of the unoccluded ``directions`` (normalised) per piece, from
the same rays. Independent randomisations of a texel for an error estimate are
``TexelPattern.keys(texels, replicate=r)``.
"""

import threading

import numpy as np

from ..montecarlo import warps
from .estimators import piece_sums, sample_terms
from ..geometry.mesh import norms
from .patterns import TexelKeys
from ..geometry.surface import aligned_pieces
from ..tracing.tracer import FAR, Clock, RayBatch, offset_points

FLAT_COLUMNS, CURVED_COLUMNS = 6, 11
# The gathers below use np.take(..., mode="clip"): their indices are the kernel's own and always in
# range, and numpy's default mode checks every index and, with ``out``, copies through a buffer
# (a feature gather at 8 samples a piece: 6.5 -> 2.4 ns a row alone; the row-by-row entries
# 59 -> 37 ns a ray).
#: Pieces shorter than this (and located samples, each on its own triangle) are computed row by row
#: from the matrices' nonzero entries gathered per ray; longer pieces broadcast each piece's entries
#: over its samples. Either way Y = X M is elementwise passes, never a BLAS product: numpy's
#: elementwise arithmetic rounds the same on every numpy line, BLAS and CPU, and a BLAS product of
#: these small matrices did not (the rays' last bits moved between numpy 1.26 and 2.x).
ROW_PIECES = 8
#: The feature planes gathered from the pool (plane 2 is the constant 1).
_VARYING = (0, 1, 3, 4, 5)
#: The nonzero entries (row j of the feature vector, output column c) of each matrix form, grouped
#: by output column: a position column is M[2, c] + a M[0, c] + b M[1, c], a direction column
#: f0 M[3, c] + f1 M[4, c] + f2 M[5, c].
_POSITION_ROWS, _DIRECTION_ROWS = (2, 0, 1), (3, 4, 5)
FLAT_ENTRIES = tuple((c, _POSITION_ROWS if c < 3 else _DIRECTION_ROWS) for c in range(FLAT_COLUMNS))
CURVED_ENTRIES = tuple((c, _POSITION_ROWS if c in (0, 1, 2, 3, 4, 5, 9) else _DIRECTION_ROWS)
                       for c in range(CURVED_COLUMNS))


def _row_table(m, entries):
    """The matrices ``m`` (T, cols, 6) (transposed) as a float32 table (entries, T) of their nonzero
    entries."""
    js = [j for c, rows in entries for j in rows]
    cs = [c for c, rows in entries for _ in rows]
    out = np.empty((len(js), len(m)), m.dtype)
    for e, (j, c) in enumerate(zip(js, cs)):  # entry by entry: a gather over the short axes is slower
        out[e] = m[:, c, j]
    return out


def triangle_matrices(table, tris, offset, curved_all=False, inward=False):
    """Per triangle of ``tris`` (unique ids), the float32 matrix M (6, 6) (flat-shaded) or (6, 11)
    (smooth-shaded, or every triangle with ``curved_all``: a flat triangle's normal is constant)
    taking a feature row to what its rays need, stored transposed, (cols, 6): the form the kernel's
    product per piece takes. Returns (flat, curved, slot, gn, eps), slot mapping
    a triangle id to its row in the array of its kind (-1 for triangles not in ``tris``).
    ``inward``: ray origins pushed off the surface to the side opposite the shading normal (rays
    into the mesh, :mod:`core.engine.thickness`)."""
    def take(a, rows):
        # numpy's a[rows] is 2-3 times slower on (T, 3[, 3]) arrays; the table's float32 rows are
        # computed with in float64 (the matrices are rounded to float32 once, at the end).
        out = np.take(a, rows, axis=0, mode="clip")
        return out.astype(np.float64) if out.dtype.kind == "f" else out

    smooth = take(table.smooth, tris) | bool(curved_all)
    n = len(tris)
    # Column by column (numpy is slow over an inner axis of 2 or 3, and over a (T, 1) factor
    # broadcast to 3 columns), with the same operations as the (T, 3) forms: the same bits.
    # The ray offset: from the largest |coordinate| on the triangle (at a corner: |.|_inf is convex).
    c = np.abs(table.corners_of(tris)).reshape(n, 9)
    cmax = c[:, 0].copy()
    for j in range(1, 9):
        np.maximum(cmax, c[:, j], out=cmax)
    eps = offset(cmax)
    fn = take(table.FN, tris)
    origin = take(table.origin, tris)
    cxy = take(table.corners_xy, tris)
    centre = [origin[:, k] + ((cxy[:, 0, k] + cxy[:, 1, k] + cxy[:, 2, k]) / 3.0 - origin[:, k]) for k in range(2)]
    nref = table.normal(tris, centre[0], centre[1])
    ln = norms(nref[:, 0], nref[:, 1], nref[:, 2])
    unit = ln > 1e-12
    div = np.where(ln > 0, ln, 1.0)
    nu = np.empty((n, 3))
    for k in range(3):
        nu[:, k] = np.where(unit, nref[:, k] / div, fn[:, k])
    below = np.einsum("ij,ij->i", fn, nu) < 0
    gn = np.empty((n, 3))
    nref = np.empty((n, 3))
    for k in range(3):
        gn[:, k] = np.where(below, -fn[:, k], fn[:, k])  # to the shading side
        nref[:, k] = np.where(smooth, nu[:, k], gn[:, k])
    sx, sy, sz, tx, ty, tz = warps.basis_components(nref[:, 0], nref[:, 1], nref[:, 2])
    fs, ft = np.stack([sx, sy, sz], 1), np.stack([tx, ty, tz], 1)
    p0 = take(table.P0, tris)
    org = np.empty((n, 3))
    push = -eps if inward else eps
    for k in range(3):
        np.multiply(gn[:, k], push, out=org[:, k])
        org[:, k] += p0[:, k]  # the offset, folded into the constant row
    slot = np.full(len(table.P0), -1, np.int64)
    flat_i, curved_i = np.flatnonzero(~smooth), np.flatnonzero(smooth)
    slot[tris[flat_i]] = np.arange(len(flat_i))
    slot[tris[curved_i]] = np.arange(len(curved_i))

    i = flat_i
    ti = tris[i]
    mf = np.zeros((len(i), FLAT_COLUMNS, 6), np.float32)
    mf[:, 0:3, 0] = take(table.Px, ti)
    mf[:, 0:3, 1] = take(table.Py, ti)
    mf[:, 0:3, 2] = take(org, i)
    mf[:, 3:6, 3] = take(fs, i)
    mf[:, 3:6, 4] = take(ft, i)
    mf[:, 3:6, 5] = take(nref, i)

    i = curved_i
    t = tris[i]
    g = take(gn, i)
    mc = np.zeros((len(i), CURVED_COLUMNS, 6), np.float32)
    for r, (e, f) in enumerate(((take(table.Px, t), take(table.Nx, t)), (take(table.Py, t), take(table.Ny, t)),
                                (take(org, i), take(table.N0, t)))):
        mc[:, 0:3, r] = e
        mc[:, 3:6, r] = f
        mc[:, 9, r] = np.einsum("ij,ij->i", f, g)
    for r, v in ((3, take(fs, i)), (4, take(ft, i)), (5, take(nref, i))):
        mc[:, 6:9, r] = v
        mc[:, 10, r] = np.einsum("ij,ij->i", v, g)
    return mf, mc, slot, gn, eps


class TileContext:
    """What the kernel needs of one tile: its units, its texels' keys, its triangles' matrices.

    ``located_curved``: located samples (each on its own triangle) take every triangle's matrix in
    the smooth-shaded form when True (a bake-wide choice: any smooth triangle in the target), in the
    flat form otherwise.

    ``inward``: the tile's rays go into the mesh (:mod:`core.engine.thickness`): origins pushed off the
    surface to the inside, every direction negated (the hemisphere about the inverted normal).
    """

    def __init__(self, table, units, keys, texel_ids, contact, offset, located_curved=True, tris=None, blocked=None,
                 inward=False):
        self.units = units
        self.inward = bool(inward)
        # Per unit, True where something lies on its point (every sample occluded), or None: the
        # contact a stage found itself (:mod:`core.highpoly`), beside the probes of ``contact``.
        self.blocked = blocked
        self.keys = keys
        self.texel_ids = texel_ids      # global flat texel index of each of the tile's texels
        self.contact = contact          # per tile texel: probe its samples for contact
        # ``tris``: the tile's triangles, ascending (a superset of its units' is fine).
        tris = np.unique(units.tri) if tris is None else np.asarray(tris, np.int64)
        self.flat_m, self.curved_m, self.slot, gn, eps = triangle_matrices(table, tris, offset, inward=self.inward)
        self.smooth = table.smooth
        # The geometric normal and offset of each of ``tris`` (for contact probes, looked up for the
        # few samples probed: per unit up front they cost more than the probes).
        self.tris, self.gn, self.eps = tris, gn, eps
        # The units' maps (A0, A1, A2, B0, B1, B2) as float32 planes (6, units), gathered by column.
        self.coef_planes = np.ascontiguousarray(units.coef.T, dtype=np.float32)
        self.flat_rows = _row_table(self.flat_m, FLAT_ENTRIES)
        self.curved_rows = _row_table(self.curved_m, CURVED_ENTRIES)
        # Located samples: one matrix per candidate triangle, all in one form.
        self.located_curved = bool(located_curved)
        cand = units.cand_tri if units.cand_tri is not None else np.zeros(0, np.int64)
        if len(cand):
            native = bool(np.all(table.smooth[cand] == self.located_curved))
            if native:  # the located form is every candidate's own form: share the matrices
                self.loc_m = self.curved_m if self.located_curved else self.flat_m
                self.loc_rows = self.curved_rows if self.located_curved else self.flat_rows
                self.loc_slot, self.loc_gn, self.loc_eps = self.slot, gn, eps
                self.loc_pos = np.full(len(table.P0), -1, np.int64)
                self.loc_pos[tris] = np.arange(len(tris))
            else:
                ctris = np.unique(cand)
                flat, curved, self.loc_slot, self.loc_gn, self.loc_eps = triangle_matrices(
                    table, ctris, offset, curved_all=self.located_curved, inward=self.inward)
                self.loc_m = curved if self.located_curved else flat
                self.loc_rows = _row_table(self.loc_m, CURVED_ENTRIES if self.located_curved else FLAT_ENTRIES)
                self.loc_pos = np.full(len(table.P0), -1, np.int64)
                self.loc_pos[ctris] = np.arange(len(ctris))  # triangle id -> row of gn, eps
        self.texels = len(texel_ids)

    @staticmethod
    def stacked_keys(keys):
        """The keys of several replicates of the same texels as one TexelKeys: replicate r's texel t
        at row r * len(texels) + t (what :meth:`Kernel.run` reads with ``replicates``)."""
        if len(keys) == 1:
            return keys[0]
        return TexelKeys(*(np.concatenate([getattr(k, f) for k in keys]) for f in TexelKeys.__slots__))



def _per_piece(values, k):
    """Per-piece values (g,) as (g, 1) to broadcast over a piece's k samples, or repeated (g, k) when
    k is small (numpy's inner loops are slow on a short broadcast axis)."""
    if k == 1:
        return values.reshape(-1, 1)
    return values[:, None] if k >= 8 else np.repeat(values, k).reshape(len(values), k)


class Kernel:
    """Traces pieces of sample units; one instance per bake, shared by the worker threads.

    Parameters
    ----------
    pattern : core.engine.patterns.TexelPattern; tracer : core.tracing.tracer.Tracer;
    distribution : 'cosine' or 'uniform'; on_rays : None or a callable taking a RayBatch.
    """

    def __init__(self, pattern, tracer, distribution, on_rays=None):
        self.pattern = pattern
        self.tracer = tracer
        self.uniform = distribution == "uniform"
        self.on_rays = on_rays
        self.kinds = {False: "uniform" if self.uniform else "cosine",
                      True: "uniform_sphere" if self.uniform else "cosine_sphere"}
        self.reach = float(tracer.tfar)
        self._local = threading.local()

    def _workspace(self, n):
        """This thread's buffers for ``n`` rays. Reused from call to call: fresh large arrays cost
        page faults on every call, which on a busy machine take as long as the arithmetic."""
        ws = getattr(self._local, "ws", None)
        if ws is None or ws.n < n:
            ws = self._local.ws = _Workspace(n)
        return ws

    def run(self, tile, curved, unit, start, size, squares, located=False, vectors=None, replicates=None):
        """Trace the ``size`` samples from ``start`` (per piece) of each piece's ``unit``;
        the first ``squares`` pieces are texel squares, the rest pieces of triangles; all pieces'
        triangles flat-shaded (``curved`` False) or all smooth-shaded. With ``located``, every piece
        is a located texel's square, each sample on its own triangle (``curved``: the tile's
        ``located_curved``).

        Returns (s1, s2, rays, seconds, cpu_seconds): per piece the sum of its samples' terms and of
        their squares (float64), the rays traced, and the time spent inside Embree.

        ``vectors``: None, or a (pieces, 3) float64 array that receives, per piece, the sum of its
        samples' unit directions each weighted by the sample's term (V for cosine directions,
        2 cos(theta) V for uniform ones, times the falloff): the bent-normal estimator, from the same
        rays (:mod:`core.post.bent`).

        ``replicates``: None (every piece is of replicate 0, whose keys are ``tile.keys``), or per
        piece the replicate it belongs to, ``tile.keys`` then holding every replicate's keys
        (:meth:`TileContext.stacked_keys`): pieces of all replicates in one call.
        """
        units, keys = tile.units, tile.keys
        g, k = len(unit), int(size)
        n = g * k
        ws = self._workspace(n)
        tex = units.texel[unit]
        kt = tex if replicates is None else tex + replicates * tile.texels  # the pieces' rows of keys
        e, o = keys.pattern[kt], keys.order[kt]
        xf, x, blocks, firsts, first = self._gather(ws, keys, kt, e, o, curved, start, k, g, n)
        a, b = x[0], x[1]
        # (u, v) -> the triangle's texel space: a translation for squares, Heitz's map and the
        # piece's corners for pieces of triangles; located samples find their triangle first.
        tri_s = None
        if located:
            best = self._locate(units, unit, x, k)
            pick = units.cand_first[unit][:, None] + best
            tri_s = units.cand_tri[pick].ravel()
            # each sample moves to its own triangle's texel space
            tr = units.cand_coef[pick]
            a += tr[:, :, 0]
            b += tr[:, :, 1]
            squares = g
        self._texel_space(tile, unit, x, k, squares, located)
        # The texel's turn about the normal: a rotation of the first two direction features.
        cos_t = _per_piece(keys.cos_turn[kt], k)
        sin_t = _per_piece(keys.sin_turn[kt], k)
        f0, f1 = x[3], x[4]
        t0 = f0 * cos_t
        t0 -= f1 * sin_t
        f1 *= cos_t
        f1 += f0 * sin_t
        f0[...] = t0
        entries = CURVED_ENTRIES if curved else FLAT_ENTRIES
        # Y = X M as planes, from each matrix's nonzero entries: per ray (a located sample's own
        # triangle's, or those of a short piece's) or per piece, broadcast over its samples.
        if located:
            table, slot = tile.loc_rows, tile.loc_slot[tri_s]
        else:
            table = tile.curved_rows if curved else tile.flat_rows
            slot = tile.slot[units.tri[unit]]
        y = ws.y[:len(entries) * n].reshape(len(entries), n)
        if located or k < ROW_PIECES:
            if not located and k > 1:
                slot = np.repeat(slot, k)
            self._linear(np.take(table, slot, axis=1, mode="clip"), entries, xf, y, ws.f2[:n])
        else:
            rows = np.take(table, slot, axis=1, mode="clip")[:, :, None]   # (entries, pieces, 1)
            self._linear(rows, entries, x, y.reshape(len(entries), g, k), ws.f2[:n].reshape(g, k))
        origins = y[0:3].T
        tfar = ws.tfar[:n]
        below = ws.below[:n]
        weight = None
        if not curved:
            directions = y[3:6].T
            below.fill(False)  # the shading hemisphere is the face's own
            tfar.fill(self.reach)
            if self.uniform:
                weight = 2.0 * xf[5]                                     # 2 cos(theta), uniform hemisphere
        else:
            length, tmp = ws.f1[:n], ws.f2[:n]
            dirs = ws.dirs[:3 * n].reshape(3, n)
            directions = dirs.T
            if not self.uniform:
                smooth_cosine_rays(y, self.reach, dirs, tfar, below, length, tmp, ws.f3[:n])
            else:
                _normal_lengths(y, length, tmp)
                nx, ny, nz = y[3], y[4], y[5]
                nv = nx * y[6]
                nv += ny * y[7]
                nv += nz * y[8]
                side = np.where(nv < 0, np.float32(-1), np.float32(1))
                for c in range(3):
                    np.multiply(y[6 + c], side, out=dirs[c])
                np.multiply(y[10], side, out=tmp)
                np.less_equal(tmp, 0, out=below)
                weight = 2.0 * np.abs(nv) / np.maximum(length, 1e-30)
                tfar.fill(self.reach)
                tfar[below] = 0.0
        if tile.inward:
            # Into the mesh: -w is distributed about -n as w is about n (both warps are symmetric),
            # and -w . (-gn) = w . gn, so ``below`` (a direction leaving through the surface) holds.
            np.negative(directions, out=directions)
        traced_tfar = tfar.copy() if self.on_rays is not None else None
        clock = Clock()
        touch = None
        near = tile.contact[tex]
        with clock:
            if self.tracer.simple:
                hit = self.tracer.occluded(origins, directions, tfar)
                value = hit | below
                np.logical_not(value, out=value)
            else:
                value = self.tracer.visibility(origins, directions, tfar)
                hit = value < 1.0
            if near.any():
                # Samples where another object's face lies on the surface are occluded (see Tracer).
                sel = np.flatnonzero(np.repeat(near, k))
                if located:
                    row = tile.loc_pos[tri_s[sel]]
                    gn, eps = tile.loc_gn[row], tile.loc_eps[row]
                else:
                    row = np.searchsorted(tile.tris, units.tri[unit[sel // k]])
                    gn, eps = tile.gn[row], tile.eps[row]
                touch = self.tracer.contact(offset_points(origins[sel], gn, -eps), gn, eps)
        if touch is not None and touch.any():
            value[sel[touch]] = 0
        if tile.blocked is not None:
            stuck = np.take(tile.blocked, unit)
            if stuck.any():
                value.reshape(g, k)[stuck] = 0
        if vectors is not None:
            _direction_sums(directions, value, weight, g, k, vectors)
        if self.on_rays is not None:
            if blocks is not None:
                samples = np.concatenate([self.pattern.block_samples(e, o, f, b) for f, (_, b, _) in zip(firsts, blocks)],
                                         axis=1).ravel()
            else:
                samples = (self.pattern.block_samples(e, o, first, k) if not self.pattern.xor
                           else start[:, None] + ws.ramp[None, :k]).ravel()
            texels = np.repeat(tile.texel_ids[tex], k)
            # One batch per replicate; a call's time is shared among them by their rays.
            for r in ([0] if replicates is None else np.unique(replicates)):
                rows = slice(None) if replicates is None else np.repeat(replicates == r, k)
                share = 1.0 if replicates is None else np.count_nonzero(replicates == r) / g
                self.on_rays(RayBatch(origins=origins[rows], directions=directions[rows], tfar=traced_tfar[rows],
                                      occluded=hit[rows], texels=texels[rows], samples=samples[rows],
                                      seconds=clock.wall * share, cpu_seconds=clock.cpu * share,
                                      replicate=int(r)))
        s1, s2 = piece_sums(value, weight, g, k)
        return s1, s2, n, clock.wall, clock.cpu


    def _gather(self, ws, keys, kt, e, o, curved, start, k, g, n):
        """The feature planes x (6, g, k) of the pieces' samples, in this thread's workspace: the
        texel-shifted position (u2, u3) in [0, 1) as planes 0, 1, the constant 1, and the lifted
        direction features of (u0, u1) (``curved``: the sphere form). Returns (xf, x, blocks, firsts,
        first): the planes flat and by piece, and how the samples were addressed (for ``on_rays``)."""
        # Feature planes of the pieces' samples: x[j] (g, k) is feature j of every sample, each
        # plane contiguous (numpy's passes over a column of (n, 6) rows cost 2-4 times as much, and
        # a piece's (6, k) planes are one matrix for BLAS, rows n apart). Xor-ordered patterns map
        # an aligned power-of-two block of samples onto consecutive pool rows (in another order),
        # whole rows of a (rows / size, size) view of each plane: a call whose pieces all start at
        # the same sample takes its samples as such blocks (a piece of 56 from sample 8: blocks of
        # 8, 16 and 32), others go sample by sample. Plane 2 is the constant 1.
        first = firsts = None
        feats = self.pattern.feature_planes(self.kinds[curved])
        xf = ws.x[:6 * n].reshape(6, n)
        xf[2].fill(1.0)
        x = xf.reshape(6, g, k)
        blocks = None
        if self.pattern.xor:
            if (k & (k - 1)) == 0 and not np.any(start & (k - 1)):
                blocks = [(0, k, start)]
            elif g and np.all(start == start[0]):
                _, b_start, b_size = aligned_pieces(np.zeros(1, np.int64), start[:1], np.array([k]))
                blocks = [(int(s0 - start[0]), int(z), int(s0)) for s0, z in zip(b_start, b_size)]
        if blocks is not None:
            firsts = []
            for at, size_b, start_b in blocks:
                first_b = self.pattern.block_rows(e, o, start_b, size_b)
                firsts.append(first_b)
                block = first_b // size_b
                for j in _VARYING:
                    rows = feats[j].reshape(-1, size_b)
                    if size_b == k:
                        np.take(rows, block, axis=0, out=x[j], mode="clip")
                    else:
                        x[j, :, at:at + size_b] = np.take(rows, block, axis=0, mode="clip")
        else:
            first = self.pattern.block_rows(e, o, start, k)
            idx = ws.idx[:n].reshape(g, k)
            if self.pattern.xor:  # rows in index order
                np.add(start[:, None], ws.ramp[None, :k], out=idx)
                idx ^= o[:, None]
                idx += (e * self.pattern.span)[:, None]
            else:
                np.add(first[:, None], ws.ramp[None, :k], out=idx)
            for j in _VARYING:
                np.take(feats[j], idx.reshape(n), out=xf[j], mode="clip")
        xu = xf.view(np.uint32).reshape(6, g, k)
        a, b = x[0], x[1]
        for c, dst in ((0, a), (1, b)):
            # The texel's shift of the position coordinate, in place, then to [0, 1) in float32.
            # Gathered column by column: numpy's gather of (2,) rows costs 5 times as much.
            self.pattern.shift_positions(xu[c], _per_piece(keys.shift[:, c][kt], k))
            np.copyto(dst, xu[c], casting="unsafe")
            dst *= np.float32(2.0 ** -32)
        return xf, x, blocks, firsts, first

    @staticmethod
    def _texel_space(tile, unit, x, k, squares, located):
        """Positions (planes 0, 1 of ``x``) from the unit square to each piece's texel space, in place:
        a translation for squares, Heitz's map and the piece's corners for pieces of triangles
        (located samples have moved already)."""
        a, b = x[0], x[1]
        g = len(unit)
        sq = slice(0, squares)
        if not located:  # the squares' translations, two planes of tile.coef_planes gathered
            a[sq] += _per_piece(np.take(tile.coef_planes[0], unit[sq]), k)
            b[sq] += _per_piece(np.take(tile.coef_planes[3], unit[sq]), k)
        if squares < g:
            tr = slice(squares, g)
            u, v = warps.square_to_triangle(a[tr], b[tr])
            ct = np.take(tile.coef_planes, unit[tr], axis=1)
            a[tr] = _per_piece(ct[0], k) + _per_piece(ct[1], k) * u + _per_piece(ct[2], k) * v
            b[tr] = _per_piece(ct[3], k) + _per_piece(ct[4], k) * u + _per_piece(ct[5], k) * v

    def positions(self, tile, unit, start, size, squares, replicates=None):
        """The texel-space positions (a, b), float64 (pieces, size), of samples ``start`` .. of each
        piece's unit, as :meth:`run` places them (not located units): what a stage that moves sample
        points elsewhere (:mod:`core.highpoly`) starts from."""
        units, keys = tile.units, tile.keys
        g, k = len(unit), int(size)
        n = g * k
        ws = self._workspace(n)
        tex = units.texel[unit]
        kt = tex if replicates is None else tex + replicates * tile.texels
        x = self._gather(ws, keys, kt, keys.pattern[kt], keys.order[kt], False, start, k, g, n)[1]
        self._texel_space(tile, unit, x, k, squares, False)
        return x[0].astype(np.float64), x[1].astype(np.float64)
    @staticmethod
    def _linear(entries_of, entries, x, y, tmp):
        """Y = X M as planes: ``y[c]`` (output column c) from the feature planes ``x[j]`` and the
        matrices' nonzero entries ``entries_of`` (entries, ...), which broadcast against a plane
        (one row per ray, or per piece over its samples): the same operations either way."""
        i = 0
        for c, rows in entries:
            out = y[c]
            if rows[0] == 2:  # position: M[2] + a M[0] + b M[1]
                np.multiply(x[0], entries_of[i + 1], out=out)
                out += entries_of[i]
                np.multiply(x[1], entries_of[i + 2], out=tmp)
                out += tmp
            else:  # direction: f0 M[3] + f1 M[4] + f2 M[5]
                np.multiply(x[3], entries_of[i], out=out)
                np.multiply(x[4], entries_of[i + 1], out=tmp)
                out += tmp
                np.multiply(x[5], entries_of[i + 2], out=tmp)
                out += tmp
            i += 3

    @staticmethod
    def _locate(units, unit, x, k):
        """Each sample's candidate among its located texel's (an index into the texel's run, (g, k)),
        at its texel-local position (a, b) = x[0:2] (x: (6, g, k) feature planes): the
        candidate whose least edge function there is largest (the one containing the point; the
        first of equals). Every piece of the call has the same number of candidates (the baker
        groups them so), so each piece's arithmetic does not depend on the others."""
        g = len(unit)
        first = units.cand_first[unit]
        m = int(units.cand_first[unit[0] + 1] - first[0])
        if m == 1:
            return np.zeros((g, k), np.int64)
        # Candidate by candidate over the samples, elementwise (the same rounding on every numpy
        # line and CPU, as the kernel's product): a short piece's edge values repeated per sample,
        # a long piece's broadcast over its samples.
        best = np.zeros((g, k), np.int64)
        short = k < ROW_PIECES
        a = x[0].reshape(-1) if short else x[0]
        b = x[1].reshape(-1) if short else x[1]
        best_d = None
        for c in range(m):
            e = units.cand_edges[first + c]
            if short and k > 1:
                e = np.repeat(e, k, axis=0)
            d = None
            for j in range(3):
                e0, e1, e2 = e[:, j, 0], e[:, j, 1], e[:, j, 2]
                if not short:
                    e0, e1, e2 = e0[:, None], e1[:, None], e2[:, None]
                v = e0 * a
                v += e1 * b
                v += e2
                d = v if d is None else np.minimum(d, v, out=d)
            if best_d is None:
                best_d = d
            else:
                better = d > best_d
                best.reshape(-1)[better.reshape(-1)] = c
                np.maximum(best_d, d, out=best_d)
        return best


def _normal_lengths(y, length, tmp):
    """|n| of the interpolated normals, output planes 3-5, into ``length``."""
    np.multiply(y[3], y[3], out=length)
    np.multiply(y[4], y[4], out=tmp)
    length += tmp
    np.multiply(y[5], y[5], out=tmp)
    length += tmp
    np.sqrt(length, out=length)


def smooth_cosine_rays(y, reach, dirs, tfar, below, length, tmp, size2):
    """The rays of smooth-shaded samples with cosine directions, from the output planes ``y`` of
    their map (origin, interpolated normal n, sphere point v, n . gn, v . gn): each direction
    |n| (n / |n| + v), cosine-distributed about the sample's own normal, into the planes ``dirs``;
    its length ``tfar`` in units of the direction (``reach`` long; 0 where the direction points
    below the geometric surface, which ``below`` marks). ``length``, ``tmp`` and ``size2`` are
    scratch planes (``length`` ends as |n|)."""
    _normal_lengths(y, length, tmp)
    size2.fill(0)
    for c in range(3):
        dc = dirs[c]
        np.multiply(y[6 + c], length, out=dc)
        dc += y[3 + c]
        np.multiply(dc, dc, out=tmp)
        size2 += tmp
    np.multiply(y[10], length, out=tmp)
    tmp += y[9]
    np.less_equal(tmp, 0, out=below)
    below |= size2 < 1e-20
    if reach < FAR:
        # Ray lengths are in units of the direction, which is not unit length here.
        np.sqrt(size2, out=tfar)
        np.maximum(tfar, np.float32(reach / FAR), out=tfar)  # at most FAR long
        np.divide(np.float32(reach), tfar, out=tfar)
    else:
        tfar.fill(FAR)
    tfar[below] = 0.0


def _direction_sums(directions, value, weight, g, k, out):
    """Per piece of ``k`` samples, the sum of the unit directions weighted by the samples' terms."""
    d = directions.astype(np.float64)
    d /= np.maximum(np.sqrt(np.einsum("ij,ij->i", d, d)), 1e-300)[:, None]
    d *= sample_terms(value, weight)[:, None]
    out[...] = d.reshape(g, k, 3).sum(axis=1)


class _Workspace:
    """Buffers for up to ``n`` rays (see :meth:`Kernel._workspace`)."""

    def __init__(self, n):
        self.n = n
        self.ramp = np.arange(n, dtype=np.int64)
        self.idx = np.empty(n, np.int64)
        self.x = np.empty(6 * n, np.float32)                  # feature planes
        self.y = np.empty(len(CURVED_ENTRIES) * n, np.float32)  # output planes
        self.tfar = np.empty(n, np.float32)
        self.below = np.empty(n, bool)
        self.dirs = np.empty(3 * n, np.float32)              # direction planes
        self.f1 = np.empty(n, np.float32)
        self.f2 = np.empty(n, np.float32)
        self.f3 = np.empty(n, np.float32)


__all__ = ["Kernel", "TileContext", "triangle_matrices", "FLAT_COLUMNS", "CURVED_COLUMNS"]
