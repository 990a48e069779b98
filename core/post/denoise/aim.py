"""Adaptive sampling aimed at the denoised map's error: where the denoiser can average many texels,
few samples do; where it cannot (AO with detail at the scale of a texel, a contact edge), the texel's
own samples must meet the target.

With denoise on, a bake with a noise target runs in two passes (:func:`core.pipeline.run.run`):
every texel takes the first round's samples; the denoiser filters that map and says, per texel, the
error its choice leaves, V + B^2 (:func:`core.post.denoise.denoise`); :func:`goal_counts` turns that
into the samples each texel needs for its denoised error to meet the target; the texels that need
more are baked again with that many (from their first sample: the same sequence, continued), and
the map is denoised once more. The target then means the denoised map's error: the half-width of a
texel's interval, z sqrt(V + B^2) (z for the request's 95%), not the raw estimate's.

The prediction. The denoised variance V is a weighted sum of the neighbourhood's raw variances,
each falling as n^(-2 rate) (rate 1/2 for independent samples, about 3/4 for the quasi-Monte Carlo
sources, as :class:`core.engine.adaptive.SamplingPlan` takes it); the bias B does not fall with
samples. A texel whose bias already exceeds the target is one whose neighbourhood the filter cannot
use: more samples let it take a narrower candidate, at worst its raw value, so its raw error must
meet the target. The counts are rounded up to powers of two (Sobol' prefixes of 2^m points are nets)
and spread over the filter's window (a texel's neighbours carry its denoised value's noise).
"""

import numpy as np

from ...montecarlo.stats import z_for_confidence

#: Texels within this many texels (the fine filter's window radius) take a texel's count too.
SPREAD = 3


def _max_filter(a, r):
    """Each entry's largest value within r entries along both axes (a square window)."""
    out = a.copy()
    for axis in (0, 1):
        src = out.copy()
        n = a.shape[axis]
        for d in range(1, r + 1):
            if d >= n:
                break
            lo = [slice(None)] * 2
            hi = [slice(None)] * 2
            lo[axis], hi[axis] = slice(0, n - d), slice(d, n)
            np.maximum(out[tuple(lo)], src[tuple(hi)], out=out[tuple(lo)])
            np.maximum(out[tuple(hi)], src[tuple(lo)], out=out[tuple(hi)])
    return out


def goal_counts(variance, bias, raw_variance, mask, first, target, cap, rate, confidence=0.95, exact=None):
    """Per texel (H, W) int32: the samples each replicate takes in the second pass (0: none).

    Parameters
    ----------
    variance, bias : (H, W) the denoised map's variance and bias after the first pass
        (:class:`core.post.denoise.DenoiseInfo`).
    raw_variance : (H, W) the raw estimate's variance (the bake's squared standard error).
    mask : (H, W) bool, the covered texels; ``exact``: those the denoiser kept as exact (none more).
    first : the samples each replicate took in the first pass.
    target : the noise target, the half-width of a texel's interval at ``confidence``.
    cap : the most samples a replicate may take; rate : the error's rate (n^-rate).
    """
    s2 = (float(target) / z_for_confidence(confidence)) ** 2
    v = np.asarray(variance, np.float64)
    b2 = np.asarray(bias, np.float64) ** 2
    raw = np.asarray(raw_variance, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        # the factor on the samples that brings the error to the target
        room = s2 - b2
        ratio = np.where(room > 0.1 * s2, v / np.maximum(room, 1e-300), raw / s2)
        factor = np.where(ratio > 0, ratio, 0.0) ** (1.0 / (2.0 * rate))
    need = first * factor
    more = mask & (need > first) & np.isfinite(need)
    if exact is not None:
        more &= ~exact
    power = 2.0 ** np.ceil(np.log2(np.maximum(need, 1.0)))
    goal = np.where(more, np.clip(np.maximum(power, 2 * first), 2 * first, cap), 0).astype(np.int32)
    goal = _max_filter(goal, SPREAD)
    return np.where(mask & (goal > first), goal, 0).astype(np.int32)


__all__ = ["goal_counts", "SPREAD"]
