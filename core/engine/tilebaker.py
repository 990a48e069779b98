"""The tile baker: one tile of texels (or one block of mesh vertices) from sample units to estimates.

Every bake goes through :class:`TileBaker`: texel images, UDIM tiles (one image each), colour
attributes (:mod:`core.targets.corners`, whose points are units of their own) and selected to active. Per
tile it rasterises the texels (:mod:`core.geometry.raster`), builds their sample units (:mod:`core.geometry.surface`),
and traces the rounds of the sampling plan (:class:`core.engine.adaptive.SamplingPlan`): each round's
pieces of samples, all replicates together, sorted into calls of equal pieces, cut into chunks of
rays that the scheduler shares out (:mod:`core.engine.scheduler`) and commits in order, each chunk through
the one kernel (:class:`core.engine.kernel.Kernel`).

What differs between targets is where a sample starts and which normal it uses, a *start stage*:

- :class:`SurfaceStart`: on the target's own surface, at the sample's point of its texel, with the
  target's interpolated normal (the kernel's per-triangle matrices); one sample per point.
- :class:`core.highpoly.stage.HighPolyStart`: at the point of the high-poly surface that the sample point's
  matching ray finds, with the high-poly's normal there; a block of directions per point.

Every stage is a :class:`StartStage`: the attributes and hooks the tile baker calls by name.
"""

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .adaptive import SamplingPlan
from .estimators import TexelEstimates, TexelWindows
from .kernel import TileContext
from ..montecarlo.hashing import hash64
from ..geometry.raster import rasterize_tile
from ..geometry.surface import LOCATED, SQUARE, TRIANGLE, allocate, build_units, contact_texels


def allocation_seeds(settings):
    """Per replicate, the seed :func:`core.geometry.surface.allocate` splits texels' samples among their units
    with. Replicate 0 keeps the bake's seed; the others allocate from seeds of their own, independent
    of it."""
    return [np.uint64(settings.seed)] + [hash64(np.uint64(settings.seed), np.uint64(r), np.uint64(31))
                                         for r in range(1, settings.replicates)]


@dataclass
class ChunkSums:
    """What a stage returns for one chunk of pieces.

    count : per piece (or one for all), the samples its sums hold; s1, s2 : per piece, the sum of the
    samples' terms and of their squares (float64); vectors : None, or per piece the sum of the
    unit directions weighted by the terms (bent normals); work : the samples the chunk stands for
    (progress); rays : rays handed to Embree; seconds, cpu_seconds : time inside Embree;
    extra : what the stage's :meth:`commit` adds to the estimates.
    """

    count: object
    s1: np.ndarray
    s2: np.ndarray
    vectors: np.ndarray
    work: int
    rays: int
    seconds: float
    cpu_seconds: float
    extra: object = None


@dataclass
class TileOut:
    """One tile's values, as the baker hands them to whoever assembles the images (this process or,
    from a worker process, plain arrays). ``texels`` flat ids; ``lost`` the texels none of whose
    sample points found a surface (selected to active: uncovered); ``sums``, ``tri``, ``weights``:
    the bent-normal sums and where each texel's normal is interpolated (None without bent normals)."""

    key: tuple
    texels: np.ndarray
    ao: np.ndarray
    stderr: np.ndarray
    samples: np.ndarray
    lost: np.ndarray
    overlapping: int = 0
    sums: np.ndarray = None
    tri: np.ndarray = None
    weights: np.ndarray = None
    bent: np.ndarray = None
    maps: dict = None  # a bake of several quantities: the tile of each other quantity, as plain data
    guide: tuple = None  # the denoiser's guide of the texels (core.post.denoise.tile_guide); None without denoise


class StartStage(Protocol):
    """Where a sample starts and which normal it uses: what the tile baker asks of a start stage.

    per_point : samples per sample point (a point's samples share its start); grouped : the samples of
    a point are not independent (the error model and the plan use replicates); locate : the rasteriser
    locates texels covered by many small triangles; located_curved : located samples take the
    smooth-shaded matrix form (:class:`core.engine.kernel.TileContext`).
    """

    per_point: int
    grouped: bool
    locate: bool
    located_curved: bool

    def estimates(self, count, replicates) -> TexelEstimates:
        """The estimates of ``count`` texels (the stage's own kind, with what it counts beside)."""

    def contact(self, frag, width, samples) -> np.ndarray:
        """Per texel of a tile's fragments, whether to probe its samples for contact."""

    def curved(self, units, unit, located) -> np.ndarray:
        """Per piece, whether its samples take the smooth-shaded form."""

    def keep(self, est, texels):
        """Which of ``texels`` take the next round (None: all)."""

    def run(self, kernel, tile, curved, unit, first, k, squares, located, vectors, replicates) -> "ChunkSums":
        """The sums of one chunk of pieces (rays traced through ``kernel``)."""

    def commit(self, est, texel, k, extra, replicate) -> None:
        """Add what :meth:`run` returned beside the sums (``extra``) to the estimates."""

    def lost(self, est) -> np.ndarray:
        """Per texel of a finished tile, whether none of its sample points found a surface."""

    def counters(self) -> dict:
        """What the stage counted over the bake (added up over worker processes)."""


class SurfaceStart:
    """Samples start on the target's surface: each at its point of the texel, with the target's
    interpolated normal. One sample per point; contact probed per texel (:func:`core.geometry.surface.contact_texels`).

    ``located_curved``: located samples (each on its own triangle) take the smooth-shaded matrix form
    (a bake-wide choice: any smooth triangle in the target), see :class:`core.engine.kernel.TileContext`.
    """

    per_point = 1
    grouped = False
    locate = True

    def __init__(self, table, tracer, located_curved=False):
        self.table, self.tracer = table, tracer
        self.located_curved = bool(located_curved)

    def estimates(self, count, replicates):
        return TexelEstimates(count, replicates)

    def contact(self, frag, width, samples):
        return contact_texels(frag, self.table, width, self.tracer, samples)

    def curved(self, units, unit, located):
        """Per piece, whether its samples take the smooth-shaded form."""
        return np.where(located, self.located_curved, self.table.smooth[units.tri[unit]])

    def keep(self, est, texels):
        """Which of ``texels`` take the next round (None: all)."""
        return None

    def run(self, kernel, tile, curved, unit, first, k, squares, located, vectors, replicates):
        s1, s2, rays, sec, cpu = kernel.run(tile, curved, unit, first, k, squares, located=located, vectors=vectors,
                                            replicates=replicates)
        return ChunkSums(k, s1, s2, vectors, len(unit) * k, rays, sec, cpu)

    def commit(self, est, texel, k, extra, replicate):
        pass

    def lost(self, est):
        """Per texel of a finished tile, whether none of its sample points found a surface: none here."""
        return np.zeros(len(est.rn[0]), bool)

    def counters(self):
        """What the stage counted over the bake (added up over worker processes): nothing here."""
        return {}


class TileBaker:
    """Bakes one tile: rasterise, build its sample units, trace the plan's rounds, estimate.

    Parameters
    ----------
    uvtris : the target's UV triangles (:func:`core.geometry.raster.prepare`), or None (units given directly,
        :meth:`trace`); table : its :class:`core.geometry.surface.SurfaceTable`; kernel, tracer, pattern : the
        bake's; settings : :class:`core.engine.settings.BakeSettings`; shared : the bake's
        :class:`core.engine.scheduler.Scheduler`; start : the start stage (a :class:`StartStage`:
        :class:`SurfaceStart` or :class:`core.highpoly.stage.HighPolyStart`); bent : also sum each texel's
        unoccluded directions (bent normals, :mod:`core.post.bent`).
    """

    def __init__(self, uvtris, table, kernel, tracer, pattern, settings, shared, start, bent=False):
        self.uvtris, self.table, self.kernel, self.tracer = uvtris, table, kernel, tracer
        self.pattern, self.s, self.shared, self.start = pattern, settings, shared, start
        self.plan = SamplingPlan(settings, grouped=start.grouped)
        #: None, or per texel of the image (its global id) the samples each replicate takes, decided
        #: before the bake (:meth:`core.engine.adaptive.SamplingPlan.rounds`' goal), or one int for all
        self.goal = None
        self.bent = bent
        self.seeds = allocation_seeds(settings)

    def layout(self, key, tri_ids):
        """(fragments, sample units or None, memo) of the tile ``key``'s texels: what the tile's texels
        are, whatever is traced from them. Bakes of several quantities over one layout
        (:func:`core.bake_maps`) take it once for all of them; nothing here depends on the tracer. The
        memo (a dict) keeps what :meth:`trace` computes from the layout alone (the texels' keys, the
        first round's allocation of samples to units) for the next quantity."""
        s = self.s
        frag = rasterize_tile(self.uvtris, tri_ids, s.width, s.height, *s.tile_bounds(key), locate=self.start.locate)
        return frag, (build_units(frag, self.table, s.width) if len(frag.texels) else None), {}

    def bake(self, key, tri_ids, layout=None):
        """(fragments, estimates, direction sums or None) of the tile ``key``'s texels; ``layout``:
        the tile's :meth:`layout`, when it was taken already."""
        s = self.s
        frag, units, memo = self.layout(key, tri_ids) if layout is None else layout
        if len(frag.texels) == 0:
            return frag, self.start.estimates(0, s.replicates), None
        contact = self.start.contact(frag, s.width, s.samples)
        est, sums = self.trace(units, frag.texels, contact, frag.texels % s.width, frag.texels // s.width,
                               tris=tri_ids, memo=memo)
        return frag, est, sums

    def trace(self, units, texel_ids, contact, x, y, tris=None, memo=None):
        """Trace the plan's rounds, in every replicate, for sample units ``units`` of the texels
        ``texel_ids`` (global ids: they key the texels' random choices); ``contact`` per texel, probe
        its samples for contact; ``x``, ``y`` where the error model pools each texel's variance
        (:func:`core.engine.estimators.window_sums`); ``tris`` the units' triangles, ascending (a superset is
        fine; None: found from the units). Texels need not be texels: mesh vertices are units of
        their own (:mod:`core.targets.corners`). ``memo``: None, or a dict shared by the quantities of one
        layout (:meth:`layout`). Returns (TexelEstimates, direction sums (n, 3) over all replicates,
        or None)."""
        s, shared, start = self.s, self.shared, self.start
        n_tex = len(texel_ids)
        est = start.estimates(n_tex, s.replicates)
        sums = np.zeros((n_tex, 3)) if self.bent else None
        if n_tex == 0:
            return est, sums
        memo = {} if memo is None else memo
        stacked = memo.get("keys")
        if stacked is None:  # the texels' keys depend on the pattern and the texels alone
            # Every replicate's keys in one tile: a round's pieces of all replicates go through the
            # kernel together (each call costs about half a millisecond before its first ray).
            stacked = memo["keys"] = TileContext.stacked_keys([self.pattern.keys(texel_ids, r)
                                                               for r in range(s.replicates)])
        tile = TileContext(self.table, units, stacked, texel_ids, contact, self.tracer.offset,
                           located_curved=start.located_curved, tris=tris,
                           inward=s.quantity == "thickness")
        if y is not None:  # the texels' windows, set up once for every round's pooling
            x, y = TexelWindows(x, y), None
        done = 0
        goal = (None if self.goal is None else np.full(len(texel_ids), self.goal, np.int64) if np.ndim(self.goal) == 0
                else self.goal[texel_ids])
        for first, count, texels in self.plan.rounds(est, np.arange(n_tex), x, y, goal=goal):
            keep = start.keep(est, texels)
            if keep is not None:
                if np.ndim(first):  # an adaptive round: each texel from its own count to its next
                    first, count = first[keep], count[keep]
                texels = texels[keep]
                if not len(texels):
                    continue
            done += self._trace(tile, units, est, sums, list(self.plan.shares(first, count, texels)), memo)
        # Credit the work the adaptive stop (and points that found nothing) saved, so progress reaches 1.
        shared.advance(n_tex * s.samples - done)
        return est, sums

    def _trace(self, tile, units, est, sums, shares, memo):
        """Trace one round: ``shares`` the (replicate, texels, start, count) of each replicate (in
        samples; a stage with ``per_point`` > 1 allocates whole points). Returns the work done."""
        s, shared, start = self.s, self.shared, self.start
        if not shares:
            return 0
        g = start.per_point

        def allocated(r, texels, first, count):
            # A round of every texel from one count to another (a fixed-count bake's only one) is
            # allocated alike for every quantity of the layout: kept in the memo.
            whole = np.ndim(first) == 0 and np.ndim(count) == 0 and len(texels) == tile.texels
            key = ("allocate", r, int(first) // g, int(count) // g) if whole else None
            if key in memo:
                return memo[key]
            out = allocate(units, texels, first // g, count // g, self.seeds[r], tile.texel_ids)
            if key is not None:
                memo[key] = out
            return out

        parts = [allocated(r, texels, first, count) for r, texels, first, count in shares]
        unit, first, size = (np.concatenate([p[i] for p in parts]) for i in range(3))
        rep = np.repeat(np.array([r for r, *_ in shares], np.int64), [len(p[0]) for p in parts])
        # Equal pieces go through the kernel together, squares before triangles, located texels
        # apart, in a fixed order (so every texel's sums are added in the same order however the
        # pieces are chunked); a replicate's pieces keep their order among each other.
        kind = units.kind[unit].astype(np.int64)
        located = kind == LOCATED
        curved = start.curved(units, unit, located)
        # Located texels go by their number of candidates too (each piece's location is then
        # the same arithmetic whatever else shares its call).
        cands = units.cand_first[unit + 1] - units.cand_first[unit]
        # One integer per piece: (size, curved, located, candidates) says its call, the last bit
        # puts squares before pieces of triangles; a stable sort keeps each texel's pieces in order.
        span = int(cands.max()) + 1 if len(cands) else 1
        key = (((size * 2 + curved) * 2 + located) * span + cands) * 2 + (kind == TRIANGLE)
        if len(key) and key.max() < 1 << 16:
            order = np.argsort(key.astype(np.uint16), kind="stable")  # a radix sort
        else:
            order = np.argsort(key, kind="stable")
        unit, first, size, kind, curved, cands, key, rep = (unit[order], first[order], size[order], kind[order],
                                                            curved[order], cands[order], key[order], rep[order])
        several = len(shares) > 1
        bounds = np.flatnonzero(np.diff(key >> 1)) + 1
        chunks = []
        for lo, hi in zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [len(size)]])):
            k = int(size[lo])
            # A located call holds 3 * candidates edge values per sample: bound it like the rays.
            step = max(1, s.chunk_rays // (k * g * max(1, int(cands[lo]) // 2)))
            chunks += [(int(lo), slice(int(c0), int(min(c0 + step, hi))), k) for c0 in range(lo, hi, step)]

        def compute(chunk):
            lo, c, k = chunk
            shared.check()
            squares = int(np.count_nonzero(kind[c] == SQUARE))
            vec = None if sums is None else np.empty((c.stop - c.start, 3))
            out = start.run(self.kernel, tile, bool(curved[lo]), unit[c], first[c], k, squares,
                            bool(kind[lo] == LOCATED), vec, rep[c])
            shared.advance(out.work, out.rays, out.seconds, out.cpu_seconds)
            return out

        done = 0

        def commit(chunk, out):
            nonlocal done
            _, c, k = chunk
            texel = units.texel[unit[c]]
            count = out.count
            for r in ([r for r, *_ in shares] if several else [shares[0][0]]):
                sel = rep[c] == r if several else slice(None)
                if several and not sel.any():
                    continue
                part = count[sel] if np.ndim(count) else count
                est.add(texel[sel], part, out.s1[sel], out.s2[sel], r)
            start.commit(est, texel, k, out.extra, rep[c])
            if out.vectors is not None:
                np.add.at(sums, texel, out.vectors)
            done += out.work

        # Chunks are committed in this order whichever thread traces them (the same sums, bit for bit).
        shared.run_chunks(chunks, compute, commit)
        return done


__all__ = ["TileBaker", "StartStage", "SurfaceStart", "ChunkSums", "TileOut", "allocation_seeds"]
