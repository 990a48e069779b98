"""Several quantities from one bake: AO and the thickness map over one set-up, each with its own rays.

:func:`core.bake_maps`, :func:`core.bake_udim_maps` and :func:`core.bake_vertex_maps` bake every
quantity of ``quantities`` ('ao', 'thickness') in one pass: the prologue (checks, frame, the
automatic extrusion), the layout (UV triangles, tiles, the surface table; for mesh corners, the
sample points and their neighbours), each tile's rasterising and sample units, the sample pattern,
the worker processes' set-up, and the Embree scene where the quantities' rays see the same meshes
(a thickness map beside AO without occluders) are made once; each quantity then traces its own
rays through its own start stage and estimator (a :class:`MapsBake` of lanes, one per quantity).

Every quantity's result is bit for bit the result of :func:`core.bake_ao` (or the UDIM or corner
bake) with ``quantity=`` that quantity and the same settings: the lanes draw the same random numbers
(by seed, texel and sample index), trace the same rays in the same chunks and add their sums in the
same order as a bake of that quantity alone.

Settings that only AO has: ``ground``, ``ignore_backfaces`` and ``bent_normals`` apply to the AO
map only (a thickness map is occluded by the object alone, :mod:`core.engine.thickness`); without 'ao' in
``quantities`` they are refused, as :func:`core.bake_ao` refuses them with ``quantity='thickness'``.
"""

import threading

from ..engine.tilebaker import TileOut


class LaneCounts:
    """The bake's scheduler as one quantity's lane sees it: everything is the shared scheduler's, and
    the rays and Embree seconds of this lane are counted apart as well (each result reports its own)."""

    def __init__(self, shared):
        self.shared = shared
        self.lock = threading.Lock()
        self.rays = 0
        self.trace_seconds = 0.0
        self.trace_cpu_seconds = 0.0

    def advance(self, work, rays=0, trace_seconds=0.0, trace_cpu_seconds=0.0):
        with self.lock:
            self.rays += rays
            self.trace_seconds += trace_seconds
            self.trace_cpu_seconds += trace_cpu_seconds
        self.shared.advance(work, rays, trace_seconds, trace_cpu_seconds)

    def __getattr__(self, name):
        return getattr(self.shared, name)


class _Starts:
    """The start stages of a :class:`MapsBake`'s lanes, as one: their counters by quantity, each with
    its lane's rays and Embree seconds (worker processes' counters are added up key by key)."""

    def __init__(self, maps):
        self.maps = maps

    def counters(self):
        return {q: dict(b.start.counters(), rays=c.rays, trace_seconds=c.trace_seconds,
                        trace_cpu_seconds=c.trace_cpu_seconds)
                for (q, b), c in zip(self.maps.lanes.items(), self.maps.counts.values())}


class MapsBake:
    """The bakes of several quantities over one layout, as one bake for :func:`core.execution.executor.bake_tiles`
    (in this process, in worker processes, on a Dask cluster).

    ``lanes``: {quantity: bake}, :class:`core.targets.texels.TexelBake` or :class:`core.targets.corners.VertexBake`
    objects made by ``lane`` from one of them (they share its layout). A tile is laid out once
    (``layout``) and baked by every lane; its :class:`core.engine.tilebaker.TileOut` is the first quantity's,
    with the others' in ``maps`` as plain data. ``start.counters()`` are the lanes' by quantity.
    """

    def __init__(self, lanes):
        self.lanes = dict(lanes)
        self.quantities = tuple(self.lanes)
        self.first = self.lanes[self.quantities[0]]
        self.s, self.pro = self.first.s, self.first.pro
        self.planned = sum(b.planned for b in self.lanes.values())
        self.counts = {}
        self.start = _Starts(self)

    def __getattr__(self, name):  # the layout's attributes (bins, blocks, rect, ...): every lane's are the same
        if name in ("first", "lanes"):
            raise AttributeError(name)
        return getattr(self.first, name)

    def aim(self, goal, again=False):
        """Every lane bakes the same decided counts (:meth:`core.targets.texels.TexelBake.aim`)."""
        for b in self.lanes.values():
            b.aim(goal, again)

    def trace_setup(self, shared, cancel, on_rays=None):
        pattern = None
        for q, b in self.lanes.items():
            self.counts[q] = counts = LaneCounts(shared)
            b.trace_setup(counts, cancel, on_rays, pattern=pattern)
            pattern = b.pattern

    def tile(self, key, directions=True):
        layout = self.first.layout(key)
        outs = {q: b.tile(key, directions, layout=layout) for q, b in self.lanes.items()}
        out = outs[self.quantities[0]]
        out.maps = {q: vars(o) for q, o in outs.items() if q != self.quantities[0]}
        return out

    def outs(self, out):
        """{quantity: TileOut} of a tile that :meth:`tile` (here or in a worker) returned."""
        more = out.maps or {}
        out.maps = None
        return {q: out if q == self.quantities[0] else TileOut(**more[q]) for q in self.quantities}


__all__ = ["MapsBake", "LaneCounts"]
