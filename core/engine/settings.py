"""A bake's settings, checked once: the limits, the validated values, and what they imply (memory, tiles).

:func:`BakeSettings.from_arguments` turns the arguments of :func:`core.bake_ao` into a frozen
:class:`BakeSettings`, refusing bad input with a :class:`~core.base.errors.SettingsError` that names the
setting and the problem, before any heavy work. Everything downstream reads this object.
"""

import dataclasses
import math
import os
from dataclasses import dataclass

import numpy as np

from ..base.errors import SettingsError
from ..tracing.ground import check_ground
from .thickness import check_quantity
from .patterns import POOL_POINTS, SOURCE_NAMES

DISTRIBUTIONS = ("cosine", "uniform")
#: Largest image side the baker accepts (the same as Blender's image size limit).
MAX_RESOLUTION = 65536
#: Most samples per texel. Chunks stay bounded for any count (a texel's samples are traced in
#: pieces), but the sample pool grows with it: 2^20 keeps it to tens of MiB, and a reference bake
#: rarely needs a tenth of it.
MAX_SAMPLES = 1 << 20
#: The largest seed: seeds are hashed as unsigned 64-bit integers.
MAX_SEED = (1 << 64) - 1
#: Most threads a bake (or one worker process) takes.
MAX_THREADS = 1024
#: Samples of one texel traced in one piece; more are traced in pieces of this many.
SAMPLE_PIECE = 1 << 16
#: Most independent randomisations (replicates) a texel's samples may be split into.
MAX_REPLICATES = 16
#: Tiles are multiples of this side, so that the blocks error estimates are pooled in
#: (core.engine.estimators.POOL_BLOCK) never straddle two tiles.
TILE_MULTIPLE = 16
#: The side of the largest tile :func:`auto_tile_shape` makes, and of the larger one it makes for bakes
#: of at most LARGE_TILE_SAMPLES samples per texel when the image gives every thread at least
#: LARGE_TILES_PER_THREAD of them.
TILE_SIDE, LARGE_TILE_SIDE = 256, 512
LARGE_TILE_SAMPLES, LARGE_TILES_PER_THREAD = 16, 8
#: Automatic tiles hold at most about this many triangles (counted by their UV centres): a tile's
#: per-triangle passes (scans, island borders, the candidates' sort, the triangle matrices) cost more
#: per triangle as their arrays outgrow the caches. A 1M-triangle grid at 512^2 x 16 on 2 threads,
#: separate processes alternated: 256^2 tiles (250k triangles each) 5.03-6.52 s, 256 x 128 4.77-5.22,
#: 128^2 (62k) 4.51-5.23 (median 4.75 against 5.30); 100k triangles (25k a tile) and 10k: no gain
#: from smaller tiles (1.50-1.72 against 1.60-1.65 s; 1.21-1.33 against 1.05-1.21).
TILE_TRIANGLES = 1 << 16


def _positive_int(value, what, lo=1):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise SettingsError(f"{what} must be an integer, got {value!r}")
    if value < lo:
        raise SettingsError(f"{what} must be at least {lo}, got {value}")
    return int(value)


def _resolution(resolution):
    if isinstance(resolution, (int, np.integer)) and not isinstance(resolution, bool):
        resolution = (resolution, resolution)
    try:
        w, h = resolution
    except (TypeError, ValueError):
        raise SettingsError(f"resolution must be an integer or a (width, height) pair, got {resolution!r}") from None
    w = _positive_int(w, "resolution width")
    h = _positive_int(h, "resolution height")
    if w > MAX_RESOLUTION or h > MAX_RESOLUTION:
        raise SettingsError(f"resolution {w} x {h} exceeds the largest supported side, {MAX_RESOLUTION}")
    return w, h


def _cpu_count():
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


@dataclass(frozen=True)
class BakeSettings:
    """The validated settings of one bake (see :func:`core.bake_ao` for their meaning).

    ``max_distance`` is in world units here; the baker scales it into its normalised scene frame.
    """

    width: int
    height: int
    samples: int
    min_samples: int
    target_error: float
    max_distance: float
    distribution: str
    source: str
    margin: int
    seed: int
    threads: int
    ignore_backfaces: bool
    falloff: float
    tile_size: int
    chunk_rays: int
    replicates: int = 2
    tile_height: int = None  # rows of a tile; None: tile_size (square tiles)
    auto_tiles: bool = False  # the tiles were chosen by auto_tile_shape (and may shrink: fit_tiles)
    constant_answer: bool = False  # benchmarks only: no query reaches Embree (see core.tracing.tracer.Tracer)
    ground: object = None  # None, 'auto' or a world height (core.tracing.ground)
    quantity: str = "ao"  # 'ao' or 'thickness' (core.engine.thickness)

    @property
    def tile_shape(self):
        """(columns, rows) of a tile."""
        return self.tile_size, self.tile_height or self.tile_size

    def tile_bounds(self, key):
        """(x0, y0, x1, y1): the texels [x0, x1) x [y0, y1) of tile ``key`` = (row, column), within
        the image."""
        (ty, tx), (tw, th) = key, self.tile_shape
        x0, y0 = tx * tw, ty * th
        return x0, y0, min(x0 + tw, self.width), min(y0 + th, self.height)

    @classmethod
    def from_arguments(cls, resolution, samples, min_samples, target_error, max_distance, distribution, source,
                       margin, seed, threads, ignore_backfaces, falloff, tile_size, chunk_rays, replicates=2, *,
                       ground=None, quantity="ao"):
        w, h = _resolution(resolution)
        samples = _positive_int(samples, "samples")
        if samples > MAX_SAMPLES:
            raise SettingsError(f"samples must be at most {MAX_SAMPLES} per texel, got {samples}")
        min_samples = _positive_int(min_samples, "min_samples")
        try:
            target_error = float(target_error)
            max_distance = float(max_distance)
            falloff = float(falloff)
        except (TypeError, ValueError):
            raise SettingsError("target_error, max_distance and falloff must be numbers") from None
        if not (math.isfinite(target_error) and target_error >= 0):
            raise SettingsError(f"target_error must be a finite number >= 0 (0 turns adaptive sampling off), "
                                f"got {target_error}")
        if not (max_distance > 0):  # also refuses NaN
            raise SettingsError(f"max_distance must be positive (inf for unlimited), got {max_distance}")
        if not (math.isfinite(falloff) and falloff >= 0):
            raise SettingsError(f"falloff must be a finite number >= 0, got {falloff}")
        if falloff > 0 and not math.isfinite(max_distance):
            raise SettingsError("a distance falloff needs a finite max_distance to fall off over")
        if distribution not in DISTRIBUTIONS:
            raise SettingsError(f"unknown distribution {distribution!r}; choose one of {', '.join(DISTRIBUTIONS)}")
        if source not in SOURCE_NAMES:
            raise SettingsError(f"unknown sample source {source!r}; choose one of {', '.join(SOURCE_NAMES)}")
        margin = _positive_int(margin, "margin", lo=0)
        seed = _positive_int(seed, "seed", lo=0)
        if seed > MAX_SEED:
            raise SettingsError(f"seed must be at most 2**64 - 1 ({MAX_SEED}), got {seed}")
        threads = _cpu_count() if threads is None else _positive_int(threads, "threads")
        if threads > MAX_THREADS:
            raise SettingsError(f"threads must be at most {MAX_THREADS}, got {threads}")
        chunk_rays = _positive_int(chunk_rays, "chunk_rays")
        auto_tiles = tile_size is None
        if auto_tiles:
            tile_size = auto_tile_shape(w, h, threads, samples)
        if isinstance(tile_size, (tuple, list)) and len(tile_size) == 2:
            tile_size, tile_height = (_positive_int(t, "tile_size") for t in tile_size)
        else:
            tile_size = tile_height = _positive_int(tile_size, "tile_size")
        tile_size, tile_height = _tile_side(tile_size), _tile_side(tile_height)
        replicates = _positive_int(replicates, "replicates")
        if replicates > MAX_REPLICATES:
            raise SettingsError(f"replicates must be at most {MAX_REPLICATES}, got {replicates}")
        replicates = min(replicates, samples)  # a replicate needs a sample
        quantity = check_quantity(quantity)
        ground = check_ground(ground)
        if quantity == "thickness":
            if ground is not None:
                raise SettingsError(f"ground={ground!r} does not apply to a thickness map, which only the object itself "
                                    "occludes; leave ground None for quantity='thickness'")
            if ignore_backfaces:
                raise SettingsError("ignore_backfaces does not apply to a thickness map: its rays meet the far side "
                                    "from behind, so nothing would count; leave it off for quantity='thickness'")
        return cls(width=w, height=h, samples=samples, min_samples=min(min_samples, samples),
                   target_error=target_error, max_distance=max_distance, distribution=distribution, source=source,
                   margin=margin, seed=seed, threads=threads, ignore_backfaces=bool(ignore_backfaces),
                   falloff=falloff, tile_size=tile_size, chunk_rays=chunk_rays, replicates=replicates,
                   tile_height=tile_height, auto_tiles=auto_tiles, ground=ground, quantity=quantity)

    def fit_tiles(self, centres):
        """These settings with automatic tiles shrunk until no tile holds more than TILE_TRIANGLES
        of the triangles whose UV centres (texel space, (2, n): x row, y row) are given: the longer
        side halved each time, down to TILE_MULTIPLE. Unchanged for tiles the caller chose. The
        tiling never changes a result."""
        if not self.auto_tiles or centres.shape[1] <= TILE_TRIANGLES:
            return self
        x = np.clip(centres[0], 0, self.width - 1).astype(np.int64)
        y = np.clip(centres[1], 0, self.height - 1).astype(np.int64)
        tw, th = self.tile_shape
        while max(tw, th) > TILE_MULTIPLE:
            across = -(-self.width // tw)
            if np.bincount((y // th) * across + x // tw).max() <= TILE_TRIANGLES:
                break
            tw, th = _halve_longer(tw, th)
        return dataclasses.replace(self, tile_size=int(tw), tile_height=int(th))

    @property
    def adaptive(self):
        return self.target_error > 0

    @property
    def binary(self):
        """Whether every sample's term is 0 or 1 (cosine directions, no falloff): hits are counted."""
        return self.distribution == "cosine" and self.falloff == 0

    @property
    def bound(self):
        """The largest value a sample's term takes (2 cos(theta) V for uniform directions)."""
        return 2.0 if self.distribution == "uniform" else 1.0

    @property
    def replicate_samples(self):
        """The most samples one replicate of a texel takes."""
        return -(-self.samples // self.replicates)

    def pool_points(self):
        """Points the sample pool holds: at least one pattern per replicate (a texel's replicates
        draw distinct patterns, see core.engine.patterns), no more patterns than texels' replicates, at most
        :data:`POOL_POINTS` beyond that."""
        span = pattern_span(self.source, self.replicate_samples)
        texels = 1 << max(0, (self.width * self.height * self.replicates - 1).bit_length())
        return max(span * self.replicates, min(POOL_POINTS, texels * span))

    def metadata(self, max_distance_world):
        return {"samples": self.samples, "min_samples": self.min_samples, "target_error": self.target_error,
                "sample_source": self.source, "distribution": self.distribution, "seed": self.seed,
                "max_distance": max_distance_world, "falloff": self.falloff,
                "ignore_backfaces": self.ignore_backfaces, "margin": self.margin, "replicates": self.replicates,
                "error_estimate": ("replicates" if self.replicates > 1
                                   else "independent" if self.source == "independent" else "bound"),
                "resolution": f"{self.width}x{self.height}",
                "quantity": self.quantity,
                "ground": "none" if self.ground is None else "auto" if self.ground == "auto" else "height"}


def pattern_span(source, samples):
    """Points one pattern of ``source`` holds for ``samples`` samples per texel (see core.engine.patterns)."""
    if source == "halton":
        return 2 * samples
    length = 1 << max(0, (samples - 1).bit_length())
    return 2 * length if source == "stratified" else length


def available_memory():
    """Bytes of memory available to a new allocation (MemAvailable on Linux), or None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def estimate_memory(width, height, triangles, threads, chunk_rays, samples=1, source="sobol", replicates=1,
                    tile_texels=TILE_SIDE * TILE_SIDE):
    """Peak bytes a bake needs: output planes, margin work, per-thread chunks, the sample pool, triangles.

    A chunk holds at most ``max(chunk_rays, SAMPLE_PIECE)`` rays (a texel with more samples is
    traced in pieces). The sample pool holds at least one pattern of the sample count (its 4D points
    and two sets of lifted features: 40 bytes a point) and at most :data:`POOL_POINTS` points
    otherwise; a tile's sample units hold their affine maps (about 600 bytes each, a few per texel).
    """
    texels = width * height
    planes = texels * (4 + 4 + 4 + 1)          # ao, stderr, samples, mask
    margin_work = texels * (4 + 4 + 1 + 1)      # dilation values, masks, frontier
    per_ray = 200                               # feature rows, outputs, indices and results of a chunk
    chunks = threads * max(chunk_rays, min(samples, SAMPLE_PIECE)) * per_ray
    span = pattern_span(source, -(-samples // replicates))
    pool = max(span * replicates, min(POOL_POINTS, texels * replicates * span)) * 64
    units = threads * tile_texels * 4 * 600     # a tile's units, a few per texel
    tris = triangles * 300                      # texel-space corners, affine maps, Embree buffers
    return planes + margin_work + chunks + pool + min(units, texels * 4 * 600 * threads) + tris


def auto_tile_shape(width, height, threads, samples=None):
    """(columns, rows) of a tile: at least one tile per thread, sides multiples of TILE_MULTIPLE and
    at most TILE_SIDE (LARGE_TILE_SIDE for bakes of few samples on large images), as large as that
    allows.

    Every tile costs its own rasterising, sample units and, per group of equal pieces, its own kernel
    calls (about half a millisecond of fixed numpy work each): tiles smaller than the threads need
    cost time and even out nothing. From 256 x 256 (or the image), the longer side is halved until
    every thread has a tile. Measured on the bench's Suzanne scene (wall seconds; 2 threads unless
    said): 128^2 x 128 spp, square tiles of 64 (the rule before, about two tiles per thread)
    0.36-0.42, 128 x 64 0.29-0.38; 1 thread, one 128^2 tile 0.50-0.54 against four of 64^2 0.64;
    256^2 x 128, 128^2 tiles 0.98-1.04, 256 x 128 0.94-0.98. Before the rule of two tiles per thread,
    2^20 rays a tile cut a 128^2 image into 16 tiles (0.84 s).

    Larger tiles: a 256^2 tile's fixed work is a few milliseconds on one thread, and with two
    threads, whose numpy calls wait for each other's Python between them, 14-18 ms of CPU. Where a
    texel takes few samples that is most of a tile's time (a 4096^2 x 1 bake spends 5.2 s outside
    embreex on 254 tiles, 3.6 s on 64 of 512^2). Where it takes many, larger tiles lose: their
    arrays outgrow the caches (one thread, 512^2 x 64: one 512^2 tile 1.91-2.00 s against four of
    256^2 1.83-1.87) and the last tiles leave threads idle (1024^2 x 64 on 2 threads, four 512^2 tiles
    3.61 s against sixteen of 256^2 3.31). So 512^2 tiles are taken for at most LARGE_TILE_SAMPLES
    samples (``samples`` None: many) when there are LARGE_TILES_PER_THREAD of them per thread. 256^2
    -> 512^2 on 2 threads: 4096^2 x 1, 4, 16 5.16 -> 3.76, 8.67 -> 7.85, 17.95 -> 17.25 s; 2048^2 x
    1, 4 1.50 -> 1.18, 2.99 -> 2.61 s; 2048^2 x 64 (not taken) 12.19 -> 12.58 s.

    Dense meshes: :meth:`BakeSettings.fit_tiles` shrinks these tiles further, once the triangles are
    known, so that none holds more than TILE_TRIANGLES of them.

    The tiling never changes a result (texels draw their samples by (texel, index) alone), and tiles
    are traced in chunks of ``chunk_rays``, so a tile's samples bound neither memory nor the
    granularity of progress and cancel.
    """
    threads = max(1, threads)
    side = TILE_SIDE
    if samples is not None and samples <= LARGE_TILE_SAMPLES:
        large = -(-width // LARGE_TILE_SIDE) * -(-height // LARGE_TILE_SIDE)
        if large >= LARGE_TILES_PER_THREAD * threads:
            side = LARGE_TILE_SIDE
    tw, th = min(side, _tile_side(width)), min(side, _tile_side(height))
    while -(-width // tw) * -(-height // th) < threads and max(tw, th) > TILE_MULTIPLE:
        tw, th = _halve_longer(tw, th)
    return int(tw), int(th)


def _halve_longer(tw, th):
    """(columns, rows) of a tile with its longer side (the rows when equal) halved, rounded up to a
    multiple of TILE_MULTIPLE."""
    return (tw, _tile_side(th / 2)) if th >= tw else (_tile_side(tw / 2), th)


def _tile_side(v):
    """``v`` texels rounded up to a multiple of TILE_MULTIPLE (at least one)."""
    return max(TILE_MULTIPLE, -(-int(math.ceil(v)) // TILE_MULTIPLE) * TILE_MULTIPLE)


__all__ = ["BakeSettings", "DISTRIBUTIONS", "MAX_RESOLUTION", "MAX_SAMPLES", "MAX_REPLICATES", "SAMPLE_PIECE", "available_memory",
           "estimate_memory", "auto_tile_shape", "pattern_span"]
