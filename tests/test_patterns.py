"""The per-texel sample points every bake draws (core.engine.patterns.TexelPattern), tested like a sampler.

In the style of pbrt-v4's sampler tests and scipy's QMCEngine test mixin: one contract class that
every sample source's test class reuses. A texel's points are addressed by (texel, sample index)
alone, so the contract is:

- each sample index, over many texels, is uniform on [0, 1)^4: every coordinate and every pair of
  coordinates (chi-square);
- the four dimensions are independent, over texels and within each texel's own set;
- texels are independent of each other (neighbours in a row and in a column);
- the same (texel, index) always gives the same point, whatever else is drawn with it, and drawing
  a sequence in pieces equals drawing it at once;
- the structure each source promises holds per texel: Sobol' prefixes of 2^m points are nets
  (every elementary interval of the right volume holds its share of points), Halton's first b^k
  points are stratified in the base-b dimension, the stratified source fills every stratum.

Each statistical test keeps a family-wise false-alarm rate of ALPHA (Sidak within the test).
"""

import math

import numpy as np
import pytest
from scipy import stats

from core.engine import patterns as P
from core.engine.patterns import DIMS, SOURCE_NAMES, TexelPattern
from core.montecarlo.hashing import below, hash64, hash_more
from core.montecarlo.sobol import Sobol, owen_scramble_uint32, sobol_uint32
from core.montecarlo.sources import SOURCES
from core.montecarlo.stratified import Stratified

ALPHA = 1e-3
#: The texels the statistical tests look at: a 64 x 64 block of a 64-texel-wide image, so that
#: texel t + 1 is its right neighbour and t + WIDE the one above.
WIDE = 64
TEXELS = np.arange(WIDE * WIDE)
#: Samples per texel in the tests: a power of two and a square (the stratified grid is 8 x 8).
N = 64
PAIRS = [(a, b) for a in range(DIMS) for b in range(a + 1, DIMS)]


def sidak(alpha, m):
    return 1.0 - (1.0 - alpha) ** (1.0 / m)


def chi2_uniform(values, bins):
    """p-value of values in [0, 1) against the uniform law on ``bins`` equal cells."""
    idx = np.floor(np.asarray(values) * bins).astype(np.int64)
    assert idx.min() >= 0 and idx.max() < bins, "values outside [0, 1)"
    return stats.chisquare(np.bincount(idx, minlength=bins)).pvalue


def chi2_joint(x, y, bins):
    """p-value of the points (x, y) against the uniform law on a bins x bins grid."""
    cell = np.floor(np.asarray(x) * bins).astype(np.int64) * bins + np.floor(np.asarray(y) * bins).astype(np.int64)
    return stats.chisquare(np.bincount(cell, minlength=bins * bins)).pvalue


def elementary_counts_ok(points, m, t):
    """Whether the 2^m points (n, s) form a (t, m, s)-net in base 2: every elementary interval
    prod_j [a_j 2^-k_j, (a_j + 1) 2^-k_j) with sum k_j = m - t holds exactly 2^t points."""
    n, s = points.shape
    assert n == 2**m
    level = m - t
    if level <= 0:
        return True
    cells = [np.floor(points[:, j] * 2.0**k).astype(np.int64) for j in range(s) for k in range(level + 1)]
    cells = np.array(cells).reshape(s, level + 1, n)

    def splits(total, parts):
        if parts == 1:
            yield (total,)
            return
        for first in range(total + 1):
            for rest in splits(total - first, parts - 1):
                yield (first,) + rest

    for ks in splits(level, s):
        key = np.zeros(n, np.int64)
        for j, k in enumerate(ks):
            key = key * (2**k) + cells[j, k]
        counts = np.bincount(key, minlength=2**level)
        if not np.all(counts == 2**t):
            return False
    return True


def stratified_on_circle(x):
    """Whether the n values hold one point in each of n equal arcs of the circle [0, 1), for some
    rotation of the arcs: sorted, x_(j) - j / n spans less than 1 / n."""
    n = len(x)
    y = np.sort(np.asarray(x)) - np.arange(n) / n
    return bool(y.max() - y.min() < 1.0 / n)


def t_value(points, m):
    """The smallest t for which the 2^m points are a (t, m, s)-net in base 2."""
    for t in range(m + 1):
        if elementary_counts_ok(points, m, t):
            return t
    return m


# ---------------------------------------------------------------------------------------------
# The contract every source honours
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="class")
def full(request):
    """Every test texel's N points of the test class's source, drawn at once: (texels, N, 4). (A
    module-level fixture: class-scoped fixtures defined as methods are deprecated in pytest 9.)"""
    return np.asarray(request.cls.make().points(TEXELS, 0, N), dtype=np.float64)


class PatternContract:
    source = None

    @classmethod
    def make(cls, seed=20261201, max_samples=N):
        return TexelPattern(cls.source, seed, max_samples)

    def test_shape_and_bounds(self, full):
        assert full.shape == (len(TEXELS), N, DIMS)
        assert np.all(full >= 0.0) and np.all(full < 1.0)
        assert self.make().points(np.array([3, 9]), 5, 0).shape == (2, 0, DIMS)
        assert self.make().points(np.zeros(0, np.int64), 0, 4).shape == (0, 4, DIMS)

    def test_same_texel_and_index_give_the_same_point(self, full):
        # Whatever else is drawn in the same call, in whatever order, by a fresh object: a texel's
        # points depend on (seed, texel, index) alone. This is what makes a bake bit-identical for
        # any thread count, tile size and chunk size.
        some = np.array([4095, 17, 64, 0, 2 * WIDE + 5])
        got = np.asarray(self.make().points(some, 11, 20), dtype=np.float64)
        np.testing.assert_array_equal(got, full[some, 11:31])
        one = np.asarray(self.make().points(np.array([17]), 0, N), dtype=np.float64)
        np.testing.assert_array_equal(one[0], full[17])
        # Texel numbers beyond this block (a 65536^2 image) work the same way.
        far = np.array([65536 * 65536 - 1, 123456789])
        a = self.make().points(far, 0, 8)
        b = self.make().points(far[::-1], 0, 8)[::-1]
        np.testing.assert_array_equal(a, b)

    def test_continuing_equals_drawing_at_once(self, full):
        t = TEXELS[::97]
        parts = [self.make().points(t, a, b - a) for a, b in ((0, 5), (5, 32), (32, 33), (33, N))]
        np.testing.assert_array_equal(np.concatenate(parts, axis=1), full[t])

    def test_seed_decides_the_points(self, full):
        again = np.asarray(self.make().points(TEXELS[:64], 0, N), dtype=np.float64)
        np.testing.assert_array_equal(again, full[:64])
        other = np.asarray(self.make(seed=7).points(TEXELS[:64], 0, N), dtype=np.float64)
        assert np.mean(other != full[:64]) > 0.99
        big = self.make(seed=2**63 + 5).points(TEXELS[:4], 0, 4)
        assert np.all((big >= 0) & (big < 1))

    def test_each_sample_index_is_uniform_over_texels(self, full):
        # Unbiasedness, index by index: over 4096 texels, the i-th point of a texel is uniform in
        # [0, 1)^4. Each coordinate on 16 cells (256 expected per cell) and each pair on 8 x 8
        # cells (64 expected). A source that forgets to randomise per texel (every texel the
        # same points), or randomises two dimensions alike (index 0 of Sobol' on the diagonal),
        # or gives two pairs one stratum order, fails here.
        indices = (0, 1, 7, N - 1)
        level = sidak(ALPHA, len(indices) * (DIMS + len(PAIRS)) + DIMS + 2 * len(PAIRS))
        for i in indices:
            u = full[:, i]
            for j in range(DIMS):
                assert chi2_uniform(u[:, j], 16) > level, f"index {i}, dimension {j}"
            for a, b in PAIRS:
                assert chi2_joint(u[:, a], u[:, b], 8) > level, f"index {i}, dimensions {a}, {b}"
        # Finer, on 256 cells (16 expected per cell): a dimension that takes only a few dozen values
        # over the texels (a sequence randomised only by where each texel starts in it) fails here.
        for j in range(DIMS):
            assert chi2_uniform(full[:, 0, j], 256) > level, f"index 0, dimension {j}, 256 cells"
        # Two dimensions that coincide for some of the points (scrambled alike) put excess mass on
        # the diagonal, too little to show on 8 x 8 cells: for independent uniform coordinates
        # their difference modulo 1 is uniform (64 cells).
        for i in (0, 5):
            for a, b in PAIRS:
                diff = np.mod(full[:, i, a] - full[:, i, b], 1.0)
                assert chi2_uniform(np.minimum(diff, np.nextafter(1.0, 0.0)), 64) > level, f"index {i}, u{a} - u{b}"

    def test_dimensions_are_independent_within_each_texel(self, full):
        # Each texel's own 64 points, every pair of dimensions on a 4 x 4 grid (4 expected per
        # cell): the per-texel chi-square statistics summed over texels are one chi-square test
        # with 4096 x 15 degrees of freedom. Structured sets (nets, strata) score far below it;
        # a texel whose position is a function of its direction (the points on a curve) far above.
        # One-sided: only too much structure in the wrong place fails.
        level = sidak(ALPHA, len(PAIRS))
        for a, b in PAIRS:
            cell = np.floor(full[..., a] * 4).astype(np.int64) * 4 + np.floor(full[..., b] * 4).astype(np.int64)
            counts = np.zeros((len(TEXELS), 16))
            np.add.at(counts, (np.repeat(np.arange(len(TEXELS)), N), cell.ravel()), 1.0)
            stat = float((((counts - N / 16) ** 2) / (N / 16)).sum())
            p = stats.chi2.sf(stat, len(TEXELS) * 15)
            assert p > level, f"dimensions {a}, {b}: chi2 {stat:.0f} on {len(TEXELS) * 15} dof"

    def test_texels_are_independent_of_their_neighbours(self, full):
        # The same index (and two different indices) of neighbouring texels, jointly on 8 x 8
        # cells: a hash that correlates neighbours, or one shared set for every texel, fails.
        left = TEXELS.reshape(WIDE, WIDE)[:, :-1].ravel()
        below = TEXELS.reshape(WIDE, WIDE)[:-1, :].ravel()
        cases = [(left, left + 1, 0, 0), (below, below + WIDE, 0, 0), (left, left + 1, 5, 5),
                 (below, below + WIDE, 3, 40)]
        level = sidak(ALPHA, len(cases) * DIMS)
        for a, b, i, k in cases:
            for j in range(DIMS):
                p = chi2_joint(full[a, i, j], full[b, k, j], 8)
                assert p > level, f"texels {a[0]} / {b[0]}, indices {i} / {k}, dimension {j}"

    def test_texels_draw_different_sets(self, full):
        # No two of the 4096 texels share their set of points (checked through the first points).
        assert np.unique(full[:, :4].reshape(len(TEXELS), -1), axis=0).shape[0] == len(TEXELS)


@pytest.mark.parametrize("source", SOURCE_NAMES)
def test_every_source_has_a_contract_class(source):
    assert any(getattr(cls, "source", None) == source for cls in PatternContract.__subclasses__())


def test_hash_more_continues_hash64():
    a, b = np.uint64(7), np.arange(1000, dtype=np.uint64)
    for tail in ((), (np.uint64(3),), (np.uint64(0), np.arange(1000, dtype=np.uint64))):
        np.testing.assert_array_equal(hash_more(hash64(a, b), *tail), hash64(a, b, *tail))
    assert hash_more(hash64(a), np.uint64(1)) == hash64(a, np.uint64(1))


@pytest.mark.parametrize("replicate", [0, 1, 3])
def test_texel_keys_are_hashes_of_seed_texel_replicate_and_tag(replicate):
    """Each texel's draws are hash64(seed, texel, replicate, tag) (the pattern: replicate 0's, then
    the next patterns), however keys() shares the mixing of the common keys."""
    p = TexelPattern("sobol", 99, 64)
    t = np.arange(0, 40000, 3, dtype=np.uint64)
    k = p.keys(t, replicate)
    r = np.uint64(replicate)
    pattern = (below(hash64(p.seed, t, np.uint64(0), P._TAG_PATTERN), p.patterns).astype(np.int64) + replicate)
    np.testing.assert_array_equal(k.pattern, pattern % p.patterns)
    np.testing.assert_array_equal(k.order, ((hash64(p.seed, t, r, P._TAG_ORDER) >> np.uint64(40))
                                            & np.uint64(p.length - 1)).astype(np.int64))
    for j, tag in enumerate((P._TAG_SHIFT2, P._TAG_SHIFT3)):
        np.testing.assert_array_equal(k.shift[:, j], (hash64(p.seed, t, r, tag) >> np.uint64(32)).astype(np.uint32)
                                      & p.shift_mask[j])
    u = (hash64(p.seed, t, r, P._TAG_TURN) >> np.uint64(40)).astype(np.float32) * np.float32(2.0 ** -24)
    turn = np.float32(2 * np.pi) * u
    assert k.cos_turn.dtype == k.sin_turn.dtype == np.float32
    np.testing.assert_array_equal(k.cos_turn, np.cos(turn))
    np.testing.assert_array_equal(k.sin_turn, np.sin(turn))
    # The turn is uniform over the circle: chi-square of its angle in 64 bins.
    angle = np.arctan2(k.sin_turn.astype(np.float64), k.cos_turn.astype(np.float64)) % (2 * np.pi)
    assert chi2_uniform(np.minimum(angle / (2 * np.pi), np.nextafter(1.0, 0.0)), 64) > ALPHA


# ---------------------------------------------------------------------------------------------
# The pool: its patterns are the library's point sets, each passing the set's structural checks
# ---------------------------------------------------------------------------------------------

SEED = 20261201


def pool_patterns(source, max_samples=N):
    """The pattern object and its pool as (patterns, span, 4) uint32."""
    p = TexelPattern(source, SEED, max_samples)
    return p, p.q.reshape(p.patterns, p.span, DIMS)


def set_size(p):
    return p.span if SOURCES[p.source].continues else p.length


@pytest.mark.parametrize("source", SOURCE_NAMES)
@pytest.mark.parametrize("max_samples", [N, 5])
def test_pool_patterns_are_the_library_sets(source, max_samples):
    # Pattern e of the pool is, bit for bit, the public class of core.montecarlo.sources under pattern e's
    # randomisation (drawn from (seed, e) alone); a set stored twice is two equal copies.
    p, q = pool_patterns(source, max_samples)
    cls = SOURCES[source]
    count = set_size(p)
    for e in (0, 1, p.patterns // 2, p.patterns - 1):
        one = cls(DIMS, randomizer=P._pattern_randomizer(cls, p.seed, [e], count))
        if cls is Sobol:  # random_uint32 emits Gray-code order: its row i is direct index gray(i)
            i = np.arange(count)
            want = np.empty((count, DIMS), np.uint32)
            want[i ^ (i >> 1)] = one.random_uint32(count)
        else:
            want = one.random_uint32(count)
        np.testing.assert_array_equal(q[e, :count], want, err_msg=f"pattern {e}")
        for c in range(count, p.span, count):
            np.testing.assert_array_equal(q[e, c:c + count], want, err_msg=f"pattern {e}, copy")


def test_pool_words_are_hashes_of_seed_pattern_and_counter():
    e = np.array([0, 5, 4095], dtype=np.uint64)
    bits = P._PatternBits(np.uint64(SEED), e)
    w = np.concatenate([bits.words(3), bits.words(70000)], axis=1)
    j = np.arange(70003, dtype=np.uint64)
    np.testing.assert_array_equal(w, hash64(np.uint64(SEED), e[:, None], j[None, :], P._TAG_SCRAMBLE))


def test_sobol_pool_is_owen_scrambled_direct_sobol():
    # Written out from the definitions: pattern e is the first `span` 4D Sobol' points (direct
    # order), each dimension Owen-scrambled with the seed hash64(seed, e, dimension) >> 32.
    p, q = pool_patterns("sobol")
    e = np.arange(p.patterns, dtype=np.uint64)[:, None]
    seeds = (hash64(p.seed, e, np.arange(DIMS, dtype=np.uint64)[None, :], P._TAG_SCRAMBLE) >> np.uint64(32)).astype(np.uint32)
    want = owen_scramble_uint32(sobol_uint32(np.arange(p.span), DIMS)[None], seeds[:, None, :])
    np.testing.assert_array_equal(q, want)


def nets_in_every_block(x, m):
    """Whether every aligned block of 2^m rows of every pattern of the uint32 points ``x``
    (patterns, n, s), s = 1 or 2, is a (0, m, s)-net in base 2."""
    pats, n, s = x.shape
    x = x.astype(np.uint64).reshape(-1, s)
    block = np.arange(len(x)) >> m
    for k in (range(m + 1) if s == 2 else [m]):
        cell = x[:, 0] >> np.uint64(32 - k)
        if s == 2:
            cell = (cell << np.uint64(m - k)) | (x[:, 1] >> np.uint64(32 - (m - k)))
        counts = np.bincount((block << m) + cell.astype(np.int64), minlength=len(x))
        if not np.all(counts == 1):
            return False
    return True


def test_every_sobol_pool_pattern_is_a_net_in_every_block():
    p, q = pool_patterns("sobol")
    for m in range(int(math.log2(p.span)) + 1):
        assert nets_in_every_block(q[..., :2], m), m
        for j in range(DIMS):
            assert nets_in_every_block(q[..., j:j + 1], m), (m, j)
    # The position pair keeps the t of the unscrambled 4D points in every pattern (checked on 64).
    m = int(math.log2(p.span))
    t_pos = t_value(sobol_uint32(np.arange(p.span), DIMS)[:, 2:].astype(np.float64) * 2.0**-32, m)
    for e in range(0, p.patterns, p.patterns // 64):
        assert elementary_counts_ok(q[e, :, 2:].astype(np.float64) * 2.0**-32, m, t_pos), e
    # The checker can fail: a toroidal shift of one dimension breaks the nets.
    assert not nets_in_every_block((q[..., :2] + np.array([0, 2**30 + 12345], np.uint32)), int(math.log2(p.span)))


def test_every_halton_pool_pattern_is_stratified():
    # In every pattern, every aligned block of b^k points of the dimension with base b holds one
    # point in each interval of length b^-k (b^k up to the pattern's length).
    p, q = pool_patterns("halton")
    for j, b in enumerate((2, 3, 5, 7)):
        k = 1
        while b**k <= p.span:
            usable = p.span - p.span % b**k
            cell = np.floor(q[:, :usable, j].astype(np.float64) * 2.0**-32 * b**k).astype(np.int64)
            blocks = cell.reshape(p.patterns, -1, b**k)
            np.testing.assert_array_equal(np.sort(blocks, axis=2), np.broadcast_to(np.arange(b**k), blocks.shape),
                                          err_msg=f"base {b}, level {k}")
            k += 1


def test_every_stratified_pool_pattern_fills_its_strata():
    p, q = pool_patterns("stratified")
    nx, ny = Stratified.grid_shape(p.length)
    ax, ay = nx.bit_length() - 1, ny.bit_length() - 1
    for j in (0, 2):
        cell = (q[:, :p.length, j] >> np.uint32(32 - ax)).astype(np.int64) * ny + (q[:, :p.length, j + 1] >> np.uint32(32 - ay))
        np.testing.assert_array_equal(np.sort(cell, axis=1), np.broadcast_to(np.arange(p.length), cell.shape),
                                      err_msg=f"dims {j}, {j + 1}")


@pytest.mark.parametrize("source", SOURCE_NAMES)
def test_pool_patterns_are_independent_randomisations(source):
    # Over the pool's patterns, a fixed row is uniform on [0, 1)^4: each coordinate on 16 cells,
    # each pair of coordinates on 8 x 8 (at least 2048 patterns: 128 and 32 expected per cell), and
    # below the first 4 bits (x * 16 mod 1, on 16 cells) where a randomisation that stops at
    # the digits the indices reach leaves every pattern on one grid. A pool whose patterns share
    # a randomisation, or whose dimensions share one (a stratum order, a scramble seed), fails.
    p, q = pool_patterns(source)
    assert p.patterns >= 2048
    u = q.astype(np.float64) * 2.0**-32
    rows = (0, 1, set_size(p) - 1)
    level = sidak(ALPHA, len(rows) * (2 * DIMS + len(PAIRS)))
    for i in rows:
        for j in range(DIMS):
            assert chi2_uniform(u[:, i, j], 16) > level, f"row {i}, dimension {j}"
            assert chi2_uniform(np.mod(u[:, i, j] * 16, 1.0), 16) > level, f"row {i}, dimension {j}, below 1/16"
        for a, b in PAIRS:
            assert chi2_joint(u[:, i, a], u[:, i, b], 8) > level, f"row {i}, dimensions {a}, {b}"


class TestSobol(PatternContract):
    source = "sobol"

    def test_prefixes_and_aligned_blocks_are_nets_per_texel(self, full):
        # Per texel, the first 2^m points (and every aligned block of 2^m points, which is what
        # adaptive sampling's doubling rounds and the baker's pieces trace) hold one point in every
        # elementary interval of dimensions (0, 1), the (0, 2)-sequence that drives the direction,
        # and in every interval of length 2^-m of each dimension on its own.
        for t in TEXELS[::257]:
            u = full[t]
            for m in range(int(math.log2(N)) + 1):
                for start in range(0, N, 2**m):
                    block = u[start:start + 2**m]
                    assert elementary_counts_ok(block[:, :2], m, 0), (t, m, start)
                    for j in range(DIMS):
                        assert elementary_counts_ok(block[:, j:j + 1], m, 0), (t, m, start, j)

    def test_each_texel_keeps_the_t_value_of_the_4d_sobol_points(self, full):
        # The 4D set of each texel is a (t, m, 4)-net with the t of the unscrambled 4D Sobol'
        # points (the scramble permutes elementary intervals, so it cannot lose any), for the
        # position pair (2, 3) and for all four dimensions together.
        m = int(math.log2(N))
        base = sobol_uint32(np.arange(N), DIMS).astype(np.float64) * 2.0**-32
        t_pos = t_value(base[:, 2:], m)
        t_all = t_value(base, m)
        for t in TEXELS[::511]:
            assert elementary_counts_ok(full[t][:, 2:], m, t_pos), t
            assert elementary_counts_ok(full[t], m, t_all), t

    def test_net_checker_can_fail(self):
        rng = np.random.default_rng(1)
        assert not elementary_counts_ok(rng.random((64, 2)), 6, 0)
        bad = sobol_uint32(np.arange(64), 2).astype(np.float64) * 2.0**-32
        bad[:, 1] = (bad[:, 1] + 0.3) % 1.0  # a toroidal shift breaks the elementary intervals
        assert not elementary_counts_ok(bad, 6, 0)


class TestHalton(PatternContract):
    source = "halton"

    def test_first_points_are_stratified_per_texel(self, full):
        # Per texel, the first b^k points of the dimension with base b (2, 3, 5, 7) fall one in
        # each of b^k equal arcs of the circle [0, 1), for some rotation of the arcs (a texel's
        # randomisation may rotate the circle, which keeps strata as arcs): sorted, the points
        # x_(j) - j / b^k all lie within one arc length.
        for t in TEXELS[::257]:
            for j, b in enumerate((2, 3, 5, 7)):
                k = 1
                while b**k <= N:
                    assert stratified_on_circle(full[t, :b**k, j]), (t, j, b, k)
                    k += 1

    def test_circle_check_can_fail(self):
        assert stratified_on_circle(np.array([0.05, 0.3, 0.55, 0.8]))
        assert stratified_on_circle(np.array([0.95, 0.2, 0.45, 0.7]))
        assert not stratified_on_circle(np.array([0.05, 0.1, 0.15, 0.8]))


class TestStratified(PatternContract):
    source = "stratified"

    def test_every_stratum_holds_one_point_per_texel(self, full):
        nx, ny = Stratified.grid_shape(N)
        for t in TEXELS[::257]:
            for j in (0, 2):
                cell = np.floor(full[t, :, j] * nx).astype(np.int64) * ny + np.floor(full[t, :, j + 1] * ny).astype(np.int64)
                np.testing.assert_array_equal(np.sort(cell), np.arange(N), err_msg=f"texel {t}, dims {j}, {j + 1}")


class TestIndependent(PatternContract):
    source = "independent"
