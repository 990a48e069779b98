"""The per-texel estimator, its error, and the rule that decides how many samples a texel takes.

A texel's estimate is the mean of its samples' terms: V(w) for cosine-weighted directions (0 or 1,
variance AO (1 - AO)), 2 cos(theta) V(w) for uniform ones, weighted by the distance falloff when
there is one.

The error of that mean. The sample variance over n samples estimates the error of the mean only when
the samples are independent. A texel's samples from a randomised quasi-Monte Carlo set (Owen-scrambled
Sobol', scrambled Halton, jittered strata) are not: they are spread out on purpose, so their mean
errs far less than the sample variance says (measured on a plane under a hovering polygon: 2 to 3
times less for Sobol' at 64 to 1024 samples). The one estimate that stays valid for every source is
the spread between independent randomisations (L'Ecuyer's randomised QMC): each texel draws its
samples from R independent replicates (:meth:`core.engine.patterns.TexelPattern.keys` by replicate), each
an unbiased randomised set of its own, and

    var(mean) ~ sum_r n_r (m_r - m)^2 / ((R - 1) N)          (m_r replicate means, N = sum n_r)

which is unbiased for equal n_r. With R = 2 it has one degree of freedom per texel, too few to trust
alone (its ratio to the truth is a chi-square with 1 degree of freedom), so the variance of each texel
is pooled over the texels around it: the mean of its neighbours' variances in a 5 x 5 window, each
scaled to the texel's own sample count (n_j / n_i, the independent-sample rate; quasi-Monte Carlo
errors fall faster, so this errs on the safe side where neighbours took fewer samples). The error
varies smoothly over a surface wherever the AO does, which is what makes pooling sound; the window
stays inside 16 x 16 blocks of the image (:data:`POOL_BLOCK`), so a texel's estimate never depends
on how texels are split into tiles. With m texels in its window the pooled variance has m (R - 1)
degrees of freedom, and the interval uses Student's t quantile for them.

R = 2 costs accuracy: two independent sets of N/2 points are a worse set than one of N points (for
Owen-scrambled Sobol' about 1.1 to 1.25 times the RMSE at equal rays, measured; none for independent
samples). ``replicates=1`` gives the lowest noise, and then the error falls back to the
independent-sample formula: exact for independent samples, an upper bound (2 to 3 times too large)
for the quasi-Monte Carlo sources.

Adaptive sampling (:class:`core.engine.adaptive.SamplingPlan`) takes ``min_samples`` for every texel, then doubles the
count of the texels whose interval is still wider than ``target_error``. A texel whose whole window
saw no variance (an open or a fully occluded region, where the cosine estimator's terms all agree)
stops at the minimum; one whose own samples all agree but whose neighbours vary keeps sampling, so
agreeing samples alone never stop a texel near a shadow.
"""

import math

import numpy as np

from ..montecarlo.sources import SOURCES
from ..montecarlo.stats import RunningStats, normal_quantile, z_for_confidence

#: Side of the image-aligned blocks within which variances are pooled (tiles are multiples of it).
POOL_BLOCK = 16
#: Pooling window: (2 * POOL_RADIUS + 1)^2 texels around each texel, within its block.
POOL_RADIUS = 2


def sample_terms(visibility, weight=None):
    """Each sample's AO term, float64: the estimator every path of the baker uses.

    ``visibility`` is V(w) per sample (bool, or in [0, 1] with a falloff); ``weight`` None for
    cosine-weighted directions (p(w) = cos(theta) / pi: the term is V itself), or per sample the
    ratio cos(theta) / (pi p(w)) of other directions (uniform: p(w) = 1 / (2 pi), weight 2 cos(theta)).
    """
    term = np.asarray(visibility).astype(np.float64)
    if weight is not None:
        term *= weight
    return term


def piece_sums(visibility, weight, pieces, k):
    """Per piece of ``k`` consecutive samples (``pieces`` of them): (sum of the terms, sum of their
    squares), float64, of :func:`sample_terms`. Binary terms (cosine directions, no falloff) are
    counted in integers, exactly."""
    if visibility.dtype == bool and weight is None:
        s1 = visibility.view(np.uint8).reshape(pieces, k).sum(axis=1, dtype=np.int64).astype(np.float64)
        return s1, s1
    term = sample_terms(visibility, weight).reshape(pieces, k)
    return term.sum(axis=1), (term * term).sum(axis=1)


#: :func:`t_quantile` of more than this many values, all whole numbers up to _T_TABLE_MAX, goes
#: through a table of every whole number up to the largest.
_T_TABLE_FROM = 256
_T_TABLE_MAX = 1 << 12


def t_quantile(p, dof):
    """Student's t quantile for probability ``p`` and ``dof`` degrees of freedom (arrays broadcast).

    Exact for 1 and 2 degrees of freedom; the Cornish-Fisher expansion (Abramowitz and Stegun
    26.7.5, four terms) above: relative error at p = 0.975 1.2e-3 at 3 degrees of freedom, 1e-5 at
    8, below 1e-7 from 50 (tests/test_estimators.py compares with scipy). The core needs no scipy.
    """
    dof = np.asarray(dof, dtype=np.float64)
    if dof.size > _T_TABLE_FROM:
        # A tile's texels share a few small whole degrees of freedom (pooled over windows): the
        # quantile of each once, from a table (the same arithmetic, value by value).
        top = float(dof.max())
        if float(dof.min()) >= 0.0 and top <= _T_TABLE_MAX:
            whole = np.floor(dof)
            if np.array_equal(whole, dof):
                table = _cornish_fisher(p, np.arange(int(top) + 1, dtype=np.float64))
                return np.take(table, whole.astype(np.intp))
    return _cornish_fisher(p, dof)


def _cornish_fisher(p, dof):
    """:func:`t_quantile` value by value."""
    z = normal_quantile(p)
    z2 = z * z
    g1 = (z2 + 1) * z / 4
    g2 = ((5 * z2 + 16) * z2 + 3) * z / 96
    g3 = (((3 * z2 + 19) * z2 + 17) * z2 - 15) * z / 384
    g4 = ((((79 * z2 + 776) * z2 + 1482) * z2 - 1920) * z2 - 945) * z / 92160
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.maximum(dof, 1.0)
        cf = z + g1 / v + g2 / v ** 2 + g3 / v ** 3 + g4 / v ** 4
        one = math.tan(math.pi * (p - 0.5))
        two = (2 * p - 1) / math.sqrt(2 * p * (1 - p))
    return np.where(dof <= 1.0, one, np.where(dof <= 2.0, two, cf))


class TexelEstimates:
    """Count, sum and sum of squares of the sample terms of each of a tile's texels, per replicate.

    ``n``, ``s1``, ``s2`` are (R, texels); the properties combine the replicates.
    """

    def __init__(self, count, replicates=1):
        self.replicates = int(replicates)
        self.rn = np.zeros((self.replicates, count), np.int64)
        self.rs1 = np.zeros((self.replicates, count))
        self.rs2 = np.zeros((self.replicates, count))

    def add(self, rows, n, s1, s2, replicate=0):
        """Add pieces of one replicate: ``rows`` (texel of each piece, repeats allowed), counts, sums.

        Pieces are added one after another in the order given, so a texel's sums do not depend on
        how its pieces were grouped into calls (floating-point addition is not associative).
        """
        rows = np.asarray(rows)
        rn, rs1, rs2 = self.rn[replicate], self.rs1[replicate], self.rs2[replicate]
        if len(rows) < 2 or np.all(rows[1:] > rows[:-1]):  # each texel once: plain indexed adds
            rn[rows] += n
            rs1[rows] += s1
            rs2[rows] += s2
            return
        np.add.at(rn, rows, n)
        np.add.at(rs1, rows, s1)
        np.add.at(rs2, rows, s2)

    @property
    def n(self):
        return self.rn.sum(axis=0)

    @property
    def mean(self):
        n = self.n
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n > 0, self.rs1.sum(axis=0) / np.maximum(n, 1), 0.0)

    @property
    def m2(self):
        """Sum of squared deviations from the mean over all samples (clipped at 0 against rounding)."""
        return self.moments()[2]

    def moments(self):
        """(n, mean, m2) over all replicates, each sum taken once (what :attr:`n`, :attr:`mean` and
        :attr:`m2` give, the same bits)."""
        n = self.n
        s1 = self.rs1.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(n > 0, s1 / np.maximum(n, 1), 0.0)
        return n, mean, np.maximum(self.rs2.sum(axis=0) - s1 * mean, 0.0)

    def replicate_variance(self):
        """Per texel, the variance of the mean from the spread of the replicate means (see the module
        docstring), or 0 where a replicate has no sample; needs at least two replicates."""
        rn = self.rn
        n = rn.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            m = np.where(n > 0, self.rs1.sum(axis=0) / np.maximum(n, 1), 0.0)
            mr = np.where(rn > 0, self.rs1 / np.maximum(rn, 1), m)
            v = (rn * (mr - m) ** 2).sum(axis=0) / ((self.replicates - 1) * np.maximum(n, 1))
        return np.where(np.all(rn > 0, axis=0), v, 0.0)

    def independent_stderr(self):
        """The standard error of each texel's mean for independent samples (0 where n < 2)."""
        return np.nan_to_num(RunningStats.from_moments(*self.moments()).stderr, nan=0.0)


class TexelWindows:
    """The windows of a fixed set of texels (see the module docstring): the index arithmetic of
    :func:`window_sums`, done once and reused for every sum over the same texels (a tile's texels are
    pooled once per round of adaptive sampling). ``x``, ``y`` (m,) are integer texel coordinates in
    the image; the texels must lie in whole :data:`POOL_BLOCK` blocks (a tile of a multiple of the
    block side) and be distinct.

    Per row of values, a summed-area table of each block padded with zeros, (side, side, blocks)
    with the blocks innermost, so both running sums add whole contiguous planes (numpy's cumsum
    along an axis is several times slower); then each block's window sums on the (B, B) grid, and
    the texels' values gathered from it: O(1) per texel whatever the window.
    """

    def __init__(self, x, y):
        B = POOL_BLOCK
        x = np.asarray(x, dtype=np.int64)
        y = np.asarray(y, dtype=np.int64)
        self.m = len(x)
        if self.m == 0:
            return
        bx, by = x // B, y // B
        bx0, by0 = int(bx.min()), int(by.min())
        nbx, nby = int(bx.max()) - bx0 + 1, int(by.max()) - by0 + 1
        self.blocks = nby * nbx
        self.block = (by - by0) * nbx + (bx - bx0)
        self.cell = y % B * B + x % B  # place in its block
        self._k = None

    def _plan(self, k):
        """Scatter and gather indices for ``k`` rows of values (cached for the last k)."""
        if self._k != k:
            B, r = POOL_BLOCK, POOL_RADIUS
            side = B + 2 * r + 1
            K = k * self.blocks
            rows = (np.arange(k) * self.blocks)[:, None] + self.block[None, :]
            y, x = np.divmod(self.cell, B)
            self._scatter = ((y + r + 1) * side + (x + r + 1)) * K + rows
            self._gather = self.cell * K + rows
            self._k = k
        return self._scatter, self._gather

    def sums(self, values):
        """(k, m) window sums of ``values`` (k, m)."""
        values = np.asarray(values, dtype=np.float64)
        k = values.shape[0]
        if self.m == 0:
            return np.zeros((k, 0))
        B, r = POOL_BLOCK, POOL_RADIUS
        side = B + 2 * r + 1
        scatter, gather = self._plan(k)
        table = np.zeros((side, side, k * self.blocks))
        table.reshape(-1)[scatter] = values
        for i in range(1, side):  # running sums down, then across: the same additions as cumsum
            np.add(table[i], table[i - 1], out=table[i])
        for i in range(1, side):
            np.add(table[:, i], table[:, i - 1], out=table[:, i])
        # Each window's corners (y1, x1) - (y0, x1) - (y1, x0) + (y0, x0), y0 = y - r - 1, y1 = y + r.
        lo, hi = slice(0, B), slice(2 * r + 1, side)
        win = table[hi, hi] - table[lo, hi]
        win -= table[hi, lo]
        win += table[lo, lo]
        return win.reshape(-1)[gather]


def window_sums(values, x, y):
    """For each texel, the sums of ``values`` (k, m) over the texels in its window (see the module
    docstring): (k, m). ``x``, ``y`` (m,) are integer texel coordinates in the image (see
    :class:`TexelWindows`, which this builds for one call).

    ``y`` None: ``x`` is an object whose ``sums(values)`` gives the sums over each point's
    neighbourhood: a :class:`TexelWindows` built once for texels summed over many times, or, for
    sample points that are not texels (mesh vertices, :mod:`core.targets.corners`), a
    :class:`core.geometry.corners.Neighbours` (a vertex and the vertices that share an edge with it)."""
    values = np.asarray(values, dtype=np.float64)
    if y is None:
        return x.sums(values)
    return TexelWindows(x, y).sums(values)


def pooled_variance(v, dof, n, x, y, also=()):
    """Each texel's variance pooled over its window (see the module docstring), and its degrees of
    freedom: the mean of the window's variances ``v`` (each of the mean of ``n`` samples, with ``dof``
    degrees of freedom, which weigh it) scaled to the texel's own ``n``. ``also``: more rows to sum
    over the same windows in the same pass, returned after those two."""
    (total, weight, *more) = window_sums([dof * v * n, dof, *also], x, y)
    weight = np.rint(weight)
    with np.errstate(invalid="ignore", divide="ignore"):
        pooled = np.where(weight > 0, np.maximum(total, 0.0) / (np.maximum(weight, 1.0) * np.maximum(n, 1)), 0.0)
    return (pooled, weight, *more) if also else (pooled, weight)


class ErrorModel:
    """Per texel: the standard error of its estimate, and the half-width of the interval adaptive
    sampling stops on, from a tile's :class:`TexelEstimates` and its texels' coordinates.

    With ``replicates`` >= 2 each texel's own variance estimate is the spread of its replicates
    (R - 1 degrees of freedom) for the quasi-Monte Carlo sources, and the sample variance of its
    mean (n - 1 degrees of freedom) for independent samples, where that one is valid; either is
    pooled over the texel's window (:func:`pooled_variance`); for binary terms see
    :meth:`variance`.

    ``grouped``: a texel's samples come in blocks that share a random position (selected to active,
    :mod:`core.highpoly`), so they are not independent even from the independent source, and the
    spread of the replicates (each of its own positions) is used for every source.
    """

    def __init__(self, settings, confidence=0.95, grouped=False):
        self.replicates = settings.replicates
        self.independent = SOURCES[settings.source].independent and not grouped
        self.binary, self.bound = settings.binary, settings.bound
        self.confidence = confidence
        self.z = z_for_confidence(confidence)

    def variance(self, est, x, y):
        """(variance of each texel's mean, degrees of freedom)."""
        if self.replicates < 2 or self.independent:
            # The sample variance (0 where n < 2), from the moments computed once (the mean and M2
            # each computed twice cost 19 ns a texel of a 4096^2 bake at 1 spp).
            moments = est.moments()
            n = moments[0]
            var = np.nan_to_num(RunningStats.from_moments(*moments).variance)
            v, dof = var / np.maximum(n, 1), np.maximum(n - 1, 0).astype(np.float64)
            if self.replicates < 2:
                return v, dof
        else:
            # A texel with a replicate of no samples (selected to active: every point of that
            # replicate missed the high-poly surface, core.highpoly) has no spread of its own: no
            # degrees of freedom, so it takes its neighbours' variance and gives them none.
            n = est.n
            v, dof = est.replicate_variance(), np.where(np.all(est.rn > 0, axis=0), self.replicates - 1.0, 0.0)
        if not self.binary:
            return pooled_variance(v, dof, n, x, y)
        # Binary terms. Texels whose samples all agree (an open texel, one under a resting object)
        # say nothing about the variance of a texel whose samples vary beside them: a texel whose
        # samples vary pools over the window's texels whose samples vary only. A texel whose samples
        # all agree pools over its whole window (so that it keeps sampling beside a shadow).
        nn = np.maximum(n, 1).astype(np.float64)
        k = np.rint(np.clip(est.mean, 0.0, 1.0) * nn)
        varying = (k > 0) & (k < nn)
        w = np.where(varying, dof, 0.0)
        pooled, pooled_dof, total, weight = pooled_variance(v, dof, n, x, y, also=(w * v * nn, w))
        weight = np.rint(weight)
        with np.errstate(invalid="ignore", divide="ignore"):
            own = np.where(weight > 0, np.maximum(total, 0.0) / (np.maximum(weight, 1.0) * nn), 0.0)
        var = np.where(varying, own, pooled)
        dof_out = np.where(varying, weight, pooled_dof)
        # The estimate moves in steps of 1 / n, and a well-stratified set can give both replicates
        # of every texel of a window the same count though their errors are not 0: a texel whose
        # samples vary is never taken below the step's variance, p (1 - p) / n^2 with p = k / n.
        p = k / nn
        return np.where(varying, np.maximum(var, p * (1.0 - p) / (nn * nn)), var), dof_out

    def stderr(self, est, x, y):
        return np.sqrt(self.variance(est, x, y)[0])

    def half_width(self, est, x, y):
        """Half-width of each texel's confidence interval at ``confidence``."""
        if self.replicates < 2:
            return interval_half_width(est.n, est.mean, est.m2, self.z, self.binary, self.bound)
        var, dof = self.variance(est, x, y)
        q = t_quantile(0.5 + self.confidence / 2.0, np.maximum(dof, 1.0))
        return q * np.sqrt(var)


def interval_half_width(n, mean, m2, z, binary, bound):
    """Half-width of the confidence interval adaptive sampling stops on without replicates.

    A texel whose samples all agree has zero sample variance, yet 16 open rays out of 16 do not
    prove AO = 1: a texel with AO 0.9 shows that 19% of the time. So for the cosine estimator, whose
    terms are 0 or 1, the interval is Agresti and Coull's: add z^2/2 successes and z^2/2 failures,
    p~ = (k + z^2/2) / (n + z^2), half-width z sqrt(p~ (1 - p~) / (n + z^2)). It never collapses, and
    an all-open texel stops once n is about 2.7 / target (the "rule of three"). Other estimators
    (uniform directions, falloff) use the sample variance, and the same bound, scaled to the terms'
    range [0, bound], when every sample agrees.
    """
    n = np.asarray(n, dtype=np.float64)
    z2 = z * z
    safe = np.maximum(n, 1.0)

    def agresti_coull(p):
        pt = (p * n + z2 / 2.0) / (n + z2)
        return z * np.sqrt(pt * (1.0 - pt) / (n + z2))

    if binary:
        return agresti_coull(np.clip(mean, 0.0, 1.0))
    var = np.nan_to_num(RunningStats.from_moments(n, mean, m2).variance)  # 0 where n < 2
    sample = z * np.sqrt(var / safe)
    return np.where(var > 0, sample, bound * agresti_coull(np.clip(mean / bound, 0.0, 1.0)))


__all__ = ["sample_terms", "piece_sums", "TexelEstimates", "ErrorModel", "pooled_variance", "window_sums", "t_quantile",
           "interval_half_width", "POOL_BLOCK", "POOL_RADIUS", "TexelWindows"]
