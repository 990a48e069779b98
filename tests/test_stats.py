"""Welford running statistics and the normal quantile that confidence intervals rest on."""

import numpy as np
import pytest
from scipy import stats as sps

from core.montecarlo.stats import RunningStats, normal_quantile, z_for_confidence


@pytest.mark.parametrize("p", [1e-12, 1e-6, 0.001, 0.02425, 0.1, 0.5, 0.8, 0.975, 0.99999, 1 - 1e-10])
def test_normal_quantile_matches_scipy(p):
    assert normal_quantile(p) == pytest.approx(sps.norm.ppf(p), rel=1e-13, abs=1e-13)


def test_z_for_95_percent():
    assert z_for_confidence(0.95) == pytest.approx(1.959963984540054, abs=1e-14)
    with pytest.raises(ValueError):
        z_for_confidence(1.0)


def test_batches_and_merges_equal_one_pass():
    rng = np.random.default_rng(0)
    x = rng.normal(3.0, 2.0, size=(4, 5, 1000))
    whole = RunningStats((4, 5)).add(x)
    pieces = [RunningStats((4, 5)).add(c) for c in np.array_split(x, 7, axis=-1)]
    merged = RunningStats((4, 5))
    for p in pieces[::-1]:  # any order
        merged.merge(p)
    for s in (whole, merged):
        np.testing.assert_array_equal(s.n, 1000)
        np.testing.assert_allclose(s.mean, x.mean(-1), rtol=1e-12)
        np.testing.assert_allclose(s.variance, x.var(-1, ddof=1), rtol=1e-10)
        np.testing.assert_allclose(s.stderr, x.std(-1, ddof=1) / np.sqrt(1000), rtol=1e-10)


def test_masked_batches_give_per_element_counts():
    rng = np.random.default_rng(1)
    x = rng.random((3, 50))
    where = rng.random((3, 50)) < np.array([[0.2], [0.7], [1.0]])
    s = RunningStats(3).add(x, where=where)
    for i in range(3):
        xi = x[i][where[i]]
        assert s.n[i] == xi.size
        assert s.mean[i] == pytest.approx(xi.mean())
        assert s.variance[i] == pytest.approx(xi.var(ddof=1))


def test_welford_is_stable_for_a_large_offset():
    # The naive E[x^2] - E[x]^2 loses every digit here; Welford/Chan keeps them.
    x = 1e9 + np.random.default_rng(2).random(10_000)
    s = RunningStats()
    for c in np.array_split(x, 10):
        s.add(c)
    assert float(s.variance) == pytest.approx(x.var(ddof=1), rel=1e-6)


def test_single_sample_has_no_variance():
    s = RunningStats().add(np.array([0.5]))
    assert np.isnan(s.variance) and np.isnan(s.stderr)


def test_confidence_interval_coverage():
    # 2000 independent 95% intervals of a uniform mean: coverage is Binomial(2000, 0.95) up to the
    # normal approximation (n = 100 per interval); accept anything within 4 sigma of 0.95.
    rng = np.random.default_rng(3)
    s = RunningStats(2000).add(rng.random((2000, 100)))
    lo, hi = s.ci(0.95)
    cover = np.mean((lo <= 0.5) & (0.5 <= hi))
    assert abs(cover - 0.95) < 4 * np.sqrt(0.95 * 0.05 / 2000)
