"""Sobol' points (Joe and Kuo's direction numbers), Owen-scrambled: the sequence, its scrambling, and the
source."""

import numpy as np

from ..base.errors import SettingsError
from .pointset import GeneratorBits, NoRandomizer, BLOCK, Sequence, U32, U64, as_uint32, check_count, check_dim


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
    v = np.zeros((32, SOBOL_MAX_DIM), dtype=U32)
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
    bits = ((np.arange(256)[:, None] >> np.arange(8)[None, :]) & 1).astype(U32)  # (256, 8)
    tables = np.empty((4, v.shape[1], 256), dtype=U32)
    for k in range(4):
        # bits * v picks v or 0 (uint32 * {0, 1} cannot overflow); xor-reduce over the 8 bits.
        t = np.bitwise_xor.reduce(bits[:, :, None] * v[None, 8 * k : 8 * k + 8, :], axis=1)
        tables[k] = t.T
    return tables


# The direct form x(i) = XOR of v_k over the set bits k of i, evaluated 8 bits at a time: one
# table lookup per byte of the index replaces eight masked xor passes over the whole batch
# (measured on 10^7 2D points: 0.2 s against 5 s for one pass per bit).
_SOBOL_BYTES = _byte_tables(_SOBOL_V)


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
    dims = check_dim(dims, SOBOL_MAX_DIM, "sobol_uint32")
    idx = as_uint32(indices, "indices")
    flat = idx.reshape(-1)
    out = np.zeros((flat.size, dims), dtype=U32)
    if flat.size == 0:
        return out.reshape(idx.shape + (dims,))
    # Bytes above the largest index's top set bit are zero everywhere and contribute nothing.
    nbytes = max(1, (int(flat.max()).bit_length() + 7) // 8)
    for start in range(0, flat.size, BLOCK):
        block = flat[start : start + BLOCK]
        # astype(uint8) keeps the low 8 bits of each shifted index.
        byte = [(block >> np.uint32(8 * k)).astype(np.uint8) for k in range(nbytes)]
        for j in range(dims):
            col = _SOBOL_BYTES[0, j][byte[0]]
            for k in range(1, nbytes):
                np.bitwise_xor(col, _SOBOL_BYTES[k, j][byte[k]], out=col)
            out[start : start + BLOCK, j] = col
    return out.reshape(idx.shape + (dims,))


# ---------------------------------------------------------------------------------------------
# Owen scrambling
# ---------------------------------------------------------------------------------------------

def _reversed_16_bits():
    """Every 16-bit value with its bits reversed, as a table: 16 array passes (a Python loop over
    the 65536 values cost a few tenths of a second at every import, in every worker process)."""
    i = np.arange(1 << 16, dtype=U32)
    r = np.zeros(1 << 16, dtype=U32)
    for b in range(16):
        r |= ((i >> b) & 1) << (15 - b)
    return r.astype(np.uint16)


_REV16 = _reversed_16_bits()


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
    x = as_uint32(x, "x")
    flat = np.ascontiguousarray(x).reshape(-1)
    # Reverse each 16-bit half with a 64k-entry table (it stays in cache), then swap the halves:
    # two lookups per value. Halves are taken arithmetically, so endianness does not matter.
    lo = _REV16[flat & np.uint32(0xFFFF)].astype(U32)
    hi = _REV16[flat >> np.uint32(16)].astype(U32)
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
    x = as_uint32(x, "x")
    seed = as_uint32(seed, "seed")
    x, seed = np.broadcast_arrays(x, seed)
    shape = x.shape
    xf = np.ascontiguousarray(x).reshape(-1)
    sf = np.ascontiguousarray(seed).reshape(-1)
    out = np.empty(xf.size, dtype=U32)
    for start in range(0, xf.size, BLOCK):
        stop = start + BLOCK
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
        seeds = as_uint32(seeds, "seeds")
        if seeds.ndim not in (1, 2):
            raise ValueError(f"seeds must have shape (sets, d) or (d,), got {seeds.shape}")
        self.seeds = np.atleast_2d(seeds)
        self.sets, self.d = self.seeds.shape

    @classmethod
    def draw(cls, bits, d):
        """Seeds for ``d`` dimensions of each of ``bits.sets`` scrambles: the top 32 bits of ``d`` words."""
        return cls((bits.words(d) >> np.uint64(32)).astype(U32))

    def __call__(self, u):
        """Scramble the points ``u`` (n, d) uint32 with every set's seeds: (sets, n, d) uint32."""
        return owen_scramble_uint32(u[None], self.seeds[:, None, :])


class Sobol(Sequence):
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
    reorder = "xor"
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
        return cls.points_uint32(np.arange(check_count(n), dtype=U64), d, randomizer)

    def _random_uint32(self, n):
        self._check_room(n)
        i = np.arange(self.num_generated, self.num_generated + n, dtype=np.uint64)
        # Gray-code order, as scipy and Joe-Kuo's generator emit the points; it permutes each
        # aligned block of 2**m indices within itself, so every such block is still a net.
        gray = (i ^ (i >> np.uint64(1))).astype(U32)
        return self.points_uint32(gray, self.d, self.randomizer)[0]


__all__ = ["SOBOL_MAX_DIM", "sobol_uint32", "reverse_bits_uint32", "owen_scramble_uint32", "OwenScrambler", "Sobol"]
