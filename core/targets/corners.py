"""Ambient occlusion at mesh vertices: one value per face corner, as Cycles bakes into colour attributes.

Cycles' AO bake into a colour attribute (``bake_targets_init_vertex_colors``,
``integrator_init_from_bake`` and ``bake_targets_output_vertex_colors`` in Blender's source)
estimates one value per face corner: at the corner's vertex, nudged a little towards the centre of
the first triangle that holds the corner, with the corner's shading normal (a flat face's corners
have its face normal),
over the same cosine-weighted hemisphere as a texel. A colour attribute on the point domain then
holds the plain mean of the values of each vertex's corners, whatever the faces' sizes or angles;
on the corner domain each corner keeps its own (:func:`vertex_means`).

Here each sample point is a *unit* of the texel baker (:mod:`core.geometry.surface`) that is not a texel: a
degenerate triangle whose position and normal are constant (Px = Py = Nx = Ny = 0), so the kernel,
the sample patterns, the estimator, adaptive sampling and the error estimates are those of a texel's,
unchanged (:meth:`core.engine.tilebaker.TileBaker.trace`); only the rasteriser is not involved. Corners
that share their vertex and their normal (a smooth vertex's corners) share one unit: Cycles' values
for them differ only by noise.
"""

import dataclasses
import time

import numpy as np

from .._version import __version__
from ..execution import workers as _workers
from ..pipeline.bake import BakeResult, Prologue, TileOut
from ..base.errors import MeshError, SettingsError
from ..engine.estimators import ErrorModel
from ..engine.kernel import Kernel
from ..geometry.mesh import corner_positions, mesh_list
from ..engine.patterns import POOL_POINTS, TexelPattern
from ..engine.settings import BakeSettings, pattern_span
from ..geometry.surface import point_table, point_units
from ..engine.tilebaker import SurfaceStart, TileBaker

#: Cycles moves a sample that sits exactly on a vertex towards its triangle's centroid by at most
#: 1e-4 object units ("empirically determined"); here 1e-4 of the mesh's size, the same in any unit.
NUDGE = 1e-4
#: Units one worker takes at a time (their keys depend on the unit alone: any split gives the same values).
BLOCK = 4096


#: The result of :func:`bake_vertex_ao`: :class:`core.BakeResult`, its arrays per corner.
VertexBakeResult = BakeResult


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


def _check_corners(corners, mesh):
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


def _block_neighbours(pairs, lo, hi):
    """The :class:`Neighbours` of the points ``lo`` .. ``hi`` - 1 among ``pairs`` (:func:`unit_pairs`)."""
    a, b = pairs
    i, j = np.searchsorted(a, [lo, hi])
    a, b = a[i:j], b[i:j]
    inside = (b >= lo) & (b < hi)
    return Neighbours(a[inside] - lo, b[inside] - lo, hi - lo)


def bake_vertex_ao(target, occluders=(), corners=None, samples=256, *, min_samples=16, target_error=0.0,
                   max_distance=float("inf"), distribution="cosine", source="sobol", seed=0, threads=None,
                   ignore_backfaces=False, falloff=0.0, replicates=2, progress=None, cancel=None,
                   chunk_rays=1 << 16, on_rays=None, merge=True, bent_normals=False, workers=1, ground=None,
                   quantity="ao", denoise=False):
    """Bake ambient occlusion at the face corners of ``target`` (Cycles' colour-attribute bake).

    Parameters
    ----------
    target : Mesh (UVs not needed). It always occludes itself.
    occluders : Meshes that also block rays, in the same world space.
    corners : (C, 2) integers, (triangle, corner 0..2) of each face corner to bake, e.g. Blender's
        face corners each mapped to the first triangle that holds it; None: every triangle corner.
    merge : corners with the same vertex and normal share one sample point (default).
    bent_normals : also estimate each corner's bent normal (world space) from the same rays
        (summed over all replicates).
    replicates : as for :func:`core.bake_ao`: with 2 or more, ``stderr`` and adaptive sampling use
        the spread between replicates, pooled over each sample point's neighbourhood on the mesh
        (its vertex and the vertices that share an edge with it: :class:`Neighbours`), as a
        texel's is pooled over the texels around it.
    ground, quantity : as for :func:`core.bake_ao` ('auto': the target's lowest point).
    denoise : filter the corners' estimates over the mesh (:func:`core.post.denoise.denoise_vertices`: the
        points up to two edges away, each weighed by its error): ``ao`` and ``stderr`` the denoised
        values and their error, ``raw_ao`` and ``raw_stderr`` the estimates before it (needs
        ``replicates`` >= 2).
    The other parameters are those of :func:`core.bake_ao`; progress is reported per chunk of
    rays and ``on_rays`` batches name the sample point (``texels``) of each ray.

    Returns
    -------
    BakeResult, its arrays per corner

    Raises
    ------
    MeshError, MeshTypeError, SettingsError, BakeCancelled.
    """
    return _bake_corners(target, occluders, corners, samples, (quantity,), **_corner_options(locals()))[quantity]


_CORNER_OPTIONS = ("min_samples", "target_error", "max_distance", "distribution", "source", "seed", "threads",
                   "ignore_backfaces", "falloff", "replicates", "progress", "cancel", "chunk_rays", "on_rays", "merge",
                   "bent_normals", "workers", "ground", "denoise")


def _corner_options(arguments):
    return {k: arguments[k] for k in _CORNER_OPTIONS}


def bake_vertex_maps(target, occluders=(), corners=None, samples=256, *, quantities=("ao", "thickness"),
                     min_samples=16, target_error=0.0, max_distance=float("inf"), distribution="cosine",
                     source="sobol", seed=0, threads=None, ignore_backfaces=False, falloff=0.0, replicates=2,
                     progress=None, cancel=None, chunk_rays=1 << 16, on_rays=None, merge=True, bent_normals=False,
                     workers=1, ground=None, denoise=False):
    """Several quantities at the face corners of ``target`` in one pass (:mod:`core.targets.maps`): one set-up
    (sample points, neighbours, pattern, scene where shared), each quantity its own rays.

    ``quantities``, ``ground``, ``ignore_backfaces``, ``bent_normals`` as for :func:`core.bake_maps`;
    the others as for :func:`bake_vertex_ao`.

    Returns
    -------
    {quantity: BakeResult}: each bit for bit :func:`bake_vertex_ao` of that quantity with the same
    settings, ``metadata['quantities']`` the quantities baked together.
    """
    from .maps import check_quantities

    return _bake_corners(target, occluders, corners, samples, check_quantities(quantities), maps=True,
                         **_corner_options(locals()))


def vertex_bake(pro, s, corners, quantities, merge=True, bent_normals=False, block=None):
    """The corner bake of ``quantities`` (a :class:`VertexBake`, or a :class:`core.targets.maps.MapsBake` of
    lanes over one's sample points), as :func:`core.pipeline.bake.texel_bake`."""
    root = VertexBake(pro, s, corners, merge, bent_normals and s.quantity == "ao", block)
    if tuple(quantities) == (s.quantity,):
        return root
    from .maps import MapsBake, lane_settings

    return MapsBake({q: root if q == s.quantity else root.lane(lane_settings(s, q), bent_normals and q == "ao")
                     for q in quantities})


def _bake_corners(target, occluders, corners, samples, quantities, *, maps=False, min_samples=16, target_error=0.0,
                  max_distance=float("inf"), distribution="cosine", source="sobol", seed=0, threads=None,
                  ignore_backfaces=False, falloff=0.0, replicates=2, progress=None, cancel=None, chunk_rays=1 << 16,
                  on_rays=None, merge=True, bent_normals=False, workers=1, ground=None, denoise=False):
    """:func:`bake_vertex_ao` of every quantity of ``quantities`` over one set-up: {quantity: BakeResult}."""
    from .maps import base_quantity

    t_start = time.perf_counter()
    base = base_quantity(quantities)
    s = BakeSettings.from_arguments(1, samples, min_samples, target_error, max_distance, distribution, source,
                                    0, seed, threads, ignore_backfaces, falloff, None, chunk_rays, replicates,
                                    ground=ground, quantity=base)
    if bent_normals and s.quantity != "ao":
        raise SettingsError(f"bent normals come with quantity='ao' only, not {s.quantity!r}: bake them in an AO bake")
    if denoise and s.replicates < 2:
        raise SettingsError("denoise needs replicates >= 2: the filter weighs each point by its standard error, "
                            "which one replicate only bounds")
    workers = _workers.check_workers(workers)
    occluders = mesh_list(occluders)
    pro = Prologue(target, occluders, s, cancel, uvs=False)
    corners = all_corners(pro.target) if corners is None else _check_corners(corners, pro.target)
    bake = vertex_bake(pro, s, corners, quantities, merge, bent_normals)
    lanes = bake.lanes if len(quantities) > 1 else {base: bake}
    root = lanes[base]
    pro.check_cancel()
    processes, per_worker = _workers.processes_of(workers, threads, s, pro.triangle_counts)
    m = len(root.p)
    values = {q: dict(ao=np.zeros(m, np.float32), se=np.zeros(m, np.float32), count=np.zeros(m, np.int32),
                      bent=np.zeros((m, 3), np.float32) if b.bent_normals else None) for q, b in lanes.items()}

    def store_one(v, out):
        ids = out.texels
        v["ao"][ids], v["se"][ids], v["count"][ids] = out.ao, out.stderr, out.samples
        if v["bent"] is not None:
            v["bent"][ids] = out.bent

    def store(out):
        for q, o in (bake.outs(out) if len(quantities) > 1 else {base: out}).items():
            store_one(values[q], o)

    keys = list(range(len(root.blocks)))
    def job():
        """What a worker rebuilds this bake from (plain data)."""
        return dict(kind="vertex", target=_workers.mesh_data(target), occluders=[_workers.mesh_data(o) for o in occluders],
                    settings=dataclasses.asdict(s), corners=corners, merge=bool(merge), bent_normals=bool(bent_normals),
                    block=root.block, quantities=list(quantities))

    rays, trace_s, trace_cpu, counters, fallback = _workers.bake_tiles(bake, keys, processes, per_worker, job, store,
                                                                       progress, cancel, on_rays)
    memory = counters.get("worker_memory", [])
    if len(quantities) == 1:
        counters = {base: dict(rays=rays, trace_seconds=trace_s, trace_cpu_seconds=trace_cpu)}
    unit = root.unit
    results = {}
    for q in quantities:
        ls, v, c = lanes[q].s, values[q], counters[q]
        metadata = dict(ls.metadata(ls.max_distance), version=__version__, rays=c["rays"])
        for key in ("margin", "resolution"):
            metadata.pop(key, None)
        metadata["sample_points"] = m
        if maps:
            metadata["quantities"] = ",".join(quantities)
        if ls.ground is not None:
            metadata["ground_height"] = pro.ground_height(ls)[0]
        report = {"corners": len(corners), "sample_points": m, "degenerate_corners": root.flat,
                  "worker_memory": memory}
        if fallback is not None:
            report.setdefault("warnings", []).append(
                f"baked on {ls.threads} threads of this process, not in worker processes: {fallback}")
        out_ao, out_se, raw_ao, raw_se = v["ao"][unit], v["se"][unit], None, None
        if denoise:
            from ..post import denoise as _denoise

            raw_ao, raw_se = out_ao, out_se
            out_ao, out_se, _ = _denoise.denoise_vertices(pro.target, raw_ao, raw_se, unit, corners)
            metadata["denoise"] = True
        results[q] = BakeResult(ao=out_ao, mask=np.ones(len(unit), bool), stderr=out_se, samples=v["count"][unit],
                                unit=unit, raw_ao=raw_ao, raw_stderr=raw_se, rays=c["rays"],
                                seconds=time.perf_counter() - t_start, trace_seconds=c["trace_seconds"],
                                threads=ls.threads, trace_cpu_seconds=c["trace_cpu_seconds"], metadata=metadata,
                                report=report, bent=None if v["bent"] is None else v["bent"][unit])
    return results


class VertexBake:
    """A corner bake set up after its prologue: its sample points, their units and blocks, and after
    :meth:`trace_setup` the tracing. The same object bakes blocks in this process and in a worker
    process (:mod:`core.execution.workers`), as :class:`core.pipeline.bake.TexelBake` bakes tiles."""

    def __init__(self, pro, s, corners, merge=True, bent_normals=False, block=None):
        self.pro, self.s, self.bent_normals = pro, s, bool(bent_normals)
        self.block = block = BLOCK if block is None else int(block)
        target = pro.target
        self.unit, self.p, self.n, self.gn, corners3, self.flat = sample_points(target, corners, merge)
        m = len(self.p)
        self.table = point_table(self.p, self.n, self.gn, corners3)
        unit_vertex = np.empty(m, np.int64)
        unit_vertex[self.unit] = target.triangles[corners[:, 0], corners[:, 1]]
        self.pairs = unit_pairs(target, unit_vertex) if s.replicates > 1 else None
        self.blocks = [np.arange(b, min(b + block, m)) for b in range(0, m, block)]
        self.planned = m * s.samples

    def lane(self, s, bent_normals=False):
        """The bake of another quantity over these sample points (taken once), with settings ``s``
        (:func:`core.targets.maps.lane_settings` of this bake's)."""
        out = object.__new__(VertexBake)
        out.__dict__.update({k: getattr(self, k) for k in ("pro", "block", "unit", "p", "n", "gn", "flat", "table",
                                                           "pairs", "blocks", "planned")})
        out.s, out.bent_normals = s, bool(bent_normals)
        return out

    def trace_setup(self, shared, cancel, on_rays=None, pattern=None):
        """The tracing: scene, sample pattern (``pattern``: another quantity's of the same bake, the
        same points), kernel, start stage and block baker."""
        s, m = self.s, len(self.p)
        self.tracer = self.pro.tracer(s)
        if pattern is None:
            span = pattern_span(s.source, s.replicate_samples)
            pool = max(span * s.replicates, min(POOL_POINTS, (1 << max(0, (m * s.replicates - 1).bit_length())) * span))
            pattern = TexelPattern(s.source, s.seed, s.replicate_samples, pool_points=pool)
        self.pattern = pattern
        kernel = Kernel(pattern, self.tracer, s.distribution, on_rays=on_rays)
        self.start = SurfaceStart(self.table, self.tracer)
        self.baker = TileBaker(None, self.table, kernel, self.tracer, pattern, s, shared, self.start,
                               bent=self.bent_normals)
        self.errors = ErrorModel(s)

    def layout(self, key):
        """Block ``key``'s points and where each pools its variance (the same for every quantity)."""
        ids = self.blocks[key]
        near = None if self.pairs is None else _block_neighbours(self.pairs, int(ids[0]), int(ids[-1]) + 1)
        return ids, near, {}

    def tile(self, key, directions=True, layout=None):
        """Bake block ``key`` of the sample points: a :class:`core.pipeline.bake.TileOut` whose ``texels`` are
        the points' numbers (bent normals are world directions already); ``layout``: the block's
        :meth:`layout`, taken already for another quantity."""
        ids, near, memo = self.layout(key) if layout is None else layout
        contact = np.zeros(len(ids), bool)
        if self.tracer.touches:
            contact = self.tracer.contact(self.p[ids], self.gn[ids])
        est, sums = self.baker.trace(point_units(ids, np.arange(len(ids))), ids, contact, near, None, memo=memo)
        out = TileOut(key, ids, np.clip(est.mean, 0.0, 1.0).astype(np.float32),
                      self.errors.stderr(est, near, None).astype(np.float32), est.n.astype(np.int32),
                      np.zeros(len(ids), bool))
        if sums is not None:
            length = np.linalg.norm(sums, axis=1)
            v = np.where((length > 0)[:, None], sums, self.n[ids])
            out.bent = (v / np.linalg.norm(v, axis=1)[:, None]).astype(np.float32)
        return out


__all__ = ["VertexBakeResult", "bake_vertex_ao", "bake_vertex_maps", "VertexBake", "all_corners", "vertex_means",
           "sample_points", "NUDGE", "Neighbours", "unit_pairs"]
