"""Sample sources: independent, stratified, Owen-scrambled Sobol' and permuted Halton points in [0, 1)^d."""

import copy
import math
import operator

import numpy as np

from ..base.errors import SettingsError

__all__ = [
    "SOBOL_MAX_DIM",
    "sobol_uint32",
    "reverse_bits_uint32",
    "owen_scramble_uint32",
    "to_unit_float",
    "Independent",
    "Stratified",
    "Sobol",
    "Halton",
    "GeneratorBits",
    "NoRandomizer",
    "OwenScrambler",
    "PermuteDigits",
    "SOURCES",
    "make_source",
]

_U32 = np.dtype(np.uint32)
_U64 = np.dtype(np.uint64)
_TWO_M32 = 2.0**-32
# Largest float64 below 1: jittered coordinates (k + u) / m can round up to exactly 1.0.
_BELOW_ONE = np.nextafter(1.0, 0.0)
# Sequences index points with 32-bit integers, like the Sobol' direction numbers they use.
_MAX_INDEX = 2**32


# ---------------------------------------------------------------------------------------------
# Integer helpers
# ---------------------------------------------------------------------------------------------


def _as_uint32(a, name):
    """Return ``a`` as a native np.uint32 array, refusing values that would wrap silently."""
    arr = np.asarray(a)
    if arr.dtype == _U32:
        return arr
    if arr.dtype == np.bool_ or arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must be an integer array (values in [0, 2**32)), got dtype {arr.dtype}")
    if arr.size and (arr.min() < 0 or arr.max() > 0xFFFFFFFF):
        raise ValueError(f"{name} must lie in [0, 2**32), got values in [{arr.min()}, {arr.max()}]")
    # Casting after the range check: astype would otherwise wrap negatives and large values.
    return arr.astype(_U32)


def _check_count(n, what="n"):
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


def _check_dim(d, max_dim=None, who="source"):
    d = _check_count(d, "d")
    if d < 1:
        raise SettingsError(f"{who}: d must be >= 1, got {d}")
    if max_dim is not None and d > max_dim:
        raise SettingsError(f"{who}: d must be <= {max_dim}, got {d}")
    return d


# ---------------------------------------------------------------------------------------------
# Sobol' points
# ---------------------------------------------------------------------------------------------

# Joe and Kuo, "Constructing Sobol sequences with better two-dimensional projections" (SIAM J. Sci.
# Comput. 30, 2008), file new-joe-kuo-6.21201, rows d = 2..21 as (s, a, m_1..m_s): s is the degree of
# the primitive polynomial, a its inner coefficients, m the initial direction numbers. Dimension 1
# (not in the file) is the van der Corput sequence, all m_k = 1. scipy.stats.qmc.Sobol reads the same
# file, which is what the tests compare against.
_JOE_KUO_6_21201 = (
    (1, 0, (1,)),
    (2, 1, (1, 3)),
    (3, 1, (1, 3, 1)),
    (3, 2, (1, 1, 1)),
    (4, 1, (1, 1, 3, 3)),
    (4, 4, (1, 3, 5, 13)),
    (5, 2, (1, 1, 5, 5, 17)),
    (5, 4, (1, 1, 5, 5, 5)),
    (5, 7, (1, 1, 7, 11, 19)),
    (5, 11, (1, 1, 5, 1, 1)),
    (5, 13, (1, 1, 1, 3, 11)),
    (5, 14, (1, 3, 5, 5, 31)),
    (6, 1, (1, 3, 3, 9, 7, 49)),
    (6, 13, (1, 1, 1, 15, 21, 21)),
    (6, 16, (1, 3, 1, 13, 27, 49)),
    (6, 19, (1, 1, 1, 15, 7, 5)),
    (6, 22, (1, 3, 1, 15, 13, 25)),
    (6, 25, (1, 1, 5, 5, 19, 61)),
    (7, 1, (1, 3, 7, 11, 23, 15, 103)),
    (7, 4, (1, 3, 7, 13, 13, 15, 69)),
)

#: Number of Sobol' dimensions whose direction numbers are built in.
SOBOL_MAX_DIM = 1 + len(_JOE_KUO_6_21201)


def _direction_numbers():
    """Direction vectors v_k (k = 1..32) of every dimension as 32-bit integers, shape (32, SOBOL_MAX_DIM)."""
    v = np.zeros((32, SOBOL_MAX_DIM), dtype=_U32)
    v[:, 0] = [1 << (31 - k) for k in range(32)]
    for j, (s, a, m) in enumerate(_JOE_KUO_6_21201, start=1):
        # Python ints here: the recurrence only shifts right and xors values below 2**32.
        col = [m[k] << (31 - k) for k in range(s)]
        for k in range(s, 32):
            x = col[k - s] ^ (col[k - s] >> s)
            for i in range(1, s):
                if (a >> (s - 1 - i)) & 1:
                    x ^= col[k - i]
            col.append(x)
        v[:, j] = col
    return v


_SOBOL_V = _direction_numbers()


def _byte_tables(v):
    """XOR of the direction vectors selected by each byte value: (4 byte positions, dims, 256)."""
    bits = ((np.arange(256)[:, None] >> np.arange(8)[None, :]) & 1).astype(_U32)  # (256, 8)
    tables = np.empty((4, v.shape[1], 256), dtype=_U32)
    for k in range(4):
        # bits * v picks v or 0 (uint32 * {0, 1} cannot overflow); xor-reduce over the 8 bits.
        t = np.bitwise_xor.reduce(bits[:, :, None] * v[None, 8 * k : 8 * k + 8, :], axis=1)
        tables[k] = t.T
    return tables


# The direct form x(i) = XOR of v_k over the set bits k of i, evaluated 8 bits at a time: one
# table lookup per byte of the index replaces eight masked xor passes over the whole batch
# (measured on 10^7 2D points: 0.2 s against 5 s for one pass per bit).
_SOBOL_BYTES = _byte_tables(_SOBOL_V)

# Points per block in the vectorised kernels: the temporaries of one block stay in cache (1.3-1.6x
# faster for the Sobol' lookups than whole-array passes) and extra memory stays a few blocks.
_BLOCK = 1 << 16


def sobol_uint32(indices, dims):
    """Unscrambled Sobol' points as 32-bit integers, for arbitrary indices.

    Point ``i`` is the XOR of the direction vectors v_k of every set bit k of ``i`` (the direct,
    Gray-code-free form), so any index can be evaluated without generating its predecessors. The
    coordinate in [0, 1) is ``value * 2**-32`` (see :func:`to_unit_float`).

    Parameters
    ----------
    indices : array_like of int
        Point indices in [0, 2**32), any shape.
    dims : int
        Number of dimensions, 1 to ``SOBOL_MAX_DIM`` (21), Joe-Kuo new-joe-kuo-6.21201 numbers.

    Returns
    -------
    numpy.ndarray of numpy.uint32, shape ``indices.shape + (dims,)``
        The points' binary fractions scaled by 2**32.

    Notes
    -----
    Indices ``0 .. 2**m - 1`` give the same set of points as the first ``2**m`` points of
    ``scipy.stats.qmc.Sobol(dims, scramble=False, bits=32)``, but scipy (like Joe and Kuo's
    reference generator) emits them in Gray-code order: scipy's point ``i`` is
    ``sobol_uint32(i ^ (i >> 1), dims)``. scipy's default ``bits=30`` keeps only the top 30 bits.
    """
    dims = _check_dim(dims, SOBOL_MAX_DIM, "sobol_uint32")
    idx = _as_uint32(indices, "indices")
    flat = idx.reshape(-1)
    out = np.zeros((flat.size, dims), dtype=_U32)
    if flat.size == 0:
        return out.reshape(idx.shape + (dims,))
    # Bytes above the largest index's top set bit are zero everywhere and contribute nothing.
    nbytes = max(1, (int(flat.max()).bit_length() + 7) // 8)
    for start in range(0, flat.size, _BLOCK):
        block = flat[start : start + _BLOCK]
        # astype(uint8) keeps the low 8 bits of each shifted index.
        byte = [(block >> np.uint32(8 * k)).astype(np.uint8) for k in range(nbytes)]
        for j in range(dims):
            col = _SOBOL_BYTES[0, j][byte[0]]
            for k in range(1, nbytes):
                np.bitwise_xor(col, _SOBOL_BYTES[k, j][byte[k]], out=col)
            out[start : start + _BLOCK, j] = col
    return out.reshape(idx.shape + (dims,))


# ---------------------------------------------------------------------------------------------
# Owen scrambling
# ---------------------------------------------------------------------------------------------

_REV16 = np.array([int(f"{i:016b}"[::-1], 2) for i in range(1 << 16)], dtype=np.uint16)


def reverse_bits_uint32(x):
    """Reverse the order of the 32 bits of each value (bit 0 becomes bit 31).

    Parameters
    ----------
    x : array_like of int
        Values in [0, 2**32).

    Returns
    -------
    numpy.ndarray of numpy.uint32, same shape as ``x``
    """
    x = _as_uint32(x, "x")
    flat = np.ascontiguousarray(x).reshape(-1)
    # Reverse each 16-bit half with a 64k-entry table (it stays in cache), then swap the halves:
    # two lookups per value. Halves are taken arithmetically, so endianness does not matter.
    lo = _REV16[flat & np.uint32(0xFFFF)].astype(_U32)
    hi = _REV16[flat >> np.uint32(16)].astype(_U32)
    lo <<= np.uint32(16)
    lo |= hi
    return lo.reshape(x.shape)


_OWEN_C0 = np.uint32(0x3D20ADEA)
_OWEN_C1 = np.uint32(0x05526C56)
_OWEN_C2 = np.uint32(0x53A22864)


def owen_scramble_uint32(x, seed):
    """Hash-based nested uniform (Owen) scramble of 32-bit binary fractions.

    Burley 2020, "Practical Hash-based Owen Scrambling" (JCGT 9(4)), with the improved constants of
    pbrt-v4's ``FastOwenScrambler``: reverse the bits, apply a Laine-Karras style hash in which every
    step (``v ^= v * even``, ``v += seed``, ``v *= odd``) only lets a bit influence the bits above it,
    and reverse back. After the reversals each output bit therefore depends only on the input bits
    above it and on the seed: the map is a bijection that permutes the two halves of every dyadic
    interval as a function of the interval, which is what nested scrambling needs. Values sharing
    their top k bits keep sharing them, so Sobol' nets stay nets.

    Parameters
    ----------
    x : array_like of int
        Values in [0, 2**32) (a point's coordinate times 2**32).
    seed : int or array_like of int
        Scramble seed(s) in [0, 2**32), broadcastable against ``x``: one per dimension, or one per
        texel and dimension. Different seeds give (practically) independent scrambles.

    Returns
    -------
    numpy.ndarray of numpy.uint32, shape ``broadcast(x, seed).shape``
    """
    x = _as_uint32(x, "x")
    seed = _as_uint32(seed, "seed")
    x, seed = np.broadcast_arrays(x, seed)
    shape = x.shape
    xf = np.ascontiguousarray(x).reshape(-1)
    sf = np.ascontiguousarray(seed).reshape(-1)
    out = np.empty(xf.size, dtype=_U32)
    for start in range(0, xf.size, _BLOCK):
        stop = start + _BLOCK
        out[start:stop] = _owen_block(xf[start:stop], sf[start:stop])
    return out.reshape(shape)


def _owen_block(x, s):
    """pbrt-v4's FastOwenScrambler on 1-D uint32 arrays of equal length."""
    v = reverse_bits_uint32(x)  # a fresh array: safe to work in place
    tmp = np.empty_like(v)
    # All arithmetic on uint32 arrays with uint32 operands: wraps modulo 2**32 on numpy 1.x and
    # 2.x alike (array ufuncs never warn on integer overflow, numpy scalars would).
    np.multiply(v, _OWEN_C0, out=tmp)
    np.bitwise_xor(v, tmp, out=v)
    np.add(v, s, out=v)
    np.right_shift(s, np.uint32(16), out=tmp)
    np.bitwise_or(tmp, np.uint32(1), out=tmp)
    np.multiply(v, tmp, out=v)
    np.multiply(v, _OWEN_C1, out=tmp)
    np.bitwise_xor(v, tmp, out=v)
    np.multiply(v, _OWEN_C2, out=tmp)
    np.bitwise_xor(v, tmp, out=v)
    return reverse_bits_uint32(v)


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
    x = _as_uint32(x_uint32, "x_uint32")
    return x.astype(np.float64) * _TWO_M32


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
        return self.rng.integers(0, 2**64, size=(1, count), dtype=_U64)


class NoRandomizer:
    """No randomisation (pbrt-v4's ``NoRandomizer``): Sobol' or Halton points as they are."""

    sets = 1

    def __call__(self, u):
        return u[None]


class OwenScrambler:
    """Nested uniform (Owen) scramble of every dimension of Sobol' points, ``sets`` scrambles at once.

    pbrt-v4's ``FastOwenScrambler`` (see :func:`owen_scramble_uint32`), one seed per set and
    dimension: a seed shared by two dimensions would correlate them.

    Parameters
    ----------
    seeds : array_like of int, shape (sets, d) or (d,)
        Seeds in [0, 2**32).
    """

    def __init__(self, seeds):
        seeds = _as_uint32(seeds, "seeds")
        if seeds.ndim not in (1, 2):
            raise ValueError(f"seeds must have shape (sets, d) or (d,), got {seeds.shape}")
        self.seeds = np.atleast_2d(seeds)
        self.sets, self.d = self.seeds.shape

    @classmethod
    def draw(cls, bits, d):
        """Seeds for ``d`` dimensions of each of ``bits.sets`` scrambles: the top 32 bits of ``d`` words."""
        return cls((bits.words(d) >> np.uint64(32)).astype(_U32))

    def __call__(self, u):
        """Scramble the points ``u`` (n, d) uint32 with every set's seeds: (sets, n, d) uint32."""
        return owen_scramble_uint32(u[None], self.seeds[:, None, :])


def _carried_digits(b):
    """K, the digits of base b carried: b**K <= 2**52, so values are exact in float64."""
    K = 1
    while b ** (K + 1) <= 2**52:
        K += 1
    return K


def _digit_counts(b, capacity):
    """(K, D) for base b: K digits carried, D digits permuted, the fewest that cover every index
    below ``capacity`` (b**D >= capacity), at most K."""
    K = _carried_digits(b)
    D = 1
    while b**D < capacity and D < K:
        D += 1
    return K, D


class PermuteDigits:
    """Random digit permutations of Halton points (pbrt-v4's ``PermuteDigits``), ``sets`` at once.

    Dimension j with base b maps an index's digit d_k (k = 0 the least significant) to
    pi_{j,k}(d_k), a uniformly random permutation of {0, ..., b-1} for every set, dimension and
    digit position k < D, where b**D >= ``capacity`` covers every index the set will be asked for.
    The digits beyond are zeros for those indices, and permuting them would give independent
    uniform digits: they are drawn as such at once, a uniform "tail" below b**-D. So each point
    is uniform on [0, 1)^d, and each digit permutation being a bijection, the first b**k points
    of a base-b dimension still hold one point in each interval of length b**-k.

    Values are integers over b**K (b**K <= 2**52), so they are exact in float64 and below 1.
    Make one with :meth:`draw` (random) or :meth:`identity` (the plain radical inverses).

    Attributes
    ----------
    bases : list of int
    capacity : int
        Indices below it can be evaluated: the least b**D over the dimensions (at least the
        ``capacity`` asked for).
    sets : int
    """

    def __init__(self, bases, perms, tails):
        self.bases = [int(b) for b in bases]
        self.sets = int(tails.shape[0])
        self.capacity = min(b ** p.shape[1] for b, p in zip(self.bases, perms))
        # Per dimension: b, b**K, contrib[s, k, v] = pi_k(v) * b**(K-1-k) (digit k of the index
        # becomes the (k+1)-th digit after the point) and high[s, u], what the digit positions
        # u..D-1 (zero digits) and the tail add for an index with u digits. Python ints below
        # 2**52 throughout: exact in uint64.
        self._dims = []
        for j, b in enumerate(self.bases):
            perm = perms[j]
            K, D = _carried_digits(b), perm.shape[1]
            weight = np.array([b ** (K - 1 - k) for k in range(D)], dtype=_U64)
            contrib = perm.astype(_U64) * weight[None, :, None]
            high = np.zeros((self.sets, D + 1), dtype=_U64)
            high[:, D] = tails[:, j]
            high[:, :D] = np.cumsum(contrib[:, ::-1, 0], axis=1)[:, ::-1] + tails[:, j : j + 1]
            self._dims.append((b, float(b**K), contrib, high))

    @classmethod
    def draw(cls, bits, bases, capacity=_MAX_INDEX):
        """Independent random permutations (and tails) for ``bits.sets`` sets of the given bases.

        Parameters
        ----------
        bits : bit source (see :class:`GeneratorBits`)
        bases : list of int
            The base of each dimension.
        capacity : int
            The most points any set will be asked for.
        """
        counts = [_digit_counts(b, capacity) for b in bases]
        need = sum(D * b for b, (K, D) in zip(bases, counts))
        w = bits.words(need + len(bases))
        perms, start = [], 0
        for b, (K, D) in zip(bases, counts):
            keys = w[:, start : start + D * b].reshape(-1, D, b)
            start += D * b
            # The sorting order of independent keys: a uniformly random permutation per set and
            # digit. A stable sort, so that (vanishingly rare) equal keys give one order everywhere.
            perms.append(np.argsort(keys, axis=2, kind="stable"))
        tails = np.empty((bits.sets, len(bases)), dtype=_U64)
        for j, (b, (K, D)) in enumerate(zip(bases, counts)):
            # Uniform on [0, b**(K-D)) from the word's top 53 bits; the product rounds in float64
            # (R <= 2**52), hence the clamp. Only its distribution below b**-D matters.
            r = b ** (K - D)
            u = (w[:, start + j] >> np.uint64(11)).astype(np.float64) * 2.0**-53
            tails[:, j] = np.minimum(np.floor(u * float(r)), float(r - 1)).astype(_U64)
        return cls(bases, perms, tails)

    @classmethod
    def identity(cls, bases, capacity=_MAX_INDEX):
        """The identity permutations and no tail: the plain radical inverses (one set)."""
        perms = []
        for b in bases:
            K, D = _digit_counts(b, capacity)
            perms.append(np.tile(np.arange(b, dtype=_U64), (1, D, 1)))
        return cls(bases, perms, np.zeros((1, len(bases)), dtype=_U64))

    def __call__(self, indices):
        """The points of every set at ``indices`` (n,) as integers over b**K: (sets, n, d) uint64.
        Divided by :attr:`scales` they are the points in [0, 1)."""
        idx = np.asarray(indices, dtype=_U64).reshape(-1)
        n = idx.size
        out = np.empty((self.sets, n, len(self.bases)), dtype=_U64)
        if n == 0:
            return out
        top = int(idx.max())
        if top >= self.capacity:
            raise SettingsError(f"Halton: index {top} is beyond the {self.capacity} points these permutations cover")
        for j, (b, scale, contrib, high) in enumerate(self._dims):
            used = 1
            while b**used <= top:
                used += 1
            acc = np.repeat(high[:, used : used + 1], n, axis=1)  # (sets, n)
            q = idx.copy()
            bb = np.uint64(b)
            for k in range(used):
                digit = q % bb
                q //= bb
                acc += np.take(contrib[:, k, :], digit.astype(np.intp), axis=1)
            out[:, :, j] = acc
        return out

    @property
    def scales(self):
        """b**K of every dimension, as floats (exact: at most 2**52)."""
        return np.array([scale for _, scale, _, _ in self._dims])

    @property
    def digits(self):
        """(b, K, D) of every dimension: its base, the digits carried, the digits permuted."""
        return [(b, _carried_digits(b), contrib.shape[1]) for b, _, contrib, _ in self._dims]


def _radical_fixed_point(a, b, K, D):
    """32-bit fixed point of base-b values ``a / b**K`` (uint64 integers): rounded down, then kept
    inside the value's interval of length b**-L (L <= D the finest level with b**L <= 2**32), so that
    the base-b strata of every level up to L survive. Plain rounding down would move a value that
    lies less than 2**-32 above an interval's start (which is not a multiple of 2**-32 for odd b)
    into the interval below it."""
    # a < 2**52 is exact in float64, a / b**K rounds (as the floats of Halton.points do), and the
    # product with 2**32 is exact: q is those floats rounded down to 32 bits.
    q = np.floor(a.astype(np.float64) / float(b**K) * 2.0**32).astype(_U64)
    if b % 2 == 0:
        return q.astype(_U32)  # base 2: every interval starts on a multiple of 2**-32
    L = D
    while b**L > 2**32:
        L -= 1
    bl = np.uint64(b**L)
    s = a // np.uint64(b ** (K - L))  # the value's interval at level L
    lo = ((s << np.uint64(32)) + bl - np.uint64(1)) // bl  # ceil(s 2**32 / b**L): the first inside
    top = (((s + np.uint64(1)) << np.uint64(32)) - np.uint64(1)) // bl  # the last inside
    return np.clip(q, lo, top).astype(_U32)


# ---------------------------------------------------------------------------------------------
# Sources
# ---------------------------------------------------------------------------------------------


class _Source:
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

    def __init__(self, d=2, *, randomizer=None, seed=None):
        self.d = _check_dim(d, self._max_dim, type(self).__name__)
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
        n = _check_count(n)
        out = self._random(n)
        self.num_generated += n
        return out

    def random_uint32(self, n=1):
        """Draw ``n`` points as 32-bit fixed point: (n, d) uint32, the coordinates times 2**32.

        The same points as :meth:`random` would give (and the sequence goes on the same way).
        """
        n = _check_count(n)
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
        n = _check_count(n)
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


class Independent(_Source):
    """Independent uniform points (plain Monte Carlo); the baseline every other source must beat.

    The points are their bit source's words laid out row by row, one word per coordinate: the
    float is ``(word >> 11) * 2**-53`` (with the default bit source, exactly ``rng.random((n, d))``)
    and the 32-bit fixed point ``word >> 32``. Consecutive calls continue one stream:
    ``random(a)`` then ``random(b)`` equals ``random(a + b)``.

    Parameters
    ----------
    randomizer : None or a bit source (see :class:`GeneratorBits`) with ``sets == 1``
    """

    name = "independent"

    @classmethod
    def randomizer_from(cls, bits, d, max_points=None):
        return bits

    @staticmethod
    def _words(n, d, bits):
        return bits.words(n * d).reshape(bits.sets, n, d)

    @classmethod
    def sets_uint32(cls, n, d, randomizer):
        return (cls._words(_check_count(n), d, randomizer) >> np.uint64(32)).astype(_U32)

    def _random(self, n):
        w = self._words(n, self.d, self._bits())[0]
        return (w >> np.uint64(11)).astype(np.float64) * 2.0**-53

    def _random_uint32(self, n):
        return (self._words(n, self.d, self._bits())[0] >> np.uint64(32)).astype(_U32)

    def _fast_forward(self, n):
        # Discard in bounded chunks: the words come out row by row, so chunking skips exactly the
        # same words as one random(n) call would, without its memory.
        bits = self._bits()
        chunk = max(1, (1 << 20) // self.d)
        while n > 0:
            k = min(n, chunk)
            bits.words(k * self.d)
            n -= k


def _in_stratum(k, m, jitter):
    """32-bit fixed-point coordinates in stratum ``k`` of ``m`` equal strata of [0, 1), placed by the
    32-bit ``jitter``: the integers v with k/m <= v 2**-32 < (k+1)/m, so that floor(v 2**-32 m) == k
    holds exactly in float64 too (for power-of-two m: k in the top bits, the jitter's top bits below)."""
    k = np.asarray(k)
    if m & (m - 1) == 0:
        a = np.uint64(m.bit_length() - 1)
        return ((k.astype(_U64) << (np.uint64(32) - a)) | (jitter.astype(_U64) >> a)).astype(_U32)
    # first[k] = ceil(k 2**32 / m), the first such integer; a table of m + 1 entries, looked up.
    first = ((np.arange(m + 1, dtype=_U64) << np.uint64(32)) + np.uint64(m - 1)) // np.uint64(m)
    k = k.astype(np.intp)
    lo = first[k]
    width = first[k + 1] - lo  # at most 2**32 - 1 + 1, so width * jitter < 2**64
    width *= jitter.astype(_U64)
    width >>= np.uint64(32)
    lo += width
    return lo.astype(_U32)


class Stratified(_Source):
    """Jittered (stratified) points: every call returns one stratified set of ``n`` points.

    Dimensions are stratified in pairs: dims (0, 1) on an ``nx x ny`` grid of strata, one jittered
    point per stratum, (2, 3) on another such grid, and so on; an odd last dimension is stratified
    into ``n`` intervals. Each block takes the strata in its own random order ("padding", as in
    pbrt), so the strata of different pairs are not correlated.

    The grid is chosen by :meth:`grid_shape`: an exact factorisation ``nx * ny == n`` with aspect
    ratio at most 2 when one exists (always for powers of two), else the near-square grid with the
    fewest strata ``nx * ny >= n``. When ``nx * ny > n`` the points occupy ``n`` distinct strata
    chosen at random, so each point is still marginally uniform on [0, 1)^2 (its stratum is uniform
    over the grid, its position uniform inside), and the estimate stays unbiased, at the price of
    a little extra variance from the choice of empty strata.

    Coordinates are 32-bit binary fractions (:func:`_in_stratum`). Repeated ``random(n)`` calls
    give fresh, independent sets (not a continuation); ``fast_forward(n)`` draws and discards one
    set of ``n``.

    Parameters
    ----------
    randomizer : None or a bit source (see :class:`GeneratorBits`) with ``sets == 1``
        Where the stratum orders and jitter come from.
    """

    name = "stratified"
    continues = False

    @staticmethod
    def grid_shape(n):
        """Grid ``(nx, ny)`` used for ``n`` points in two dimensions.

        Parameters
        ----------
        n : int
            Number of points, >= 1.

        Returns
        -------
        tuple of int
            ``nx * ny >= n``, ``nx >= ny``, ``max(nx, ny) <= 2 * min(nx, ny)`` when n > 2.
        """
        n = _check_count(n)
        if n == 0:
            return (0, 0)
        # Candidates with aspect ratio near 2 at most; ceil(sqrt(n)) is always among them.
        lo = max(1, math.isqrt(max(n // 2 - 1, 0)))
        hi = math.isqrt(2 * n) + 1
        nx = np.arange(lo, hi + 1)
        ny = -(-n // nx)
        ok = (np.maximum(nx, ny) <= 2 * np.minimum(nx, ny)) | (n <= 2)
        nx, ny = nx[ok], ny[ok]
        # Fewest empty strata first (they add variance), then the squarest grid.
        key = (nx * ny - n) * (4 * n + 4) + np.abs(nx - ny)
        i = int(np.argmin(key))
        a, b = int(nx[i]), int(ny[i])
        return (max(a, b), min(a, b))

    @classmethod
    def randomizer_from(cls, bits, d, max_points=None):
        return bits

    @classmethod
    def sets_uint32(cls, n, d, randomizer):
        n = _check_count(n)
        out = np.empty((randomizer.sets, n, d), dtype=_U32)
        if n == 0:
            return out
        nx, ny = cls.grid_shape(n)
        pairs, odd = divmod(d, 2)
        w = randomizer.words(pairs * (nx * ny + n) + odd * 2 * n)
        start = 0
        for j in range(0, 2 * pairs, 2):
            # The first n ranks of independent keys: a uniformly random ordered choice of n distinct
            # strata, its own for every pair and set. A stable sort, so that (vanishingly rare)
            # equal keys give the same order everywhere.
            cell = np.argsort(w[:, start : start + nx * ny], axis=1, kind="stable")[:, :n]
            start += nx * ny
            jitter = w[:, start : start + n]  # both halves of each word: one per coordinate
            start += n
            row, col = np.divmod(cell, nx)
            out[:, :, j] = _in_stratum(col, nx, jitter >> np.uint64(32))
            out[:, :, j + 1] = _in_stratum(row, ny, jitter & np.uint64(0xFFFFFFFF))
        if odd:
            cell = np.argsort(w[:, start : start + n], axis=1, kind="stable")
            out[:, :, -1] = _in_stratum(cell, n, w[:, start + n : start + 2 * n] >> np.uint64(32))
        return out

    def _random_uint32(self, n):
        return self.sets_uint32(n, self.d, self._bits())[0]


class _Sequence(_Source):
    """A deterministic sequence randomised once at construction (Sobol', Halton): ``reset`` replays
    the same points, and points are indexed by 32-bit integers."""

    def reset(self):
        # The randomisation was drawn at construction and stays: reset replays the same points.
        self.num_generated = 0
        return self

    def _capacity(self):
        return _MAX_INDEX

    def _check_room(self, n):
        if self.num_generated + n > self._capacity():
            raise SettingsError(
                f"{type(self).__name__}: cannot go past {self._capacity()} points ({self.num_generated} drawn, {n} more asked)"
            )

    def _fast_forward(self, n):
        self._check_room(n)


class Sobol(_Sequence):
    """Sobol' sequence (Joe-Kuo direction numbers), Owen-scrambled by default.

    Parameters
    ----------
    d : int
        Dimension, 1 to ``SOBOL_MAX_DIM`` (21).
    scramble : bool
        If true (default), each dimension gets its own nested uniform scramble
        (:class:`OwenScrambler`) with a seed drawn from the rng; points are then unbiased and the
        (t, m, s)-net structure is kept. If false, the points are exactly those of
        ``scipy.stats.qmc.Sobol(d, scramble=False, bits=32)``, in the same (Gray-code) order.
    randomizer : None, NoRandomizer or OwenScrambler (one set of ``d`` seeds)
        Given, it decides the scramble (and ``scramble`` is not used).
    seed : see :class:`Independent`
        Only used for the scramble seeds.

    Notes
    -----
    Any ``n`` works, but the balance properties hold for blocks of ``2**m`` points starting at a
    multiple of ``2**m``: ask for powers of two (and continue in powers of two) to get them; other
    counts give a valid but less balanced set. Consecutive calls continue the sequence, up to
    ``2**32`` points in all. :meth:`random` emits the points in Gray-code order, as scipy does;
    :meth:`points_uint32` and :meth:`sets_uint32` take direct indices (pbrt-v4's order). Both
    orders permute every aligned block of ``2**m`` indices within itself.
    """

    name = "sobol"
    _max_dim = SOBOL_MAX_DIM

    def __init__(self, d=2, *, scramble=True, randomizer=None, seed=None):
        super().__init__(d, randomizer=randomizer, seed=seed)
        if self.randomizer is None:
            self.randomizer = (
                self.randomizer_from(GeneratorBits(self.rng), self.d) if scramble else NoRandomizer()
            )
        elif not isinstance(self.randomizer, (NoRandomizer, OwenScrambler)):
            raise TypeError(f"Sobol takes NoRandomizer or OwenScrambler, got {type(self.randomizer).__name__}")
        elif isinstance(self.randomizer, OwenScrambler) and self.randomizer.d != self.d:
            raise SettingsError(f"Sobol: {self.randomizer.d} scramble seeds for {self.d} dimensions")
        self.scramble = isinstance(self.randomizer, OwenScrambler)

    @classmethod
    def randomizer_from(cls, bits, d, max_points=None):
        return OwenScrambler.draw(bits, d)

    @classmethod
    def points_uint32(cls, indices, d, randomizer):
        """The points with direct indices ``indices`` (n,) of every set: (sets, n, d) uint32."""
        return randomizer(sobol_uint32(indices, d))

    @classmethod
    def sets_uint32(cls, n, d, randomizer):
        return cls.points_uint32(np.arange(_check_count(n), dtype=_U64), d, randomizer)

    def _random_uint32(self, n):
        self._check_room(n)
        i = np.arange(self.num_generated, self.num_generated + n, dtype=np.uint64)
        # Gray-code order, as scipy and Joe-Kuo's generator emit the points; it permutes each
        # aligned block of 2**m indices within itself, so every such block is still a net.
        gray = (i ^ (i >> np.uint64(1))).astype(_U32)
        return self.points_uint32(gray, self.d, self.randomizer)[0]


def _primes(k):
    """The first ``k`` primes."""
    limit = max(16, int(k * (math.log(k + 1) + math.log(math.log(k + 3)))) + 16)
    while True:
        sieve = np.ones(limit + 1, dtype=bool)
        sieve[:2] = False
        for p in range(2, math.isqrt(limit) + 1):
            if sieve[p]:
                sieve[p * p :: p] = False
        primes = np.flatnonzero(sieve)
        if len(primes) >= k:
            return [int(p) for p in primes[:k]]
        limit *= 2


class Halton(_Sequence):
    """Halton sequence (bases 2, 3, 5, 7, 11, ...) randomised by random digit permutations.

    Dimension j with base b maps index i = sum_k d_k b^k to sum_k pi_{j,k}(d_k) b^-(k+1), where
    every dimension and digit position has its own uniformly random permutation pi_{j,k} of
    {0, ..., b-1} (pbrt-v4's ``PermuteDigits``, see :class:`PermuteDigits`). Each point is then
    uniform on [0, 1)^d, while each digit permutation is a bijection, so the stratification of the
    sequence survives: the first ``b**k`` points of a base-b dimension hold one point in each
    interval of length ``b**-k``, and the first ``2**a * 3**b`` points of dims (0, 1) one in each
    cell of a ``2**-a x 3**-b`` grid.

    Digits are carried to ``b**-K`` with ``b**K <= 2**52``, finer than float64 resolves near 1, and
    the value is computed as an exact integer over ``b**K``, so it is always below 1.

    Parameters
    ----------
    d : int
        Dimension, 1 to 1000.
    scramble : bool
        If false, the plain radical inverses (identity permutations).
    randomizer : None, NoRandomizer or PermuteDigits (one set, the first ``d`` primes as bases)
        Given, it decides the randomisation (and ``scramble`` is not used); the sequence then
        stops at the permutations' ``capacity``.
    seed : see :class:`Independent`
        Only used for the permutations.

    Notes
    -----
    Consecutive calls continue the sequence, up to ``2**32`` points in all. High bases converge
    slowly in their first points and correlate in pairs; prefer Sobol' beyond a few dimensions.
    """

    name = "halton"
    _max_dim = 1000

    def __init__(self, d=2, *, scramble=True, randomizer=None, seed=None):
        super().__init__(d, randomizer=randomizer, seed=seed)
        self.bases = _primes(self.d)
        if self.randomizer is None:
            self.randomizer = (
                PermuteDigits.draw(GeneratorBits(self.rng), self.bases) if scramble else NoRandomizer()
            )
        elif not isinstance(self.randomizer, (NoRandomizer, PermuteDigits)):
            raise TypeError(f"Halton takes NoRandomizer or PermuteDigits, got {type(self.randomizer).__name__}")
        elif isinstance(self.randomizer, PermuteDigits) and self.randomizer.bases != self.bases:
            raise SettingsError(f"Halton: permutations for bases {self.randomizer.bases}, not {self.bases}")
        self.scramble = isinstance(self.randomizer, PermuteDigits)
        self._digits = self._permutations(self.randomizer, self.bases)

    @staticmethod
    def _permutations(randomizer, bases):
        return PermuteDigits.identity(bases) if isinstance(randomizer, NoRandomizer) else randomizer

    @classmethod
    def randomizer_from(cls, bits, d, max_points=_MAX_INDEX):
        return PermuteDigits.draw(bits, _primes(d), max_points)

    @classmethod
    def points(cls, indices, d, randomizer):
        """The points with indices ``indices`` (n,) of every set: (sets, n, d) float64 in [0, 1)."""
        perm = cls._permutations(randomizer, _primes(d))
        # An integer below b**K <= 2**52 over b**K: exact in float64, rounded to at most 1 - 2**-52.
        return perm(indices).astype(np.float64) / perm.scales

    @classmethod
    def points_uint32(cls, indices, d, randomizer):
        """:meth:`points` as 32-bit fixed point (sets, n, d) uint32: rounded down, except that a
        value within 2**-32 above the start of one of its base-b intervals stays in it (see
        :func:`_radical_fixed_point`); so the fixed-point points keep the strata, and they are
        within 2**-32 of the floats."""
        perm = cls._permutations(randomizer, _primes(d))
        a = perm(indices)
        out = np.empty(a.shape, dtype=_U32)
        for j, (b, K, D) in enumerate(perm.digits):
            out[..., j] = _radical_fixed_point(a[..., j], b, K, D)
        return out

    @classmethod
    def sets_uint32(cls, n, d, randomizer):
        return cls.points_uint32(np.arange(_check_count(n), dtype=_U64), d, randomizer)

    def _capacity(self):
        return min(_MAX_INDEX, self._digits.capacity)

    def _random(self, n):
        self._check_room(n)
        start = self.num_generated
        return self.points(np.arange(start, start + n, dtype=_U64), self.d, self._digits)[0]

    def _random_uint32(self, n):
        self._check_room(n)
        start = self.num_generated
        return self.points_uint32(np.arange(start, start + n, dtype=_U64), self.d, self._digits)[0]


SOURCES = {cls.name: cls for cls in (Independent, Stratified, Sobol, Halton)}


def make_source(name, d=2, seed=None):
    """Construct a sample source by name.

    Parameters
    ----------
    name : str
        One of the keys of :data:`SOURCES`: 'independent', 'stratified', 'sobol', 'halton'.
    d : int
        Dimension of the points.
    seed : None, int, SeedSequence or Generator
        Passed to the source.

    Returns
    -------
    Independent, Stratified, Sobol or Halton
    """
    try:
        cls = SOURCES[name]
    except (KeyError, TypeError):
        raise SettingsError(
            f"unknown sample source {name!r}; valid names: {', '.join(sorted(SOURCES))}"
        ) from None
    return cls(d, seed=seed)
