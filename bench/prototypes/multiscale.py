"""Prototype: a multi-scale surface denoiser whose variance is exact (weights held fixed).

Quality first, cost later: this file is for measuring ideas on the cached bakes
(bench.prototypes.denoise_eval), not a product.

Pyramid candidates. Level l groups the image into cells of 2^l x 2^l texels (one island a cell: the
highest island among its texels; the others' texels leave that level). A cell holds sums over its
texels: count B, sum of AO X, sum of variances Q, normals. A texel's level-l candidate interpolates
the four nearest cells (tent weights between cell centres) with an edge-stopping factor per cell
(same island, normal, the texel's pilot against the cell's mean):

    F_i = sum_c a_ic X_c / sum_c a_ic B_c,     V_i = sum_c a_ic^2 Q_c / (sum_c a_ic B_c)^2

exact because every texel lies in one cell of a level, so the cells' sums are independent. Each
texel takes the least V + B^2 among its raw value, the fine candidates (today's filter) and the
levels; B by double smoothing (the same weights applied to F).
"""

import numpy as np


def _cells(island, y, var, normal, levels):
    """Per level, the cells' island and sums (B, X, Q, normal sums), and each texel's membership."""
    h, w = island.shape
    out = []
    isl = island.copy()
    B = (island >= 0).astype(np.float64)
    X = np.where(island >= 0, y, 0).astype(np.float64)
    Q = np.where(island >= 0, var, 0).astype(np.float64)
    N = [np.where(island >= 0, normal[..., k], 0).astype(np.float64) for k in range(3)]
    # member[l]: (h, w) bool, the texel counts in its level-l cell
    member = island >= 0
    for lev in range(1, levels + 1):
        s = 2 ** lev
        hc, wc = -(-h // s), -(-w // s)
        # island of the cell: the max of its texels' islands that are still members
        ip = np.full((hc * s, wc * s), -1, np.int64)
        ip[:h, :w] = np.where(member, island, -1)
        cisl = ip.reshape(hc, s, wc, s).max(axis=(1, 3))
        up = np.repeat(np.repeat(cisl, s, 0), s, 1)[:h, :w]
        member = member & (island == up)

        def csum(a):
            p = np.zeros((hc * s, wc * s))
            p[:h, :w] = np.where(member, a, 0)
            return p.reshape(hc, s, wc, s).sum(axis=(1, 3))

        cB = csum(np.ones((h, w)))
        cisl = np.where(cB > 0, cisl, -1)
        cells = dict(s=s, island=cisl, B=cB, X=csum(y), Q=csum(var), N=[csum(normal[..., k]) for k in range(3)],
                     member=member.copy())
        nn = np.sqrt(sum(c * c for c in cells["N"]))
        cells["n"] = [np.where(nn > 0, c / np.maximum(nn, 1e-30), 0) for c in cells["N"]]
        out.append(cells)
    return out


def _corners(h, w, s):
    """For texels (h, w) and cells of side s: the four nearest cells' (row, col) and tent weights."""
    yc = (np.arange(h) + 0.5) / s - 0.5
    xc = (np.arange(w) + 0.5) / s - 0.5
    y0, x0 = np.floor(yc).astype(int), np.floor(xc).astype(int)
    fy, fx = yc - y0, xc - x0
    out = []
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            out.append((y0 + dy, x0 + dx, wy[:, None] * wx[None, :]))
    return out


def level_candidate(cells, island, normal, pilot, pilot_var, beta=40.0, kappa=2.0, flat=3.0, value=None):
    """The level's candidate F, its variance V and the weights' arrays (for the bias pass)."""
    h, w = island.shape
    hc, wc = cells["island"].shape
    num = np.zeros((h, w))
    den = np.zeros((h, w))
    q = np.zeros((h, w))
    weights = []
    for r, c, tent in _corners(h, w, cells["s"]):
        ok_r, ok_c = (r >= 0) & (r < hc), (c >= 0) & (c < wc)
        rr, cc = np.clip(r, 0, hc - 1), np.clip(c, 0, wc - 1)
        take = lambda a: a[rr][:, cc]  # noqa: E731
        valid = ok_r[:, None] & ok_c[None, :] & (take(cells["island"]) == island) & (island >= 0)
        B = take(cells["B"])
        X = take(cells["X"]) if value is None else value(rr, cc)
        Q = take(cells["Q"])
        dot = sum(normal[..., k] * take(cells["n"][k]) for k in range(3))
        mean = np.where(B > 0, take(cells["X"]) / np.maximum(B, 1), 0)
        vmean = np.where(B > 0, Q / np.maximum(B, 1) ** 2, 0)
        d2 = (pilot - mean) ** 2 / (2 * kappa ** 2 * (pilot_var + vmean) + 1e-12)
        a = np.where(valid & (B > 0), tent * np.exp(-beta * (1 - dot) - np.maximum(d2 - flat, 0)), 0)
        weights.append((rr, cc, a))
        num += a * X
        den += a * B
        q += a * a * Q
    with np.errstate(invalid="ignore", divide="ignore"):
        F = np.where(den > 0, num / den, np.nan)
        V = np.where(den > 0, q / den ** 2, np.inf)
    return F, V, weights, den


def resmooth(cells, weights, den, F, member):
    """The level's operator applied to the field F (double smoothing): cells' sums of F, interpolated
    with the same weights."""
    h, w = F.shape
    s = cells["s"]
    hc, wc = cells["island"].shape
    p = np.zeros((hc * s, wc * s))
    p[:h, :w] = np.where(member & np.isfinite(F), F, 0)
    XF = p.reshape(hc, s, wc, s).sum(axis=(1, 3))
    num = np.zeros((h, w))
    for rr, cc, a in weights:
        num += a * XF[rr][:, cc]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def fine_candidates(ao, se, mask, guide, bandwidths=(1.25, 2.5)):
    """Today's filter's candidates one by one: (F, V, B) per bandwidth."""
    from core.post import denoise as D

    out = []
    for b in bandwidths:
        F, err, info = D.denoise(ao, se, mask, guide, bandwidths=(b,), use_error=False)
        out.append((F.astype(np.float64), info.variance.astype(np.float64), info.bias.astype(np.float64)))
    return out


def multiscale(ao, se, mask, guide, levels=4, bias_scale=1.0, use_fine=True, verbose=False):
    from core.post import denoise as D
    from core.post.denoise import filter as DF

    mask = mask & guide.covered
    island = np.where(mask, guide.island, -1)
    y = np.where(mask, ao, 0).astype(np.float64)
    var = np.where(mask, se.astype(np.float64) ** 2, 0)
    # trusted zeros as today
    F0 = DF._Features(guide, mask, D.RADIUS)
    var = DF._trusted_zeros(F0, var.astype(np.float32)).astype(np.float64)
    exact = var == 0
    normal = guide.normal.astype(np.float64)
    fine = fine_candidates(ao, se, mask, guide)
    pilot, pilot_var = fine[0][0], fine[0][1]
    cands = [(y, var, np.zeros_like(y))]
    if use_fine:
        cands += fine
    for cells in _cells(island, y, var, normal, levels):
        F, V, weights, den = level_candidate(cells, island, normal, pilot, pilot_var)
        SF = resmooth(cells, weights, den, F, cells["member"])
        B = bias_scale * (SF - F)
        cands.append((F, V, np.where(np.isfinite(B), B, np.inf)))
    best = np.full(y.shape, np.inf)
    out = y.copy()
    var_o = var.copy()
    bias_o = np.zeros_like(y)
    choice = np.zeros(y.shape, int)
    for k, (F, V, B) in enumerate(cands):
        m = V + B * B
        take = np.isfinite(m) & (m < best) & ~exact
        best = np.where(take, m, best)
        out = np.where(take, F, out)
        var_o = np.where(take, V, var_o)
        bias_o = np.where(take, B, bias_o)
        choice[take] = k
    se_o = np.sqrt(var_o + bias_o ** 2)
    if verbose:
        print("choice", np.bincount(choice[mask], minlength=len(cands)))
    out = np.where(mask, np.clip(out, 0, 1), ao)
    return out.astype(np.float32), np.where(mask, se_o, 0).astype(np.float32)


def fine_all(ao, se, mask, guide, bandwidths=(1.25, 2.5), radius=3, gradient_range=False):
    """Today's filter's candidates with everything the selection may need: per bandwidth (F, V, B,
    Lii) with Lii = 1 / W the weight of the texel's own value (weights held fixed), plus the trusted
    variance and the exact texels. A copy of core.post.denoise.denoise's steps."""
    import math

    from core.post import denoise as D
    from core.post.denoise import filter as DF

    h, w = ao.shape
    r = radius
    mask = np.asarray(mask, bool) & guide.covered
    F = DF._Features(guide, mask, r)
    halo = DF._halo_pairs(guide, mask, r, F)
    y = np.where(mask, ao, 0).astype(np.float32)
    var = np.where(mask, np.asarray(se, np.float32) ** 2, 0).astype(np.float32)
    exact = var == 0
    var = DF._trusted_zeros(F, var)
    exact &= var == 0
    bws = [float(b) for b in bandwidths]
    K = len(bws)
    inv2h2 = [np.float32(0.5 / (b * b)) for b in bws]
    pilot = np.float32(0.5 / D.PILOT_BANDWIDTH ** 2)
    beta = np.float32(D.NORMAL_SHARPNESS)
    zero = np.float32(0)
    P = lambda a: np.pad(a, r)  # noqa: E731
    yp, vp = P(y), P(var)

    def geometric(valid, d2, dot, c, o):
        g = np.exp(-(d2 * pilot + beta * (1.0 - dot)))
        return [g if valid is None else np.where(valid, g, zero)]

    Wg, Yg, Vg = DF._filter(F, halo, geometric, [(0, None, 1), (0, yp, 1), (0, vp, 2)], radius=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        G = P(np.where(Wg > 0, Yg / Wg, 0).astype(np.float32))
        vG = P(np.where(Wg > 0, Vg / (Wg * Wg), 0).astype(np.float32))
    Gf, vGf = G[r:r + h, r:r + w].reshape(-1), vG[r:r + h, r:r + w].reshape(-1)
    k2 = np.float32(2.0 * D.RANGE_SIGMAS ** 2)
    flat, eps = np.float32(D.RANGE_FLAT), np.float32(1e-12)
    if gradient_range:
        # the pilot's gradient per texel (central differences on the island, one-sided at its border)
        Gin0 = G[r:r + h, r:r + w].astype(np.float64)
        isl = np.where(mask, guide.island, -1)
        grads = []
        for axis in (1, 0):
            f = np.pad(Gin0, 1)
            ip = np.pad(isl, 1, constant_values=-1)
            cc = (slice(1, h + 1), slice(1, w + 1))
            if axis == 1:
                lo, hi = (slice(1, h + 1), slice(0, w)), (slice(1, h + 1), slice(2, w + 2))
            else:
                lo, hi = (slice(0, h), slice(1, w + 1)), (slice(2, h + 2), slice(1, w + 1))
            a, b = ip[lo] == isl, ip[hi] == isl
            fwd, bwd = f[hi] - f[cc], f[cc] - f[lo]
            # minmod: the smaller one-sided difference where both agree in sign, else 0 (a step has
            # one side flat: no gradient across it, so the range term still stops there)
            mm = np.where(fwd * bwd > 0, np.sign(fwd) * np.minimum(np.abs(fwd), np.abs(bwd)), 0.0)
            d = np.where(a & b, mm, 0.0)
            grads.append(P(d.astype(np.float32)))
        GX, GY = grads

    def candidates(valid, d2, dot, c, o):
        if valid is None:
            gi, gj, vi, vj = Gf[c], Gf[o], vGf[c], vGf[o]
            diff = gi - gj
        else:
            gi, gj, vi, vj = G[c], G[o], vG[c], vG[o]
            diff = gi - gj
            if gradient_range:
                dy = o[0].start - c[0].start
                dx = o[1].start - c[1].start
                pred = np.float32(0.5) * ((GX[c] + GX[o]) * np.float32(dx) + (GY[c] + GY[o]) * np.float32(dy))
                diff = gj - gi - pred
                # the prediction's own noise: each one-sided difference has about 2 v, over |offset|
                vi = vi * np.float32(1 + (dx * dx + dy * dy) / 2.0)
                vj = vj * np.float32(1 + (dx * dx + dy * dy) / 2.0)
        base = beta * (1.0 - dot) + np.maximum(diff ** 2 / (k2 * (vi + vj) + eps) - flat, zero)
        if valid is not None:
            base = np.where(valid, base, np.float32(np.inf))
        return [np.exp(-(d2 * inv + base)) for inv in inv2h2]

    Wk, Yk, Vk, Fk, Sk = DF._candidates_and_bias(F, halo, candidates, K, yp, vp, y, var)
    Gin = G[r:r + h, r:r + w]
    _, YG, _, _, _ = DF._candidates_and_bias(F, halo, candidates, K, G, vp, Gin, var, bias=False)
    fine_all.SG = [np.where(Wk[k] > 0, YG[k] / np.where(Wk[k] > 0, Wk[k], 1), Gin).astype(np.float64)
                   for k in range(K)]
    out = []
    with np.errstate(invalid="ignore", divide="ignore"):
        for k in range(K):
            V = np.where(Wk[k] > 0, Vk[k] / (Wk[k] * Wk[k]), var).astype(np.float64)
            B = np.where(Wk[k] > 0, Sk[k] / Wk[k] - Fk[k], 0).astype(np.float64)
            L = np.where(Wk[k] > 0, 1.0 / Wk[k], 1.0).astype(np.float64)
            out.append((Fk[k].astype(np.float64), V, B, L))
    return out, var.astype(np.float64), exact, (G[r:r + h, r:r + w].astype(np.float64),
                                                 vG[r:r + h, r:r + w].astype(np.float64))
