"""Tests of core.montecarlo.sources: the shared contract of every source, then Sobol', Owen, stratified, Halton."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from scipy.stats import qmc

from core.base.errors import SettingsError
from core.montecarlo.halton import _radical_fixed_point, Halton, PermuteDigits
from core.montecarlo.independent import Independent
from core.montecarlo.pointset import GeneratorBits, NoRandomizer, to_unit_float
from core.montecarlo.sobol import owen_scramble_uint32, OwenScrambler, reverse_bits_uint32, Sobol, SOBOL_MAX_DIM, sobol_uint32
from core.montecarlo.sources import make_source, SOURCES
from core.montecarlo.stratified import _in_stratum, Stratified

ROOT = Path(__file__).resolve().parents[1]

# Family-wise false-alarm rate of every statistical test below; tests that run several
# chi-square tests split it with the Sidak correction.
ALPHA = 1e-3


def sidak(alpha, m):
    """Per-test level that keeps the family-wise level at alpha over m independent tests."""
    return 1.0 - (1.0 - alpha) ** (1.0 / m)


def uniform_pvalue(values, bins):
    """Chi-square p-value of values in [0, 1) against the uniform law, on `bins` equal cells."""
    counts = np.bincount(np.floor(values * bins).astype(np.int64), minlength=bins)
    assert counts.size == bins, "values outside [0, 1)"
    return stats.chisquare(counts).pvalue


def gray(i):
    i = np.asarray(i, dtype=np.uint64)
    return i ^ (i >> np.uint64(1))


def is_net_2d(points, m):
    """True when the 2**m points form a (0, m, 2)-net in base 2.

    Every elementary interval [a 2^-k, (a+1) 2^-k) x [b 2^-(m-k), (b+1) 2^-(m-k)) of area 2^-m,
    for every k = 0..m, holds exactly one point. Coordinates are multiples of 2^-32, so
    floor(x * 2^k) is exact.
    """
    assert len(points) == 2**m
    for k in range(m + 1):
        cx = np.floor(points[:, 0] * 2.0**k).astype(np.int64)
        cy = np.floor(points[:, 1] * 2.0 ** (m - k)).astype(np.int64)
        if np.unique(cx * 2 ** (m - k) + cy).size != 2**m:
            return False
    return True


def one_per_interval(x, cells):
    """True when the len(x) == cells values hold one point in each interval of length 1/cells."""
    return np.unique(np.floor(x * cells).astype(np.int64)).size == cells == len(x)


# ---------------------------------------------------------------------------------------------
# The contract every source honours (reused like scipy's QMCEngine test mixin)
# ---------------------------------------------------------------------------------------------


class SourceContract:
    cls = None
    #: True when consecutive random() calls continue one sequence (all but Stratified).
    continues = True

    def make(self, d=2, seed=12345):
        return self.cls(d, seed=seed)

    def test_registered(self):
        assert SOURCES[self.cls.name] is self.cls
        assert isinstance(make_source(self.cls.name, 3, seed=1), self.cls)

    @pytest.mark.parametrize("d", [1, 2, 3])
    def test_zero_samples(self, d):
        out = self.make(d).random(0)
        assert out.shape == (0, d) and out.dtype == np.float64

    @pytest.mark.parametrize("d", [1, 2, 3, 5])
    @pytest.mark.parametrize("n", [1, 3, 16, 1000])
    def test_bounds_and_shape(self, d, n):
        out = self.make(d).random(n)
        assert out.shape == (n, d) and out.dtype == np.float64
        assert np.all(out >= 0.0) and np.all(out < 1.0)

    def test_non_power_of_two(self):
        src = self.make(3)
        out = src.random(1000)
        assert out.shape == (1000, 3)
        assert src.num_generated == 1000
        # Distinct points: a stuck or repeating generator would fail this.
        assert np.unique(out, axis=0).shape[0] == 1000

    def test_reset_reproduces(self):
        src = self.make(3)
        first = src.random(37)
        src.random(11)
        src.reset()
        assert src.num_generated == 0
        np.testing.assert_array_equal(src.random(37), first)

    def test_continuing_equals_one_go(self):
        src = self.make(3)
        chunks = np.concatenate([src.random(5), src.random(27), src.random(100)])
        whole = self.make(3).random(132)
        if self.continues:
            np.testing.assert_array_equal(chunks, whole)
        else:
            # Each call is a fresh set: the first matches, the continuation does not.
            np.testing.assert_array_equal(chunks[:5], self.make(3).random(5))
            assert not np.array_equal(chunks, whole)

    def test_fast_forward_equals_discarding(self):
        a = self.make(3)
        b = self.make(3)
        assert a.fast_forward(45) is a
        b.random(45)
        assert a.num_generated == b.num_generated == 45
        np.testing.assert_array_equal(a.random(20), b.random(20))

    def test_seeds(self):
        same = self.make(2, seed=7).random(64)
        np.testing.assert_array_equal(self.make(2, seed=7).random(64), same)
        # Every accepted seed form is normalised by default_rng and gives the same stream.
        np.testing.assert_array_equal(self.make(2, seed=np.random.SeedSequence(7)).random(64), same)
        np.testing.assert_array_equal(self.make(2, seed=np.random.default_rng(7)).random(64), same)
        assert not np.array_equal(self.make(2, seed=8).random(64), same)
        assert not np.array_equal(self.make(2, seed=None).random(64), self.make(2, seed=None).random(64))

    def test_generator_reset_uses_initial_state(self):
        rng = np.random.default_rng(3)
        src = self.make(2, seed=rng)
        first = src.random(10)
        rng.random(5)  # the caller moving its generator must not change what reset replays
        src.reset()
        np.testing.assert_array_equal(src.random(10), first)

    @pytest.mark.parametrize("bad", [0, -1, 2.0, True])
    def test_bad_dimension(self, bad):
        with pytest.raises((ValueError, TypeError)):
            self.cls(bad)

    @pytest.mark.parametrize("bad", [-1, 2.5, "3"])
    def test_bad_count(self, bad):
        with pytest.raises((ValueError, TypeError)):
            self.make().random(bad)

    def test_each_point_uniform_over_seeds(self):
        # Unbiasedness: over random seeds, a fixed row of a set of n = 7 (not a power of two, not
        # a rectangle) is uniform in [0, 1)^3. Rows 0 and 5; each coordinate on 16 bins and the
        # pairs (0, 1), (1, 2) jointly on 8 x 8 cells: 2048 seeds give expected counts of 128
        # and 32, well inside the chi-square approximation. A source that skipped its
        # randomisation, chose strata badly or scrambled two dimensions with one seed (row 0 of
        # Sobol' would then sit on the diagonal) fails.
        seeds = np.random.SeedSequence(99).spawn(2048)
        sets = np.array([self.cls(3, seed=s).random(7) for s in seeds])
        level = sidak(ALPHA, 2 * 5)
        for row in (0, 5):
            pts = sets[:, row]
            for j in range(3):
                assert uniform_pvalue(pts[:, j], 16) > level, f"row {row}, dimension {j}"
            for j in (0, 1):
                cell = np.floor(pts[:, j] * 8) * 8 + np.floor(pts[:, j + 1] * 8)
                assert uniform_pvalue(cell / 64, 64) > level, f"row {row}, dimensions {j}, {j + 1}"


    def test_random_uint32_is_random_in_fixed_point(self):
        # The same points, the same continuation: floats and fixed point from one implementation.
        a, b = self.make(3), self.make(3)
        for n in (5, 27, 0, 64):
            x, q = a.random(n), b.random_uint32(n)
            assert q.dtype == np.uint32 and q.shape == (n, 3)
            assert np.all(np.abs(to_unit_float(q) - x) < 2.0**-32)
            if self.cls is not Halton:  # Halton rounds to keep its strata (tested below)
                np.testing.assert_array_equal(q, (x * 2.0**32).astype(np.uint32))
        assert a.num_generated == b.num_generated == 96

    def test_given_randomizer_reset_replays(self):
        # A randomisation passed in is used as given, and reset rewinds it like the rng.
        r = self.cls.randomizer_from(GeneratorBits(np.random.default_rng(4)), 3, 64)
        src = self.cls(3, randomizer=r)
        first = src.random(16)
        src.random(16)
        src.reset()
        np.testing.assert_array_equal(src.random(16), first)
        again = self.cls(3, randomizer=self.cls.randomizer_from(GeneratorBits(np.random.default_rng(4)), 3, 64))
        np.testing.assert_array_equal(again.random(16), first)

    def test_refuses_a_randomizer_of_several_sets(self):
        with pytest.raises(ValueError):
            self.cls(2, randomizer=self.cls.randomizer_from(ManySets(3, seed=0), 2, 8))


class TestIndependent(SourceContract):
    cls = Independent

    def test_is_the_generators_stream(self):
        # The default bit source keeps Independent exactly numpy's Generator.random.
        np.testing.assert_array_equal(Independent(3, seed=5).random(10), np.random.default_rng(5).random((10, 3)))


class TestStratified(SourceContract):
    cls = Stratified
    continues = False


class TestSobol(SourceContract):
    cls = Sobol


class TestHalton(SourceContract):
    cls = Halton


# ---------------------------------------------------------------------------------------------
# Many randomised sets at once (the baker's pools) are the public sets
# ---------------------------------------------------------------------------------------------


class ManySets:
    """A bit source of ``sets`` randomisations, set ``s`` drawing from its own Generator: that set
    alone is ``GeneratorBits(default_rng(seeds[s]))``."""

    def __init__(self, sets, seed):
        self.seeds = [seed * 1000 + s for s in range(sets)]
        self.gens = [np.random.default_rng(x) for x in self.seeds]
        self.sets = sets

    def words(self, count):
        return np.concatenate([GeneratorBits(g).words(count) for g in self.gens])


class FastManySets:
    """Many sets from one Generator (no per-set stream): for statistics over thousands of sets."""

    def __init__(self, sets, seed):
        self.rng = np.random.default_rng(seed)
        self.sets = sets

    def words(self, count):
        return self.rng.integers(0, 2**64, size=(self.sets, count), dtype=np.uint64)


def direct_order(cls, q):
    """Rows of ``random_uint32`` output in the order of :meth:`sets_uint32` (Sobol' emits Gray-code
    order: its row i is direct index gray(i))."""
    if cls is not Sobol:
        return q
    out = np.empty_like(q)
    out[gray(np.arange(len(q))).astype(np.int64)] = q
    return out


@pytest.mark.parametrize("name", sorted(SOURCES))
@pytest.mark.parametrize("n,d", [(64, 4), (37, 3), (1, 5), (0, 2)])
def test_sets_are_the_public_sets(name, n, d):
    # One implementation: set s of a many-set build is, bit for bit, what the public class gives
    # with set s's randomisation (and its floats, to the last bit they carry).
    cls = SOURCES[name]
    many = cls.sets_uint32(n, d, cls.randomizer_from(ManySets(3, seed=n), d, n))
    assert many.shape == (3, n, d) and many.dtype == np.uint32
    full = n if cls is not Sobol else 1 << max(0, (n - 1).bit_length())  # whole aligned block
    for s, seed in enumerate(ManySets(3, seed=n).seeds):
        one = lambda: cls(d, randomizer=cls.randomizer_from(GeneratorBits(np.random.default_rng(seed)), d, full))
        q = direct_order(cls, one().random_uint32(full))[:n]
        np.testing.assert_array_equal(many[s], q, err_msg=f"set {s}")
        x = direct_order(cls, one().random(full))[:n]
        assert np.all(np.abs(to_unit_float(many[s]) - x) < 2.0**-32)
        if cls in (Sobol, Stratified):  # natively 32-bit: the floats are the same bits
            np.testing.assert_array_equal(to_unit_float(many[s]), x)
    if n > 1:
        assert not np.array_equal(many[0], many[1])


def test_sobol_sets_are_owen_scrambles_of_the_direct_form():
    seeds = np.array([[1, 2, 3], [2**32 - 1, 0, 77]], dtype=np.uint32)
    got = Sobol.sets_uint32(16, 3, OwenScrambler(seeds))
    base = sobol_uint32(np.arange(16), 3)
    for s in range(2):
        np.testing.assert_array_equal(got[s], owen_scramble_uint32(base, seeds[s]))
    np.testing.assert_array_equal(Sobol.sets_uint32(16, 3, NoRandomizer())[0], base)


def test_randomizers_are_checked():
    with pytest.raises(TypeError):
        Sobol(2, randomizer=PermuteDigits.identity([2, 3]))
    with pytest.raises(TypeError):
        Halton(2, randomizer=OwenScrambler([1, 2]))
    with pytest.raises(ValueError):
        Sobol(3, randomizer=OwenScrambler([1, 2]))
    with pytest.raises(ValueError):
        Halton(2, randomizer=PermuteDigits.identity([2, 5]))
    np.testing.assert_array_equal(Halton(3, randomizer=NoRandomizer()).random(50), Halton(3, scramble=False).random(50))


def test_halton_stops_at_its_permutations_capacity():
    r = PermuteDigits.draw(GeneratorBits(np.random.default_rng(0)), [2, 3], capacity=100)
    assert r.capacity >= 100
    src = Halton(2, randomizer=r)
    src.random(r.capacity)
    with pytest.raises(ValueError):
        src.random(1)


def test_halton_tail_is_uniform_below_the_permuted_digits():
    # Below the D permuted digits (b**D >= capacity), every point's value is the random tail,
    # uniform: x * b**D modulo 1, over 4096 randomisations, on 16 cells. A randomisation that
    # left out the tail (points on the grid of b**-D) or drew it badly fails.
    n, d, sets = 20, 3, 4096
    r = Halton.randomizer_from(FastManySets(sets, seed=3), d, n)
    x = Halton.points(np.arange(n), d, r)
    level = sidak(ALPHA, 2 * d)
    for j, (b, K, D) in enumerate(r.digits):
        assert b**D >= n > b ** (D - 1)
        for i in (0, n - 1):
            frac = np.mod(x[:, i, j] * float(b**D), 1.0)
            assert uniform_pvalue(frac, 16) > level, (b, i)


def test_stratified_sets_fill_their_strata_and_pad_independently():
    # Many sets at once: each set's pairs fill the grid, and over sets the two pairs' strata are
    # independent ("padding"): the stratum of point 0 in dims (0, 1) against that in dims (2, 3)
    # on 8 x 8 strata (16 x 8 grid for n = 128, columns halved), 64 expected per cell.
    n, sets = 128, 4096
    q = Stratified.sets_uint32(n, 4, FastManySets(sets, seed=5))
    nx, ny = Stratified.grid_shape(n)
    for j in (0, 2):
        cell = (q[..., j] >> np.uint32(32 - 4)).astype(np.int64) * ny + (q[..., j + 1] >> np.uint32(32 - 3))
        np.testing.assert_array_equal(np.sort(cell, axis=1), np.broadcast_to(np.arange(n), (sets, n)))
    a = (q[:, 0, 0] >> np.uint32(29)).astype(np.int64) * 8 + (q[:, 0, 2] >> np.uint32(29))
    assert stats.chisquare(np.bincount(a, minlength=64)).pvalue > ALPHA


@pytest.mark.parametrize("m", [1, 2, 3, 5, 7, 12, 64, 1000, 10007, 2**20])
def test_in_stratum_is_exact(m):
    # Every jitter, extremes included, lands in its stratum, and the float of the fixed point
    # too; power-of-two strata (shifts) follow the same rule as the others (divisions).
    rng = np.random.default_rng(m)
    k = np.concatenate([[0, m - 1], rng.integers(0, m, 500)])
    jitter = np.concatenate([[0, 2**32 - 1], rng.integers(0, 2**32, 500, dtype=np.uint64)]).astype(np.uint64)
    for jit in (jitter, np.zeros_like(jitter), np.full_like(jitter, 2**32 - 1)):
        v = _in_stratum(k, m, jit)
        assert v.dtype == np.uint32
        np.testing.assert_array_equal(np.floor(to_unit_float(v) * m).astype(np.int64), k)
        first = [-(-(int(a) << 32) // m) for a in k]
        last = [-(-((int(a) + 1) << 32) // m) for a in k]
        ref = [f + (((l - f) * int(j)) >> 32) for f, l, j in zip(first, last, jit)]
        assert [int(x) for x in v] == ref


@pytest.mark.parametrize("b", [3, 5, 7, 11])
def test_halton_fixed_point_keeps_the_strata(b):
    # Values just above an interval's start (not a multiple of 2**-32 for odd b) stay in it;
    # elsewhere the fixed point is the value rounded down.
    K, D = 52 // int(np.log2(b)), 4
    while b**K > 2**52:
        K -= 1
    starts = np.arange(b**D, dtype=np.uint64) * np.uint64(b ** (K - D))
    a = np.concatenate([starts, starts + np.uint64(1), starts + np.uint64(b ** (K - D) - 1)])
    q = _radical_fixed_point(a, b, K, D)
    s = a // np.uint64(b ** (K - D))
    np.testing.assert_array_equal(np.floor(to_unit_float(q) * b**D).astype(np.int64), s.astype(np.int64))
    x = a.astype(np.float64) / float(b**K)
    assert np.all(np.abs(to_unit_float(q) - x) < 2.0**-32)
    # Plain rounding down would have failed here: the check can fail.
    plain = np.floor(x * 2.0**32) * 2.0**-32
    assert np.any(np.floor(plain * b**D) != s)


def test_make_source_unknown_name():
    with pytest.raises(ValueError) as info:
        make_source("sobel")
    message = str(info.value)
    assert "sobel" in message
    for name in ("independent", "stratified", "sobol", "halton"):
        assert name in message


def test_registry_names():
    assert set(SOURCES) == {"independent", "stratified", "sobol", "halton"}
    for name, cls in SOURCES.items():
        assert cls.name == name


def test_core_sources_needs_neither_scipy_nor_bpy():
    code = "import sys, core.montecarlo.sources; print('scipy' in sys.modules, 'bpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]


# ---------------------------------------------------------------------------------------------
# Sobol' points
# ---------------------------------------------------------------------------------------------


def test_sobol_uint32_matches_scipy_first_4096_points_8_dims():
    n, d = 2**12, 8
    ref = qmc.Sobol(d, scramble=False, bits=32).random(n)
    i = np.arange(n)
    # scipy emits the points in Gray-code order: its point i is the direct form at gray(i).
    ours = sobol_uint32(gray(i), d)
    assert ours.dtype == np.uint32 and ours.shape == (n, d)
    np.testing.assert_array_equal(ours.astype(np.uint64), (ref * 2.0**32).astype(np.uint64))
    np.testing.assert_array_equal(to_unit_float(ours), ref)
    # As a set, the first 2^12 indices in natural order are the same points.
    natural = to_unit_float(sobol_uint32(i, d))
    np.testing.assert_array_equal(np.unique(natural, axis=0), np.unique(ref, axis=0))
    # scipy's default bits=30 keeps the top 30 bits of the same numbers.
    ref30 = qmc.Sobol(d, scramble=False).random(n)
    np.testing.assert_array_equal(ours >> np.uint32(2), (ref30 * 2.0**30).astype(np.uint32))


@pytest.mark.filterwarnings("ignore:The balance properties of Sobol:UserWarning")
def test_sobol_class_unscrambled_equals_scipy():
    src = Sobol(8, scramble=False, seed=0)
    ref = qmc.Sobol(8, scramble=False, bits=32)
    np.testing.assert_array_equal(src.random(1000), ref.random(1000))
    np.testing.assert_array_equal(src.random(3096), ref.random(3096))


def test_sobol_direction_numbers_all_dims_and_bits():
    # Single-bit indices give the direction vectors themselves: v_k of every built-in dimension,
    # for all 32 bits, compared with scipy's table of the same Joe-Kuo file.
    ours = sobol_uint32(np.uint32(1) << np.arange(32, dtype=np.uint32), SOBOL_MAX_DIM)
    sv = getattr(qmc.Sobol(SOBOL_MAX_DIM, scramble=False, bits=32), "_sv", None)
    if sv is None:
        pytest.skip("scipy no longer exposes its direction numbers")
    np.testing.assert_array_equal(ours.T, sv)


def test_sobol_uint32_large_indices_match_scipy():
    start = 2**22 + 12345
    ref = qmc.Sobol(SOBOL_MAX_DIM, scramble=False, bits=32)
    ref.fast_forward(start)
    i = np.arange(start, start + 64)
    np.testing.assert_array_equal(to_unit_float(sobol_uint32(gray(i), SOBOL_MAX_DIM)), ref.random(64))


def test_sobol_uint32_is_linear_in_the_index():
    # The direct form is GF(2)-linear: x(i ^ j) = x(i) ^ x(j), here up to the top index bit.
    rng = np.random.default_rng(5)
    i = rng.integers(0, 2**32, size=1000, dtype=np.uint32)
    j = rng.integers(0, 2**32, size=1000, dtype=np.uint32)
    np.testing.assert_array_equal(
        sobol_uint32(i ^ j, 8), sobol_uint32(i, 8) ^ sobol_uint32(j, 8)
    )
    # Van der Corput (dimension 0) reverses the index's bits: the largest index gives all ones.
    assert sobol_uint32(np.array([2**32 - 1]), 1)[0, 0] == 0xFFFFFFFF


def test_sobol_uint32_shapes_and_validation():
    assert sobol_uint32(np.zeros((0,), dtype=np.int64), 3).shape == (0, 3)
    assert sobol_uint32(np.arange(6).reshape(2, 3), 2).shape == (2, 3, 2)
    with pytest.raises(ValueError):
        sobol_uint32([-1], 2)
    with pytest.raises(ValueError):
        sobol_uint32([2**32], 2)
    with pytest.raises(TypeError):
        sobol_uint32([0.5], 2)
    with pytest.raises(ValueError):
        sobol_uint32([0], SOBOL_MAX_DIM + 1)


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_scrambled_sobol_is_a_net_for_every_prefix(seed):
    pts = Sobol(2, seed=seed).random(2**12)
    assert np.all(pts >= 0.0) and np.all(pts < 1.0)
    for m in range(13):
        assert is_net_2d(pts[: 2**m], m), f"m={m}"


@pytest.mark.parametrize("m", [3, 6, 9])
def test_scrambled_sobol_continuing_chunks_are_nets(m):
    src = Sobol(2, seed=2024)
    for _ in range(5):
        assert is_net_2d(src.random(2**m), m)
    src.fast_forward(7 * 2**m)
    assert is_net_2d(src.random(2**m), m)


def test_scrambled_sobol_every_dimension_stratified():
    # Every Sobol' dimension is a (0, m, 1)-net on its own; the scramble must keep it so.
    pts = Sobol(SOBOL_MAX_DIM, seed=11).random(2**10)
    for m in range(11):
        for j in range(SOBOL_MAX_DIM):
            assert one_per_interval(pts[: 2**m, j], 2**m), (m, j)


def test_net_checker_can_fail():
    # Negative controls: independent points are not a net, and a scramble without the nested
    # structure (xor with a per-point random word) breaks Sobol' nets.
    assert not is_net_2d(Independent(2, seed=0).random(2**8), 8)
    rng = np.random.default_rng(0)
    u = sobol_uint32(np.arange(2**8), 2) ^ rng.integers(0, 2**32, size=(2**8, 2), dtype=np.uint32)
    assert not is_net_2d(to_unit_float(u), 8)


def test_sobol_scramble_seeds_differ_per_dimension():
    # Dimensions 0 and 1 scrambled with one seed would stay correlated; each has its own.
    pts = Sobol(2, seed=1).random(2**10)
    assert not np.array_equal(pts[:, 0], pts[:, 1])
    assert not np.array_equal(Sobol(2, seed=1).random(64), Sobol(2, scramble=False).random(64))


def test_sobol_refuses_to_wrap_past_2_32():
    src = Sobol(2, seed=0).fast_forward(2**32 - 4)
    assert src.random(4).shape == (4, 2)
    with pytest.raises(ValueError):
        src.random(1)


# ---------------------------------------------------------------------------------------------
# Owen scrambling and bit helpers
# ---------------------------------------------------------------------------------------------


def _reverse_ref(x):
    return int(f"{int(x):032b}"[::-1], 2)


def _fast_owen_ref(v, seed):
    """pbrt-v4 FastOwenScrambler in Python ints with explicit 32-bit wrap-around."""
    mask = 0xFFFFFFFF
    v = _reverse_ref(v)
    v ^= (v * 0x3D20ADEA) & mask
    v = (v + seed) & mask
    v = (v * ((seed >> 16) | 1)) & mask
    v ^= (v * 0x05526C56) & mask
    v ^= (v * 0x53A22864) & mask
    return _reverse_ref(v)


def test_reverse_bits_matches_reference():
    rng = np.random.default_rng(1)
    x = np.concatenate([[0, 1, 2**31, 2**32 - 1, 0x12345678], rng.integers(0, 2**32, 1000)])
    got = reverse_bits_uint32(x)
    assert got.dtype == np.uint32
    assert [int(g) for g in got] == [_reverse_ref(v) for v in x]
    np.testing.assert_array_equal(reverse_bits_uint32(got), x.astype(np.uint32))
    assert reverse_bits_uint32(np.uint32(1)).shape == ()
    assert reverse_bits_uint32(x.reshape(-1, 5)).shape == (201, 5)


def test_owen_matches_scalar_reference():
    rng = np.random.default_rng(2)
    x = rng.integers(0, 2**32, size=500, dtype=np.uint32)
    seed = rng.integers(0, 2**32, size=500, dtype=np.uint32)
    x[:3] = [0, 2**32 - 1, 2**31]
    seed[:3] = [0, 2**32 - 1, 0xFFFF0000]
    got = owen_scramble_uint32(x, seed)
    assert got.dtype == np.uint32
    assert [int(g) for g in got] == [_fast_owen_ref(int(a), int(s)) for a, s in zip(x, seed)]


def test_owen_keeps_shared_bit_prefixes():
    # Nested scrambling: x and y sharing their top k bits map to values sharing their top k bits,
    # for every k, with the same seed. The check can fail: a plain hash of x would not do this.
    rng = np.random.default_rng(3)
    n = 4000
    for k in range(1, 33):
        low = np.uint32((1 << (32 - k)) - 1)
        x = rng.integers(0, 2**32, size=n, dtype=np.uint32)
        y = (x & ~low) | (rng.integers(0, 2**32, size=n, dtype=np.uint32) & low)
        seed = rng.integers(0, 2**32, size=n, dtype=np.uint32)
        sx, sy = owen_scramble_uint32(x, seed), owen_scramble_uint32(y, seed)
        np.testing.assert_array_equal(sx & ~low, sy & ~low, err_msg=f"k={k}")


def test_owen_permutes_each_level():
    # With one seed, the 2^16 values with distinct top 16 bits keep distinct top 16 bits: the
    # scramble is a permutation of the dyadic intervals at that level (what keeps nets nets).
    rng = np.random.default_rng(4)
    x = (np.arange(2**16, dtype=np.uint32) << np.uint32(16)) | rng.integers(
        0, 2**16, size=2**16, dtype=np.uint32
    )
    top = owen_scramble_uint32(x, 0xDEADBEEF) >> np.uint32(16)
    assert np.unique(top).size == 2**16


def test_owen_marginal_is_uniform_over_seeds():
    # For a fixed input, the scrambled value over random seeds must be uniform: its top byte
    # and a middle byte are chi-square tested on 256 cells with 2^17 seeds (512 per cell).
    rng = np.random.default_rng(5)
    xs = [0, 2**31, 0xFFFFFFFF, int(rng.integers(0, 2**32))]
    level = sidak(ALPHA, 2 * len(xs))
    for x in xs:
        seeds = rng.integers(0, 2**32, size=2**17, dtype=np.uint32)
        out = owen_scramble_uint32(np.uint32(x), seeds)
        for shift in (24, 12):
            byte = ((out >> np.uint32(shift)) & np.uint32(255)).astype(np.int64)
            p = stats.chisquare(np.bincount(byte, minlength=256)).pvalue
            assert p > level, f"x={x:#x}, bits {shift}..{shift + 7}"


def test_owen_seed_broadcasting():
    rng = np.random.default_rng(6)
    x = rng.integers(0, 2**32, size=(50, 2), dtype=np.uint32)
    per_dim = np.array([17, 2**32 - 5], dtype=np.uint32)
    got = owen_scramble_uint32(x, per_dim)
    assert got.shape == (50, 2)
    for j in range(2):
        np.testing.assert_array_equal(got[:, j], owen_scramble_uint32(x[:, j], int(per_dim[j])))
    per_point = rng.integers(0, 2**32, size=(50, 2), dtype=np.uint32)
    got = owen_scramble_uint32(x, per_point)
    assert [int(g) for g in got.ravel()] == [
        _fast_owen_ref(int(a), int(s)) for a, s in zip(x.ravel(), per_point.ravel())
    ]
    assert owen_scramble_uint32(5, 7).shape == ()
    assert not np.array_equal(owen_scramble_uint32(x, 1), owen_scramble_uint32(x, 2))


def test_owen_validation():
    with pytest.raises(ValueError):
        owen_scramble_uint32([1, 2], -1)
    with pytest.raises(ValueError):
        owen_scramble_uint32([2**32], 0)
    with pytest.raises(TypeError):
        owen_scramble_uint32([0.5], 0)


def test_to_unit_float():
    got = to_unit_float(np.array([0, 1, 2**31, 2**32 - 1], dtype=np.uint32))
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, [0.0, 2.0**-32, 0.5, 1.0 - 2.0**-32])
    assert got.max() < 1.0


# ---------------------------------------------------------------------------------------------
# Stratified
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", list(range(1, 200)) + [1000, 1024, 4096, 10007])
def test_grid_shape(n):
    nx, ny = Stratified.grid_shape(n)
    assert nx * ny >= n and nx >= ny >= 1
    assert nx <= 2 * ny or n <= 2
    # Never more wasted strata than the near-square ceil grid would have.
    c = int(np.ceil(np.sqrt(n)))
    assert nx * ny - n <= c * int(np.ceil(n / c)) - n
    if n & (n - 1) == 0:
        assert nx * ny == n


@pytest.mark.parametrize("n", [12, 16, 32, 64, 1000])
def test_stratified_one_point_per_stratum(n):
    nx, ny = Stratified.grid_shape(n)
    assert nx * ny == n
    pts = Stratified(5, seed=n).random(n)
    for j in (0, 2):  # the (0, 1) and (2, 3) blocks each fill their own grid
        cell = np.floor(pts[:, j] * nx).astype(int) * ny + np.floor(pts[:, j + 1] * ny).astype(int)
        np.testing.assert_array_equal(np.sort(cell), np.arange(n))
    assert one_per_interval(pts[:, 4], n)  # odd last dimension: 1D strata


@pytest.mark.parametrize("n", [7, 13, 101])
def test_stratified_partial_grid(n):
    nx, ny = Stratified.grid_shape(n)
    assert nx * ny > n
    src = Stratified(2, seed=n)
    # Every stratum holds at most one point ...
    pts = src.random(n)
    cell = np.floor(pts[:, 0] * nx).astype(int) * ny + np.floor(pts[:, 1] * ny).astype(int)
    assert np.unique(cell).size == n
    # ... and the empty strata move around, so the points are marginally uniform: pooled over
    # 3000 sets, counts on a 10 x 10 grid (not aligned with the strata) pass a chi-square test.
    # Always leaving the same strata empty would starve some cells and fail.
    pooled = np.concatenate([src.random(n) for _ in range(3000)])
    cells = np.floor(pooled[:, 0] * 10).astype(int) * 10 + np.floor(pooled[:, 1] * 10).astype(int)
    assert stats.chisquare(np.bincount(cells, minlength=100)).pvalue > ALPHA


def test_stratified_calls_are_fresh_sets():
    src = Stratified(2, seed=0)
    a, b = src.random(64), src.random(64)
    assert not np.array_equal(np.sort(a, axis=0), np.sort(b, axis=0))


# ---------------------------------------------------------------------------------------------
# Halton
# ---------------------------------------------------------------------------------------------


def test_halton_unscrambled_equals_scipy():
    ours = Halton(6, scramble=False).random(5000)
    ref = qmc.Halton(6, scramble=False).random(5000)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-15)
    assert Halton(6).bases == [2, 3, 5, 7, 11, 13]


def test_halton_projections_uniform():
    pts = Halton(5, seed=8).random(10007)
    level = sidak(ALPHA, 5)
    for j in range(5):
        assert uniform_pvalue(pts[:, j], 50) > level, f"dimension {j}"


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_halton_radical_stratification(seed):
    src = Halton(3, seed=seed)
    pts = src.random(5**5)
    # First b^k points of a base-b dimension: one per interval of length b^-k. The digit
    # permutations are bijections, so the scramble keeps this.
    for j, b in enumerate((2, 3, 5)):
        k = 1
        while b**k <= len(pts):
            assert one_per_interval(pts[: b**k, j], b**k), (j, b, k)
            k += 1
    # Aligned later blocks too, reached by skipping ahead.
    aligned = Halton(3, seed=seed).fast_forward(2**12).random(2**8)
    assert one_per_interval(aligned[:, 0], 2**8)


@pytest.mark.parametrize("a,b", [(3, 2), (4, 3), (6, 4)])
def test_halton_2d_grid_stratification(a, b):
    # The first 2^a 3^b points of dims (0, 1) hold one point in each 2^-a x 3^-b cell.
    n = 2**a * 3**b
    pts = Halton(2, seed=a * 10 + b).random(n)
    cell = np.floor(pts[:, 0] * 2**a).astype(int) * 3**b + np.floor(pts[:, 1] * 3**b).astype(int)
    np.testing.assert_array_equal(np.sort(cell), np.arange(n))
    # Negative control: independent points are not stratified so.
    ind = Independent(2, seed=0).random(n)
    cell = np.floor(ind[:, 0] * 2**a).astype(int) * 3**b + np.floor(ind[:, 1] * 3**b).astype(int)
    assert np.unique(cell).size < n


# ---------------------------------------------------------------------------------------------
# Convergence of a smooth integral
# ---------------------------------------------------------------------------------------------

_KS = np.arange(4, 13)  # n = 2^4 .. 2^12
_REPS = 256
_TRUE = (np.e - 1.0) * np.sin(1.0)  # integral of exp(x) cos(y) over [0, 1]^2


def _rmse_slope(name):
    ns = 2**_KS
    seeds = np.random.SeedSequence(20240611).spawn(len(ns) * _REPS)
    err = np.empty((len(ns), _REPS))
    for i, n in enumerate(ns):
        for r in range(_REPS):
            u = make_source(name, 2, seed=seeds[i * _REPS + r]).random(n)
            err[i, r] = np.mean(np.exp(u[:, 0]) * np.cos(u[:, 1])) - _TRUE
    rmse = np.sqrt(np.mean(err**2, axis=1))
    return np.polyfit(np.log(ns), np.log(rmse), 1)[0]


@pytest.mark.slow
def test_independent_rmse_slope_is_one_half():
    # RMSE = sigma / sqrt(n) exactly, so the true slope is -1/2. Each log RMSE is estimated from
    # R independent errors that are close to normal, so var(log RMSE) ~ 1/(2R); ordinary least
    # squares over x = log n then has sd(slope) = sqrt(1 / (2R Sxx)). Allow 5 sd (~0.04 here).
    x = np.log(2.0**_KS)
    sxx = np.sum((x - x.mean()) ** 2)
    tol = 5.0 * np.sqrt(1.0 / (2 * _REPS * sxx))
    slope = _rmse_slope("independent")
    assert abs(slope + 0.5) < tol, (slope, tol)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["stratified", "sobol", "halton"])
def test_structured_sources_converge_faster(name):
    # Expected slopes for this smooth integrand: -1 for jittered 2D strata and for randomised
    # Halton (up to logs), -3/2 for Owen-scrambled Sobol'. -0.75 sits more than 20 standard
    # deviations (same estimate as above, ~0.01) away from all of them and from -1/2.
    slope = _rmse_slope(name)
    assert slope < -0.75, slope
