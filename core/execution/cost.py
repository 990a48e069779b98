"""What a bake will cost before it runs: its time and its memory, from its size, calibrated by the bench.

The time is a linear model of the work a bake does, fitted to the bench's own bakes
(bench/results/latest.json: the resolution, one-sample and triangle rows, 2 shared cores):

    CPU seconds = NS_PER_RAY rays + NS_PER_TEXEL covered texels + NS_PER_TRIANGLE triangles + FIXED

(rays: covered texels times samples; triangles: every mesh the bake holds), and the wall time is that
over the cores the bake uses at PARALLEL_EFFICIENCY. It is 0.53-1.27 times the measured time on every
bench row (tests/test_cost.py; the one-sample 512^2 bake the lowest), and errs more on machines far
from that one (a faster core scales it all) and on scenes whose rays cost more (long rays through
dense geometry): an estimate to show before a bake, not a promise. Adaptive sampling takes fewer samples than the most it may: the estimate is for the
most.

The memory, ONE model for every use: the result's planes and the margin's work per image texel, each
process's copy of the scene per triangle (a target's, an occluder's and a high-poly mesh's triangles
cost differently), what the parent keeps per triangle while worker processes bake, a process's fixed
share (an interpreter with numpy, embreex and the sample pool), and the chunks of rays in flight per
thread (the model the bench's peak memory rows check; the per-triangle figures are
bench.sections.memory's). :func:`estimate` prices a bake before it is set up (the add-on's panel,
:func:`core.execution.executor.auto_workers`); :func:`bake_bytes` is what a bake set up in this
process adds, with its sample pool and its tiles' sample units, the figure a bake is refused on
(:meth:`core.pipeline.prologue.Prologue.check_memory`).
"""

from dataclasses import dataclass

import numpy as np

from ..engine.patterns import POOL_POINTS
from ..engine.settings import SAMPLE_PIECE, TILE_SIDE, pattern_span

#: The time model (nanoseconds), fitted to the bench's bakes on 2 cores (see the module docstring).
NS_PER_RAY, NS_PER_TEXEL, NS_PER_TRIANGLE, FIXED_SECONDS = 168.0, 520.0, 3570.0, 0.075
#: Wall time over CPU time on n cores, the bench's 2-thread bakes: 0.52-0.67 of the CPU time.
PARALLEL_EFFICIENCY = 0.9
#: Nanoseconds of CPU per covered texel of a denoised map (the surface guide and the filter: measured
#: on the Suzanne scene, 64 samples, 256^2 and 512^2 in one thread, 6.7-7.1 us; bench.sections.estimate).
NS_PER_DENOISED_TEXEL = 7000.0
#: CPU seconds to start one worker process (an interpreter, numpy and embreex imported, its self-test):
#: 0.31-0.40 measured on 2 shared cores (children's CPU time, 2 workers, three starts).
WORKER_START_SECONDS = 0.35
#: Bytes: per image texel (ao, stderr, samples, mask planes, the margin's work), a process's own, and
#: per ray of a chunk in flight.
BYTES_PER_TEXEL, BYTES_PER_PROCESS, BYTES_PER_CHUNK_RAY = 26, 150 << 20, 200
#: Bytes per triangle of a process that bakes tiles, at its peak beyond its idle size
#: (bench.sections.memory, 2M-triangle grids on 2 workers, bench/results/memory*.txt): a target's
#: (its float32 UV triangles and bins as the parent laid them out, its surface table, Embree scene, the
#: positions and triangles it was sent: 281 measured, memory-layout.txt; 316 when it was sent the UVs
#: and laid them out itself), an occluder's (two Embree scenes, occlusion and contact:
#: 412) and a high-poly mesh's (one robust scene that matches and occludes: 193; 161 at 10M
#: triangles), with some headroom.
BYTES_PER_TRIANGLE, BYTES_PER_OCCLUDER_TRIANGLE, BYTES_PER_HIGHPOLY_TRIANGLE = 340, 450, 220
#: Bytes a point of the sample pool takes (its 4D point and two sets of lifted features), and a sample
#: unit (its affine maps; a few per texel of a tile, UNITS_PER_TEXEL).
BYTES_PER_POOL_POINT, BYTES_PER_UNIT, UNITS_PER_TEXEL = 64, 600, 4
#: Threads or processes (:func:`choose_parallel`): the model of how a bake's work shares the cores, from
#: the bench's quiet 2-core runs (bench/results/device.json, bench/LOG.md "threads or processes").
#: n busy cores run n / (1 + CORE_CONTENTION (n - 1)) times one (2 worker processes: 1.88x); T threads of
#: one process run a further T / (1 + GIL_SHARE (T - 1)) slower (their numpy calls wait for each other's
#: Python: 2 threads 1.71x against 1 thread).
CORE_CONTENTION, GIL_SHARE = 0.064, 0.10
#: The part of NS_PER_TRIANGLE that is set-up before the tiles (CPU ns a triangle; the rest is the tiles'
#: per-triangle work, which the cores share): the prologue, UV triangles and bins (the parent's; worker
#: processes bake from its layout), the surface table (each process that bakes tiles) and the Embree scene
#: (each such process; a worker keeps its scene for the next bake of the same meshes). Measured on
#: dense.blend's 524k triangles (bench.sections.parallel).
NS_SETUP_PER_TRIANGLE, NS_TABLE_PER_TRIANGLE, NS_EMBREE_PER_TRIANGLE = 270.0, 390.0, 120.0
#: What a worker process repeats of the parent's set-up (CPU ns a triangle of the target): the checks and
#: the prologue of the job's meshes; its UV triangles and tiles come laid out in the job
#: (bench.sections.parallel --components: the worker's steps with the layout sent against the UVs sent).
NS_WORKER_SETUP_PER_TRIANGLE = 40.0
#: Bytes a triangle of the target puts in a worker's job in place of its UVs (48): its UV triangle's
#: float32 corners and two flags (26) and its entry in its tile's bins (8; a few triangles across a
#: tile's edge are in two).
LAYOUT_BYTES_PER_TRIANGLE = 36
#: A worker's job (the meshes as arrays): CPU ns a byte to send it (the parent, worker after worker)
#: and to receive it (each worker); a bake's fixed cost on a warm pool (messages, the worker's bake set
#: up, the results assembled); the share of a mean tile the last tiles leave workers idle (tiles go
#: whole to one worker: 4 tiles on 2 workers measured 7-11% over an even split, bench.sections.parallel).
#: A pool's start is WORKER_START_SECONDS of each worker, side by side, until one is measured in this process.
NS_SEND_PER_BYTE, NS_RECEIVE_PER_BYTE, WORKER_BAKE_SECONDS, TAIL_TILES = 1.0, 0.5, 0.015, 0.25
#: Bytes per triangle the parent adds while worker processes bake (its UV triangles and tiles of the
#: target: 90 measured; 30 for an occluder or a high-poly mesh), beyond the caller's own arrays.
BYTES_PER_PARENT_TRIANGLE, BYTES_PER_PARENT_OTHER_TRIANGLE = 110, 40


@dataclass(frozen=True)
class Cost:
    """An estimate: ``seconds`` of wall time and peak ``bytes`` (every process together)."""

    seconds: float
    bytes: int

    def describe(self):
        """E.g. 'about 12 s and 1.3 GiB', 'under a second and 300 MiB'."""
        s = self.seconds
        t = ("under a second" if s < 1 else f"{s:.1f} s" if s < 10 else f"{s:.0f} s" if s < 120
             else f"{s / 60:.0f} min")
        gib = self.bytes / 2 ** 30
        m = f"{gib:.1f} GiB" if gib >= 1 else f"{self.bytes / 2 ** 20:.0f} MiB"
        return f"{t} and {m}" if s < 1 else f"about {t} and {m}"


def process_bytes(triangles, occluder_triangles=0, highpoly_triangles=0):
    """Peak bytes of one process that bakes tiles of a target of ``triangles`` with these occluder
    and high-poly triangles (its interpreter included)."""
    return int(BYTES_PER_PROCESS + scene_bytes(triangles, occluder_triangles, highpoly_triangles))


def scene_bytes(triangles, occluder_triangles=0, highpoly_triangles=0):
    """Bytes of one process's copy of a bake's scene (tables and Embree scenes), its interpreter aside."""
    return int(BYTES_PER_TRIANGLE * int(triangles) + BYTES_PER_OCCLUDER_TRIANGLE * int(occluder_triangles)
               + BYTES_PER_HIGHPOLY_TRIANGLE * int(highpoly_triangles))


def chunk_bytes(threads, chunk_rays, rays):
    """Bytes of the chunks of rays ``threads`` threads have in flight (at most ``rays`` rays each)."""
    return int(threads) * min(int(chunk_rays), int(rays)) * BYTES_PER_CHUNK_RAY


def bake_bytes(width, height, triangles, threads, chunk_rays, samples=1, source="sobol", replicates=1,
               tile_texels=TILE_SIDE * TILE_SIDE):
    """Peak bytes a bake set up in this process adds: the image's planes and margin work, the scene
    (``triangles``: a count, costed as the target's, or (target, occluder, high-poly) triangles), the
    chunks of rays in flight, the sample pool and the tiles' sample units.

    A chunk holds at most ``max(chunk_rays, SAMPLE_PIECE)`` rays (a texel with more samples is traced
    in pieces). The sample pool holds at least one pattern of the sample count and at most
    :data:`core.engine.patterns.POOL_POINTS` points otherwise.
    """
    target, occluders, highpoly = (int(triangles), 0, 0) if np.ndim(triangles) == 0 else map(int, triangles)
    texels = int(width) * int(height)
    span = pattern_span(source, -(-samples // replicates))
    pool = max(span * replicates, min(POOL_POINTS, texels * replicates * span)) * BYTES_PER_POOL_POINT
    units = int(threads) * min(int(tile_texels), texels) * UNITS_PER_TEXEL * BYTES_PER_UNIT
    return int(BYTES_PER_TEXEL * texels + scene_bytes(target, occluders, highpoly)
               + chunk_bytes(threads, max(chunk_rays, min(samples, SAMPLE_PIECE)), max(chunk_rays, samples))
               + pool + units)


def parent_bytes(triangles, other_triangles=0):
    """Bytes the parent adds while worker processes bake (beyond the caller's arrays)."""
    return int(BYTES_PER_PARENT_TRIANGLE * int(triangles) + BYTES_PER_PARENT_OTHER_TRIANGLE * int(other_triangles))


def estimate(covered_texels, samples, triangles, image_texels=None, threads=1, processes=1, chunk_rays=1 << 16,
             occluder_triangles=0, highpoly_triangles=0, quantities=1, denoise=False, load=None, cpus=None,
             starting=0):
    """The :class:`Cost` of a bake of ``covered_texels`` at ``samples`` each, holding ``triangles``
    (the target's; occluders' and high-poly meshes' given apart, or counted in ``triangles``, which
    costs their time the same and overstates their memory), on ``processes`` x ``threads``
    (``image_texels``: the whole image, for the memory; the covered ones when not given).

    ``quantities``: the maps baked from it (AO and thickness: 2; each its own rays, a thickness ray
    costing about an AO ray, measured). ``denoise``: each map filtered (NS_PER_DENOISED_TEXEL a
    covered texel). ``load``: the machine's load before the bake (runnable threads, the 1-minute load
    average) on ``cpus`` cores: the bake's threads share the cores with it (:func:`cores_of`).
    ``starting``: worker processes the bake starts first (none where the pool is running already,
    core.execution.pool.pool_ready), WORKER_START_SECONDS of CPU each, side by side."""
    covered_texels, triangles = int(covered_texels), int(triangles)
    other = int(occluder_triangles) + int(highpoly_triangles)
    quantities = max(1, int(quantities))
    rays = covered_texels * int(samples) * quantities
    # Every process that bakes tiles builds its own tables and Embree scenes: the triangles' share is
    # paid once per process, side by side (a 524k-triangle terrain on 2 workers: twice the CPU).
    cpu = (NS_PER_RAY * rays + NS_PER_TEXEL * covered_texels * quantities
           + (NS_PER_DENOISED_TEXEL * covered_texels * quantities if denoise else 0.0)
           + NS_PER_TRIANGLE * (triangles + other) * max(1, int(processes))) * 1e-9 + FIXED_SECONDS
    cores = max(1, int(threads) * int(processes))
    seconds = cpu / cores_of(cores, load, cpus) / (PARALLEL_EFFICIENCY if cores > 1 else 1.0)
    if starting:
        seconds += WORKER_START_SECONDS * int(starting) / cores_of(int(starting), load, cpus)
    image = covered_texels if image_texels is None else int(image_texels)
    memory = (BYTES_PER_TEXEL * image + int(processes) * process_bytes(triangles, occluder_triangles, highpoly_triangles)
              + (parent_bytes(triangles, other) if int(processes) > 1 else 0)
              + chunk_bytes(cores, chunk_rays, rays))
    return Cost(float(seconds), int(memory))


def cores_of(threads, load=None, cpus=None):
    """The cores ``threads`` busy threads get on ``cpus`` cores already running ``load`` runnable
    threads (the load average): all they ask for on an idle machine, a fair share of the cores on a
    busy one (threads x cpus / (load + threads), at most threads and cpus)."""
    threads = max(1, int(threads))
    if load is None or not cpus:
        return threads
    return max(min(threads, cpus, threads * cpus / (max(0.0, float(load)) + threads)), 0.05)


def machine_load():
    """(the 1-minute load average, the cores) of this machine, or (None, None) where the system does
    not say (Windows)."""
    import os

    try:
        return os.getloadavg()[0], os.cpu_count()
    except (AttributeError, OSError):
        return None, None


@dataclass(frozen=True)
class Work:
    """What a bake will do, for :func:`choose_parallel`: ``covered`` texels (or points) of ``samples``
    each on a ``width`` x ``height`` image, ``triangles`` (target, occluders, high-poly) and the
    ``job_bytes`` a worker process is sent (the meshes' arrays; an image's target with its layout,
    LAYOUT_BYTES_PER_TRIANGLE, in place of its UVs)."""

    covered: float
    samples: int
    triangles: tuple
    width: int = 1
    height: int = 1
    job_bytes: int = 0

    def tile_seconds(self):
        """CPU seconds of the tiles' work on one thread (what the cores share)."""
        tiles_per_triangle = NS_PER_TRIANGLE - NS_SETUP_PER_TRIANGLE - NS_TABLE_PER_TRIANGLE - NS_EMBREE_PER_TRIANGLE
        return 1e-9 * (NS_PER_RAY * self.covered * self.samples + NS_PER_TEXEL * self.covered
                       + tiles_per_triangle * sum(self.triangles))


def speedup(processes, threads):
    """How many times one thread's speed ``processes`` x ``threads`` run the tiles at (the model above)."""
    n = processes * threads
    return n / (1.0 + CORE_CONTENTION * (n - 1)) / (1.0 + GIL_SHARE * (threads - 1))


def parallel_seconds(work, processes, threads, pool_start=0.0, scene_kept=False, tiles=None):
    """Predicted wall seconds of ``work`` on ``processes`` x ``threads`` (1 x T: this process's threads),
    as {part: seconds}: ``parent`` (the checks, UV triangles and bins, the margin and the result, in
    this process either way), ``scene`` (a baking process's surface table and Embree scene), ``tiles``
    (the tiles' work shared by the cores) and, in worker processes, ``start`` (a pool not running:
    ``pool_start``), ``send`` (the job to each worker in turn), ``workers`` (each worker's own set-up:
    receiving the job, its checks, table and, unless ``scene_kept``, its Embree scene; its UV triangles
    and bins come in the job) and
    ``tail`` (the last ``tiles`` whole tiles, which leave other workers idle)."""
    tri = work.triangles
    target, every = tri[0], sum(tri)
    tile = work.tile_seconds()
    out = {"parent": FIXED_SECONDS + 1e-9 * NS_SETUP_PER_TRIANGLE * target}
    scene = 1e-9 * (NS_TABLE_PER_TRIANGLE * target + (0 if scene_kept else NS_EMBREE_PER_TRIANGLE * every))
    if processes == 1:
        out.update(scene=scene, tiles=tile / speedup(1, threads))
        return out
    if tiles is None:
        tiles = 2 * processes * threads
    out.update(start=float(pool_start), send=1e-9 * NS_SEND_PER_BYTE * work.job_bytes * processes,
               workers=WORKER_BAKE_SECONDS + 1e-9 * (NS_RECEIVE_PER_BYTE * work.job_bytes
                                                     + NS_WORKER_SETUP_PER_TRIANGLE * target) + scene,
               tiles=tile / speedup(processes, threads),
               tail=TAIL_TILES * tile / max(int(tiles), 1) / speedup(1, threads))
    return out


@dataclass(frozen=True)
class ParallelChoice:
    """Where a bake's tiles run: ``processes`` (1: this process) x ``threads`` each, with ``why`` (a
    sentence) and the ``predicted`` wall seconds of each option weighed ({'threads': ..., 'processes':
    ...}, each a :func:`parallel_seconds` sum)."""

    processes: int
    threads: int
    why: str
    predicted: dict = None
    options: dict = None

    def report(self):
        """The choice as plain data (``BakeReport.parallel``): ``processes``, ``threads``, ``why``, and
        where the bake chose, ``predicted_seconds`` and ``options`` ({'threads': [1, T], 'processes': [P,
        threads each]}) of the options weighed."""
        out = {"processes": self.processes, "threads": self.threads, "why": self.why}
        if self.predicted and len(self.predicted) > 1:
            out.update(predicted_seconds=dict(self.predicted), options={k: list(v) for k, v in self.options.items()})
        return out


#: What each part of the worker processes' extra time is called in a choice's ``why``.
_PART_WORDS = {"start": "starting them", "send": "sending each the meshes", "workers": "each one's own set-up",
               "tail": "the last tiles, which go whole to one process"}


def choose_parallel(work, cores, workers, pool_start=0.0, scene_kept=False, tiles=None):
    """Threads of this process or worker processes for ``work`` (:class:`Work`), whichever the model
    (:func:`parallel_seconds`) predicts sooner: ``cores`` threads here against ``workers`` = (processes,
    threads each), what :func:`core.execution.executor.auto_workers` lets the memory hold, with the
    pool's start (``pool_start`` seconds: 0 when one runs) and the Embree scenes the workers keep
    (``scene_kept``). Returns a :class:`ParallelChoice` whose ``why`` names the biggest difference."""
    processes, per_worker = workers
    here = parallel_seconds(work, 1, cores)
    if processes <= 1:
        reason = "one core" if cores <= 1 else "the memory holds one copy of the scene"
        return ParallelChoice(1, cores, f"{_threads(cores)} of this process: {reason}", {"threads": sum(here.values())})
    there = parallel_seconds(work, processes, per_worker, pool_start, scene_kept, tiles)
    t_here, t_there = sum(here.values()), sum(there.values())
    predicted = {"threads": t_here, "processes": t_there}
    options = {"threads": (1, cores), "processes": (processes, per_worker)}
    in_workers = f"{processes} worker processes" + (f" of {_threads(per_worker)} each" if per_worker > 1 else "")
    if t_there < t_here:
        why = (f"{in_workers}: about {_s(t_there)} against {_s(t_here)} on {_threads(cores)} of this process, "
               f"whose numpy work waits for one interpreter ({_s(here['tiles'] - there['tiles'])} more in the tiles)")
        return ParallelChoice(processes, per_worker, why, predicted, options)
    extra = {k: there[k] - here.get(k, 0.0) for k in ("start", "send", "workers", "tail")}
    part = max(extra, key=extra.get)
    why = (f"{_threads(cores)} of this process: about {_s(t_here)} against {_s(t_there)} in {in_workers}, "
           f"most of the difference {_PART_WORDS[part]} ({_s(extra[part])})")
    return ParallelChoice(1, cores, why, predicted, options)


def _threads(n):
    return f"{n} thread{'s' if n != 1 else ''}"


def _s(seconds):
    """Seconds in a choice's words: 0.23 s, 5.48 s, 12.3 s."""
    return f"{seconds:.2f} s" if seconds < 10 else f"{seconds:.1f} s"


def covered_texels(uvs, width, height):
    """About how many texels of a ``width`` x ``height`` image UV triangles ``uvs`` (T, 3, 2) cover: their
    area (:func:`covered_fraction`) plus a texel per texel of the islands' borders (cut texels count)."""
    covered = covered_fraction(uvs) * width * height
    uv = np.asarray(uvs, np.float64) * [width, height]
    border = 0.5 * np.linalg.norm(np.roll(uv, -1, axis=1) - uv, axis=2).sum()
    return min(width * height, covered + border)


def covered_fraction(uvs):
    """About the share of a [0, 1] UV square that UV triangles ``uvs`` (T, 3, 2) cover: their areas
    inside the square added up (overlaps counted twice), at most 1."""
    uv = np.clip(np.asarray(uvs, np.float64), 0.0, 1.0)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    return float(min(1.0, 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()))


def estimate_bake(target, occluders=(), resolution=(1024, 1024), samples=256, threads=1, processes=1,
                  highpoly=()):
    """The :class:`Cost` of :func:`core.bake_ao` of these meshes, before any work: the covered texels
    from the UVs' area (:func:`covered_fraction`), plus the texels along the islands' borders."""
    w, h = (resolution, resolution) if np.ndim(resolution) == 0 else resolution
    covered = covered_texels(target.uvs, w, h) if target.uvs is not None else 0.0
    return estimate(covered, samples, target.triangle_count, image_texels=w * h, threads=threads, processes=processes,
                    occluder_triangles=sum(m.triangle_count for m in occluders),
                    highpoly_triangles=sum(m.triangle_count for m in highpoly))


__all__ = ["Cost", "estimate", "estimate_bake", "bake_bytes", "covered_fraction", "cores_of", "machine_load",
           "process_bytes", "parent_bytes", "scene_bytes", "chunk_bytes"]
