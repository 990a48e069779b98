"""What every point set shares: the interface (modelled on scipy.stats.qmc.QMCEngine), the checks, 32-bit
integers to floats, and the randomisations that need no structure (fresh random bits, none at all)."""

import copy
import operator

import numpy as np

from ..base.errors import SettingsError


U32 = np.dtype(np.uint32)
U64 = np.dtype(np.uint64)
TWO_M32 = 2.0**-32
# Largest float64 below 1: jittered coordinates (k + u) / m can round up to exactly 1.0.
BELOW_ONE = np.nextafter(1.0, 0.0)
# Sequences index points with 32-bit integers, like the Sobol' direction numbers they use.
MAX_INDEX = 2**32


# ---------------------------------------------------------------------------------------------
# Integer helpers
# ---------------------------------------------------------------------------------------------


def as_uint32(a, name):
    """Return ``a`` as a native np.uint32 array, refusing values that would wrap silently."""
    arr = np.asarray(a)
    if arr.dtype == U32:
        return arr
    if arr.dtype == np.bool_ or arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must be an integer array (values in [0, 2**32)), got dtype {arr.dtype}")
    if arr.size and (arr.min() < 0 or arr.max() > 0xFFFFFFFF):
        raise ValueError(f"{name} must lie in [0, 2**32), got values in [{arr.min()}, {arr.max()}]")
    # Casting after the range check: astype would otherwise wrap negatives and large values.
    return arr.astype(U32)


def check_count(n, what="n"):
    """Return ``n`` as a Python int >= 0; floats and bools are refused rather than truncated."""
    if isinstance(n, (bool, np.bool_)):
        raise TypeError(f"{what} must be an integer, got {n!r}")
    try:
        n = operator.index(n)
    except TypeError:
        raise TypeError(f"{what} must be an integer, got {n!r}") from None
    if n < 0:
        raise SettingsError(f"{what} must be >= 0, got {n}")
    return n


def check_dim(d, max_dim=None, who="source"):
    d = check_count(d, "d")
    if d < 1:
        raise SettingsError(f"{who}: d must be >= 1, got {d}")
    if max_dim is not None and d > max_dim:
        raise SettingsError(f"{who}: d must be <= {max_dim}, got {d}")
    return d


# Points per block in the vectorised kernels: the temporaries of one block stay in cache (1.3-1.6x
# faster for the Sobol' lookups than whole-array passes) and extra memory stays a few blocks.
BLOCK = 1 << 16


def to_unit_float(x_uint32):
    """Map 32-bit binary fractions to float64 in [0, 1): ``x * 2**-32``, exact.

    Parameters
    ----------
    x_uint32 : array_like of int
        Values in [0, 2**32).

    Returns
    -------
    numpy.ndarray of float64, same shape; the largest value is 1 - 2**-32.
    """
    x = as_uint32(x_uint32, "x_uint32")
    return x.astype(np.float64) * TWO_M32


# ---------------------------------------------------------------------------------------------
# Randomisations: where the random bits come from, and what they randomise
# ---------------------------------------------------------------------------------------------
#
# Every source is one point set with its randomisation passed in as a strategy, as in pbrt-v4's
# samplers: Sobol' takes NoRandomizer or OwenScrambler, Halton NoRandomizer or PermuteDigits, and
# the stratified and independent sets, which are nothing but their random choices laid out, take a
# bit source. A randomisation holds ``sets`` independent randomisations at once, so that the baker
# builds its pool of thousands of randomised sets (core.engine.patterns) with the same code, vectorised,
# that makes a single set here.
#
# A bit source is anything with ``sets`` and ``words(count) -> (sets, count) uint64`` (fresh words
# on every call). The public classes use GeneratorBits; the baker's pools use counter-based words,
# hashes of (seed, set, word index), so that each pool pattern depends on (seed, pattern) alone.


class GeneratorBits:
    """Random 64-bit words from a numpy Generator, for one randomisation (``sets == 1``).

    Parameters
    ----------
    rng : numpy.random.Generator
        Used and advanced as is.
    """

    sets = 1

    def __init__(self, rng):
        self.rng = rng

    def words(self, count):
        """``count`` fresh words, shape (1, count) uint64.

        ``Generator.random()`` is ``(word >> 11) * 2**-53`` of the same words (for numpy's
        default bit generator), which keeps :class:`Independent` the plain Generator stream.
        """
        return self.rng.integers(0, 2**64, size=(1, count), dtype=U64)


class NoRandomizer:
    """No randomisation (pbrt-v4's ``NoRandomizer``): Sobol' or Halton points as they are."""

    sets = 1

    def __call__(self, u):
        return u[None]


class PointSet:
    """Common interface, modelled on scipy.stats.qmc.QMCEngine.

    Parameters
    ----------
    d : int
        Dimension of the points.
    randomizer : None or a randomisation of this source (see the module's randomisations)
        Holding one set (``sets == 1``). None: a random one drawn from ``seed``.
    seed : None, int, array_like of int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised once with ``numpy.random.default_rng``. A Generator is used (and advanced) as is,
        like scipy does; a copy of its initial state is kept for :meth:`reset`.

    Every source also builds many randomised sets at once, for the baker's pools:
    ``cls.sets_uint32(n, d, cls.randomizer_from(bits, d, n))`` is (sets, n, d) uint32, set ``s``
    being what ``cls(d, randomizer=<set s's randomisation>).random_uint32(n)`` returns (for
    Sobol', in direct rather than Gray-code order). :meth:`random_uint32` gives the points of
    :meth:`random` in 32-bit fixed point: the same bits, rounded down where the floats have more
    (Halton keeps its strata in the rounding, see :meth:`Halton.points_uint32`).
    """

    name = "source"
    _max_dim = None
    #: Whether consecutive calls continue one sequence, so that the first points of a set are a
    #: set themselves (all but the stratified sets, which are whole sets of n points).
    continues = True

    # -- the set's rules when a bake reuses its randomised sets for every texel (core.engine.patterns) --

    #: How a texel reorders a set's points keeping its structure: 'xor' (index i xor c maps every
    #: aligned block of 2^m indices onto another: each power-of-two prefix stays a net), or 'offset'
    #: (a window i + o of a set stored twice in a row).
    reorder = "offset"
    #: How a texel shifts the position coordinates: 'xor' (a digital shift, elementary intervals onto
    #: elementary intervals) or 'add' (a Cranley-Patterson rotation, strata stay arcs of the circle).
    shift = "xor"
    #: Whether the points are independent: the independent-sample error formula is then exact.
    independent = False
    #: The rate r of the error of n samples, n^-r, that adaptive sampling grows a texel's count by.
    error_rate = 0.75

    @classmethod
    def pattern_length(cls, samples):
        """Points of one set for ``samples`` samples a texel: a power of two (a net, a grid)."""
        return 1 << max(0, (int(samples) - 1).bit_length())

    @classmethod
    def pattern_span(cls, samples):
        """Rows one set takes in a bake's pool: its length, twice over for a window ``i + o``."""
        length = cls.pattern_length(samples)
        return length if cls.reorder == "xor" else 2 * length

    @classmethod
    def shift_masks(cls, length):
        """The bits of the (x, y) position coordinates a texel's shift may change (all of them)."""
        return 0xFFFFFFFF, 0xFFFFFFFF

    def __init__(self, d=2, *, randomizer=None, seed=None):
        self.d = check_dim(d, self._max_dim, type(self).__name__)
        self.rng = np.random.default_rng(seed)
        self._rng_init = copy.deepcopy(self.rng)
        if randomizer is not None and getattr(randomizer, "sets", None) != 1:
            raise SettingsError(f"{type(self).__name__}: the randomizer must hold one randomisation (sets == 1)")
        self.randomizer = randomizer
        self._randomizer_init = copy.deepcopy(randomizer)
        self.num_generated = 0

    @classmethod
    def randomizer_from(cls, bits, d, max_points):
        """The source's random randomisation for ``d`` dimensions and sets of up to ``max_points``
        points, ``bits.sets`` of them, their random choices taken from the bit source ``bits``."""
        raise NotImplementedError

    @classmethod
    def sets_uint32(cls, n, d, randomizer):
        """The first ``n`` points of every set of ``randomizer``: (sets, n, d) uint32, the
        coordinates times 2**32 (rounded down where they have more bits)."""
        raise NotImplementedError

    def random(self, n=1):
        """Draw ``n`` points.

        Parameters
        ----------
        n : int
            Number of points, >= 0.

        Returns
        -------
        numpy.ndarray of float64, shape (n, d), values in [0, 1)
        """
        n = check_count(n)
        out = self._random(n)
        self.num_generated += n
        return out

    def random_uint32(self, n=1):
        """Draw ``n`` points as 32-bit fixed point: (n, d) uint32, the coordinates times 2**32.

        The same points as :meth:`random` would give (and the sequence goes on the same way).
        """
        n = check_count(n)
        out = self._random_uint32(n)
        self.num_generated += n
        return out

    def reset(self):
        """Return to the state right after construction; returns ``self``."""
        self.rng = copy.deepcopy(self._rng_init)
        self.randomizer = copy.deepcopy(self._randomizer_init)
        self.num_generated = 0
        return self

    def fast_forward(self, n):
        """Skip ``n`` points, as if ``random(n)`` had been called and discarded; returns ``self``."""
        n = check_count(n)
        self._fast_forward(n)
        self.num_generated += n
        return self

    def _bits(self):
        # The bit source of the sources that draw on every call: the one given, or the rng (read
        # here, as reset replaces it).
        return self.randomizer if self.randomizer is not None else GeneratorBits(self.rng)

    def _fast_forward(self, n):
        self._random(n)

    def _random(self, n):
        return to_unit_float(self._random_uint32(n))

    def _random_uint32(self, n):
        raise NotImplementedError

    def __repr__(self):
        return f"{type(self).__name__}(d={self.d})"


class Sequence(PointSet):
    """A deterministic sequence randomised once at construction (Sobol', Halton): ``reset`` replays
    the same points, and points are indexed by 32-bit integers."""

    def reset(self):
        # The randomisation was drawn at construction and stays: reset replays the same points.
        self.num_generated = 0
        return self

    def _capacity(self):
        return MAX_INDEX

    def _check_room(self, n):
        if self.num_generated + n > self._capacity():
            raise SettingsError(
                f"{type(self).__name__}: cannot go past {self._capacity()} points ({self.num_generated} drawn, {n} more asked)"
            )

    def _fast_forward(self, n):
        self._check_room(n)


__all__ = [
    "U32", "U64", "TWO_M32", "BELOW_ONE", "MAX_INDEX", "as_uint32", "check_count", "check_dim", "BLOCK",
    "to_unit_float", "GeneratorBits", "NoRandomizer", "PointSet", "Sequence"
]
