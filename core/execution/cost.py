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
#: (its float32 UV triangles and surface table, Embree scene, the positions and triangles it was sent:
#: 283 measured, memory-pss-float32.txt), an occluder's (two Embree scenes, occlusion and contact:
#: 412) and a high-poly mesh's (one robust scene that matches and occludes: 193; 161 at 10M
#: triangles), with some headroom.
BYTES_PER_TRIANGLE, BYTES_PER_OCCLUDER_TRIANGLE, BYTES_PER_HIGHPOLY_TRIANGLE = 340, 450, 220
#: Bytes a point of the sample pool takes (its 4D point and two sets of lifted features), and a sample
#: unit (its affine maps; a few per texel of a tile, UNITS_PER_TEXEL).
BYTES_PER_POOL_POINT, BYTES_PER_UNIT, UNITS_PER_TEXEL = 64, 600, 4
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
    frac = covered_fraction(target.uvs) if target.uvs is not None else 0.0
    covered = frac * w * h
    # Texels cut by an island's border are covered too: about a texel per texel of border.
    uv = np.asarray(target.uvs, np.float64) * [w, h] if target.uvs is not None else np.zeros((0, 3, 2))
    border = 0.5 * np.linalg.norm(np.roll(uv, -1, axis=1) - uv, axis=2).sum()
    covered = min(w * h, covered + border)
    return estimate(covered, samples, target.triangle_count, image_texels=w * h, threads=threads, processes=processes,
                    occluder_triangles=sum(m.triangle_count for m in occluders),
                    highpoly_triangles=sum(m.triangle_count for m in highpoly))


__all__ = ["Cost", "estimate", "estimate_bake", "bake_bytes", "covered_fraction", "cores_of", "machine_load",
           "process_bytes", "parent_bytes", "scene_bytes", "chunk_bytes"]
