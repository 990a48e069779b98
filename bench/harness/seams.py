"""Fix Seams: the bilinear lookups on both sides of every UV seam, their mismatch, and the
least-squares pass that makes them agree (numpy only).

How Blender shows a baked image (Image Texture node, Linear interpolation, the default): a lookup at
``uv`` reads the four texels around ``x = u * W - 0.5``, ``y = v * H - 0.5`` (texel centres at
``(j + 0.5) / W``, row 0 at v = 0) with weights ``(1 - fx)(1 - fy)`` ... from the fractions of x and
y, and wraps at the image's border as the node's Extension says ('REPEAT', the default: column -1 is
column W - 1; 'EXTEND' clamps). Cycles does exactly this (``interp_linear`` in
intern/cycles/kernel/device/cpu/image.h; an 8-bit texel reads as byte / 255); the viewport's GPU
sampler does the same at full resolution, on an 8-bit Non-Color image as the bytes / 255 and on a
float image as half floats (imb_gpu_get_format in source/blender/imbuf/intern/util_gpu.cc; an sRGB
8-bit image would be decoded to linear before filtering, which an AO map, Non-Color, never is). A
UDIM image is one such image per tile, the tile chosen by the point's ``floor(u), floor(v)``.

A seam is a mesh edge shared in space by exactly two triangles whose UVs differ along it (or, in a
UDIM image, that lie in different tiles). Both sides are the same surface points, so both lookups
should give the same value; they do not, because they read different texels, and the texels on an
island's border mix in the margin beyond it. The mismatch of a seam point is the difference of its
two lookups; :class:`SeamLookups` holds them as rows of a sparse matrix (four texels a side), so
that the mismatch of an image is one product, and :func:`fix_seams` solves for the texels that make
it small.
"""

import math
from dataclasses import dataclass

import numpy as np

#: Points per texel of a seam edge's length (the longer of its two sides in the image): every
#: bilinear cell the edge crosses holds several, so the sum over points stands for the integral
#: of the squared mismatch along the edge.
POINTS_PER_TEXEL = 4
WRAPS = ("repeat", "extend")
#: Seam points made at a time (their temporaries are a few hundred bytes each).
CHUNK = 1 << 15
#: A seam edge is a crease where the two sides' shading normals at one of its ends differ by more
#: than this (degrees): a sharp edge, split normals, flat faces meeting at an angle. Blender's smooth
#: shading gives both sides one normal (to the last bits); AO is a function of the point and the
#: normal, so only there must both sides agree.
SMOOTH_ANGLE = 1.0
FIRST_TILE = 1001


@dataclass
class SeamLookups:
    """The pairs of bilinear lookups of the points along every seam edge of one or more meshes.

    shape : (N, H, W), the planes the texel indices address: one image (N = 1) or N UDIM tiles,
        in the order of ``tiles``.
    index : (K, 8) int32 (int64 from 2^31 texels), flat texel indices into the N * H * W planes: the four texels side A's
        lookup reads, then side B's.
    weight : (K, 8) float64, their bilinear weights, side B's negated: a row times the texel values
        is lookup A - lookup B.
    length : (K,) float64, the length of seam (texels, the longer side's) each point stands for.
    edge : (K,) int64, the seam edge each point lies on (0 .. edges - 1).
    target : (K,) int32, the mesh (of those given) the point belongs to.
    triangle : (K, 2) int64, the point's triangle on side A and on side B (of its mesh).
    uv : (K, 2, 2) float64, the point's UV coordinates on side A and on side B.
    crease : (K,) bool, the point lies on a crease: the shading normals of the two sides differ
        there (by more than SMOOTH_ANGLE degrees at an end of its edge), so the AO may differ too
        and the fix leaves the point alone (the seam is what lets the map show the crease).
    tiles : None (one image) or the UDIM tile numbers of the planes.
    wrap : how lookups wrap at the image's (each tile's) border.
    """

    shape: tuple
    index: np.ndarray
    weight: np.ndarray
    length: np.ndarray
    edge: np.ndarray
    target: np.ndarray
    edges: int
    triangle: np.ndarray = None
    uv: np.ndarray = None
    crease: np.ndarray = None
    tiles: tuple = None
    wrap: str = "repeat"

    @property
    def points(self):
        return len(self.index)

    def subset(self, which):
        """The lookups of the points ``which`` (a boolean mask or indices) alone."""
        fields = ("index", "weight", "length", "edge", "target", "triangle", "uv", "crease")
        return SeamLookups(shape=self.shape, edges=self.edges, tiles=self.tiles, wrap=self.wrap,
                           **{f: getattr(self, f)[which] for f in fields})

    def difference(self, planes):
        """Lookup A - lookup B at every point (K,) float64, of ``planes`` ((N, H, W), or (H, W) for
        one image)."""
        flat = np.asarray(planes).reshape(-1)
        if flat.size != int(np.prod(self.shape)):
            raise ValueError(f"planes of {flat.size} texels; the lookups address {self.shape}")
        vals = flat[self.index].astype(np.float64)
        return np.einsum("kj,kj->k", vals, self.weight)

    def mismatch(self, planes, creases=True):
        """The mean |lookup A - lookup B| over every seam point (``creases`` False: over the smooth
        ones, those the fix makes agree): what a user sees as the seam."""
        d = self.difference(planes)
        if not creases:
            d = d[~self.crease]
        return float(np.mean(np.abs(d))) if len(d) else 0.0


def _weld(positions):
    """Per vertex, one index per distinct position (meshes split at seams still join there)."""
    return np.unique(np.asarray(positions), axis=0, return_inverse=True)[1].reshape(-1)


def _valid(mesh):
    """Triangles with area in space and in the UV map (the ones a bake covers)."""
    uv = np.asarray(mesh.uvs, np.float64)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    return (np.abs(det) > 0) & (np.asarray(mesh.areas) > 0)


def seam_edges(mesh):
    """The mesh's manifold edges: (tA, kA, tB, kB, same) arrays, one entry per edge shared in space
    (vertices welded by position) by exactly two valid triangles: triangle tA's edge from corner kA
    to kA + 1 is triangle tB's edge from corner kB to kB + 1 (``same``) or from kB + 1 to kB."""
    valid = _valid(mesh)
    weld = _weld(mesh.positions)
    tri = np.flatnonzero(valid)
    v = weld[np.asarray(mesh.triangles)[tri]]
    t = np.repeat(tri, 3)
    k = np.tile(np.arange(3), len(tri))
    a, b = v.reshape(-1), v[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(a, b).astype(np.int64) * (int(weld.max()) + 1 if len(weld) else 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    t, k, a, key = t[order], k[order], a[order], key[order]
    start = np.ones(len(key), bool)
    start[1:] = key[1:] != key[:-1]
    gid = np.cumsum(start) - 1
    size = np.bincount(gid)
    i = np.flatnonzero(start & (size[gid] == 2))
    i = i[t[i] != t[i + 1]]
    return t[i], k[i], t[i + 1], k[i + 1], a[i] == a[i + 1]


def _tile_of(uv, inward, tiles):
    """(plane index (K,), or -1 for a point in no listed tile; the tile's (u, v) origin (K, 2)) of
    points ``uv`` on a triangle edge, the tile taken a hair inside the triangle (towards
    ``inward``), as a renderer's lookup just inside that triangle finds it."""
    nudged = uv + 1e-7 * (inward - uv)
    origin = np.floor(nudged)
    number = FIRST_TILE + origin[:, 0] + 10 * origin[:, 1]
    ok = (origin[:, 0] >= 0) & (origin[:, 0] < 10) & (origin[:, 1] >= 0)
    tiles = np.asarray(tiles, np.int64)
    pos = np.searchsorted(tiles, number)
    pos = np.minimum(pos, len(tiles) - 1)
    ok &= tiles[pos] == number
    return np.where(ok, pos, -1), origin


def _bilinear(uv, width, height, wrap):
    """(rows (K, 4), columns (K, 4), weights (K, 4)) of a Linear lookup at ``uv`` (in one image or
    tile, coordinates from its own origin)."""
    x = uv[:, 0] * width - 0.5
    y = uv[:, 1] * height - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    cols = np.stack([x0, x0 + 1, x0, x0 + 1], axis=1)
    rows = np.stack([y0, y0, y0 + 1, y0 + 1], axis=1)
    if wrap == "repeat":
        cols, rows = np.mod(cols, width), np.mod(rows, height)
    else:
        cols, rows = np.clip(cols, 0, width - 1), np.clip(rows, 0, height - 1)
    w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1)
    return rows, cols, w


def seam_lookups(meshes, resolution, tiles=None, wrap="repeat", points_per_texel=POINTS_PER_TEXEL):
    """The seam points of ``meshes`` (one core.Mesh or a list: the targets of one image) and their
    two bilinear lookups in a ``resolution`` image.

    Parameters
    ----------
    meshes : core.Mesh with UVs, or a list of them (an atlas: each its own seams).
    resolution : int or (width, height) of the image (of each UDIM tile).
    tiles : None: one image, UVs looked up as they are (wrapping outside [0, 1]); or UDIM tile
        numbers: one plane per tile in this order, each point looked up in its own tile.
    wrap : 'repeat' (the Image Texture node's default Extension) or 'extend'.

    Returns
    -------
    SeamLookups
    """
    if isinstance(resolution, (int, np.integer)):
        resolution = (int(resolution), int(resolution))
    w, h = int(resolution[0]), int(resolution[1])
    if wrap not in WRAPS:
        raise ValueError(f"wrap must be one of {WRAPS}, got {wrap!r}")
    if not isinstance(meshes, (list, tuple)):
        meshes = [meshes]
    tiles = None if tiles is None else tuple(sorted(int(t) for t in tiles))
    n_planes = 1 if tiles is None else len(tiles)
    itype = np.int32 if n_planes * h * w < 2 ** 31 else np.int64
    scale = np.array([w, h], np.float64)
    per_mesh = []
    for mesh in meshes:
        uv = np.asarray(mesh.uvs, np.float64)
        tA, kA, tB, kB, same = seam_edges(mesh)
        nrm = mesh.corner_normals()
        kB0 = np.where(same, kB, (kB + 1) % 3)  # B's corner at A's corner kA
        kB1 = np.where(same, (kB + 1) % 3, kB)
        cos = math.cos(math.radians(SMOOTH_ANGLE))
        crease = ((np.einsum("ij,ij->i", nrm[tA, kA], nrm[tB, kB0]) < cos)
                  | (np.einsum("ij,ij->i", nrm[tA, (kA + 1) % 3], nrm[tB, kB1]) < cos))
        a0, a1 = uv[tA, kA], uv[tA, (kA + 1) % 3]
        b0 = np.where(same[:, None], uv[tB, kB], uv[tB, (kB + 1) % 3])
        b1 = np.where(same[:, None], uv[tB, (kB + 1) % 3], uv[tB, kB])
        cA, cB = uv[tA].mean(axis=1), uv[tB].mean(axis=1)
        differ = np.any(a0 != b0, axis=1) | np.any(a1 != b1, axis=1)
        if tiles is not None:  # the same UVs in two tiles: a tile border, looked up in each tile
            differ |= np.any(np.floor(cA) != np.floor(cB), axis=1)
        sel = np.flatnonzero(differ)
        length = np.maximum(np.hypot(*((a1 - a0)[sel] * scale).T), np.hypot(*((b1 - b0)[sel] * scale).T))
        n = np.maximum(1, np.ceil(points_per_texel * length)).astype(np.int64)
        per_mesh.append((a0[sel], a1[sel], b0[sel], b1[sel], cA[sel], cB[sel], np.stack([tA[sel], tB[sel]], 1),
                         crease[sel], length, n))
    total = sum(int(m[-1].sum()) for m in per_mesh)
    out = dict(index=np.empty((total, 8), itype), weight=np.empty((total, 8)), length=np.empty(total),
               edge=np.empty(total, np.int64), target=np.empty(total, np.int32),
               triangle=np.empty((total, 2), np.int64), uv=np.empty((total, 2, 2)), crease=np.empty(total, bool))
    at = edges = 0
    for m_i, (a0, a1, b0, b1, cA, cB, tris, crease, length, n) in enumerate(per_mesh):
        # Edges in slices of about CHUNK points: the temporaries stay small whatever the image.
        ends = np.searchsorted(np.cumsum(n), np.arange(CHUNK, int(n.sum()) + CHUNK, CHUNK), side="right")
        lo = 0
        for hi in np.unique(np.append(ends, len(n))):
            if hi <= lo:
                continue
            sl = slice(lo, hi)
            e = np.repeat(np.arange(lo, hi), n[sl])
            first = np.cumsum(n[sl]) - n[sl]
            t = ((np.arange(len(e)) - first[e - lo]) + 0.5) / n[e]
            keep = np.ones(len(e), bool)
            sides = []
            for p0, p1, c, sign in ((a0, a1, cA, 1.0), (b0, b1, cB, -1.0)):
                p = p0[e] + t[:, None] * (p1 - p0)[e]
                if tiles is None:
                    plane, local = np.zeros(len(p), np.int64), p
                else:
                    plane, origin = _tile_of(p, c[e], tiles)
                    keep &= plane >= 0
                    local = p - origin
                rows, cols, bw = _bilinear(local, w, h, wrap)
                sides.append((p, (np.maximum(plane, 0)[:, None] * h + rows) * w + cols, sign * bw))
            k = int(keep.sum())
            dst = slice(at, at + k)
            for j, (p, idx, bw) in enumerate(sides):
                out["index"][dst, 4 * j:4 * j + 4] = idx[keep]
                out["weight"][dst, 4 * j:4 * j + 4] = bw[keep]
                out["uv"][dst, j] = p[keep]
            out["length"][dst] = (length / n)[e][keep]
            out["edge"][dst] = (e + edges)[keep]
            out["target"][dst] = m_i
            out["triangle"][dst] = tris[e][keep]
            out["crease"][dst] = crease[e][keep]
            at += k
            lo = hi
        edges += len(n)
    if at < total:  # points in no listed tile
        out = {key: v[:at].copy() for key, v in out.items()}
    return SeamLookups(shape=(n_planes, h, w), edges=edges, tiles=tiles, wrap=wrap, **out)


def seam_mismatch(meshes, image, tiles=None, wrap="repeat"):
    """The mean |lookup A - lookup B| over the seam points of ``meshes`` in ``image`` ((H, W), or
    (N, H, W) UDIM tiles in the order of ``tiles``)."""
    image = np.asarray(image)
    h, w = image.shape[-2:]
    return seam_lookups(meshes, (w, h), tiles=tiles, wrap=wrap).mismatch(image)


# --- the least-squares fix -------------------------------------------------------------------------

#: Weight of the squared mismatch per texel of seam length, in units of the squared error of a
#: typical texel (the median standard error of the covered texels the fix may change).
SEAM_WEIGHT = 100.0
#: Weight that keeps a margin (or empty) texel near its value, in the same units: small, so that the
#: margin takes the seam's correction first (it holds no estimate of its own).
MARGIN_WEIGHT = 1e-2
#: Conjugate gradients stop when the preconditioned residual has fallen by this factor, or after
#: MAX_ITERATIONS.
TOLERANCE = 1e-6
MAX_ITERATIONS = 2000
#: Solves at most, each holding the texels the last one took past the value range at its bound.
BOUND_ROUNDS = 4


def _dot(a, b):
    # numpy's pairwise sum, not BLAS: the same bits for any BLAS thread count.
    return float(np.add.reduce(a * b))


@dataclass
class SeamFix:
    """What :func:`fix_seams` did: texels (flat indices it changed the values of), iterations,
    residual (the preconditioned residual's norm over the initial one), before and after (the
    mismatch of the lookups at smooth seams, those it makes agree), unknowns (texels it solved
    for)."""

    texels: np.ndarray
    iterations: int
    residual: float
    before: float
    after: float
    unknowns: int
    rounds: int = 1


class _System:
    """The normal equations of the fix over its unknowns (see :func:`fix_seams`), in units of s_ref^2:
    A x = b, A = D + C^T diag(lam) C, applied without forming A. C is kept as its eight columns of
    (K,) weights and unknown indices (contiguous; each product a sum of eight gathers, each
    transpose eight bincounts added in order), so no (K, 8) temporary is made per iteration."""

    def __init__(self, flat_v, flat_s, flat_m, lookups, owner, seam_weight, margin_weight, pinned=None):
        touched, pos = np.unique(lookups.index.T, return_inverse=True)  # pos: (8, K), column by column
        it = np.int32 if len(touched) < 2 ** 31 else np.int64
        pos = pos.reshape(8, -1).astype(it)
        y = flat_v[touched].astype(np.float64)
        s = flat_s[touched].astype(np.float64)
        covered = flat_m[touched]
        free = ~(covered & (s <= 0))
        if owner is not None:
            own = np.asarray(owner).reshape(-1)[touched]
            for j in range(8):
                other = (own[pos[j]] >= 0) & (own[pos[j]] != lookups.target)
                free[pos[j][other]] = False
        self.solvable = free.copy()  # before any texel is pinned at a bound
        if pinned is not None:  # (positions among the touched texels, the values they are held at)
            free[pinned[0]] = False
            y[pinned[0]] = pinned[1]
        self.touched, self.free = touched, free
        self.n = n = int(free.sum())
        fi = (np.cumsum(free) - 1).astype(it)  # index among the unknowns
        cov_free = covered & free
        self.s_ref = s_ref = float(np.median(s[cov_free])) if cov_free.any() else 1.0
        self.covered = covered[free]
        self.s = s[free]
        self.d = np.where(covered, (s_ref / np.where(s > 0, s, s_ref)) ** 2, margin_weight)[free]
        self.lam = seam_weight * lookups.length
        self.c = np.empty((8, len(self.lam)))
        self.col = np.empty((8, len(self.lam)), it)
        g = np.zeros(len(self.lam))  # the held texels' part of each difference
        for j in range(8):
            var = free[pos[j]]
            w = lookups.weight[:, j]
            self.c[j] = np.where(var, w, 0.0)
            self.col[j] = np.where(var, fi[pos[j]], 0)
            g += np.where(var, 0.0, w) * y[pos[j]]
        del pos
        self.y = y[free]
        self.b = self.d * self.y - self.ctr(self.lam * g)
        self.diag = self.d.copy()
        for j in range(8):
            self.diag += np.bincount(self.col[j], weights=self.lam * self.c[j] * self.c[j], minlength=n)

    def cx(self, x):
        out = self.c[0] * x[self.col[0]]
        for j in range(1, 8):
            out += self.c[j] * x[self.col[j]]
        return out

    def ctr(self, r):
        out = np.bincount(self.col[0], weights=self.c[0] * r, minlength=self.n)
        for j in range(1, 8):
            out += np.bincount(self.col[j], weights=self.c[j] * r, minlength=self.n)
        return out

    def apply(self, x):
        return self.d * x + self.ctr(self.lam * self.cx(x))

    def solve(self, b, x, tolerance, max_iterations, start=None):
        """Preconditioned conjugate gradients from ``x`` (changed in place), until the preconditioned
        residual r' M^-1 r is ``tolerance``^2 of ``start`` (None: of its own at ``x``):
        (x, iterations, residual / start, start)."""
        r = b - self.apply(x)
        z = r / self.diag
        p = z.copy()
        rz = _dot(r, z)
        rz0 = rz if start is None else start
        it = 0
        while it < max_iterations and rz > (tolerance ** 2) * rz0 and rz > 0:
            q = self.apply(p)
            alpha = rz / _dot(p, q)
            x += alpha * p
            r -= alpha * q
            z = r / self.diag
            rz_new = _dot(r, z)
            p *= rz_new / rz
            p += z
            rz = rz_new
            it += 1
        return x, it, math.sqrt(rz / rz0) if rz0 > 0 else 0.0, rz0


def fix_seams(values, stderr, mask, lookups, *, owner=None, value_range=(0.0, 1.0), seam_weight=SEAM_WEIGHT,
              margin_weight=MARGIN_WEIGHT, tolerance=TOLERANCE, max_iterations=MAX_ITERATIONS, out=None,
              stderr_out=None):
    """Adjust the texels the seam lookups read so that both sides of every seam agree.

    Minimises, over the texels x that the lookups read (the others stay bit-equal),

        sum_points seam_weight * length_k * (lookup_A(x) - lookup_B(x))^2 / s_ref^2
        + sum_covered (x_i - y_i)^2 / s_i^2 + sum_margin margin_weight * (x_i - y_i)^2 / s_ref^2

    with y the baked values, s_i each covered texel's standard error and s_ref their median: a
    texel moves in proportion to its error, a margin texel freely. Points on creases (see
    :class:`SeamLookups`) take no part: the AO may differ across them. Covered texels with no error
    (exactly open or occluded) are held, as are texels ``owner`` gives to another target than the
    lookup's. Solved by conjugate gradients with a Jacobi preconditioner, in float64, in a fixed
    order (the same bits for any threads); the result is clipped to ``value_range``. The error of a
    covered texel the fix changed by d becomes sqrt(s_i^2 + d^2), never less than its mean squared
    error: the fix's noise is at most the estimate's, and d estimates the bias it adds without bias.

    Parameters
    ----------
    values, stderr, mask : (H, W) or (N, H, W) arrays (one channel): the map, its standard error,
        the covered texels.
    lookups : SeamLookups of the same shape.
    owner : None, or (H, W) / (N, H, W) int: the target owning each texel (-1: none); a texel
        owned by another target than a lookup's is held.
    out, stderr_out : arrays to write the fixed map and error into (may be ``values`` and
        ``stderr`` themselves); None: copies.

    Returns
    -------
    (fixed values, its stderr, SeamFix)
    """
    values = np.asarray(values)
    out = values.copy() if out is None else out
    if out is not values:
        np.copyto(out, values)
    stderr = np.asarray(stderr)
    se_out = stderr.copy() if stderr_out is None else stderr_out
    if se_out is not stderr:
        np.copyto(se_out, stderr)
    if lookups.crease is not None and lookups.crease.any():
        lookups = lookups.subset(~lookups.crease)
    before = lookups.mismatch(values)
    none = SeamFix(np.zeros(0, np.int64), 0, 0.0, before, before, 0)
    if not lookups.points:
        return out, se_out, none
    flat = values.reshape(-1), stderr.reshape(-1), np.asarray(mask).reshape(-1)
    lo, hi = value_range
    # Bounds by an active set: texels the solution takes past a bound are held there and the rest
    # solved again (from where they were), until none crosses or BOUND_ROUNDS have been solved.
    pinned, total, start = None, 0, None
    sys_ = None
    for round_ in range(BOUND_ROUNDS):
        sys_ = None  # the last round's system goes before the next is built
        sys_ = _System(*flat, lookups, owner, seam_weight, margin_weight, pinned)
        if round_ == 0:
            if sys_.n == 0:
                return out, se_out, none
            y0, solvable = flat[0][sys_.touched].astype(np.float64), sys_.solvable
            current = y0.copy()
        # From where the texels are, to the first solve's residual times the tolerance.
        x, it, res, start = sys_.solve(sys_.b, current[sys_.free], tolerance, max_iterations, start)
        total += it
        current[sys_.free] = x
        cross = np.flatnonzero(sys_.free)[(x < lo) | (x > hi)]
        if not len(cross):
            break
        held = np.clip(current[cross], lo, hi)
        current[cross] = held
        pinned = (cross, held) if pinned is None else (np.concatenate([pinned[0], cross]),
                                                      np.concatenate([pinned[1], held]))
    current = np.clip(current, lo, hi)
    texels = sys_.touched[solvable]
    new = current[solvable].astype(out.dtype)
    out.reshape(-1)[texels] = new
    # The error of a changed covered texel: its noise is at most the estimate's (A >= D, so the
    # fixed value's variance diag(A^-1 D A^-1) <= diag(A^-1) <= s_i^2), and the change d = x - y is
    # an unbiased estimate of the bias the fix adds (E[x] - t = E[x - y]), so
    # E[s_i^2 + d_i^2] = s_i^2 + bias^2 + var(d_i) >= the fixed value's mean squared error.
    cov = flat[2][texels]
    s0 = flat[1][texels[cov]].astype(np.float64)
    d = new[cov].astype(np.float64) - y0[solvable][cov]
    se_out.reshape(-1)[texels[cov]] = np.sqrt(s0 ** 2 + d * d).astype(se_out.dtype)
    after = lookups.mismatch(out)
    return out, se_out, SeamFix(texels, total, res, before, after, int(solvable.sum()), round_ + 1)
