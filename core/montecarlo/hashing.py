"""Counter-based random numbers: uint64 hashes of integer keys, and uniform numbers from them.

Every random choice of a bake is a hash of what it is for (seed, texel, sample, a tag), like Cycles'
per-pixel hashing and pbrt-v4's ``Hash(pixel, dimension, seed)``: nothing depends on the order in
which work is done, so results are bit-identical for any threads, tiles and processes.
:func:`hash64` mixes each key in with splitmix64's finaliser.
"""

import numpy as np

GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


def _mix(x):
    """splitmix64's finaliser: a bijection of uint64 with full avalanche (wrapping multiplies)."""
    x = np.asarray(x, dtype=np.uint64)
    x = x ^ (x >> np.uint64(30))
    x = x * _M1
    x = x ^ (x >> np.uint64(27))
    x = x * _M2
    return x ^ (x >> np.uint64(31))


def hash64(*keys):
    """Hash integer keys (arrays broadcast together) into uint64, one mixing round per key."""
    return hash_more(np.array(0x2545F4914F6CDD1D, dtype=np.uint64), *keys)


def hash_more(state, *keys):
    """Continue :func:`hash64` from ``state`` (what it returned for the keys before these):
    ``hash_more(hash64(a, b), c, d) == hash64(a, b, c, d)``, so hashes that share their first keys
    mix those once."""
    # 0-d arrays, not numpy scalars: array arithmetic wraps silently, scalar arithmetic warns.
    h = np.asarray(state, dtype=np.uint64)
    tmp = None
    with np.errstate(over="ignore"):
        for k in keys:
            k = np.asarray(k)
            k = k.astype(np.uint64) if k.dtype != np.uint64 else k
            h = np.bitwise_xor(h, k)  # a new array: the keys and the state are never written
            h += GOLDEN
            if h.ndim == 0:
                h = _mix(h)
            else:
                if tmp is None or tmp.shape != h.shape:
                    tmp = np.empty_like(h)
                mix_into(h, tmp)
    return h


def mix_into(x, tmp):
    """:func:`_mix` of the uint64 array ``x`` in place (``tmp``: scratch of its shape)."""
    np.right_shift(x, np.uint64(30), out=tmp)
    x ^= tmp
    x *= _M1
    np.right_shift(x, np.uint64(27), out=tmp)
    x ^= tmp
    x *= _M2
    np.right_shift(x, np.uint64(31), out=tmp)
    x ^= tmp
    return x


def hash_uniform(*keys):
    """Uniform float64 in [0, 1) from the top 53 bits of :func:`hash64`."""
    return unit_float(hash64(*keys))


def unit_float(h):
    """Uniform float64 in [0, 1) from the top 53 bits of the uint64 hashes ``h``."""
    return (h >> np.uint64(11)).astype(np.float64) * (2.0 ** -53)


def below(x, n):
    """Map uint64 hashes to integers in [0, n) (multiply-shift on the top 32 bits: unbiased to 2^-32)."""
    return ((x >> np.uint64(32)) * np.uint64(n)) >> np.uint64(32)


__all__ = ["GOLDEN", "hash64", "hash_more", "hash_uniform", "mix_into", "unit_float", "below"]
