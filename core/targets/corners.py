"""A bake of face corners (colour attributes): each sample point a unit of the tile baker that is not a texel.

Each sample point (:func:`core.geometry.corners.sample_points`) is a *unit* of the tile baker
(:mod:`core.geometry.surface`) that is not a texel: a degenerate triangle whose position and normal
are constant (Px = Py = Nx = Ny = 0), so the kernel, the sample patterns, the estimator, adaptive
sampling and the error estimates are those of a texel's, unchanged
(:meth:`core.engine.tilebaker.TileBaker.trace`); only the rasteriser is not involved. Points go to
threads and processes in blocks of :data:`BLOCK`.
"""

import numpy as np

from ..engine.estimators import ErrorModel
from ..engine.kernel import Kernel
from ..engine.patterns import POOL_POINTS, TexelPattern
from ..engine.settings import pattern_span
from ..engine.thickness import quantity_settings
from ..engine.tilebaker import SurfaceStart, TileBaker, TileOut
from ..geometry.corners import block_neighbours, sample_points, unit_pairs
from ..geometry.surface import point_table, point_units
from .maps import MapsBake

#: Units one worker takes at a time (their keys depend on the unit alone: any split gives the same values).
BLOCK = 4096


def vertex_bake(pro, s, corners, quantities, merge=True, bent_normals=False, block=None):
    """The corner bake of ``quantities`` (a :class:`VertexBake`, or a :class:`core.targets.maps.MapsBake` of
    lanes over one's sample points), as :func:`core.targets.texels.texel_bake`."""
    root = VertexBake(pro, s, corners, merge, bent_normals and s.quantity == "ao", block)
    if tuple(quantities) == (s.quantity,):
        return root
    return MapsBake({q: root if q == s.quantity else root.lane(quantity_settings(s, q), bent_normals and q == "ao")
                     for q in quantities})


class VertexBake:
    """A corner bake set up after its prologue: its sample points, their units and blocks, and after
    :meth:`trace_setup` the tracing. The same object bakes blocks in this process and in a worker
    process (:mod:`core.execution.pool`), as :class:`core.targets.texels.TexelBake` bakes tiles."""

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
        (:func:`core.engine.thickness.quantity_settings` of this bake's)."""
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
        near = None if self.pairs is None else block_neighbours(self.pairs, int(ids[0]), int(ids[-1]) + 1)
        return ids, near, {}

    def tile(self, key, directions=True, layout=None):
        """Bake block ``key`` of the sample points: a :class:`core.engine.tilebaker.TileOut` whose ``texels`` are
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


__all__ = ["VertexBake", "vertex_bake", "BLOCK"]
