"""Stratified (jittered) points: one point in each cell of a grid, at a random place in it."""

import math

import numpy as np

from .pointset import PointSet, U32, U64, check_count


def _in_stratum(k, m, jitter):
    """32-bit fixed-point coordinates in stratum ``k`` of ``m`` equal strata of [0, 1), placed by the
    32-bit ``jitter``: the integers v with k/m <= v 2**-32 < (k+1)/m, so that floor(v 2**-32 m) == k
    holds exactly in float64 too (for power-of-two m: k in the top bits, the jitter's top bits below)."""
    k = np.asarray(k)
    if m & (m - 1) == 0:
        a = np.uint64(m.bit_length() - 1)
        return ((k.astype(U64) << (np.uint64(32) - a)) | (jitter.astype(U64) >> a)).astype(U32)
    # first[k] = ceil(k 2**32 / m), the first such integer; a table of m + 1 entries, looked up.
    first = ((np.arange(m + 1, dtype=U64) << np.uint64(32)) + np.uint64(m - 1)) // np.uint64(m)
    k = k.astype(np.intp)
    lo = first[k]
    width = first[k + 1] - lo  # at most 2**32 - 1 + 1, so width * jitter < 2**64
    width *= jitter.astype(U64)
    width >>= np.uint64(32)
    lo += width
    return lo.astype(U32)


class Stratified(PointSet):
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

    @classmethod
    def shift_masks(cls, length):
        """A digital shift below the strata: the bits under each axis's grid cells, so every point
        stays in its stratum."""
        nx, ny = cls.grid_shape(length)
        return (1 << (32 - (nx.bit_length() - 1))) - 1, (1 << (32 - (ny.bit_length() - 1))) - 1

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
        n = check_count(n)
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
        n = check_count(n)
        out = np.empty((randomizer.sets, n, d), dtype=U32)
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


__all__ = ["Stratified"]
