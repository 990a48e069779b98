"""Monte Carlo integration as the lecture teaches it, with standard errors and confidence intervals.

Two estimators:

- uniform samples on [a, b]:  F_N = (b - a)/N * sum f(x_i)              (:func:`integrate`)
- any sampler with a pdf:     F_N = 1/N * sum f(X_i) / p(X_i), X_i ~ p  (:func:`estimate`)

Both are unbiased, E[F_N] = integral of f, and their standard error falls as 1/sqrt(N) for
independent samples; stratified and quasi-Monte Carlo sources converge faster on smooth integrands.
"""

import math
from dataclasses import dataclass

import numpy as np

from .stats import z_for_confidence


@dataclass(frozen=True)
class Estimate:
    """A Monte Carlo estimate: ``value`` of the integral, its ``stderr``, from ``n`` samples.

    ``stderr`` is sqrt(s^2 / n) with s^2 the unbiased sample variance of the per-sample terms
    (nan for n = 1: one sample says nothing about its own spread). For stratified and QMC samples
    it is the independent-sample formula and so overestimates the error (conservative).
    """

    value: float
    stderr: float
    n: int

    def ci(self, level=0.95):
        """Normal-theory confidence interval (lo, hi) at ``level``."""
        h = z_for_confidence(level) * self.stderr
        return self.value - h, self.value + h


def _estimate_from_terms(terms):
    terms = np.asarray(terms, dtype=np.float64)
    n = terms.size
    value = float(terms.mean())
    stderr = float(terms.std(ddof=1) / math.sqrt(n)) if n > 1 else float("nan")
    return Estimate(value, stderr, n)


def _check_n(n):
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"the number of samples must be a positive integer, got {n!r}")
    return int(n)


def uniform_points(n, d=1, *, source="independent", seed=None):
    """n points of [0, 1)^d from a sample source ('independent', 'stratified', 'sobol', 'halton')."""
    n = _check_n(n)
    if source == "independent":
        return np.random.default_rng(seed).random((n, d))
    from .sources import make_source

    return make_source(source, d=d, seed=seed).random(n)


def integrate(f, a, b, n, *, seed=None, source="independent"):
    """Integral of f over [a, b] from n uniform samples: F_N = (b - a)/N sum f(x_i).

    Parameters
    ----------
    f : vectorised function of an (n,) array of abscissae, returning (n,) values.
    a, b : the interval, a < b.
    n : number of samples.
    seed : None, int, SeedSequence or Generator; the same seed gives the same estimate.
    source : 'independent' (the lecture's randf()), 'stratified', 'sobol' or 'halton'.

    Returns
    -------
    Estimate with the integral's value, its standard error and n.
    """
    if not (math.isfinite(a) and math.isfinite(b) and a < b):
        raise ValueError(f"integrate needs finite a < b, got [{a}, {b}]")
    x = a + (b - a) * uniform_points(n, 1, source=source, seed=seed)[:, 0]
    return _estimate_from_terms((b - a) * np.asarray(f(x), dtype=np.float64))


def estimate(f, sampler, n, *, seed=None):
    """The general estimator F_N = 1/N sum f(X_i) / p(X_i) with X_i drawn from ``sampler``.

    Parameters
    ----------
    f : vectorised function of an (n, d) array of points, returning (n,) values.
    sampler : anything with ``draw(n, rng) -> (n, d)`` and ``pdf(points) -> (n,)``, such as an
        entry of :data:`core.montecarlo.warps.REGISTRY`; the integral is over the sampler's domain, in the
        measure its pdf is stated in.
    n, seed : as in :func:`integrate`.
    """
    n = _check_n(n)
    rng = np.random.default_rng(seed)
    x = sampler.draw(n, rng)
    p = np.asarray(sampler.pdf(x), dtype=np.float64)
    if np.any(p <= 0):
        raise ValueError(f"{sampler!r} drew points where its own pdf is 0; the sampler and pdf disagree")
    return _estimate_from_terms(np.asarray(f(x), dtype=np.float64) / p)


def gauss_legendre(f, a, b, order=200, panels=8):
    """A deterministic reference: composite Gauss-Legendre quadrature of f over [a, b].

    For the lecture's smooth, bounded integrand 8 panels of 200 nodes reach double precision,
    which makes it an independent check of the Monte Carlo estimates.
    """
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(a, b, panels + 1)
    total = 0.0
    for lo, hi in zip(edges[:-1], edges[1:]):
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        total += half * float(np.dot(w, f(mid + half * x)))
    return total


def lecture_integrand(x):
    """The lecture's worked example: f(x) = exp(sin(3 x^2))."""
    return np.exp(np.sin(3.0 * np.asarray(x) ** 2))


#: The value the lecture prints for the integral of exp(sin(3x^2)) over [0, 1].
LECTURE_TRUE_VALUE = 1.760977217585905


def worked_example_table(ns=(1, 10, 100, 1000, 10_000, 100_000, 1_000_000), seed=0, source="independent"):
    """Rows (N, F_N, error against the quadrature value, stderr) for the lecture's table.

    Each N uses its own independent stream (SeedSequence spawning), as separate runs would.
    """
    truth = gauss_legendre(lecture_integrand, 0.0, 1.0)
    streams = np.random.SeedSequence(seed).spawn(len(ns))
    rows = []
    for n, ss in zip(ns, streams):
        e = integrate(lecture_integrand, 0.0, 1.0, n, seed=ss, source=source)
        rows.append((n, e.value, e.value - truth, e.stderr))
    return truth, rows
