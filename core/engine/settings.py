"""A bake's settings as the engine reads them: the request's checked options and what they imply.

:meth:`BakeSettings.of` derives them from a :class:`core.base.request.BakeRequest` (checked when it was
made: nothing is checked here again): the image's size, the threads (every core when not given), the
tiles (:func:`auto_tile_shape` when not given) and the replicates a sample count allows.
Everything downstream reads this object.
"""

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..base.machine import cpu_count
from ..montecarlo.sources import SOURCES
from .patterns import POOL_POINTS

#: Samples of one texel traced in one piece; more are traced in pieces of this many.
SAMPLE_PIECE = 1 << 16
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
    thickness_distance: float = 0.0  # a thickness lane's max_distance (core.engine.thickness.resolved); 0: none

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
    def of(cls, request, quantity=None):
        """The settings of a bake of ``request`` (a checked :class:`core.base.request.BakeRequest`) and
        ``quantity`` (None: the request's base quantity). A bake of mesh corners is a 1 x 1 image
        without margin: its points are units of their own."""
        r = request
        quantity = r.base_quantity if quantity is None else quantity
        # a thickness map's rays look as far as its own distance (core.engine.thickness.resolved)
        max_distance = r.thickness_distance if quantity == "thickness" and r.thickness_distance > 0 else r.max_distance
        w, h = (1, 1) if r.kind == "corners" else r.resolution
        samples = r.samples
        threads = cpu_count() if r.threads is None else r.threads
        auto_tiles = r.tile_size is None
        tile_size = auto_tile_shape(w, h, threads, samples) if auto_tiles else r.tile_size
        if isinstance(tile_size, (tuple, list)):
            tile_size, tile_height = tile_size
        else:
            tile_height = tile_size
        return cls(width=w, height=h, samples=samples, min_samples=min(r.min_samples, samples),
                   target_error=r.target_error, max_distance=max_distance, distribution=r.distribution,
                   source=r.source, margin=0 if r.kind == "corners" else r.margin, seed=r.seed, threads=threads,
                   ignore_backfaces=r.ignore_backfaces, falloff=r.falloff, tile_size=_tile_side(tile_size),
                   chunk_rays=r.chunk_rays, replicates=min(r.replicates, samples), tile_height=_tile_side(tile_height),
                   auto_tiles=auto_tiles, constant_answer=r.constant_answer, ground=r.ground,
                   quantity=quantity, thickness_distance=r.thickness_distance)

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
                                   else "independent" if SOURCES[self.source].independent else "bound"),
                "resolution": f"{self.width}x{self.height}",
                "quantity": self.quantity,
                "ground": "none" if self.ground is None else "auto" if self.ground == "auto" else "height"}


def pattern_span(source, samples):
    """Points one pattern of ``source`` holds for ``samples`` samples per texel (see core.engine.patterns)."""
    return SOURCES[source].pattern_span(samples)


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


__all__ = ["BakeSettings", "SAMPLE_PIECE", "auto_tile_shape", "pattern_span"]
