"""Halton points, digit-permuted: the radical inverses in bases of the first primes, their random digit
permutations, and the source."""

import math

import numpy as np

from ..base.errors import SettingsError
from .pointset import GeneratorBits, NoRandomizer, MAX_INDEX, Sequence, U32, U64, check_count


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
            weight = np.array([b ** (K - 1 - k) for k in range(D)], dtype=U64)
            contrib = perm.astype(U64) * weight[None, :, None]
            high = np.zeros((self.sets, D + 1), dtype=U64)
            high[:, D] = tails[:, j]
            high[:, :D] = np.cumsum(contrib[:, ::-1, 0], axis=1)[:, ::-1] + tails[:, j : j + 1]
            self._dims.append((b, float(b**K), contrib, high))

    @classmethod
    def draw(cls, bits, bases, capacity=MAX_INDEX):
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
        tails = np.empty((bits.sets, len(bases)), dtype=U64)
        for j, (b, (K, D)) in enumerate(zip(bases, counts)):
            # Uniform on [0, b**(K-D)) from the word's top 53 bits; the product rounds in float64
            # (R <= 2**52), hence the clamp. Only its distribution below b**-D matters.
            r = b ** (K - D)
            u = (w[:, start + j] >> np.uint64(11)).astype(np.float64) * 2.0**-53
            tails[:, j] = np.minimum(np.floor(u * float(r)), float(r - 1)).astype(U64)
        return cls(bases, perms, tails)

    @classmethod
    def identity(cls, bases, capacity=MAX_INDEX):
        """The identity permutations and no tail: the plain radical inverses (one set)."""
        perms = []
        for b in bases:
            K, D = _digit_counts(b, capacity)
            perms.append(np.tile(np.arange(b, dtype=U64), (1, D, 1)))
        return cls(bases, perms, np.zeros((1, len(bases)), dtype=U64))

    def __call__(self, indices):
        """The points of every set at ``indices`` (n,) as integers over b**K: (sets, n, d) uint64.
        Divided by :attr:`scales` they are the points in [0, 1)."""
        idx = np.asarray(indices, dtype=U64).reshape(-1)
        n = idx.size
        out = np.empty((self.sets, n, len(self.bases)), dtype=U64)
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
    q = np.floor(a.astype(np.float64) / float(b**K) * 2.0**32).astype(U64)
    if b % 2 == 0:
        return q.astype(U32)  # base 2: every interval starts on a multiple of 2**-32
    L = D
    while b**L > 2**32:
        L -= 1
    bl = np.uint64(b**L)
    s = a // np.uint64(b ** (K - L))  # the value's interval at level L
    lo = ((s << np.uint64(32)) + bl - np.uint64(1)) // bl  # ceil(s 2**32 / b**L): the first inside
    top = (((s + np.uint64(1)) << np.uint64(32)) - np.uint64(1)) // bl  # the last inside
    return np.clip(q, lo, top).astype(U32)


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


class Halton(Sequence):
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
    shift = "add"

    @classmethod
    def pattern_length(cls, samples):
        """Points of one set: exactly ``samples`` (every b^k consecutive points are stratified in base b)."""
        return int(samples)
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
    def randomizer_from(cls, bits, d, max_points=MAX_INDEX):
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
        out = np.empty(a.shape, dtype=U32)
        for j, (b, K, D) in enumerate(perm.digits):
            out[..., j] = _radical_fixed_point(a[..., j], b, K, D)
        return out

    @classmethod
    def sets_uint32(cls, n, d, randomizer):
        return cls.points_uint32(np.arange(check_count(n), dtype=U64), d, randomizer)

    def _capacity(self):
        return min(MAX_INDEX, self._digits.capacity)

    def _random(self, n):
        self._check_room(n)
        start = self.num_generated
        return self.points(np.arange(start, start + n, dtype=U64), self.d, self._digits)[0]

    def _random_uint32(self, n):
        self._check_room(n)
        start = self.num_generated
        return self.points_uint32(np.arange(start, start + n, dtype=U64), self.d, self._digits)[0]


__all__ = ["PermuteDigits", "Halton"]
