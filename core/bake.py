"""The bake pipeline: from a target mesh and its occluders to an ambient occlusion texture.

For a surface point x with shading normal n, AO(x) = (1/pi) * integral over the hemisphere of
V(x, w) cos(theta) dw, V = 1 where the ray from x along w meets nothing within max_distance. A texel's
value is the mean AO over the part of the surface its square covers.

One bake, per tile of texels (tiles go to worker threads; nothing a texel draws depends on which):

    core.raster      which pieces of which triangles each texel covers
    core.surface     sample units: affine maps from the unit square / triangle to the surface, normals
    core.patterns    each texel's 4D sample points (direction, position in the texel)
    core.kernel      rays of a chunk of units in one matrix product; Embree through core.tracing
    core.estimators  per-texel sums, standard errors, and the rounds adaptive sampling takes
    core.margin      extends the islands into the margin

Estimators: cosine-weighted directions (p = cos/pi) give the term V(w), variance AO(1 - AO), exactly
0 on open surfaces; uniform directions (p = 1/(2 pi)) give 2 cos(theta) V(w). Both estimate the same
AO. Rays leave from the surface point pushed off along the geometric normal, on the side the shading
normal faces; a direction from the shading hemisphere that points below the geometric surface
(possible where interpolated normals bend away from the face) counts as occluded without being
traced: that is what a ray leaving the true surface would meet first, the surface itself, and it
keeps AO continuous across smooth-shaded terminators.
"""

import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from . import bent as bent_mod
from ._version import __version__
from .errors import BakeCancelled, BakeMemoryError, MeshError, SettingsError
from .estimators import ErrorModel, SamplingPlan, TexelEstimates, TexelWindows, interval_half_width
from .kernel import Kernel, TileContext
from .margin import dilate
from .mesh import Mesh
from .patterns import TexelPattern, hash64
from . import raster as R
from .raster import bin_triangles, prepare, rasterize_tile
from .settings import (DISTRIBUTIONS, MAX_RESOLUTION, MAX_SAMPLES, SAMPLE_PIECE, BakeSettings, auto_tile_shape,
                       available_memory, estimate_memory)
from .surface import LOCATED, SQUARE, TRIANGLE, SurfaceTable, allocate, build_units, contact_texels
from .tracing import Tracer
from . import highpoly as _highpoly


@dataclass
class BakeResult:
    """What a bake returns. Arrays are (H, W), row 0 is v = 0 (Blender's pixel order).

    ao : float32 in [0, 1]; covered texels hold their estimate, margin texels the dilated value,
        the rest 0.
    mask : bool, texels a UV triangle covers.
    stderr : float32, each covered texel's standard error (0 elsewhere): the error its estimate
        makes, with replicates (see :func:`bake_ao`); an upper bound for the quasi-Monte Carlo
        sources without (``metadata['error_estimate']`` says which).
    samples : int32, samples taken per covered texel (0 elsewhere).
    rays : rays handed to Embree (a direction below the geometric surface goes with length 0 and
        counts as occluded).
    seconds : wall time of the bake; trace_seconds : time inside embreex, summed over threads;
    trace_cpu_seconds : the same in thread CPU time (steadier on a shared machine).
    metadata : settings and version, for image files.
    miss : selected to active only (else None): bool, texels a UV triangle covers where no sample
        point's matching ray found the high-poly surface; they are not in ``mask`` (the margin
        fills them). See :mod:`core.highpoly`.
    missed : selected to active only: sample points whose matching ray missed (each point carries a
        block of samples, ``report['directions_per_point']``; none of them is traced).
    report : counts of what the input held: degenerate UV triangles skipped, triangles of zero area
        in space skipped (they have no surface), triangles with UVs
        outside [0, 1] (only their part inside the image is baked), texels covered by more than one
        UV island (averaged over all surfaces covering them), covered texels.
    bent : None, or with ``bent_normals``, (H, W, 3) float32 unit bent normals in the bake's
        ``bent_space`` (covered and margin texels; zero elsewhere), see :mod:`core.bent`.
    """

    ao: np.ndarray
    mask: np.ndarray
    stderr: np.ndarray
    samples: np.ndarray
    rays: int
    seconds: float
    trace_seconds: float
    threads: int
    trace_cpu_seconds: float = 0.0
    metadata: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)
    bent: np.ndarray = None
    miss: np.ndarray = None
    missed: int = 0

    @property
    def rays_per_second(self):
        return self.rays / self.seconds if self.seconds > 0 else float("nan")


def _cancelled(cancel):
    if cancel is None:
        return False
    if hasattr(cancel, "is_set"):
        return cancel.is_set()
    return bool(cancel())


class _Shared:
    """State the worker threads share: progress, cancellation, errors, timing, and the chunks of
    rays a thread with no tile left may trace for another (:meth:`run_chunks`).

    Progress is reported on the bake's own events (each chunk of rays traced, each tile finished),
    never throttled by a clock: what a caller sees does not depend on how fast the machine is.
    Callers that draw a progress bar throttle their drawing themselves.
    """

    def __init__(self, total_work, progress, cancel):
        self.lock = threading.Lock()
        self.total = max(total_work, 1)
        self.done = 0
        self.progress = progress
        self.cancel = cancel
        self.stop = threading.Event()
        self.trace_seconds = 0.0
        self.trace_cpu_seconds = 0.0
        self.rays = 0
        # Chunks open to helpers (see run_chunks); set up by _run_all when it runs several threads.
        self.jobs = None
        self.changed = threading.Condition(threading.Lock())
        self.pending = 0

    def check(self):
        if self.stop.is_set():
            raise _Stop()
        if _cancelled(self.cancel):
            self.halt()
            raise _Stop()

    def halt(self):
        """Stop every worker: set ``stop`` and wake the threads waiting for chunks to help with."""
        self.stop.set()
        with self.changed:
            self.changed.notify_all()

    def advance(self, work, rays=0, trace_seconds=0.0, trace_cpu_seconds=0.0):
        with self.lock:
            self.done += work
            self.rays += rays
            self.trace_seconds += trace_seconds
            self.trace_cpu_seconds += trace_cpu_seconds
            if self.progress is not None and work > 0:
                self.progress(min(self.done / self.total, 1.0))

    def run_chunks(self, chunks, compute, commit):
        """commit(chunk, compute(chunk)) for every chunk, the commits in order on this thread.

        With several threads, the chunks are open to the threads that have no item of their own
        left (the last tiles of a bake): any thread may compute a chunk, this one commits them in
        order. So a texel's sums are added in the same order whoever traced its rays, and the
        result does not depend on the threads. This thread computes chunks too while it waits for
        the next one to commit.
        """
        if self.jobs is None or len(chunks) < 2:
            for c in chunks:
                commit(c, compute(c))
            return
        job = _Chunks(chunks, compute)
        with self.changed:
            self.jobs.append(job)
            self.changed.notify_all()
        try:
            for i, c in enumerate(chunks):
                commit(c, job.result(i))
        finally:
            with self.changed:
                self.jobs.remove(job)

    def help(self):
        """Compute other threads' chunks until every item is done (or the bake stops)."""
        with self.changed:
            while not self.stop.is_set() and self.pending > 0:
                job = max(self.jobs, key=_Chunks.left, default=None)
                i = job.claim() if job is not None else None
                if i is None:
                    self.changed.wait()
                    continue
                self.changed.release()
                try:
                    job.run(i)
                finally:
                    self.changed.acquire()


class _Chunks:
    """The chunks of one round of one tile, claimed in order by its own thread and by helpers."""

    def __init__(self, chunks, compute):
        self.chunks, self.compute = chunks, compute
        self.lock = threading.Lock()
        self.next = 0
        self.results = [None] * len(chunks)
        self.ready = [threading.Event() for _ in chunks]

    def left(self):
        return len(self.chunks) - self.next

    def claim(self):
        """The index of the next chunk no thread has taken, or None."""
        with self.lock:
            i = self.next
            if i >= len(self.chunks):
                return None
            self.next = i + 1
            return i

    def run(self, i):
        try:
            self.results[i] = (True, self.compute(self.chunks[i]))
        except BaseException as e:  # raised on the committing thread, in its turn
            self.results[i] = (False, e)
        self.ready[i].set()

    def result(self, i):
        """Chunk i's result, computing the next open chunks (this one or later ones) until it is
        ready."""
        while not self.ready[i].is_set():
            j = self.claim()
            if j is None:
                self.ready[i].wait()
                break
            self.run(j)
        ok, value = self.results[i]
        self.results[i] = None
        if not ok:
            raise value
        return value


class _Stop(Exception):
    """Raised inside workers once the bake is cancelled or another worker failed."""


def allocation_seeds(settings):
    """Per replicate, the seed :func:`core.surface.allocate` splits texels' samples with. Replicate 0
    keeps the bake's seed (one replicate traces what a bake always traced); the others allocate from
    seeds of their own, independent of it (also used by :class:`core.highpoly.HighPolyBaker`)."""
    return [np.uint64(settings.seed)] + [hash64(np.uint64(settings.seed), np.uint64(r), np.uint64(31))
                                         for r in range(1, settings.replicates)]


def _run_all(work, items, threads, shared, progress):
    """work(item) for every item, on ``threads`` threads; the first error stops the others and is
    raised, a cancel (``shared.stop``) raises BakeCancelled; progress reaches 1 at the end. Shared by
    the texel bake and the vertex bake (core.vertices).

    With several threads, each takes the next item until none is left, then helps the threads
    still working with their chunks of rays (:meth:`_Shared.run_chunks`) until every item is done:
    no thread idles while the last tiles are traced, and one tile alone is traced by all of them.
    """

    def guarded(item):
        try:
            work(item)
        except _Stop:
            pass
        except BaseException:
            shared.halt()
            raise

    if threads == 1:
        for item in items:
            guarded(item)
    else:
        queue = iter(list(items))
        shared.jobs, shared.pending = [], len(items)

        def worker():
            try:
                while not shared.stop.is_set():
                    with shared.changed:
                        item = next(queue, _Stop)
                    if item is _Stop:
                        break
                    try:
                        guarded(item)
                    finally:
                        with shared.changed:
                            shared.pending -= 1
                            shared.changed.notify_all()
            finally:
                shared.help()

        with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="mc_ao") as pool:
            for f in [pool.submit(worker) for _ in range(threads)]:
                f.result()
    if shared.stop.is_set():
        raise BakeCancelled("the bake was cancelled; nothing was written")
    if progress is not None:
        progress(1.0)


class _TileBaker:
    """Bakes one tile: rasterise, build its sample units, trace the plan's rounds, estimate.

    ``bent``: also sum each texel's unoccluded directions (bent normals, :mod:`core.bent`).
    """

    def __init__(self, uvtris, table, kernel, tracer, pattern, settings, shared, bent=False):
        self.uvtris, self.table, self.kernel, self.tracer = uvtris, table, kernel, tracer
        self.pattern, self.s, self.shared = pattern, settings, shared
        self.plan = SamplingPlan(settings)
        self.bent = bent
        self.seeds = allocation_seeds(settings)
        # Located samples take one matrix form for the whole bake (see core.kernel.TileContext).
        self.located_curved = bool(uvtris is not None and np.any(table.smooth[uvtris.valid]))

    def bake(self, key, tri_ids):
        """(fragments, estimates, direction sums or None) of the tile ``key``'s texels."""
        s = self.s
        frag = rasterize_tile(self.uvtris, tri_ids, s.width, s.height, *s.tile_bounds(key))
        if len(frag.texels) == 0:
            return frag, TexelEstimates(0, s.replicates), None
        units = build_units(frag, self.table, s.width)
        contact = contact_texels(frag, self.table, s.width, self.tracer, s.samples)
        est, sums = self.trace(units, frag.texels, contact, frag.texels % s.width, frag.texels // s.width,
                               tris=tri_ids)
        return frag, est, sums

    def trace(self, units, texel_ids, contact, x, y, tris=None):
        """Trace the plan's rounds, in every replicate, for sample units ``units`` of the texels
        ``texel_ids`` (global ids: they key the texels' random choices); ``contact`` per texel, probe
        its samples for contact; ``x``, ``y`` where the error model pools each texel's variance
        (:func:`core.estimators.window_sums`); ``tris`` the units' triangles, ascending (a superset is
        fine; None: found from the units). Texels need not be texels: mesh vertices are units of
        their own (:mod:`core.vertices`). Returns (TexelEstimates, direction sums (n, 3) over all
        replicates, or None)."""
        s, shared = self.s, self.shared
        n_tex = len(texel_ids)
        est = TexelEstimates(n_tex, s.replicates)
        sums = np.zeros((n_tex, 3)) if self.bent else None
        if n_tex == 0:
            return est, sums
        keys = [self.pattern.keys(texel_ids, r) for r in range(s.replicates)]
        # Every replicate's keys in one tile: a round's pieces of all replicates go through the
        # kernel together (each call costs about half a millisecond before its first ray).
        tile = TileContext(self.table, units, TileContext.stacked_keys(keys), texel_ids, contact, self.tracer.offset,
                           located_curved=self.located_curved, tris=tris)
        if y is not None:  # the texels' windows, set up once for every round's pooling
            x, y = TexelWindows(x, y), None
        for start, count, texels in self.plan.rounds(est, np.arange(n_tex), x, y):
            self._trace(tile, units, est, sums, list(self.plan.shares(start, count, texels)))
        # Credit the work the adaptive stop saved, so progress reaches 1.
        shared.advance(n_tex * s.samples - int(est.n.sum()))
        return est, sums

    def _trace(self, tile, units, est, sums, shares):
        """Trace one round: ``shares`` the (replicate, texels, start, count) of each replicate."""
        s, shared = self.s, self.shared
        if not shares:
            return
        parts = [allocate(units, texels, start, count, self.seeds[r], tile.texel_ids) for r, texels, start, count in shares]
        unit, first, size = (np.concatenate([p[i] for p in parts]) for i in range(3))
        rep = np.repeat(np.array([r for r, *_ in shares], np.int64), [len(p[0]) for p in parts])
        # Equal pieces go through the kernel together, squares before triangles, located texels
        # apart, in a fixed order (so every texel's sums are added in the same order however the
        # pieces are chunked); a replicate's pieces keep their order among each other.
        kind = units.kind[unit].astype(np.int64)
        located = kind == LOCATED
        curved = np.where(located, self.located_curved, self.table.smooth[units.tri[unit]])
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
            step = max(1, s.chunk_rays // (k * max(1, int(cands[lo]) // 2)))
            chunks += [(int(lo), slice(int(c0), int(min(c0 + step, hi))), k) for c0 in range(lo, hi, step)]

        def compute(chunk):
            lo, c, k = chunk
            shared.check()
            squares = int(np.count_nonzero(kind[c] == SQUARE))
            vec = None if sums is None else np.empty((c.stop - c.start, 3))
            s1, s2, rays, sec, cpu = self.kernel.run(tile, bool(curved[lo]), unit[c], first[c], k, squares,
                                                     located=bool(kind[lo] == LOCATED), vectors=vec,
                                                     replicates=rep[c])
            shared.advance(rays, rays, sec, cpu)
            return s1, s2, vec

        def commit(chunk, result):
            _, c, k = chunk
            s1, s2, vec = result
            texel = units.texel[unit[c]]
            if several:
                for r, *_ in shares:
                    sel = rep[c] == r
                    if sel.any():
                        est.add(texel[sel], k, s1[sel], s2[sel], r)
            else:
                est.add(texel, k, s1, s2, shares[0][0])
            if vec is not None:
                np.add.at(sums, texel, vec)

        # Chunks are committed in this order whichever thread traces them (the same sums, bit for bit).
        shared.run_chunks(chunks, compute, commit)


#: Occluders farther than this many target sizes from the target are refused: float32 rays cannot
#: hold both (and so far away they cannot occlude it measurably).
MAX_SCENE_SPAN = 1e15


def _frame(target):
    """(centre, unit) of the frame :func:`_normalized_scene` moves a bake into."""
    lo, hi = target.positions.min(axis=0), target.positions.max(axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        unit = float(np.max(hi - lo))
    if not math.isfinite(unit):
        raise MeshError(f"mesh {target.name!r} spans more than the largest float ({unit}); scale it down")
    if unit <= 0 or unit < np.finfo(np.float64).tiny * 1e3:
        unit = 1.0  # a point: every triangle is degenerate and skipped anyway
    return (lo + hi) / 2.0, unit


def _normalized_scene(target, occluders):
    """The target and its occluders in a frame centred on the target and scaled to its size.

    AO does not depend on the unit (max_distance scales with it), but float32 rays do: a scene
    modelled in metres at 1e13 or at 1e-14 loses the offsets that keep rays off their own surface.
    In this frame the target spans about 1 around the origin whatever units the input used.
    Occluders that are the target again (the same object or the same surface) are dropped: a
    surface coinciding with the target would hide every ray.

    Returns (target, occluders, unit): the world length of one unit of the new frame.
    """
    kept = []
    for o in occluders:
        if o is target or target.same_geometry(o) or any(o is k or k.same_geometry(o) for k in kept):
            continue
        kept.append(o)
    centre, unit = _frame(target)
    scene = []
    for o in kept:
        m = o.transformed(centre, unit)
        far = float(np.abs(m.positions).max())
        if not far < MAX_SCENE_SPAN:
            raise MeshError(
                f"occluder {o.name!r} reaches {far:.3g} times the size of {target.name!r} away from it; "
                "ray tracing in single precision cannot hold both: leave it out of the occluders"
            )
        scene.append(m)
    return target.transformed(centre, unit), scene, unit




def bake_ao(target, occluders=(), resolution=(1024, 1024), samples=256, *, min_samples=16, target_error=0.0,
            max_distance=float("inf"), distribution="cosine", source="sobol", margin=16, seed=0, threads=None,
            ignore_backfaces=False, falloff=0.0, replicates=2, progress=None, cancel=None, on_tile=None,
            tile_size=None, chunk_rays=1 << 16, on_rays=None, bent_normals=False, bent_space=None, highpoly=None,
            extrusion=0.0, max_ray_distance=0.0, cage=None):
    """Bake ambient occlusion of ``target`` into a (H, W) texture over its UVs.

    With ``highpoly``, bake the AO of the high-poly meshes into the target's UVs instead (Blender's
    "Selected to Active"): each sample point of the target is moved to the high-poly surface by
    Cycles' rules and AO is evaluated there (:mod:`core.highpoly` says exactly how).

    Parameters
    ----------
    target : Mesh with UVs. It always occludes itself.
    occluders : Meshes (UVs not needed) that also block rays, in the same world space.
    resolution : int or (width, height) in texels.
    samples : the most samples per texel (every texel takes exactly this many when adaptive is off).
    min_samples : with adaptive sampling, what every texel takes before it may stop.
    target_error : adaptive sampling when > 0: a texel stops once the half-width of its 95%
        confidence interval is at most this (in AO units: 0.01 means its AO is known to +-0.01, 95%
        of the time), after ``min_samples`` and rounds that grow its count to what its interval
        predicts (see :class:`core.estimators.SamplingPlan`). With replicates (the default) the
        interval comes from the pooled error estimate of :mod:`core.estimators`: texels whose whole
        neighbourhood agrees (open, or fully occluded) stop at ``min_samples``, texels whose samples
        agree beside varying ones go on. Without (``replicates=1``) it is Agresti and Coull's
        interval for independent samples, which never stops an open texel before about
        2.7 / target_error samples. 0 turns adaptive sampling off.
    max_distance : occluders farther than this along a ray do not count (world units).
    distribution : 'cosine' (importance sampling, default) or 'uniform' (weight 2 cos theta).
    source : 'sobol' (Owen-scrambled, default), 'stratified', 'independent' or 'halton'.
    margin : texels to extend each UV island by, from the nearest covered texel.
    seed : non-negative integer; the same seed gives a bit-identical result for any thread count.
    threads : worker threads (None: every core this process may use).
    ignore_backfaces : hits on the back of a triangle (its winding's normal facing along the ray)
        do not occlude; the ray continues past them.
    falloff : 0 for plain AO; p > 0 weighs a hit at distance t by (1 - t / max_distance)^p, so
        distant occluders darken less (needs a finite max_distance).
    replicates : how many independent randomisations a texel's samples are split into (1 to 16,
        at most ``samples``). With 2 (the default) or more, ``stderr`` is the error the texel's
        estimate really makes, for every sample source (the spread between replicates, pooled over
        neighbouring texels: :mod:`core.estimators`), at a cost in noise: two sets of N/2 points
        are a worse set than one of N (measured at equal rays: Sobol' 1.16-1.20 times the RMSE,
        Halton 1.14-1.19, stratified 1.29-1.31, independent 1.0). With 1 the noise is lowest and
        ``stderr`` is the independent-sample formula: exact for independent samples, 2 to 3 times
        too large for the quasi-Monte Carlo sources.
    progress : called as progress(fraction) from worker threads, one call at a time, after every
        chunk of rays and every finished tile (not on a clock: the calls a bake makes do not depend
        on the machine's speed), and once with 1.0 at the end. Throttle any drawing in the callback.
    cancel : a threading.Event or a callable returning True to stop; checked between chunks of
        rays. A cancelled bake raises BakeCancelled and returns nothing.
    on_tile : called as on_tile(rows, cols, ao_block) from worker threads when a tile of texels is
        final (before margin dilation); ``rows``, ``cols`` are slices of the (H, W) result.
    tile_size, chunk_rays : the unit of work a thread takes, in texels: a side (square tiles) or
        (columns, rows), rounded up to multiples of 16 (None: :func:`core.settings.auto_tile_shape`
        of the resolution, threads and samples), and rays traced per call into Embree (bounds memory;
        a thread with no tile left traces chunks of the tiles still running). Neither changes the
        result: texels draw their samples by (texel, index) alone, and each tile adds its chunks'
        sums in the same order whichever thread traced them.
    on_rays : called as on_rays(batch) from worker threads after every call into Embree, with a
        :class:`core.tracing.RayBatch` (origins, directions, lengths, Embree's answer, the texel and
        sample index of every ray, the call's time). Its arrays are valid during the call only.
    bent_normals : also estimate each texel's bent normal from the same rays (no extra ray):
        ``BakeResult.bent``. See :mod:`core.bent`.
    bent_space : the space of the bent normals: None (world space), a (3, 3) matrix (M b,
        normalised; Blender's object space is the inverse of the object's matrix) or a
        :class:`core.bent.TangentFrames` (tangent space, Blender's normal-map convention).
    highpoly : None, or a Mesh or a list of Meshes (corner normals used, UVs not needed) whose AO is
        baked into the target's UVs. The high-poly meshes occlude, as do the ``occluders``; the target
        and the cage never do (left out of the occluders if they are among them).
    extrusion : with ``highpoly``, the distance (world units, >= 0) the matching rays start out from the
        target's surface along its interpolated normal, pointing back along it (Cycles' Extrusion).
    max_ray_distance : with ``highpoly``, the longest matching ray (world units, measured from where it
        starts), 0 for no limit.
    cage : with ``highpoly``, None or a Mesh of the target's topology (same vertex count and triangles,
        vertices moved): the matching rays go from the cage's points towards the target's (the
        extrusion is then not used).

    Returns
    -------
    BakeResult

    Raises
    ------
    MeshError, MeshTypeError, SettingsError, BakeMemoryError (before any heavy work), BakeCancelled.
    With ``highpoly``, also MeshError when no matching ray finds the high-poly surface (it says what
    to change), before any AO ray is traced.
    """
    t_start = time.perf_counter()
    if not isinstance(target, Mesh):
        raise SettingsError(f"the target must be a core.Mesh, got {type(target).__name__}")
    if target.uvs is None:
        raise MeshError(f"mesh {target.name!r} has no UVs: the baker needs a UV map to know where each texel lies")
    occluders = list(occluders or ())
    for o in occluders:
        if not isinstance(o, Mesh):
            raise SettingsError(f"occluders must be core.Mesh objects, got {type(o).__name__}")
    s = BakeSettings.from_arguments(resolution, samples, min_samples, target_error, max_distance, distribution,
                                    source, margin, seed, threads, ignore_backfaces, falloff, tile_size, chunk_rays,
                                    replicates)
    s2a = None
    if highpoly is not None:  # selected to active: checked here, before any work
        if bent_normals:
            raise SettingsError("bent normals are not baked with selected to active (highpoly): bake them "
                                "from the high-poly object itself, or bake AO only")
        s2a = _highpoly.SelectedToActive.check(target, highpoly, extrusion, max_ray_distance, cage)
        occluders = s2a.occluders_of(occluders)
        s2a = s2a.normalized(*_frame(target), MAX_SCENE_SPAN)
    bent_space = bent_mod.check_space(bent_space, target) if bent_normals else None
    target, occluders, unit = _normalized_scene(target, occluders)
    w, h = s.width, s.height
    tri_total = target.triangle_count + sum(o.triangle_count for o in occluders) + (s2a.triangle_count if s2a else 0)
    need = estimate_memory(w, h, tri_total, s.threads, s.chunk_rays, s.samples, s.source, s.replicates,
                           s.tile_shape[0] * s.tile_shape[1])
    avail = available_memory()
    if avail is not None and need > avail:
        raise BakeMemoryError(f"a {w} x {h} bake of {tri_total} triangles needs about {need / 2**30:.2f} GiB, "
                              f"but only {avail / 2**30:.2f} GiB is available; lower the resolution")
    if _cancelled(cancel):
        raise BakeCancelled("the bake was cancelled before it started")

    uvtris = prepare(target, w, h)
    s = s.fit_tiles(R.uv_centres(uvtris))  # automatic tiles of dense meshes: fewer triangles each
    table = SurfaceTable.build(target, uvtris)
    bins = bin_triangles(uvtris, w, h, s.tile_shape)
    stage = None if s2a is None else _highpoly.HighPolyStage(s2a, target, occluders, uvtris, table, bins, s, unit,
                                                              lambda: _cancelled(cancel))
    tracer = (Tracer([target] + occluders, s.ignore_backfaces, s.falloff, s.max_distance / unit) if stage is None
              else stage.scene.tracer)
    pattern = TexelPattern(s.source, s.seed, s.replicate_samples, pool_points=s.pool_points())
    kernel = Kernel(pattern, tracer, s.distribution, on_rays=on_rays)

    def rect(key):
        """Rows, columns and texel count of tile ``key``."""
        x0, y0, x1, y1 = s.tile_bounds(key)
        return slice(y0, y1), slice(x0, x1), (x1 - x0) * (y1 - y0)

    # Planned work: texel-samples of every tile's bounding rectangle is unknown before rasterising,
    # so count each tile's texels times samples as it is rasterised, against an upper bound.
    planned = sum(rect(key)[2] for key in bins) * s.samples
    shared = _Shared(planned, progress, cancel)
    baker = (_TileBaker(uvtris, table, kernel, tracer, pattern, s, shared, bent=bool(bent_normals)) if stage is None
             else stage.baker(pattern, shared, on_rays, allocation_seeds(s)))
    errors = ErrorModel(s, grouped=stage is not None)

    ao = np.zeros((h, w), np.float32)
    se = np.zeros((h, w), np.float32)
    count = np.zeros((h, w), np.int32)
    mask = np.zeros((h, w), bool)
    bent = np.zeros((h, w, 3), np.float32) if bent_normals else None
    coverage_over = 0
    keys = sorted(bins)

    def work(key):
        nonlocal coverage_over
        frag, est, sums = baker.bake(key, bins[key])
        r, c, area = rect(key)
        shared.advance(area * s.samples - len(frag.texels) * s.samples)
        if len(frag.texels):
            t = frag.texels
            rows, cols = t // w, t % w
            ao.reshape(-1)[t] = np.clip(est.mean, 0.0, 1.0)
            se.reshape(-1)[t] = errors.stderr(est, cols, rows)
            count.reshape(-1)[t] = est.n
            mask.reshape(-1)[t] = True
            if sums is not None:
                tri = bent_mod.primary_pieces(frag, w)
                weights = bent_mod.barycentric(table.corners_xy, tri, cols + 0.5, rows + 0.5)
                bent[rows, cols] = bent_mod.texel_directions(sums, tri, weights, target.normals, bent_space)
            if stage is not None:
                baker.settle(est, rows, cols, mask, se)
            with shared.lock:
                coverage_over += int((frag.coverage > 1.0 + R.OVERLAP_REPORT_AREA).sum())
            if on_tile is not None:
                with shared.lock:
                    on_tile(r, c, ao[r, c].copy())

    _run_all(work, keys, s.threads, shared, progress)

    miss, missed, extra = baker.finish(mask) if stage is not None else (None, 0, {})
    if s.margin > 0:
        dilate(ao, mask, s.margin, threads=s.threads, out=ao)
    if bent is not None:
        bent, _ = bent_mod.dilate_directions(bent, mask, s.margin, s.threads)
    seconds = time.perf_counter() - t_start
    metadata = dict(s.metadata(s.max_distance), version=__version__, rays=shared.rays)
    report = {"covered_texels": int(mask.sum()), "degenerate_uv_triangles": uvtris.degenerate,
              "degenerate_triangles": uvtris.degenerate_space,
              "uv_outside_triangles": uvtris.outside, "overlapping_texels": coverage_over}
    if stage is not None:
        metadata.update(s2a.metadata())
        report.update(extra)
    return BakeResult(ao=ao, mask=mask, stderr=se, samples=count, rays=shared.rays, seconds=seconds,
                      trace_seconds=shared.trace_seconds, threads=s.threads, metadata=metadata, report=report,
                      trace_cpu_seconds=shared.trace_cpu_seconds, bent=bent, miss=miss, missed=missed)


__all__ = ["bake_ao", "BakeResult", "DISTRIBUTIONS", "MAX_SAMPLES", "MAX_RESOLUTION", "SAMPLE_PIECE",
           "estimate_memory", "available_memory", "interval_half_width", "auto_tile_shape"]
