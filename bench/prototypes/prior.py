"""Prototype: the width of the filter from the geometry the bake saw (irradiance caching's rule).

Ward, Rubinstein and Clear 1988 (irradiance caching) bound how fast irradiance changes with the
distance to the surfaces a point sees: the change over a step dx is about dx / R (R the harmonic mean
distance of the hits). For AO only the occluded directions change, so AO's curvature at a texel is
about kappa = (1 - AO) / t^2, t the mean hit distance of its occluded rays. A filter of world radius
h then errs by about c kappa h^2: wide where the occluders are far (open walls), narrow near a
contact. Here t comes from two converged bakes (falloff 1 and none, the same rays): E[t/d; hit] is
their difference.
"""

import numpy as np

from bench.prototypes.boxfit import BoxFit, box, sat


def hit_distance(ao0, ao1, dmax):
    """Mean hit distance of the occluded rays from AO without falloff (ao0) and with falloff 1 (ao1)."""
    occ = 1.0 - ao0
    with np.errstate(invalid="ignore", divide="ignore"):
        t = dmax * (ao1 - ao0) / occ
    return np.where(occ > 1e-4, np.clip(t, 1e-4 * dmax, dmax), dmax)


def prior_denoise(ao, se, mask, guide, tbar, radii=(4, 8, 16), c=1.0, window=True, fine=True, verbose=False,
                  ds=False):
    from bench.prototypes.boxfit import select
    from bench.prototypes.multiscale import fine_all

    mask = mask & guide.covered
    island = np.where(mask, guide.island, -1)
    fc, var, exact, _ = fine_all(ao, se, mask, guide)
    y = np.where(mask, ao, 0).astype(np.float64)
    cands = [(y, var, np.zeros_like(y), "raw")]
    for (F, V, B, L), b in zip(fc, (1.25, 2.5)):
        cands.append((F, V, B, f"fine {b}"))
    pilot = fc[-1][0]
    s = guide.scale.astype(np.float64)
    kappa = np.where(mask, (1 - np.clip(pilot, 0, 1)) / np.maximum(tbar, 1e-6) ** 2, 0)
    bf = BoxFit(mask, island, radii, 1)
    K = bf.kernels()
    if window:
        m = mask.astype(np.float64)
        Sk, Sn = sat(kappa), sat(m)
    for R, k, (F, V) in zip(radii, K, bf.apply(y, K, var)):
        kap = kappa
        if window:  # the largest of the centre's and the window's mean
            n = box(Sn, R)
            kap = np.maximum(kappa, np.where(n > 0, box(Sk, R) / np.maximum(n, 1), 0))
        B = c * kap * (R * s) ** 2
        if ds:
            SF = bf.apply(np.where(np.isfinite(F), F, y), [k], radii=[R])[0][0]
            B = np.maximum(B, np.abs(SF - F))
        cands.append((F, V, np.where(np.isfinite(F), B, np.inf), f"box {R}"))
    out, vo, bo, choice = select(cands, exact)
    if verbose:
        print("choice", dict(zip([c_[3] for c_ in cands], np.bincount(choice[mask], minlength=len(cands)))))
    out = np.where(mask, np.clip(out, 0, 1), ao)
    return out.astype(np.float32), np.where(mask, np.sqrt(vo + bo * bo), 0).astype(np.float32)
