"""Bent normals: the mean unoccluded direction of each texel, from the AO bake's own rays.

For a surface point with normal n and cosine-distributed directions w_i (p = cos / pi), the vector

    m = (1/pi) * integral over the visible directions V of w cos(theta) dw

is estimated without bias by (1/N) sum_i w_i V(w_i): the kernel sums each sample's unit direction
weighted by the sample's AO term (:meth:`core.engine.kernel.Kernel.run`'s ``vectors``), so bent normals
cost no extra ray. For uniform directions the term is 2 cos(theta) V, which is the same weight
cos(theta) / (pi p). The bent normal is m / |m|; on an open plane m = (0, 0, 2/3) and the bent normal
is n; beside an infinite wall it leans away from the wall by atan(2 / pi) (tests/test_bent.py has the
closed forms for a wall, with and without an AO distance). A texel whose every sample is occluded has no bent direction
and takes its shading normal.

The texture stores it in one of three spaces (:func:`check_space`):

- world space (``space=None``);
- any linear space (a (3, 3) matrix M: M b, normalised), e.g. Blender's object space, whose bake
  applies the inverse of the object's matrix;
- tangent space (:class:`TangentFrames`): Blender's normal-map convention, exactly as its normal
  bake and Cycles' Normal Map node do it (``RE_bake_normal_world_to_tangent``, ``svm_node_normal_map``):
  at the texel's centre, in the triangle that holds it, the barycentric interpolations of the corner
  tangents T and shading normals N, *not normalised* (Blender 5.1 and later normalise N: see
  ``TangentFrames.unit_normal``), the bitangent sign s = sign of the interpolated signs (+1 at 0),
  B = s (N x T), and the texel's value normalize([T | B | N]^-1 M b) (the inverse of the frame, not
  dot products, so the Normal Map node's decoding gives back M b's direction).
  Encoded as RGB = n / 2 + 1/2 (:func:`encode`).

Texels that a UV triangle covers only in part (island edges) use the triangle that holds the texel's
centre, else the piece of largest area; its maps are evaluated at the centre (extrapolated a little
when the centre lies outside it), as the normal baker's per-pixel frame would be.
"""

from dataclasses import dataclass

import numpy as np

from ..base.errors import MeshError, SettingsError
from ..geometry.margin import margin_texels


@dataclass(frozen=True)
class TangentFrames:
    """Per triangle corner of the target: the tangent frame a normal map is decoded with.

    tangents : (T, 3, 3) the corners' tangents (MikkTSpace, as ``Mesh.calc_tangents`` gives them).
    signs : (T, 3) the bitangent signs (+1 or -1).
    normals : (T, 3, 3) the corners' shading normals in the same space (a flat face's corners: its
        face normal).
    matrix : (3, 3) from world space to the space of the three above (Blender: the transpose of the
        object's 3x3 matrix, as its bake uses).
    unit_normal : whether the decoder normalises the interpolated normal before it forms the frame:
        Blender 5.1 and later's Normal Map node does (the tangent stays as interpolated), 4.2 to 5.0
        use both as interpolated (measured: a map made for one convention, decoded by the other,
        lands up to 1 degree off on a 16-segment sphere at 64^2; tests/blender/test_blender_bent.py).
    """

    tangents: np.ndarray
    signs: np.ndarray
    normals: np.ndarray
    matrix: np.ndarray
    unit_normal: bool = False

    def checked(self, triangles, name):
        """A float64 copy, after checking the shapes against ``triangles`` triangles of mesh ``name``."""
        t = np.asarray(self.tangents, dtype=np.float64)
        s = np.asarray(self.signs, dtype=np.float64)
        n = np.asarray(self.normals, dtype=np.float64)
        m = np.asarray(self.matrix, dtype=np.float64)
        for arr, shape, what in ((t, (triangles, 3, 3), "tangents"), (s, (triangles, 3), "signs"),
                                 (n, (triangles, 3, 3), "normals"), (m, (3, 3), "matrix")):
            if arr.shape != shape:
                raise MeshError(f"mesh {name!r}: tangent frames' {what} must have shape {shape}, got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise MeshError(f"mesh {name!r}: tangent frames' {what} contain non-finite values")
        return TangentFrames(t, s, n, m, bool(self.unit_normal))


def check_space(space, mesh):
    """The space argument of a bake with bent normals, checked: None, a (3, 3) float64 matrix, or
    a checked :class:`TangentFrames`."""
    if space is None:
        return None
    if isinstance(space, TangentFrames):
        return space.checked(mesh.triangle_count, mesh.name)
    m = np.asarray(space, dtype=np.float64)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise SettingsError(f"bent_space must be None, a finite (3, 3) matrix or core.post.bent.TangentFrames, "
                            f"got {getattr(space, 'shape', type(space).__name__)}")
    return m


def primary_pieces(frag, width):
    """Per covered texel of a tile (:class:`core.geometry.raster.TileFragments`), the triangle whose map its
    frame comes from: the one covering it whole, else the piece that holds its centre, else its
    largest piece. Returns (n,) triangle ids."""
    from ..geometry.raster import LOCATED

    tri = frag.full_tri.copy()
    if not np.any(tri < 0):
        return tri
    located = tri == LOCATED
    if np.any(located):
        # A located texel (covered once by several triangles): the candidate holding its centre,
        # the one whose least edge function at (1/2, 1/2) is largest.
        e = frag.loc_edges
        d = (e[:, :, 0] * 0.5 + e[:, :, 1] * 0.5 + e[:, :, 2]).min(axis=1)
        owner = np.repeat(np.arange(len(tri)), np.diff(frag.loc_start))
        order = np.lexsort((-d, owner))
        first = np.ones(len(order), bool)
        first[1:] = owner[order][1:] != owner[order][:-1]
        best = order[first]
        tri[owner[best]] = frag.loc_tri[best]
    if not len(frag.sub_texel):
        return tri
    xy = frag.sub_xy
    a, b, c = xy[:, 0], xy[:, 1], xy[:, 2]
    area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    texel = frag.texels[frag.sub_texel]
    centre = np.stack([texel % width, texel // width], axis=1) + 0.5

    def edge(p, q):
        return (q[:, 0] - p[:, 0]) * (centre[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (centre[:, 0] - p[:, 0])

    e0, e1, e2 = edge(a, b), edge(b, c), edge(c, a)
    holds = ((e0 >= 0) & (e1 >= 0) & (e2 >= 0)) | ((e0 <= 0) & (e1 <= 0) & (e2 <= 0))
    score = area + holds * 4.0  # a piece's area is at most 1 texel
    order = np.lexsort((-score, frag.sub_texel))
    first = np.ones(len(order), bool)
    first[1:] = frag.sub_texel[order][1:] != frag.sub_texel[order][:-1]
    best = order[first]
    tri[frag.sub_texel[best]] = frag.sub_tri[best]
    return tri


def barycentric(corners_xy, tri, x, y):
    """Weights (n, 3) of the point (x, y) in the texel-space triangles ``corners_xy[tri]``."""
    c = np.asarray(corners_xy[tri], np.float64)  # the UV triangles keep float32 corners
    e1 = c[:, 1] - c[:, 0]
    e2 = c[:, 2] - c[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    det = np.where(det != 0, det, 1.0)
    px, py = x - c[:, 0, 0], y - c[:, 0, 1]
    w1 = (px * e2[:, 1] - py * e2[:, 0]) / det
    w2 = (e1[:, 0] * py - e1[:, 1] * px) / det
    return np.stack([1.0 - w1 - w2, w1, w2], axis=1)


def texel_directions(sums, tri, weights, world_normals, space):
    """Per texel, the unit bent normal in ``space`` (see the module docstring).

    sums : (n, 3) the texels' weighted direction sums (world space); tri : (n,) each texel's
    triangle; weights : (n, 3) the texel centre's barycentric weights in it; world_normals :
    (T, 3, 3) unit shading normals per corner in world space (the fallback of a texel with no
    unoccluded sample); space : from :func:`check_space`.
    """
    sums = np.asarray(sums, dtype=np.float64)
    length = np.linalg.norm(sums, axis=1)
    none = ~(length > 0)
    if isinstance(space, TangentFrames):
        T = np.einsum("nk,nkc->nc", weights, space.tangents[tri])
        N = np.einsum("nk,nkc->nc", weights, space.normals[tri])
        if space.unit_normal:
            N = _unit_rows(N)  # a zero normal stays zero: the frame is singular either way
        s = np.where(np.einsum("nk,nk->n", weights, space.signs[tri]) < 0, -1.0, 1.0)
        B = s[:, None] * np.cross(N, T)
        b = sums @ space.matrix.T
        # [T | B | N]^-1 b: the rows of the inverse are (B x N, N x T, T x B) / det.
        BN, NT, TB = np.cross(B, N), np.cross(N, T), np.cross(T, B)
        det = np.einsum("ij,ij->i", T, BN)
        local = np.stack([np.einsum("ij,ij->i", BN, b), np.einsum("ij,ij->i", NT, b),
                          np.einsum("ij,ij->i", TB, b)], axis=1)
        scale = np.maximum(np.abs(T).max(axis=1) * np.abs(B).max(axis=1) * np.abs(N).max(axis=1), 1e-300)
        singular = ~(np.abs(det) > 1e-12 * scale)
        local /= np.where(singular, 1.0, det)[:, None]
        none |= singular
        out = local
        out[none] = (0.0, 0.0, 1.0)  # the shading normal, in its own frame
    else:
        fallback = np.einsum("nk,nkc->nc", weights, world_normals[tri])
        out = np.where(none[:, None], fallback, sums)
        if space is not None:
            out = out @ space.T
    return _unit_rows(out).astype(np.float32)


def _unit_rows(v):
    """Each row of ``v`` (n, 3) divided by its length; rows of length 0 stay as they are."""
    size = np.linalg.norm(v, axis=1)
    return v / np.where(size > 0, size, 1.0)[:, None]


def encode(bent, filled, tangent):
    """(H, W, 3) unit bent normals -> (H, W, 3) RGB = n / 2 + 1/2, Blender's normal-map encoding.

    ``filled`` (H, W) bool: texels that hold a bent normal (covered and margin); the others get
    Blender's fill for unbaked texels: the flat normal (0.5, 0.5, 1) in tangent space, black else.
    """
    rgb = np.asarray(bent, dtype=np.float32) * 0.5 + 0.5
    rgb[~filled] = (0.5, 0.5, 1.0) if tangent else (0.0, 0.0, 0.0)
    return rgb


def dilate_directions(bent, mask, margin, threads=1, owner=None, rank=None):
    """Extend the covered texels' unit vectors into the margin (per component, then normalised).

    Returns (bent, filled): the dilated (H, W, 3) float32 vectors and which texels hold one (the
    rest hold 0). The three components share the margin's rings
    (:func:`core.geometry.margin.margin_texels`), and only the covered and margin texels are normalised, one
    component plane at a time: a 4096^2 image took 5.4-7.7 s in a bake when each component was
    dilated into a copy of the image, stacked, and normalised over the whole image. ``owner``,
    ``rank``: several targets in one image, each margin texel from its own target's texels
    (:func:`core.geometry.margin.dilate`; ``owner`` is not changed here).
    """
    if margin <= 0:
        return bent, mask.copy()
    h, w = mask.shape
    flat = np.ascontiguousarray(bent, np.float32).reshape(-1)
    idx, vals, *_ = margin_texels(bent, mask, margin, threads, owner=owner, rank=rank)
    vals = vals.astype(np.float32, copy=False)
    cov = np.flatnonzero(mask)
    # The covered texels, then the margin's: component c of texel t is flat[3 t + c] = flat[c:][3 t],
    # so one index array serves all three components.
    ids3 = 3 * np.concatenate([cov, idx])
    x, y, z = comps = [np.concatenate([np.take(flat[c:], ids3[:len(cov)]), vals[:, c]]) for c in range(3)]
    # |v| summed as numpy's norm over a last axis of 3 sums it, (x^2 + y^2) + z^2: the bits of
    # np.linalg.norm(v, axis=-1) (numpy 1.26, 2.2 and 2.5).
    size = np.sqrt((x * x + y * y) + z * z)
    good = size > 0
    out = np.zeros(h * w * 3, np.float32)
    for c, comp in enumerate(comps):
        np.divide(comp, size, out=comp, where=good)  # zero vectors stay 0
        out[c:][ids3] = comp
    filled = mask.copy()
    filled.reshape(-1)[idx[good[len(cov):]]] = True
    return out.reshape(h, w, 3), filled


__all__ = ["TangentFrames", "check_space", "primary_pieces", "barycentric", "texel_directions", "encode",
           "dilate_directions"]
