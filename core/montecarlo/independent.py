"""Independent uniform points: no structure, the plain Monte Carlo the others are measured against."""

import numpy as np

from .pointset import PointSet, U32, check_count


class Independent(PointSet):
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
    reorder = "xor"
    independent = True
    error_rate = 0.5

    @classmethod
    def randomizer_from(cls, bits, d, max_points=None):
        return bits

    @staticmethod
    def _words(n, d, bits):
        return bits.words(n * d).reshape(bits.sets, n, d)

    @classmethod
    def sets_uint32(cls, n, d, randomizer):
        return (cls._words(check_count(n), d, randomizer) >> np.uint64(32)).astype(U32)

    def _random(self, n):
        w = self._words(n, self.d, self._bits())[0]
        return (w >> np.uint64(11)).astype(np.float64) * 2.0**-53

    def _random_uint32(self, n):
        return (self._words(n, self.d, self._bits())[0] >> np.uint64(32)).astype(U32)

    def _fast_forward(self, n):
        # Discard in bounded chunks: the words come out row by row, so chunking skips exactly the
        # same words as one random(n) call would, without its memory.
        bits = self._bits()
        chunk = max(1, (1 << 20) // self.d)
        while n > 0:
            k = min(n, chunk)
            bits.words(k * self.d)
            n -= k


__all__ = ["Independent"]
