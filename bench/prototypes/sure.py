"""Prototype: candidates chosen per texel by Stein's unbiased risk estimate, smoothed over a window.

For a candidate F = L y linear in the map (weights held fixed) and independent texel errors,
SURE_i = (F_i - y_i)^2 - sigma_i^2 + 2 sigma_i^2 L_ii has the texel's mean squared error as its
expectation (Stein 1981; Li, Wu and Chuang 2012 for rendering). One texel's SURE is far too noisy
to choose by; its mean over the texels around is not.
"""

import numpy as np

from bench.prototypes.boxfit import BoxFit, smooth


def sure_denoise(ao, se, mask, guide, radii=(2, 4, 8), rho=4, fine=True, verbose=False, report="sure"):
    from bench.prototypes.multiscale import fine_all

    mask = mask & guide.covered
    island = np.where(mask, guide.island, -1)
    fc, var, exact, _ = fine_all(ao, se, mask, guide)
    y = np.where(mask, ao, 0).astype(np.float64)
    cands = [(y, var, np.ones_like(y), "raw", np.zeros_like(y))]
    if fine:
        for (F, V, B, L), b in zip(fc, (1.25, 2.5)):
            cands.append((F, V, L, f"fine {b}", B))
    if radii:
        bf = BoxFit(mask, island, radii, 1)
        K = bf.kernels()
        for R, (c0, _, _, ok), (F, V) in zip(radii, K, bf.apply(y, K, var)):
            cands.append((F, V, np.where(ok, c0, np.nan), f"box {R}", None))
    best = np.full(y.shape, np.inf)
    out, vo, so = y.copy(), var.copy(), var.copy()
    choice = np.zeros(y.shape, int)
    for k, (F, V, L, name, _) in enumerate(cands):
        ok = np.isfinite(F) & np.isfinite(V) & mask
        s = np.where(ok, (F - y) ** 2 - var + 2 * var * L, 0)
        ssm = smooth(s, ok, rho)
        vsm = smooth(np.where(ok, V, 0), ok, rho)
        risk = np.where(ok, ssm, np.inf)
        take = ok & (risk < best) & ~exact
        best = np.where(take, risk, best)
        out = np.where(take, F, out)
        vo = np.where(take, V, vo)
        so = np.where(take, np.maximum(V + np.maximum(ssm - vsm, 0), V), so)
        choice[take] = k
    if verbose:
        print("choice", dict(zip([c[3] for c in cands], np.bincount(choice[mask], minlength=len(cands)))))
    se_o = np.sqrt(so if report == "sure" else vo)
    out = np.where(mask, np.clip(out, 0, 1), ao)
    return out.astype(np.float32), np.where(mask, se_o, 0).astype(np.float32)
