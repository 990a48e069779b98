"""Per-texel 4D sample points for the baker: (direction u0, u1, position-in-texel u2, u3).

Each texel gets its own randomised copy of a sample set, addressed by (texel, sample index) alone:
counter-based, like Cycles' per-pixel hashing and pbrt-v4's ``Hash(pixel, dimension, seed)``. So a
texel's points do not depend on how texels are grouped into tiles, chunks, rounds or threads, which
is what makes bakes bit-identical for any thread count.

Sources, all unbiased per texel (every point is uniform on [0, 1)^4):

- 'sobol': the first N points of the 4D Sobol' sequence, Owen-scrambled per texel and dimension
  (hash-based nested scrambling). Dimensions 0 and 1, a (0, 2)-sequence, drive the direction.
- 'halton': the 4D Halton sequence (bases 2, 3, 5, 7) with a per-texel Cranley-Patterson rotation.
- 'stratified': jittered strata for the direction pair and for the position pair, each pair in its
  own per-texel random order ("padding"), so the two pairs are not correlated.
- 'independent': uniform random numbers from the hash.
"""

import numpy as np

from .errors import SettingsError
from .sources import Halton, Stratified, reverse_bits_uint32, sobol_uint32

SOURCE_NAMES = ("sobol", "stratified", "independent", "halton")
DIMS = 4

_BELOW_ONE = np.nextafter(1.0, 0.0)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
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
    # 0-d arrays, not numpy scalars: array arithmetic wraps silently, scalar arithmetic warns.
    h = np.array(0x2545F4914F6CDD1D, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for k in keys:
            k = np.asarray(k)
            k = k.astype(np.uint64) if k.dtype != np.uint64 else k
            h = _mix(np.add(h ^ k, _GOLDEN))
    return h


def hash_uniform(*keys):
    """Uniform float64 in [0, 1) from the top 53 bits of :func:`hash64`."""
    return (hash64(*keys) >> np.uint64(11)).astype(np.float64) * (2.0 ** -53)


_C0, _C1, _C2 = np.uint32(0x3D20ADEA), np.uint32(0x05526C56), np.uint32(0x53A22864)


def _owen_from_reversed(v_rev, seed):
    """:func:`core.sources.owen_scramble_uint32` of values given already bit-reversed (broadcasting).

    The same Laine-Karras hash with pbrt-v4's constants; skipping the input reversal saves a third
    of the work, since the baker reverses its shared Sobol' base once per bake instead of per texel.
    """
    v = np.broadcast_to(v_rev, np.broadcast_shapes(v_rev.shape, seed.shape)).copy()
    odd = (seed >> np.uint32(16)) | np.uint32(1)  # on the small seed array, broadcast below
    tmp = np.empty_like(v)
    np.multiply(v, _C0, out=tmp)
    v ^= tmp
    v += seed
    v *= odd
    np.multiply(v, _C1, out=tmp)
    v ^= tmp
    np.multiply(v, _C2, out=tmp)
    v ^= tmp
    return reverse_bits_uint32(v)


def _seed_key(seed):
    return np.uint64(int(seed) % (1 << 64))


class TexelPattern:
    """Sample points for texels, ``points(texels, start, count) -> (len(texels), count, 4)``.

    Parameters
    ----------
    source : one of :data:`SOURCE_NAMES`.
    seed : non-negative integer; the same seed gives the same points.
    max_samples : the most samples any texel takes (the stratified grid and the base sequences are
        sized by it).
    """

    def __init__(self, source, seed, max_samples):
        if source not in SOURCE_NAMES:
            raise SettingsError(f"unknown sample source {source!r}; choose one of {', '.join(SOURCE_NAMES)}")
        self.source = source
        self.seed = _seed_key(seed)
        self.max_samples = int(max_samples)
        if source == "sobol":
            # Stored bit-reversed: the scramble works on reversed bits, and every texel shares the base.
            self._base_rev = reverse_bits_uint32(sobol_uint32(np.arange(self.max_samples, dtype=np.uint64), DIMS).T)
        elif source == "halton":
            self._base = np.ascontiguousarray(Halton(DIMS, scramble=False).random(self.max_samples).T)
        elif source == "stratified":
            self._grid = Stratified.grid_shape(self.max_samples)

    def points(self, texels, start, count):
        """Samples [start, start + count) of each texel: (len(texels), count, 4) in [0, 1)."""
        return np.moveaxis(self.points_by_dim(texels, start, count), 0, -1)

    def points_by_dim(self, texels, start, count):
        """The same points laid out dimension-major, (4, len(texels), count), for long inner loops."""
        texels = np.asarray(texels, dtype=np.uint64)
        s = self.seed
        dims = np.arange(DIMS, dtype=np.uint64)[:, None]
        if self.source == "sobol":
            seeds = (hash64(s, texels[None, :], dims) >> np.uint64(32)).astype(np.uint32)
            x = _owen_from_reversed(self._base_rev[:, None, start:start + count], seeds[:, :, None])
            return x.astype(np.float64) * (2.0 ** -32)
        if self.source == "halton":
            shift = hash_uniform(s, texels[None, :], dims, np.uint64(1))
            p = self._base[:, None, start:start + count] + shift[:, :, None]
            p -= np.floor(p)
            return np.minimum(p, _BELOW_ONE)
        idx = np.arange(start, start + count, dtype=np.uint64)
        u = hash_uniform(s, texels[None, :, None], idx[None, None, :], dims[:, :, None])
        if self.source == "independent":
            return u
        nx, ny = self._grid
        strata = np.arange(nx * ny, dtype=np.uint64)
        for pair in range(2):
            # A per-texel random order of the strata: sample i takes stratum order[i].
            keys = hash64(s, texels[:, None], np.uint64(100 + pair), strata[None, :])
            order = np.argsort(keys, axis=1)[:, start:start + count]
            u[2 * pair] = (order % nx + u[2 * pair]) / nx
            u[2 * pair + 1] = (order // nx + u[2 * pair + 1]) / ny
        return np.minimum(u, _BELOW_ONE)
