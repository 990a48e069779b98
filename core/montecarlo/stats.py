"""Running statistics: Welford mean and variance over arrays, mergeable across tiles and threads.

The same object serves one estimate (shape ()) and a whole image of texels (shape (H, W)): every
attribute is an array of that shape. Batches are added with a vectorised form of Chan et al.'s
parallel update, which is also how two partial results merge, so accumulating in any grouping gives
the same mean and variance up to rounding.
"""

import math

import numpy as np


def normal_quantile(p):
    """The standard normal quantile Phi^-1(p) for 0 < p < 1, to full double precision.

    Acklam's rational approximation (relative error 1.2e-9) refined by one Halley step on
    erfc, so the core needs no scipy.
    """
    p = float(p)
    if not 0.0 < p < 1.0:
        raise ValueError(f"normal_quantile needs 0 < p < 1, got {p}")
    if p > 0.5:
        # 1 - p is exact for p >= 0.5 (Sterbenz), and the lower tail avoids erfc's cancellation near 1.
        return -normal_quantile(1.0 - p)
    a = (-3.969683028665376e01, 2.209460984245205e02, -2.759285104469687e02,
         1.383577518672690e02, -3.066479806614716e01, 2.506628277459239e00)
    b = (-5.447609879822406e01, 1.615858368580409e02, -1.556989798598866e02,
         6.680131188771972e01, -1.328068155288572e01)
    c = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e00,
         -2.549732539343734e00, 4.374664141464968e00, 2.938163982698783e00)
    d = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e00, 3.754408661907416e00)
    lo = 0.02425
    if p < lo:
        q = math.sqrt(-2.0 * math.log(p))
        x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) / \
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0)
    else:
        q = p - 0.5
        r = q * q
        x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q / \
            (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0)
    e = 0.5 * math.erfc(-x / math.sqrt(2.0)) - p
    u = e * math.sqrt(2.0 * math.pi) * math.exp(x * x / 2.0)
    return x - u / (1.0 + x * u / 2.0)


def z_for_confidence(level):
    """The two-sided normal critical value: P(|Z| <= z) = level (1.959963984540054 for 0.95)."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"confidence level must be in (0, 1), got {level}")
    return normal_quantile(0.5 + level / 2.0)


class RunningStats:
    """Count, mean and sum of squared deviations (M2) per element of an array of estimates.

    Parameters
    ----------
    shape : shape of the array of independent estimates (() for a single one).

    Notes
    -----
    ``variance`` is the unbiased sample variance M2 / (n - 1) of the samples (nan where n < 2);
    ``stderr`` = sqrt(variance / n) is the standard error of the mean under independent samples.
    For quasi-Monte Carlo samples it overestimates the actual error, which only makes confidence
    intervals conservative.
    """

    def __init__(self, shape=()):
        self.n = np.zeros(shape, dtype=np.int64)
        self.mean = np.zeros(shape, dtype=np.float64)
        self.m2 = np.zeros(shape, dtype=np.float64)

    @classmethod
    def from_moments(cls, n, mean, m2):
        s = cls.__new__(cls)
        s.n = np.asarray(n, dtype=np.int64).copy()
        s.mean = np.asarray(mean, dtype=np.float64).copy()
        s.m2 = np.asarray(m2, dtype=np.float64).copy()
        return s

    def add(self, values, axis=-1, where=None):
        """Add a batch of samples lying along ``axis`` (one batch per element of the stats' shape).

        ``where`` (same shape as values) masks samples out, so elements can take different counts.
        """
        values = np.asarray(values, dtype=np.float64)
        if where is None:
            k = np.full(np.delete(values.shape, axis % values.ndim), values.shape[axis], dtype=np.int64)
            bmean = values.mean(axis=axis)
            bm2 = ((values - np.expand_dims(bmean, axis)) ** 2).sum(axis=axis)
        else:
            where = np.asarray(where, dtype=bool)
            k = where.sum(axis=axis).astype(np.int64)
            safe = np.maximum(k, 1)
            bmean = np.where(where, values, 0.0).sum(axis=axis) / safe
            bm2 = np.where(where, (values - np.expand_dims(bmean, axis)) ** 2, 0.0).sum(axis=axis)
        self.merge_moments(k, bmean, bm2)
        return self

    def merge_moments(self, k, bmean, bm2):
        """Chan et al.: combine (n, mean, M2) with another group's (k, mean_b, M2_b)."""
        k = np.asarray(k, dtype=np.int64)
        total = self.n + k
        safe = np.maximum(total, 1)
        delta = bmean - self.mean
        self.mean = np.where(total > 0, self.mean + delta * (k / safe), 0.0)
        self.m2 = self.m2 + bm2 + delta * delta * (self.n * k / safe)
        self.n = total
        return self

    def merge(self, other):
        """Fold another RunningStats (for example a tile finished by another thread) into this one."""
        return self.merge_moments(other.n, other.mean, other.m2)

    @property
    def variance(self):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.n > 1, self.m2 / np.maximum(self.n - 1, 1), np.nan)

    @property
    def stderr(self):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.sqrt(self.variance / np.maximum(self.n, 1))

    def half_width(self, level=0.95):
        """Half-width of the normal-theory confidence interval of the mean at ``level``."""
        return z_for_confidence(level) * self.stderr

    def ci(self, level=0.95):
        h = self.half_width(level)
        return self.mean - h, self.mean + h
