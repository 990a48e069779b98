"""The stopping rule: how many samples each texel takes, round by round (adaptive sampling).

:class:`SamplingPlan` yields the rounds the tile baker (:mod:`core.engine.tilebaker`) traces: all samples
at once, or with adaptive sampling ``min_samples`` first and then, for each texel whose confidence
interval (:class:`core.engine.estimators.ErrorModel`) is still wider than the target, the count its
interval predicts. Each replicate takes its own share of the samples (:func:`replicate_samples`).
"""

import numpy as np

from .estimators import ErrorModel
from ..montecarlo.sources import SOURCES
from .settings import SAMPLE_PIECE


def replicate_samples(samples, replicates):
    """How many of a texel's ``samples`` each replicate takes: as equal as possible, the first ones
    one more when they do not divide."""
    base, extra = divmod(int(samples), int(replicates))
    return [base + (r < extra) for r in range(int(replicates))]


class SamplingPlan:
    """Rounds of samples, per replicate: ``rounds(est, texels, x, y)`` yields (start, count, texels),
    sample indices of each replicate's own sequence, for the baker to trace in every replicate
    (``start`` and ``count`` one number for all the texels, or one per texel in adaptive rounds).

    Without adaptive sampling, one round of all samples. With it, ``min_samples`` first (shared
    among the replicates); then each texel whose interval (:class:`ErrorModel`) is still wider than
    ``target_error`` goes on to the count its interval predicts it needs: the half-width falls as
    n^-rate (rate 1/2 for independent samples; about 3/4 measured for the quasi-Monte Carlo sources
    on AO), so n (half / target)^(1 / rate), rounded up to a power of two (Sobol' prefixes of 2^m
    points are nets), at least twice and at most eight times its count, within the cap. A prediction
    that falls short costs one more round; one round per doubling would cost a pass over the tile
    for every power of two. A round longer than :data:`core.engine.settings.SAMPLE_PIECE` is traced in
    pieces of that many, which bounds a chunk's memory for any sample count. Replicate r never goes
    beyond its share of ``samples`` (:func:`replicate_samples`).
    """

    #: How much a texel's count may grow in one round, at the most.
    MAX_GROWTH = 64

    def __init__(self, settings, confidence=0.95, grouped=False):
        R = settings.replicates
        self.caps = replicate_samples(settings.samples, R)
        self.cap = self.caps[0]
        first = settings.min_samples if settings.adaptive else settings.samples
        self.first = max(1, -(-first // R))
        self.target = settings.target_error
        self.rate = SOURCES[settings.source].error_rate  # the point set's error rate, n^-rate
        self.errors = ErrorModel(settings, confidence, grouped)

    def next_counts(self, est, texels, n, x, y):
        """Per texel of ``texels`` (current count ``n`` per replicate): the count it goes on to, or
        its own count where its interval is within the target (or it reached the cap)."""
        half = self.errors.half_width(est, x, y)[texels]
        with np.errstate(divide="ignore", invalid="ignore"):
            need = n * (half / self.target) ** (1.0 / self.rate)
        need = np.nan_to_num(need, nan=0.0, posinf=float(self.cap))
        power = 2.0 ** np.ceil(np.log2(np.maximum(need, 1.0)))
        grow = np.clip(power, 2 * n, self.MAX_GROWTH * n)
        return np.where(half > self.target, np.minimum(grow, self.cap), n).astype(np.int64)

    def shares(self, start, count, texels):
        """Each replicate's own part of a round (start, count, texels from :meth:`rounds`): yields
        (replicate, texels, start, count) for the replicates with samples left below their cap."""
        for r, cap in enumerate(self.caps):
            c = np.minimum(count, cap - start)
            if np.ndim(c):
                some = c > 0
                if np.any(some):
                    yield r, texels[some], start[some], c[some]
            elif c > 0:
                yield r, texels, start, c

    def rounds(self, est, texels, x, y, goal=None):
        """Yields the rounds (start, count, texels) of ``texels`` (see the class). ``goal``: per texel
        the samples each replicate takes (0: none), in one round from the first sample: a bake whose
        counts were decided before it (:func:`core.post.denoise.aim.goal_counts`)."""
        if not len(texels):
            return
        if goal is not None:
            goal = np.minimum(np.asarray(goal, np.int64), self.cap)
            some = goal > 0
            texels, goal = texels[some], goal[some]
            for s in range(0, int(goal.max(initial=0)), SAMPLE_PIECE):
                more = goal > s
                yield np.full(int(more.sum()), s, np.int64), np.minimum(SAMPLE_PIECE, goal[more] - s), texels[more]
            return
        first = min(self.first, self.cap)
        for s in range(0, first, SAMPLE_PIECE):
            yield s, min(SAMPLE_PIECE, first - s), texels
        if self.target <= 0 or first >= self.cap:
            return
        n = np.full(len(texels), first, np.int64)
        while len(texels):
            nxt = self.next_counts(est, texels, n, x, y)
            grow = nxt > n
            texels, n, nxt = texels[grow], n[grow], nxt[grow]
            # One pass for the round: each texel from its own count to its own next count (pieces of
            # at most SAMPLE_PIECE samples; a pass per group of equal counts cost a pass's overhead
            # for every group).
            for s in range(0, int((nxt - n).max(initial=0)), SAMPLE_PIECE):
                more = nxt - n > s
                yield n[more] + s, np.minimum(SAMPLE_PIECE, nxt[more] - n[more] - s), texels[more]
            n = nxt
            keep = n < self.cap
            texels, n = texels[keep], n[keep]


__all__ = ["SamplingPlan", "replicate_samples"]
