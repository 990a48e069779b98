"""Per-texel 4D sample points for the baker: (direction u0, u1, position in the texel u2, u3).

Every texel draws its points from a pool of P randomised point sets ("patterns") of the chosen
source, built once per bake from the seed, and randomises them again on its own, all addressed by
(seed, texel, sample index) alone: counter-based, like Cycles' per-pixel hashing and pbrt-v4's
``Hash(pixel, dimension, seed)``. So a texel's points do not depend on how texels are grouped into
tiles, chunks, rounds or threads, which is what makes bakes bit-identical for any thread count.

Texel t with sample index i takes the point

    u(t, i) = (q0, q1, q2 (op) d2(t), q3 (op) d3(t)),   q = pattern e(t), point perm_t(i)

- e(t): a pattern picked by a hash of the texel;
- perm_t: a per-texel reordering of the pattern's points that keeps the source's structure
  (Sobol': i xor c(t), which maps every aligned block of 2^m indices onto another aligned block,
  so every power-of-two prefix is still a net; Halton: a window i + o(t) of a pattern twice as long,
  so every b^k consecutive points are still stratified in base b; stratified and independent:
  (i + o(t)) mod N);
- d2, d3: a per-texel random shift of the two position coordinates (Sobol', independent: a digital
  shift, xor with a random 32-bit word, which maps elementary intervals onto elementary intervals;
  Halton: a Cranley-Patterson rotation, which keeps its strata as arcs of the circle; stratified: a
  digital shift below the strata, which keeps every point in its stratum).

Each pattern is an independent randomisation of the source's point set, so every point of every
texel is uniform on [0, 1)^4 (the estimate is unbiased) and each texel's set is a randomised copy of
the source's set (Owen-scrambled Sobol' net, digit-permuted Halton, jittered grid, independent
points). The pool size only limits how often two texels draw their direction coordinates from the
same pattern (probability 1/P per pair); their positions still differ, and the baker also turns
each texel's tangent frame by its own random angle (see :mod:`core.engine.kernel`), so no two texels trace
the same directions.

The baker never evaluates warps per ray for the directions: :meth:`TexelPattern.features` lifts
every pool point once into the quantities the kernel multiplies by each unit's affine map (see
:mod:`core.engine.kernel`).
"""

import threading
from collections import OrderedDict

import numpy as np

from ..montecarlo import warps
from ..base.errors import SettingsError
from ..montecarlo.hashing import GOLDEN, below, hash64, hash_more, mix_into
from ..base.request import SOURCES as SOURCE_NAMES
from ..montecarlo.sources import SOURCES

DIMS = 4
#: Points in a pool (all patterns together). 2^18 points hold 4096 Sobol' sets of 64 points; the
#: pool and its lifted features take about 10 MiB.
POOL_POINTS = 1 << 18

_TWO_M32 = 2.0 ** -32

# Hash tags: one per independent quantity drawn from (seed, texel, replicate).
_TAG_PATTERN, _TAG_ORDER, _TAG_SHIFT2, _TAG_SHIFT3, _TAG_TURN, _TAG_SCRAMBLE = 11, 12, 13, 14, 15, 16


def _seed_key(seed):
    return np.uint64(int(seed) % (1 << 64))


class TexelKeys:
    """What one texel (and replicate) draws: pattern, reordering, position shifts and frame turn."""

    __slots__ = ("pattern", "order", "shift", "cos_turn", "sin_turn")

    def __init__(self, pattern, order, shift, cos_turn, sin_turn):
        self.pattern = pattern    # (n,) int64, which pattern of the pool
        self.order = order        # (n,) int64, the reordering key (xor mask or offset)
        self.shift = shift        # (n, 2) uint32, position shifts d2, d3
        self.cos_turn = cos_turn  # (n,) float32, the tangent frame's turn about the normal
        self.sin_turn = sin_turn


class TexelPattern:
    """Sample points for texels: ``points(texels, start, count) -> (len(texels), count, 4)`` in [0, 1).

    Parameters
    ----------
    source : one of :data:`SOURCE_NAMES`.
    seed : non-negative integer; the same seed gives the same points.
    max_samples : the most samples any texel takes (the patterns are sized by it).
    pool_points : points in the pool, all patterns together (at least one pattern).
    """

    def __init__(self, source, seed, max_samples, pool_points=POOL_POINTS):
        if source not in SOURCE_NAMES:
            raise SettingsError(f"unknown sample source {source!r}; choose one of {', '.join(SOURCE_NAMES)}")
        max_samples = int(max_samples)
        if max_samples < 1:
            raise SettingsError(f"max_samples must be at least 1, got {max_samples}")
        self.source = source
        self.seed = _seed_key(seed)
        self.max_samples = max_samples
        # Points per pattern (length) and rows per pattern in the pool (span), and how a texel
        # reorders them (see the module docstring): xor for Sobol' and independent points; a window
        # i + o for Halton and for the stratified sets, which are stored twice in a row so that
        # (i + o) mod N needs no wrap. Either way, an aligned block of a texel's samples is a run of
        # consecutive pool rows.
        cls = SOURCES[source]  # the point set's own rules (core.montecarlo.pointset.PointSet)
        self.xor = cls.reorder == "xor"
        self.length = cls.pattern_length(max_samples)
        self.span = cls.pattern_span(max_samples)
        self.patterns = max(1, int(pool_points) // self.span)
        self._pool = _pool(source, self.seed, self.patterns, self.span, self.length)
        self.q = self._pool.q
        # Position shifts: digital (xor) or Cranley-Patterson (add, modulo 2^32), and which bits.
        self.shift_add = cls.shift == "add"
        self.shift_mask = np.array(cls.shift_masks(self.length), dtype=np.uint32)

    # -- per texel -----------------------------------------------------------------------------

    def keys(self, texels, replicate=0):
        """The random choices of ``texels`` (array of non-negative ints) for ``replicate``."""
        t = np.asarray(texels, dtype=np.uint64)
        r = np.uint64(replicate)
        # hash64(seed, t, r, tag) for every tag, the shared keys mixed once (hash_more).
        st = hash64(self.seed, t)
        str_ = hash_more(st, r)
        # A texel's replicates take distinct patterns (consecutive ones from its first: each pattern
        # is an independent randomisation), so that replicates are independent of each other.
        first = str_ if replicate == 0 else hash_more(st, np.uint64(0))
        pattern = below(hash_more(first, _TAG_PATTERN), self.patterns).astype(np.int64)
        if replicate:  # (below patterns already for replicate 0: an int64 remainder a texel saved)
            pattern = (pattern + int(replicate)) % self.patterns
        h = hash_more(str_, _TAG_ORDER)
        order = (h >> np.uint64(40)) & np.uint64(self.length - 1) if self.xor else below(h, self.length)
        shift = np.empty(t.shape + (2,), np.uint32)  # column by column: numpy is slow over an axis of 2
        for c, tag in enumerate((_TAG_SHIFT2, _TAG_SHIFT3)):
            np.bitwise_and((hash_more(str_, tag) >> np.uint64(32)).astype(np.uint32), self.shift_mask[c],
                           out=shift[..., c])
        # The turn in float32, as the kernel rotates float32 features: an angle of 24 random bits
        # (exact in float32), its cosine and sine from numpy's float32 loops (0.13 ms for a 512^2
        # tile's 124k texels, against 4.5 ms in float64, most of what the keys cost).
        u = (hash_more(str_, _TAG_TURN) >> np.uint64(40)).astype(np.float32) * np.float32(2.0 ** -24)
        turn = np.float32(warps.TWO_PI) * u
        return TexelKeys(pattern, order.astype(np.int64), shift, np.cos(turn), np.sin(turn))

    def rows(self, keys, index):
        """Pool rows of the samples ``index`` (n, k) of the texels whose keys are given: e * span + perm(i)."""
        return self.rows_of(keys.pattern, keys.order, index)

    def rows_of(self, pattern, order, index):
        """:meth:`rows` from the keys' arrays: ``pattern``, ``order`` (n,), ``index`` (n, k)."""
        index = np.asarray(index, dtype=np.int64)
        perm = index ^ order[:, None] if self.xor else index + order[:, None]
        perm += pattern[:, None] * self.span
        return perm

    def block_rows(self, pattern, order, start, size):
        """First pool row of each texel's block of samples [start, start + size) (arrays (n,)),
        ``start`` a multiple of the power of two ``size``: the block's points are the rows
        first .. first + size - 1, in the order :meth:`block_samples` gives."""
        base = (start ^ order) & ~np.int64(size - 1) if self.xor else start + order
        return pattern * self.span + base

    def block_samples(self, pattern, order, first, size):
        """The sample index of every row of the blocks :meth:`block_rows` returned: (n, size)."""
        row = (first - pattern * self.span)[:, None] + np.arange(size)[None, :]
        return row ^ order[:, None] if self.xor else row - order[:, None]

    def shift_positions(self, q, shift):
        """Apply the texels' position shifts to uint32 position coordinates ``q`` (..., 2) in place."""
        if self.shift_add:
            np.add(q, shift, out=q)  # uint32 wraps: a rotation of the circle [0, 1)
        else:
            np.bitwise_xor(q, shift, out=q)
        return q

    # -- what the tests and the baker read -----------------------------------------------------

    def points(self, texels, start, count, replicate=0):
        """Samples [start, start + count) of each texel: (len(texels), count, 4) float64 in [0, 1)."""
        texels = np.asarray(texels)
        keys = self.keys(texels, replicate)
        if start < 0 or start + count > self.max_samples:
            raise SettingsError(f"samples [{start}, {start + count}) lie outside [0, {self.max_samples})")
        index = np.broadcast_to(np.arange(start, start + count)[None, :], (len(texels), count))
        idx = self.rows(keys, index)
        q = self.q[idx]  # (n, count, 4) uint32
        if len(texels):
            self.shift_positions(q[..., 2:], keys.shift[:, None, :])
        return q.astype(np.float64) * _TWO_M32

    def features(self, kind):
        """Lifted pool rows for the kernel, float32 (span * patterns, 6), one row per pool point:
        [q2, q3 (uint32 bits), 1, f0, f1, f2] with f the direction features of ``kind``:

        - 'cosine': Malley's polar map of (u0, u1), the direction in the tangent frame;
        - 'cosine_sphere': the sphere point v with normalize(n + v) that direction (per-sample normals);
        - 'uniform': the uniform hemisphere direction (cos theta = u0) in the tangent frame;
        - 'uniform_sphere': the uniform sphere point, folded onto the normal's side per sample.
        """
        return self._pool.features(kind)

    def feature_planes(self, kind):
        """:meth:`features` as planes, float32 (6, span * patterns): plane j is column j of every
        row (what the kernel gathers, one contiguous plane per feature)."""
        return self._pool.feature_planes(kind)


def _lift(q, kind):
    u0 = q[:, 0].astype(np.float64) * _TWO_M32
    u1 = q[:, 1].astype(np.float64) * _TWO_M32
    if kind in ("cosine", "cosine_sphere"):
        d = warps.cosine_hemisphere_polar_xyz(u0, u1)
        if kind == "cosine_sphere":
            d = warps.cosine_sphere_point(*d)
    elif kind == "uniform":
        d = warps.uniform_hemisphere_xyz(u0, u1)
    elif kind == "uniform_sphere":
        w = warps.sample_uniform_sphere(np.stack([u0, u1], axis=1))
        d = (w[:, 0], w[:, 1], w[:, 2])
    else:
        raise ValueError(f"unknown feature kind {kind!r}")
    out = np.empty((len(q), 6), np.float32)
    out[:, 0:2].view(np.uint32)[...] = q[:, 2:4]
    out[:, 2] = 1.0
    for j in range(3):
        out[:, 3 + j] = d[j]
    return out


class _Pool:
    """A pool's points and, built on first use, their lifted features (read-only, shared by bakes)."""

    def __init__(self, q):
        self.q = q
        self._features = {}
        self._lock = threading.Lock()

    def features(self, kind):
        with self._lock:
            f = self._features.get(kind)
            if f is None:
                f = _lift(self.q, kind)
                f.setflags(write=False)
                self._features[kind] = f
            return f

    def feature_planes(self, kind):
        f = self.features(kind)
        with self._lock:
            p = self._features.get((kind, "planes"))
            if p is None:
                p = np.ascontiguousarray(f.T)
                p.setflags(write=False)
                self._features[(kind, "planes")] = p
            return p


_POOLS = OrderedDict()
_POOLS_LOCK = threading.Lock()
_POOLS_KEEP = 4


def _pool(source, seed, patterns, span, length):
    """The pool of ``source`` for ``seed``; the last few are kept (a bake's pattern is built once,
    and a series of bakes with the same settings, as in the benchmark or the tests, reuses it)."""
    key = (source, int(seed), patterns, span, length)
    with _POOLS_LOCK:
        if key in _POOLS:
            _POOLS.move_to_end(key)
            return _POOLS[key]
    pool = _Pool(_build_pool(source, seed, patterns, span, length))
    with _POOLS_LOCK:
        _POOLS[key] = pool
        while len(_POOLS) > _POOLS_KEEP:
            _POOLS.popitem(last=False)
    return pool


class _PatternBits:
    """The random words of pool patterns, counter-based: word j of pattern e is
    hash64(seed, e, j, _TAG_SCRAMBLE), so each pattern's randomisation depends on (seed, e) alone.
    A bit source of :mod:`core.montecarlo.sources` (``sets``, ``words(count)``) for the patterns ``patterns``."""

    def __init__(self, seed, patterns):
        self._state = hash64(seed, np.asarray(patterns, dtype=np.uint64).reshape(-1))
        self.sets = len(self._state)
        self._next = 0

    def words(self, count):
        j = np.arange(self._next, self._next + count, dtype=np.uint64)
        self._next += count
        out = np.empty((self.sets, count), np.uint64)
        if count == 0:
            return out
        # hash_more(state, j, tag) a block of patterns at a time, in place and on flat arrays: the
        # temporaries stay in cache, and no inner loop is as short as a pattern's few words.
        rows = max(1, _WORDS_BLOCK // count)
        counters = np.tile(j, min(rows, self.sets))
        tmp = np.empty(counters.size, np.uint64)
        tag = np.uint64(_TAG_SCRAMBLE)
        flat = out.reshape(-1)
        for r in range(0, self.sets, rows):
            state = self._state[r:r + rows]
            h = flat[r * count:(r + len(state)) * count]
            t = tmp[:h.size]
            h[:] = np.repeat(state, count)
            h ^= counters[:h.size]
            h += GOLDEN
            mix_into(h, t)
            h ^= tag
            h += GOLDEN
            mix_into(h, t)
        return out


_WORDS_BLOCK = 1 << 15


def _pattern_randomizer(cls, seed, patterns, count):
    """The randomisation of the pool patterns ``patterns`` of the source class ``cls``."""
    return cls.randomizer_from(_PatternBits(seed, patterns), DIMS, count)


def _build_pool(source, seed, patterns, span, length):
    """The points (patterns * span, 4) uint32 of ``source`` for ``seed``: pattern e is the source's
    point set (:data:`core.montecarlo.sources.SOURCES`) under the randomisation drawn from (seed, e). A
    sequence gives its first ``span`` points; a whole set (stratified) of ``length`` points is
    stored twice in a row, so that a window i + o needs no wrap."""
    cls = SOURCES[source]
    count = span if cls.continues else length
    q = cls.sets_uint32(count, DIMS, _pattern_randomizer(cls, seed, np.arange(patterns), count))
    if count < span:
        q = np.tile(q, (1, span // count, 1))
    q = np.ascontiguousarray(q.reshape(patterns * span, DIMS))
    q.setflags(write=False)
    return q


__all__ = ["SOURCE_NAMES", "DIMS", "POOL_POINTS", "TexelPattern", "TexelKeys"]
