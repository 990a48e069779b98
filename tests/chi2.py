"""Chi-square goodness-of-fit harness for samplers, in Mitsuba's style (python/mitsuba/chi2.py).

Samples are histogrammed in parameters (s, t) in [0, 1]^2 (or s in [0, 1]) where cell size is
proportional to the domain's measure; each cell's expected count is the sampler's pdf integrated over
the cell by Gauss-Legendre quadrature; cells expecting fewer than 5 are pooled. A sample outside the
domain, or in a cell the pdf says is empty, fails the test outright.
"""

import math

import numpy as np
from scipy import stats as sps

from core import warps

#: Tests sharing the suite-wide alpha (Sidak), over every chi-square and binomial check of samplers.
SUITE_ALPHA = 0.01


def sidak(alpha, m):
    return 1.0 - (1.0 - alpha) ** (1.0 / m)


def _frame(sampler):
    n = getattr(sampler, "normal", np.array([0.0, 0.0, 1.0]))
    s, t = warps.orthonormal_basis(n)
    return s, t, n


def to_params(sampler, pts):
    """Points -> (params (n, k), inside-domain mask)."""
    d = sampler.domain
    if d == "interval":
        x = pts[:, 0]
        return x[:, None], (x >= 0) & (x <= 1)
    if d == "square":
        return pts, np.all((pts >= 0) & (pts <= 1), axis=1)
    if d == "triangle":
        # (s, t) = ((1 - b0)^2, b1 / (1 - b0)): area-preserving up to the constant factor 1/2.
        b0, b1 = pts[:, 0], pts[:, 1]
        rest = 1.0 - b0
        inside = (b0 >= 0) & (b1 >= 0) & (b0 + b1 <= 1.0 + 1e-12)
        t = np.where(rest > 0, b1 / np.where(rest > 0, rest, 1.0), 0.0)
        return np.stack([rest * rest, np.clip(t, 0.0, 1.0)], axis=1), inside
    if d == "disk":
        r2 = np.einsum("ij,ij->i", pts, pts)
        t = np.mod(np.arctan2(pts[:, 1], pts[:, 0]) / (2 * math.pi), 1.0)
        return np.stack([r2, t], axis=1), r2 <= 1.0 + 1e-12
    s_, t_, n = _frame(sampler)
    norm_ok = np.abs(np.linalg.norm(pts, axis=1) - 1.0) < 1e-9
    z, x, y = pts @ n, pts @ s_, pts @ t_
    t = np.mod(np.arctan2(y, x) / (2 * math.pi), 1.0)
    if d == "sphere":
        return np.stack([(z + 1.0) / 2.0, t], axis=1), norm_ok
    if d == "hemisphere":
        return np.stack([z, t], axis=1), norm_ok & (z >= 0)
    raise ValueError(d)


def from_params(sampler, prm):
    """(s, t) -> points, and the measure per unit parameter area (the Jacobian, constant by design)."""
    d = sampler.domain
    if d == "interval":
        return prm[:, :1], 1.0
    if d == "square":
        return prm, 1.0
    if d == "triangle":
        r = np.sqrt(prm[:, 0])
        return np.stack([1.0 - r, prm[:, 1] * r], axis=1), 0.5
    if d == "disk":
        r, phi = np.sqrt(prm[:, 0]), 2 * math.pi * prm[:, 1]
        return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1), math.pi
    s_, t_, n = _frame(sampler)
    z = 2.0 * prm[:, 0] - 1.0 if d == "sphere" else prm[:, 0]
    phi = 2 * math.pi * prm[:, 1]
    rho = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    local = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)
    world = local[:, :1] * s_ + local[:, 1:2] * t_ + local[:, 2:3] * n
    return world, (4 * math.pi if d == "sphere" else 2 * math.pi)


def default_resolution(sampler):
    # Cell edges fall on the piecewise tables' bin edges (12 bins, 8 x 6 bins) so the pdf is smooth
    # inside every cell and quadrature is exact; odd counts elsewhere keep edges off symmetry lines.
    return {"interval": (48,), "square": (24, 24), "disk": (21, 41), "sphere": (31, 61),
            "hemisphere": (25, 51), "triangle": (25, 25)}[sampler.domain]


def expected_fractions(sampler, res, order=4):
    """The pdf integrated over each cell of the parameter grid (sums to 1 for a normalised pdf)."""
    x, w = np.polynomial.legendre.leggauss(order)
    x, w = (x + 1) / 2, w / 2
    axes = []
    for r in res:
        lo = np.arange(r) / r
        axes.append(((lo[:, None] + x[None, :] / r).ravel(), np.tile(w / r, r)))
    if len(res) == 1:
        pts, jac = from_params(sampler, axes[0][0][:, None])
        vals = sampler.pdf(pts) * jac * axes[0][1]
        return vals.reshape(res[0], order).sum(axis=1)
    (sx, wx), (tx, wt) = axes
    S, T = np.meshgrid(sx, tx, indexing="ij")
    W = np.outer(wx, wt)
    pts, jac = from_params(sampler, np.stack([S.ravel(), T.ravel()], axis=1))
    vals = (sampler.pdf(pts) * jac).reshape(S.shape) * W
    return vals.reshape(res[0], order, res[1], order).sum(axis=(1, 3))


def chi2_test(sampler, n, rng, res=None):
    """Returns (p-value, message). p = 0 for samples outside the domain or in empty cells."""
    res = res or default_resolution(sampler)
    pts = sampler.draw(n, rng)
    if pts.shape != (n, sampler.dim):
        return 0.0, f"draw returned shape {pts.shape}, expected {(n, sampler.dim)}"
    prm, inside = to_params(sampler, pts)
    if not inside.all():
        return 0.0, f"{(~inside).sum()} samples outside the domain"
    idx = np.minimum((prm * np.array(res)).astype(int), np.array(res) - 1)
    flat = np.ravel_multi_index(tuple(idx.T), res)
    observed = np.bincount(flat, minlength=int(np.prod(res))).astype(float)
    expected = expected_fractions(sampler, res).ravel() * n
    if np.any((expected <= 0) & (observed > 0)):
        return 0.0, "samples in cells where the pdf integrates to 0"
    small = expected < 5
    obs = np.concatenate([observed[~small], [observed[small].sum()]]) if small.any() else observed
    exp = np.concatenate([expected[~small], [expected[small].sum()]]) if small.any() else expected
    keep = exp > 0
    obs, exp = obs[keep], exp[keep]
    stat = float(((obs - exp) ** 2 / exp).sum())
    dof = len(obs) - 1
    return float(sps.chi2.sf(stat, dof)), f"chi2={stat:.1f}, dof={dof}"
