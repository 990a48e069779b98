"""Monte Carlo estimators: the lecture's worked example, unbiasedness against analytic integrals,
convergence rates per sample source, and the zero-variance property of cosine-weighted sampling."""

import math
import subprocess
import sys

import numpy as np
import pytest
from scipy import integrate as spi

from core import estimate, integrate, warps
from core.montecarlo.integrate import LECTURE_TRUE_VALUE, gauss_legendre, lecture_integrand, worked_example_table
from core.montecarlo.stats import normal_quantile
from chi2 import SUITE_ALPHA, sidak

TRUTH = spi.quad(lecture_integrand, 0.0, 1.0, epsabs=1e-13, epsrel=1e-13, limit=200)[0]


def test_true_value_is_computed_independently_to_full_precision():
    assert gauss_legendre(lecture_integrand, 0.0, 1.0) == pytest.approx(TRUTH, rel=1e-14)
    # The lecture prints 1.760977217585905 as the true value; the integral is 1.7760990452...:
    # the lecture's value is off by 0.0151, far beyond its own table's large-N estimates' noise.
    assert TRUTH == pytest.approx(1.7760990452428, abs=1e-12)
    assert abs(TRUTH - LECTURE_TRUE_VALUE) > 0.015


def test_lecture_table_rows():
    truth, rows = worked_example_table(seed=1)
    assert [r[0] for r in rows] == [1, 10, 100, 1000, 10_000, 100_000, 1_000_000]
    for n, value, err, se in rows:
        assert err == pytest.approx(value - TRUTH, abs=1e-12)
        if n == 1:
            assert math.isnan(se)
        else:
            assert abs(err) < 5 * se


def test_worked_example_is_unbiased_across_seeds():
    k, n = 400, 1000
    z_crit = normal_quantile(1 - 0.01 / (2 * k))  # Sidak over the k seeds, alpha 0.01
    z = np.array([(e.value - TRUTH) / e.stderr for e in
                  (integrate(lecture_integrand, 0, 1, n, seed=[s, 446]) for s in range(k))])
    assert np.all(np.abs(z) < z_crit), np.abs(z).max()
    # No systematic bias: the mean z-score is N(0, 1/k) for an unbiased estimator.
    assert abs(z.mean()) < normal_quantile(0.995) / math.sqrt(k)
    # The stderr is honest: z-scores have unit variance (chi-square bounds for k - 1 dof, alpha 0.01).
    from scipy.stats import chi2

    lo, hi = chi2.ppf([0.005, 0.995], k - 1) / (k - 1)
    assert lo < z.var(ddof=1) < hi


def test_interval_scaling_and_estimate_interface():
    e = integrate(lambda x: np.ones_like(x), 2.0, 5.0, 100, seed=0)
    assert e.value == 3.0 and e.stderr == 0.0 and e.n == 100
    e = integrate(lambda x: x, -1.0, 3.0, 100_000, seed=0)  # integral 4
    lo, hi = e.ci(0.999)
    assert lo < 4.0 < hi and hi - lo < 0.1


@pytest.mark.parametrize("bad", [0, -3, 2.5, True])
def test_bad_sample_counts_are_refused(bad):
    with pytest.raises(ValueError, match="positive integer"):
        integrate(lecture_integrand, 0, 1, bad)


def test_empty_or_reversed_interval_is_refused():
    with pytest.raises(ValueError, match="a < b"):
        integrate(lecture_integrand, 1, 1, 10)


def test_same_seed_same_estimate():
    a = integrate(lecture_integrand, 0, 1, 1000, seed=42)
    b = integrate(lecture_integrand, 0, 1, 1000, seed=42)
    c = integrate(lecture_integrand, 0, 1, 1000, seed=43)
    assert a == b and a != c


def _rmse_slope(source, reps, ns):
    rmse = []
    for n in ns:
        errs = [integrate(lecture_integrand, 0, 1, n, seed=[r, n, 1], source=source).value - TRUTH
                for r in range(reps)]
        rmse.append(math.sqrt(np.mean(np.square(errs))))
    return np.polyfit(np.log(ns), np.log(rmse), 1)[0]


NS = [2 ** k for k in range(4, 15)]


@pytest.mark.slow
def test_independent_samples_converge_at_minus_one_half():
    # 300 repetitions: each RMSE is known to ~4%, so the slope's own standard error is ~0.006.
    slope = _rmse_slope("independent", 300, NS)
    assert abs(slope + 0.5) < 0.05, slope


@pytest.mark.slow
@pytest.mark.parametrize("source", ["stratified", "sobol", "halton"])
def test_stratified_and_qmc_converge_clearly_faster(source):
    slope = _rmse_slope(source, 60, NS)
    assert slope < -0.9, slope  # theory: -1.5 for jittered 1D and for Owen-scrambled nets


# --- the general estimator 1/N sum f/p over every registry sampler -----------------------------------

def _table_truth(table, g_int):
    """Integral of table(x) * g over the bins, for g with known per-bin integrals g_int(lo, hi)."""
    n = len(table)
    return sum(v * g_int(i / n, (i + 1) / n) for i, v in enumerate(table))


def _case(name):
    """(f, exact integral over the sampler's domain) with f = 0 wherever the pdf is 0."""
    s = warps.REGISTRY[name]
    if name == "piecewise_constant_1d":
        t = warps.EXAMPLE_TABLE_1D
        f = lambda p: s.pdf(p) * p[:, 0]  # noqa: E731
        # pdf = table / integral, so f integrates to sum(v_i * (hi^2 - lo^2) / 2) / integral
        integral = t.sum() / len(t)
        return f, _table_truth(t, lambda lo, hi: (hi * hi - lo * lo) / 2) / integral
    if name == "piecewise_constant_2d":
        t = warps.EXAMPLE_TABLE_2D
        f = lambda p: s.pdf(p) * p[:, 0] * p[:, 1]  # noqa: E731
        ny, nx = t.shape
        truth = sum(t[j, i] * ((2 * i + 1) / (2 * nx * nx)) * ((2 * j + 1) / (2 * ny * ny))
                    for j in range(ny) for i in range(nx)) / (t.sum() / t.size)
        return f, truth
    if s.domain == "interval":
        return (lambda p: p[:, 0] ** 2), 1 / 3
    if s.domain == "disk":
        return (lambda p: p[:, 0] ** 2 + 1.0), math.pi / 4 + math.pi
    if s.domain == "sphere":
        return (lambda w: w[:, 2] ** 2 + w[:, 0]), 4 * math.pi / 3
    if s.domain == "triangle":
        # Over {b0, b1 >= 0, b0 + b1 <= 1}: integral of b0 b1 is 1/24, of 1 is 1/2.
        return (lambda b: b[:, 0] * b[:, 1] + 1.0), 1 / 24 + 1 / 2
    n = getattr(s, "normal", np.array([0.0, 0.0, 1.0]))
    return (lambda w: (w @ n) ** 2), 2 * math.pi / 3


NAMES = sorted(warps.REGISTRY)


@pytest.mark.parametrize("name", NAMES)
def test_general_estimator_is_unbiased_for_every_sampler(name):
    f, truth = _case(name)
    e = estimate(f, warps.REGISTRY[name], 200_000, seed=[NAMES.index(name), 99])
    z_crit = normal_quantile(1 - sidak(SUITE_ALPHA, len(NAMES)) / 2)
    assert abs(e.value - truth) < z_crit * e.stderr, (e.value, truth, e.stderr)


def test_cosine_hemisphere_has_zero_variance_for_the_cosine_integral():
    # (1/pi) * integral of cos(theta) over the hemisphere = 1; with p = cos/pi each term f/p is 1.
    f = lambda w: w[:, 2] / math.pi  # noqa: E731
    cos = estimate(f, warps.REGISTRY["hemisphere_cosine"], 10_000, seed=0)
    assert cos.value == pytest.approx(1.0, abs=1e-12) and cos.stderr < 1e-14
    uni = estimate(f, warps.REGISTRY["hemisphere_uniform"], 200_000, seed=0)
    # Uniform: f/p = 2 cos(theta), variance 4/3 - 1 = 1/3, so stderr ~ sqrt(1/3 / N).
    assert uni.stderr == pytest.approx(math.sqrt(1 / 3 / 200_000), rel=0.02)
    assert abs(uni.value - 1.0) < 4 * uni.stderr


def test_estimator_refuses_a_sampler_that_contradicts_its_pdf():
    class Liar:
        def draw(self, n, rng):
            return np.full((n, 3), [0.0, 0.0, -1.0])

        pdf = staticmethod(warps.uniform_hemisphere_pdf)

    with pytest.raises(ValueError, match="pdf is 0"):
        estimate(lambda w: w[:, 2], Liar(), 10)


def test_core_never_imports_bpy():
    code = "import sys, core, core.montecarlo.warps, core.montecarlo.integrate, core.montecarlo.stats, core.demo; " \
           "import pkgutil; [__import__('core.' + m.name) for m in pkgutil.iter_modules(core.__path__)]; " \
           "assert 'bpy' not in sys.modules, 'bpy imported'; print('ok')"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=__file__.rsplit("/tests/", 1)[0])
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_demo_prints_the_table():
    out = subprocess.run([sys.executable, "-m", "core.demo", "--seed", "3"], capture_output=True, text=True,
                         cwd=__file__.rsplit("/tests/", 1)[0])
    assert out.returncode == 0, out.stderr
    assert "1000000" in out.stdout and "1.776099045242" in out.stdout
