"""UV seams as Blender shows them: the bilinear lookups on both sides of every seam edge, and their
mismatch (the least-squares fix that makes them agree is :mod:`core.post.fixseams`).

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
that the mismatch of an image is one product, and :func:`core.post.fixseams.fix_seams` solves for
the texels that make it small.
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
    weight : (K, 8) float32, their bilinear weights, side B's negated: a row times the texel values
        is lookup A - lookup B (float32 as Blender's own lookup computes them).
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
                           **{f: None if getattr(self, f) is None else getattr(self, f)[which] for f in fields})

    def difference(self, planes):
        """Lookup A - lookup B at every point (K,) float64, of ``planes`` ((N, H, W), or (H, W) for
        one image)."""
        flat = np.asarray(planes).reshape(-1)
        if flat.size != int(np.prod(self.shape)):
            raise ValueError(f"planes of {flat.size} texels; the lookups address {self.shape}")
        # Column by column, in order: no (K, 8) temporary, and the same bits on every numpy.
        out = flat[self.index[:, 0]] * self.weight[:, 0].astype(np.float64)
        for j in range(1, 8):
            out += flat[self.index[:, j]] * self.weight[:, j].astype(np.float64)
        return out

    def mismatch(self, planes, creases=True):
        """The mean |lookup A - lookup B| over every seam point (``creases`` False: over the smooth
        ones, those the fix makes agree): what a user sees as the seam."""
        d = self.difference(planes)
        if not creases:
            d = d[~self.crease]
        # a running sum, in order (numpy's pairwise sums unroll differently from one version to another)
        return float(np.cumsum(np.abs(d))[-1] / len(d)) if len(d) else 0.0


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


def seam_lookups(meshes, resolution, tiles=None, wrap="repeat", points_per_texel=POINTS_PER_TEXEL, keep_points=True,
                 creases=True):
    """The seam points of ``meshes`` (one core.Mesh or a list: the targets of one image) and their
    two bilinear lookups in a ``resolution`` image.

    Parameters
    ----------
    meshes : core.Mesh with UVs, or a list of them (an atlas: each its own seams).
    resolution : int or (width, height) of the image (of each UDIM tile).
    tiles : None: one image, UVs looked up as they are (wrapping outside [0, 1]); or UDIM tile
        numbers: one plane per tile in this order, each point looked up in its own tile.
    wrap : 'repeat' (the Image Texture node's default Extension) or 'extend'.
    keep_points : False: no ``triangle`` and ``uv`` (None; what the fix does not need, 48 bytes a point).
    creases : False: the smooth seams' points alone (what the fix works on).

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
        if not creases:
            differ &= ~crease
        sel = np.flatnonzero(differ)
        length = np.maximum(np.hypot(*((a1 - a0)[sel] * scale).T), np.hypot(*((b1 - b0)[sel] * scale).T))
        n = np.maximum(1, np.ceil(points_per_texel * length)).astype(np.int64)
        per_mesh.append((a0[sel], a1[sel], b0[sel], b1[sel], cA[sel], cB[sel], np.stack([tA[sel], tB[sel]], 1),
                         crease[sel], length, n))
    total = sum(int(m[-1].sum()) for m in per_mesh)
    out = dict(index=np.empty((total, 8), itype), weight=np.empty((total, 8), np.float32), length=np.empty(total),
               edge=np.empty(total, np.int64), target=np.empty(total, np.int32),
               triangle=np.empty((total, 2), np.int64) if keep_points else None,
               uv=np.empty((total, 2, 2)) if keep_points else None, crease=np.empty(total, bool))
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
                if keep_points:
                    out["uv"][dst, j] = p[keep]
            out["length"][dst] = (length / n)[e][keep]
            out["edge"][dst] = (e + edges)[keep]
            out["target"][dst] = m_i
            if keep_points:
                out["triangle"][dst] = tris[e][keep]
            out["crease"][dst] = crease[e][keep]
            at += k
            lo = hi
        edges += len(n)
    if at < total:  # points in no listed tile
        out = {key: None if v is None else v[:at].copy() for key, v in out.items()}
    return SeamLookups(shape=(n_planes, h, w), edges=edges, tiles=tiles, wrap=wrap, **out)


def seam_mismatch(meshes, image, tiles=None, wrap="repeat"):
    """The mean |lookup A - lookup B| over the seam points of ``meshes`` in ``image`` ((H, W), or
    (N, H, W) UDIM tiles in the order of ``tiles``)."""
    image = np.asarray(image)
    h, w = image.shape[-2:]
    return seam_lookups(meshes, (w, h), tiles=tiles, wrap=wrap).mismatch(image)


__all__ = ["SeamLookups", "seam_edges", "seam_lookups", "seam_mismatch", "POINTS_PER_TEXEL", "SMOOTH_ANGLE", "WRAPS"]
