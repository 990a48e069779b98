"""The per-texel estimator, its error, and the rule that decides how many samples a texel takes.

A texel's estimate is the mean of its samples' terms: V(w) for cosine-weighted directions (0 or 1,
variance AO (1 - AO)), 2 cos(theta) V(w) for uniform ones, weighted by the distance falloff when
there is one. :class:`TexelEstimates` accumulates, per texel of a tile, the count and the sums of
the terms and of their squares (the kernel hands them over per piece of samples); everything else
(mean, standard error, the interval adaptive sampling stops on) is computed from those three.

:class:`SamplingPlan` says which samples each round traces and which texels take part: all of
``samples`` at once without adaptive sampling, else ``min_samples`` and then doubling rounds for
the texels whose interval (:func:`interval_half_width`) is still wider than the target. The
plan and the error estimate are the two places to change for another stopping rule or error model;
they see nothing but these sums. An error model from independent randomisations per texel would
add a replicate index to :meth:`TexelEstimates.add` (the sample pattern already draws independent
randomisations by replicate, :meth:`core.patterns.TexelPattern.keys`).
"""

import numpy as np

from .settings import SAMPLE_PIECE
from .stats import RunningStats, z_for_confidence


class TexelEstimates:
    """Count, sum and sum of squares of the sample terms of each of a tile's texels (float64)."""

    def __init__(self, count):
        self.n = np.zeros(count, np.int64)
        self.s1 = np.zeros(count)
        self.s2 = np.zeros(count)

    def add(self, rows, n, s1, s2):
        """Add pieces: ``rows`` (texel of each piece, repeats allowed), their sample counts and sums.

        Pieces are added one after another in the order given, so a texel's sums do not depend on
        how its pieces were grouped into calls (floating-point addition is not associative).
        """
        rows = np.asarray(rows)
        if len(rows) < 2 or np.all(rows[1:] > rows[:-1]):  # each texel once: plain indexed adds
            self.n[rows] += n
            self.s1[rows] += s1
            self.s2[rows] += s2
            return
        np.add.at(self.n, rows, n)
        np.add.at(self.s1, rows, s1)
        np.add.at(self.s2, rows, s2)

    @property
    def mean(self):
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.n > 0, self.s1 / np.maximum(self.n, 1), 0.0)

    @property
    def m2(self):
        """Sum of squared deviations from the mean (clipped at 0 against rounding)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.maximum(self.s2 - self.s1 * self.mean, 0.0)

    @property
    def stderr(self):
        """The standard error of each texel's mean for independent samples (0 where n < 2)."""
        return np.nan_to_num(RunningStats.from_moments(self.n, self.mean, self.m2).stderr, nan=0.0)


def interval_half_width(n, mean, m2, z, binary, bound):
    """Half-width of the confidence interval adaptive sampling stops on, per texel.

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


class SamplingPlan:
    """Rounds of samples: ``rounds(estimates)`` yields (start, count, texels) for the baker to trace.

    Without adaptive sampling, one round of all samples; with it, ``min_samples`` first, then rounds
    that double each texel's count (so Sobol' blocks stay aligned powers of two) for the texels whose
    interval is wider than ``target_error``. A round longer than :data:`core.settings.SAMPLE_PIECE`
    is traced in pieces of that many, which bounds a chunk's memory for any sample count.
    """

    def __init__(self, settings, confidence=0.95):
        self.samples = settings.samples
        self.first = settings.min_samples if settings.adaptive else settings.samples
        self.target = settings.target_error
        self.binary, self.bound = settings.binary, settings.bound
        self.z = z_for_confidence(confidence)

    def still_open(self, est, texels):
        """Which of ``texels`` have not reached the target error yet."""
        half = interval_half_width(est.n[texels], est.mean[texels], est.m2[texels], self.z,
                                   binary=self.binary, bound=self.bound)
        return half > self.target

    def rounds(self, est, texels):
        start, count = 0, self.first
        while len(texels) and count > 0:
            for s in range(start, start + count, SAMPLE_PIECE):
                yield s, min(SAMPLE_PIECE, start + count - s), texels
            start += count
            if start >= self.samples or self.target <= 0:
                return
            texels = texels[self.still_open(est, texels)]
            count = min(start, self.samples - start)


__all__ = ["TexelEstimates", "SamplingPlan", "interval_half_width"]
