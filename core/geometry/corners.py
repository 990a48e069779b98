"""Face corners as sample points: which corners share a point, where each point lies, its neighbours.

Cycles' AO bake into a colour attribute (``bake_targets_init_vertex_colors``,
``integrator_init_from_bake`` and ``bake_targets_output_vertex_colors`` in Blender's source)
estimates one value per face corner: at the corner's vertex, nudged a little towards the centre of
the first triangle that holds the corner, with the corner's shading normal (a flat face's corners
have its face normal). A colour attribute on the point domain then holds the plain mean of the
values of each vertex's corners, whatever the faces' sizes or angles; on the corner domain each
corner keeps its own (:func:`vertex_means`). Corners that share their vertex and their normal (a
smooth vertex's corners) share one sample point: Cycles' values for them differ only by noise.
"""

import numpy as np

from ..base.errors import MeshError
from .mesh import corner_positions

#: Cycles moves a sample that sits exactly on a vertex towards its triangle's centroid by at most
#: 1e-4 object units ("empirically determined"); here 1e-4 of the mesh's size, the same in any unit.
NUDGE = 1e-4


def all_corners(mesh):
    """Every triangle corner of ``mesh`` as a (T * 3, 2) array of (triangle, corner 0..2)."""
    t = np.arange(mesh.triangle_count, dtype=np.int64)
    return np.stack([np.repeat(t, 3), np.tile(np.arange(3, dtype=np.int64), len(t))], axis=1)


def vertex_means(values, corner_vertex, vertex_count):
    """Per vertex, the plain mean of its corners' ``values`` (Cycles' point domain); 0 for a vertex
    without corners (a loose vertex). ``values`` (C,) or (C, k)."""
    values = np.asarray(values, dtype=np.float64)
    corner_vertex = np.asarray(corner_vertex, dtype=np.int64)
    count = np.bincount(corner_vertex, minlength=vertex_count).astype(np.float64)
    flat = values.reshape(len(values), -1)
    sums = np.stack([np.bincount(corner_vertex, weights=flat[:, c], minlength=vertex_count)
                     for c in range(flat.shape[1])], axis=1)
    out = sums / np.maximum(count, 1.0)[:, None]
    return out.reshape((vertex_count,) + values.shape[1:])


def check_corners(corners, mesh):
    c = np.asarray(corners)
    if c.ndim != 2 or c.shape[1] != 2 or not np.issubdtype(c.dtype, np.integer):
        raise MeshError(f"mesh {mesh.name!r}: corners must be an integer array (C, 2) of (triangle, corner "
                        f"0..2), got {c.dtype} {c.shape}")
    if len(c) == 0:
        raise MeshError(f"mesh {mesh.name!r}: no corners to bake")
    bad = (c[:, 0] < 0) | (c[:, 0] >= mesh.triangle_count) | (c[:, 1] < 0) | (c[:, 1] > 2)
    if bad.any():
        raise MeshError(f"mesh {mesh.name!r}: {int(bad.sum())} corners name a triangle or corner that does not "
                        f"exist (first: {tuple(int(v) for v in c[np.argmax(bad)])}; the mesh has "
                        f"{mesh.triangle_count} triangles)")
    return c.astype(np.int64)


def sample_points(mesh, corners, merge=True):
    """The sample units of ``corners`` of ``mesh`` (in its own frame): (unit of each corner, and per
    unit: position, shading normal, geometric normal, its triangle's corners).

    Corners with the same vertex and the same normal share a unit (``merge``). A unit's position is
    its vertex moved towards the centroid of the first triangle of its corners by at most ``NUDGE``
    times the mesh's size; its geometric normal is that triangle's face normal (the shading normal
    where the triangle has no area).
    """
    tri, slot = corners[:, 0], corners[:, 1]
    vert = mesh.triangles[tri, slot]
    normal = mesh.normals[tri, slot]
    if merge:
        key = np.concatenate([vert[:, None], np.ascontiguousarray(normal, dtype=np.float64).view(np.int64)], axis=1)
        _, first, unit = np.unique(key, axis=0, return_index=True, return_inverse=True)
        unit = unit.reshape(-1)
        # Units numbered in the order of their first corner: the result does not depend on sorting.
        order = np.argsort(first, kind="stable")
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        unit = rank[unit]
        first = first[order]
    else:
        first = np.arange(len(corners))
        unit = first.copy()
    t = tri[first]
    p = mesh.positions[vert[first]]
    corners3 = corner_positions(mesh.positions, mesh.triangles[t])
    to_centre = corners3.mean(axis=1) - p
    dist = np.linalg.norm(to_centre, axis=1)
    size = float(np.max(mesh.positions.max(axis=0) - mesh.positions.min(axis=0)))
    step = np.minimum(dist, NUDGE * size)
    p = p + to_centre * (step / np.where(dist > 0, dist, 1.0))[:, None]
    n = normal[first]
    gn = mesh.face_normals[t]
    flat = ~(np.linalg.norm(gn, axis=1) > 0)
    gn = np.where(flat[:, None], n, gn)
    return unit.astype(np.int64), p, n, gn, corners3, int(flat[unit].sum())


class Neighbours:
    """Where the error model pools a sample point's variance (:func:`core.engine.estimators.window_sums`
    with ``y`` None): the point itself and the points whose vertex is its own or shares an edge
    with it (a vertex's 1-ring, the mesh's analogue of a texel's window), among the points of one
    block (so that a point's estimate never depends on how blocks go to threads). ``a``, ``b``:
    pairs of distinct points of the block (local numbers); ``m``: points in the block."""

    def __init__(self, a, b, m):
        self.a, self.b, self.m = a, b, m

    def sums(self, values):
        values = np.asarray(values, dtype=np.float64)
        out = values.copy()
        for row in range(len(values)):
            out[row] += np.bincount(self.a, weights=values[row, self.b], minlength=self.m)
        return out


def unit_pairs(mesh, unit_vertex):
    """(a, b), sorted by a then b: every pair of distinct sample points whose vertices (``unit_vertex``
    per point) are the same vertex or share an edge of ``mesh``."""
    unit_vertex = np.asarray(unit_vertex, dtype=np.int64)
    v_count = len(mesh.positions)
    tri = np.asarray(mesh.triangles, dtype=np.int64)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    same = np.repeat(np.unique(unit_vertex), 2).reshape(-1, 2)
    e = np.unique(np.concatenate([e, e[:, ::-1], same]), axis=0)
    order = np.argsort(unit_vertex, kind="stable")
    count = np.bincount(unit_vertex, minlength=v_count)
    start = np.concatenate([[0], np.cumsum(count)])
    ca, cb = count[e[:, 0]], count[e[:, 1]]
    keep = (ca > 0) & (cb > 0)
    e, ca, cb = e[keep], ca[keep], cb[keep]
    pairs = ca * cb
    edge = np.repeat(np.arange(len(e)), pairs)
    offset = np.arange(int(pairs.sum())) - np.repeat(np.cumsum(pairs) - pairs, pairs)
    a = order[start[e[edge, 0]] + offset // cb[edge]]
    b = order[start[e[edge, 1]] + offset % cb[edge]]
    keep = a != b
    a, b = a[keep], b[keep]
    o = np.lexsort((b, a))
    return a[o], b[o]


def block_neighbours(pairs, lo, hi):
    """The :class:`Neighbours` of the points ``lo`` .. ``hi`` - 1 among ``pairs`` (:func:`unit_pairs`)."""
    a, b = pairs
    i, j = np.searchsorted(a, [lo, hi])
    a, b = a[i:j], b[i:j]
    inside = (b >= lo) & (b < hi)
    return Neighbours(a[inside] - lo, b[inside] - lo, hi - lo)


__all__ = ["NUDGE", "all_corners", "vertex_means", "check_corners", "sample_points", "Neighbours", "unit_pairs",
           "block_neighbours"]
