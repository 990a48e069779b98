"""Prototype: edge-avoiding a-trous passes over the texel graph (Dammertz et al. 2010), measured.

Level l filters the previous level's output with a (2 r + 1)^2 kernel h (B3 spline taps for r = 2,
[1, 2, 1] / 4 for r = 1) whose taps are 2^l texels apart, each tap weighed by edge-stopping terms
(same island, normals, the range of the previous level's values against their variance). Every
level's output is a candidate. The filter is linear in the map for fixed weights, so any probe
image pushed through the same weights tells its variance: Var(M y)_i = E[(M z)_i^2] for z_j =
sigma_j e_j with e_j independent, mean 0, variance 1 (Hutchinson's estimator of diag(M S M^T)).

Quality first, cost later (a prototype for bench.prototypes.denoise_eval).
"""

import numpy as np

B3 = np.array([1, 4, 6, 4, 1], np.float64) / 16
TENT = np.array([1, 2, 1], np.float64) / 4


def probes(shape, count, seed=0):
    """Rademacher signs (count, H, W), from a counter-based generator of (seed, texel)."""
    rng = np.random.default_rng([seed, 0xA7])
    return rng.choice(np.array([-1.0, 1.0]), size=(count,) + tuple(shape))


class Atrous:
    """The cascade's weights per level (kept, to apply the same operator to anything)."""

    def __init__(self, guide, mask, levels=4, kernel=B3, beta=40.0, kappa=2.0, flat=3.0, use_range=True, base=2,
                 beta_decay=1.0):
        self.mask = mask & guide.covered
        self.island = np.where(self.mask, guide.island, -1)
        self.n = guide.normal.astype(np.float64)
        self.p = guide.position.astype(np.float64)
        self.s = guide.scale.astype(np.float64)
        self.levels, self.kernel = levels, kernel
        self.beta, self.kappa, self.flat, self.use_range = beta, kappa, flat, use_range
        self.weights = []  # per level: list of (dy, dx, w (H, W)) and the normaliser
        self.base, self.beta_decay = base, beta_decay

    def _shift(self, a, dy, dx, fill=0):
        """a[i + dy, j + dx] at (i, j) (fill beyond the image)."""
        h, w = a.shape[:2]
        out = np.full_like(a, fill)
        ys, yd = (slice(dy, h), slice(0, h - dy)) if dy >= 0 else (slice(0, h + dy), slice(-dy, h))
        xs, xd = (slice(dx, w), slice(0, w - dx)) if dx >= 0 else (slice(0, w + dx), slice(-dx, w))
        out[yd, xd] = a[ys, xs]
        return out

    def build(self, y, var, pilot=None):
        """Filter ``y`` (variance ``var``) level by level, keeping each level's weights; returns the
        outputs per level and their naive propagated variance. ``pilot`` (g, var g): the range term
        compares it (fixed) instead of each level's input."""
        r = len(self.kernel) // 2
        c, v = np.where(self.mask, y, 0.0), np.where(self.mask, var, 0.0)
        outs = []
        for lev in range(self.levels):
            step = self.base ** lev
            beta = self.beta / self.beta_decay ** lev
            taps = []
            W = np.zeros(y.shape)
            num = np.zeros(y.shape)
            vn = np.zeros(y.shape)
            for ky in range(-r, r + 1):
                for kx in range(-r, r + 1):
                    dy, dx = ky * step, kx * step
                    isl = self._shift(self.island, dy, dx, -1)
                    ok = (isl == self.island) & (self.island >= 0)
                    dot = sum(self.n[..., k] * self._shift(self.n[..., k], dy, dx) for k in range(3))
                    w = self.kernel[ky + r] * self.kernel[kx + r] * np.exp(-beta * (1 - dot))
                    if self.use_range and (dy or dx):
                        gc, gv = (c, v) if pilot is None else pilot
                        cj, vj = self._shift(gc, dy, dx), self._shift(gv, dy, dx)
                        d2 = (gc - cj) ** 2 / (2 * self.kappa ** 2 * (gv + vj) + 1e-12)
                        w = w * np.exp(-np.maximum(d2 - self.flat, 0))
                    w = np.where(ok, w, 0)
                    taps.append((dy, dx, w))
                    W += w
                    num += w * self._shift(c, dy, dx)
                    vn += w * w * self._shift(v, dy, dx)
            with np.errstate(invalid="ignore", divide="ignore"):
                c = np.where(W > 0, num / W, c)
                v = np.where(W > 0, vn / W ** 2, v)
            self.weights.append((taps, W))
            outs.append((c.copy(), v.copy()))
        return outs

    def apply(self, x):
        """The kept operator on ``x`` (H, W) or (P, H, W): every level's output."""
        c = np.where(self.mask, x, 0.0)
        outs = []
        for taps, W in self.weights:
            num = np.zeros_like(c)
            for dy, dx, w in taps:
                if c.ndim == 3:
                    num += w * np.stack([self._shift(ci, dy, dx) for ci in c])
                else:
                    num += w * self._shift(c, dy, dx)
            with np.errstate(invalid="ignore", divide="ignore"):
                c = np.where(W > 0, num / W, c)
            outs.append(c.copy())
        return outs


def oracle(ao, se, mask, guide, ref, levels=4, kernel=B3, P=32, verbose=True, pilot=False, with_fine=False, **kw):
    """Candidates of the cascade, their true bias (the operator on the reference) and their variance
    (P probes): the per-texel choice by the true MSE, the best any estimate of it could do."""
    A = Atrous(guide, mask, levels, kernel, **kw)
    var = np.where(A.mask, se.astype(np.float64) ** 2, 0)
    pil = None
    if pilot:
        from bench.prototypes.multiscale import fine_candidates
        F, V, _ = fine_candidates(ao, se, mask, guide, bandwidths=(2.5,))[0]
        pil = (F, V)
    outs = A.build(ao.astype(np.float64), var, pil)
    truth = A.apply(ref["ao"].astype(np.float64))
    z = probes(ao.shape, P) * np.sqrt(var)
    pz = A.apply(z)
    res = []
    cands = [(ao.astype(np.float64), var, np.zeros(ao.shape))]
    if with_fine:
        from bench.prototypes.multiscale import fine_candidates
        for b in (1.25, 2.5):
            F, V, _ = fine_candidates(ao, se, mask, guide, bandwidths=(b,))[0]
            T = fine_candidates(ref["ao"], se, mask, guide, bandwidths=(b,))[0][0]
            cands.append((F, V, T - ref["ao"]))
    for lev, ((c, vn), t, q) in enumerate(zip(outs, truth, pz)):
        V = np.mean(q ** 2, axis=0)
        Bt = t - ref["ao"]
        cands.append((c, V, Bt))
        m = A.mask
        if verbose:
            e = c - ref["ao"]
            res.append((lev, np.sqrt(np.mean(e[m] ** 2)), np.sqrt(np.mean(V[m])), np.sqrt(np.mean(vn[m])),
                        np.sqrt(np.mean(Bt[m] ** 2))))
            print("level %d rmse %.4f sd(probes) %.4f sd(naive) %.4f bias %.4f" % res[-1])
    best = np.full(ao.shape, np.inf)
    out = ao.astype(np.float64).copy()
    choice = np.zeros(ao.shape, int)
    for k, (c, V, B) in enumerate(cands):
        m = V + B * B
        take = m < best
        best = np.where(take, m, best)
        out = np.where(take, c, out)
        choice[take] = k
    if verbose:
        print("oracle choice", np.bincount(choice[A.mask], minlength=len(cands)))
    return out, np.sqrt(best), cands, A


def tiled_denoise(ao, se, mask, guide, levels=4, kernel=TENT, beta_decay=1.0, pilot="today", rho_scale=0.5,
                  debias_scale=0.5, with_fine=False, verbose=False, bias="pilot", min_level_bias=1, **kw):
    """A-trous with 3 taps a level, 3^l apart (their supports tile: the propagated variance is
    exact), each level a candidate; the bias of level l from a pilot P: L_l P - P (the same
    weights), its square averaged over a window of radius rho_scale 3^l and debiased by
    debias_scale V_P; each texel takes the least V + B^2."""
    from bench.prototypes.selection import select
    from bench.prototypes.multiscale import fine_all
    from bench.prototypes.selection import smooth

    A = Atrous(guide, mask, levels, kernel, base=3, beta_decay=beta_decay, **kw)
    fc, var, exact, _ = fine_all(ao, se, mask, guide)
    y = np.where(A.mask, ao, 0).astype(np.float64)
    fine = [(y, var, np.zeros_like(y), "raw")] + [(F, V, B, f"fine {b}") for (F, V, B, L), b in
                                                   zip(fc, (1.25, 2.5))]
    P, VP, _, _ = select(fine, exact)
    outs = A.build(y, var)
    cands = [fine[0]] + (fine[1:] if with_fine else [])
    LP = A.apply(P)
    for lev, ((c, v), lp) in enumerate(zip(outs, LP)):
        b = lp - P
        ok = A.mask
        rho = max(1, int(round(rho_scale * 3 ** (lev + 1))))
        if bias == "pilot":
            sq = np.where(ok, b * b - debias_scale * VP, 0)
            B = np.sqrt(np.maximum(smooth(sq, ok, rho), 0))
        else:
            B = np.abs(b)
        cands.append((c, v, np.where(ok, B, np.inf), f"level {lev + 1}"))
    out, vo, bo, choice = select(cands, exact)
    if verbose:
        print("choice", dict(zip([c_[3] for c_ in cands], np.bincount(choice[A.mask], minlength=len(cands)))))
    out = np.where(A.mask, np.clip(out, 0, 1), ao)
    return out.astype(np.float32), np.where(A.mask, np.sqrt(vo + bo * bo), 0).astype(np.float32)


def atrous_fine(ao, se, mask, guide, levels=2, kernel=TENT, pilot_range=True, **kw):
    """Fine candidates from the exact-variance a-trous (3 taps, 3^l apart): per level (F, V, B, None)
    with B by double smoothing (the cascade up to the level applied to its own output), as
    multiscale.fine_all returns them; the range term compares a 3x3 geometric pilot."""
    from bench.prototypes.multiscale import fine_all

    fc, var, exact, (G, vG) = fine_all(ao, se, mask, guide, bandwidths=(1.25,), radius=2)
    A = Atrous(guide, mask, levels, kernel, base=3, **kw)
    y = np.where(A.mask, ao, 0).astype(np.float64)
    outs = A.build(y, var, (G, vG) if pilot_range else None)
    cands = []
    for lev, (c, v) in enumerate(outs):
        # S_l (c_l): the cascade up to level l applied to c_l
        again = A.apply(c)[lev]
        cands.append((c, v, np.where(A.mask, again - c, 0), None))
    return cands, var, exact, (G, vG)
