"""Prototype: wide candidates at a constant cost a texel, from integral images (summed-area tables).

For a square window of radius R around texel i, the sums over the covered texels of i's island of
1, u, v, uu, uv, vv, f, uf, vf (u, v the texel offsets) give the weighted least-squares plane's value
at i (a local-linear fit, first order: a window cut by an island's border leaves no first-order
bias), and the sums of sigma^2 times 1, u, v, uu, uv, vv its exact variance: the fit is linear in the
map, a_i = sum_j l_j f_j with l_j = c0 + c1 u_j + c2 v_j, so Var a_i = sum_j l_j^2 sigma_j^2 (the
bake's texels have independent errors). Every sum over a window is four lookups of a summed-area
table, whatever R: the cost does not grow with the reach. A window holding covered texels of
another island is not used (sums of the island index and its square tell).

Quality first, cost later (a prototype for bench.prototypes.denoise_eval).
"""

import numpy as np

from bench.prototypes.selection import box, sat, select, smooth  # noqa: F401








def wbox(a, R, passes=1):
    """Window sums of ``a``: a box of radius R (passes 1) or a box of a box (passes 2: tent weights
    (R + 1 - |dx|)(R + 1 - |dy|) over radius 2R)."""
    out = box(sat(a), R)
    for _ in range(passes - 1):
        out = box(sat(out), R)
    return out


class BoxFit:
    """The fits of one map's mask and islands at radii ``radii`` (their kernels are fixed: they depend
    on the mask and islands alone, so the same fit applies to any map)."""

    def __init__(self, mask, island, radii=(2, 4, 8, 16), order=1, ridge=1e-3, passes=1):
        self.mask, self.island, self.radii, self.order, self.ridge = mask, island, radii, order, ridge
        self.passes = passes
        h, w = mask.shape
        Y, X = np.mgrid[0:h, 0:w].astype(np.float64)
        self.X, self.Y = X, Y
        m = mask.astype(np.float64)
        isl = np.where(mask, island, 0).astype(np.float64)
        self.A = dict(n=m, x=m * X, y=m * Y, xx=m * X * X, xy=m * X * Y, yy=m * Y * Y, i=m * isl, ii=m * isl * isl)

    def _moments(self, R):
        """Per texel: centred moments (n, su, sv, suu, suv, svv) and whether the window is pure."""
        A, X, Y = self.A, self.X, self.Y
        b = lambda k: wbox(A[k], R, self.passes)  # noqa: E731
        n, sx, sy = b("n"), b("x"), b("y")
        sxx, sxy, syy = b("xx"), b("xy"), b("yy")
        si, sii = b("i"), b("ii")
        k = np.where(self.mask, self.island, 0).astype(np.float64)
        pure = self.mask & (np.abs(sii - 2 * k * si + k * k * n) < 0.5)
        su, sv = sx - n * X, sy - n * Y
        suu = sxx - 2 * X * sx + n * X * X
        suv = sxy - X * sy - Y * sx + n * X * Y
        svv = syy - 2 * Y * sy + n * Y * Y
        return n, su, sv, suu, suv, svv, pure

    def kernels(self):
        """Per radius: (c0, c1, c2, pure): the equivalent kernel l_j = c0 + c1 u_j + c2 v_j."""
        out = []
        for R in self.radii:
            n, su, sv, suu, suv, svv, pure = self._moments(R)
            if self.order == 0:
                c0 = np.where(n > 0, 1 / np.maximum(n, 1), 0)
                out.append((c0, np.zeros_like(c0), np.zeros_like(c0), pure & (n > 0)))
                continue
            lam = self.ridge * np.maximum(n, 1) * (R * R if np.isscalar(R) else R[0] * R[1])
            # c = M^-1 e1 for M = [[n, su, sv], [su, suu + lam, suv], [sv, suv, svv + lam]]
            a, b, c = suu + lam, suv, svv + lam
            det2 = a * c - b * b
            # Schur complement: c0 = 1 / (n - [su sv] A^-1 [su sv]^T), [c1 c2] = -A^-1 [su sv] c0
            with np.errstate(invalid="ignore", divide="ignore"):
                p = (c * su - b * sv) / det2
                q = (a * sv - b * su) / det2
                schur = n - (su * p + sv * q)
                c0 = 1 / schur
            ok = pure & (n >= 3) & np.isfinite(c0) & (schur > 1e-9)
            out.append((np.where(ok, c0, 0), np.where(ok, -p * c0, 0), np.where(ok, -q * c0, 0), ok))
        return out

    def apply(self, f, kernels, var=None, radii=None):
        """Each radius's fit of ``f`` (and with ``var``, its variance): list of (F, V)."""
        radii = self.radii if radii is None else radii
        m = self.mask.astype(np.float64)
        X, Y = self.X, self.Y
        fm = np.where(self.mask, f, 0) * m
        p = self.passes
        Sf = {"f": fm, "xf": fm * X, "yf": fm * Y}
        if var is not None:
            vm = np.where(self.mask, var, 0)
            Sv = {k: vm * w for k, w in dict(v=1, xv=X, yv=Y, xxv=X * X, xyv=X * Y, yyv=Y * Y).items()}
        out = []
        for R, (c0, c1, c2, ok) in zip(radii, kernels):
            sf, sxf, syf = wbox(Sf["f"], R, p), wbox(Sf["xf"], R, p), wbox(Sf["yf"], R, p)
            suf, svf = sxf - X * sf, syf - Y * sf
            F = np.where(ok, c0 * sf + c1 * suf + c2 * svf, np.nan)
            V = None
            if var is not None:
                # the variance needs the squared weights: for a tent (passes 2) their sums are no box of
                # a box; only the box's variance is written here
                if p != 1:
                    raise NotImplementedError("the variance of tent-weighted fits")
                sv_, sxv, syv = (wbox(Sv[k], R, 1) for k in ("v", "xv", "yv"))
                sxxv, sxyv, syyv = (wbox(Sv[k], R, 1) for k in ("xxv", "xyv", "yyv"))
                su_, svv_ = sxv - X * sv_, syv - Y * sv_
                suu = sxxv - 2 * X * sxv + X * X * sv_
                suv = sxyv - X * syv - Y * sxv + X * Y * sv_
                svv2 = syyv - 2 * Y * syv + Y * Y * sv_
                V = (c0 * c0 * sv_ + 2 * c0 * c1 * su_ + 2 * c0 * c2 * svv_ + c1 * c1 * suu + 2 * c1 * c2 * suv
                     + c2 * c2 * svv2)
                V = np.where(ok, np.maximum(V, 0), np.inf)
            out.append((F, V))
        return out


def oracle(ao, se, mask, guide, ref, radii=(2, 4, 8, 16), order=1, fine=True, verbose=True):
    """Box fits' candidates (and today's filter's, with ``fine``), chosen per texel by the true MSE
    (true bias: the fit of the reference): the best any estimate of the MSE could do."""
    from bench.prototypes.multiscale import fine_candidates

    mask = mask & guide.covered
    island = np.where(mask, guide.island, -1)
    bf = BoxFit(mask, island, radii, order)
    K = bf.kernels()
    var = np.where(mask, se.astype(np.float64) ** 2, 0)
    cands = [(ao.astype(np.float64), var, np.zeros(ao.shape), "raw")]
    if fine:
        for (F, V, _), b in zip(fine_candidates(ao, se, mask, guide), (1.25, 2.5)):
            T = fine_candidates(ref["ao"], se, mask, guide, bandwidths=(b,))[0][0]  # not exact: weights move
            cands.append((F, V, T - ref["ao"], f"fine {b}"))
    fits = bf.apply(ao.astype(np.float64), K, var)
    tru = bf.apply(ref["ao"].astype(np.float64), K)
    for R, (F, V), (T, _) in zip(radii, fits, tru):
        B = T - ref["ao"]
        cands.append((F, V, np.where(np.isfinite(B), B, np.inf), f"box{order} {R}"))
        if verbose:
            ok = np.isfinite(F) & mask
            e = F - ref["ao"]
            print(f"R {R}: usable {ok.mean() / mask.mean():.2f} rmse {np.sqrt(np.mean(e[ok] ** 2)):.4f} "
                  f"sd {np.sqrt(np.mean(V[ok])):.4f} bias {np.sqrt(np.mean(B[ok] ** 2)):.4f} "
                  f"z {np.std(e[ok] / np.sqrt(V[ok] + B[ok] ** 2 + ref['stderr'][ok].astype(float) ** 2)):.3f}")
    best = np.full(ao.shape, np.inf)
    out = ao.astype(np.float64).copy()
    choice = np.zeros(ao.shape, int)
    for k, (F, V, B, _) in enumerate(cands):
        mse = V + B * B
        take = np.isfinite(mse) & (mse < best)
        best = np.where(take, mse, best)
        out = np.where(take, F, out)
        choice[take] = k
    if verbose:
        print("oracle choice", dict(zip([c[3] for c in cands], np.bincount(choice[mask], minlength=len(cands)))))
    return np.clip(out, 0, 1), np.sqrt(best), cands, bf




def boxfit_denoise(ao, se, mask, guide, radii=(2, 4, 8, 16), order=1, fine=True, bias_scale=1.0, verbose=False):
    """The box fits (bias by double smoothing: the fit of the fit) with today's candidates and the raw
    value, chosen per texel by the least V + B^2."""
    from bench.prototypes.multiscale import fine_candidates
    from core.post import denoise as D
    from core.post.denoise import filter as DF

    mask = mask & guide.covered
    island = np.where(mask, guide.island, -1)
    y = np.where(mask, ao, 0).astype(np.float64)
    var = np.where(mask, se.astype(np.float64) ** 2, 0)
    F0 = DF._Features(guide, mask, D.RADIUS)
    var = DF._trusted_zeros(F0, var.astype(np.float32)).astype(np.float64)
    exact = var == 0
    cands = [(y, var, np.zeros_like(y), "raw")]
    if fine:
        for (F, V, B), b in zip(fine_candidates(ao, se, mask, guide), (1.25, 2.5)):
            cands.append((F, V, B, f"fine {b}"))
    bf = BoxFit(mask, island, radii, order)
    K = bf.kernels()
    fits = bf.apply(y, K, var)
    for R, k, (F, V) in zip(radii, K, fits):
        SF = bf.apply(np.where(np.isfinite(F), F, y), [k], radii=[R])[0][0]
        B = bias_scale * (SF - F)
        cands.append((F, V, np.where(np.isfinite(B), B, np.inf), f"box{order} {R}"))
    out, vo, bo, choice = select(cands, exact)
    if verbose:
        print("choice", dict(zip([c[3] for c in cands], np.bincount(choice[mask], minlength=len(cands)))))
    out = np.where(mask, np.clip(out, 0, 1), ao)
    return out.astype(np.float32), np.where(mask, np.sqrt(vo + bo * bo), 0).astype(np.float32)


def lepski(cands, kappa=2.0, exact=None, report="diff"):
    """Lepski's rule over candidates ordered from the least smoothing (raw) to the most: each texel
    takes the widest candidate k with |F_k - F_j| <= kappa sqrt(V_j - V_k) for every finer j (nested
    estimators: Var(F_j - F_k) = V_j - V_k, exact for first-order fits in nested windows with a
    constant sigma). The reported bias: per ``report``."""
    F0, V0 = cands[0][0], cands[0][1]
    out, vo = np.array(F0, np.float64), np.array(V0, np.float64)
    bo = np.zeros_like(out)
    alive = np.ones(out.shape, bool) if exact is None else ~exact
    choice = np.zeros(out.shape, int)
    for k in range(1, len(cands)):
        Fk, Vk = cands[k][0], cands[k][1]
        ok = alive & np.isfinite(Fk) & np.isfinite(Vk)
        worst = np.zeros_like(out)
        for j in range(k):
            Fj, Vj = cands[j][0], cands[j][1]
            dv = np.maximum(Vj - Vk, 0)
            d = np.where(np.isfinite(Fj), Fk - Fj, 0)
            ok &= ~np.isfinite(Fj) | (np.abs(d) <= kappa * np.sqrt(dv))
            worst = np.maximum(worst, np.where(np.isfinite(Fj), np.maximum(d * d - dv, 0), 0))
        out = np.where(ok, Fk, out)
        vo = np.where(ok, Vk, vo)
        bo = np.where(ok, np.sqrt(worst) if report == "diff" else 0, bo)
        choice[ok] = k
        alive &= ok
    return out, vo, bo, choice


def boxfit_lepski(ao, se, mask, guide, radii=(2, 4, 8, 16), kappa=2.0, fine=True, report="diff", verbose=False):
    from bench.prototypes.multiscale import fine_candidates
    from core.post import denoise as D
    from core.post.denoise import filter as DF

    mask = mask & guide.covered
    island = np.where(mask, guide.island, -1)
    y = np.where(mask, ao, 0).astype(np.float64)
    var = np.where(mask, se.astype(np.float64) ** 2, 0)
    F0 = DF._Features(guide, mask, D.RADIUS)
    var = DF._trusted_zeros(F0, var.astype(np.float32)).astype(np.float64)
    exact = var == 0
    cands = [(y, var, np.zeros_like(y), "raw")]
    if fine:
        for (F, V, B), b in zip(fine_candidates(ao, se, mask, guide), (1.25, 2.5)):
            cands.append((F, V, B, f"fine {b}"))
    bf = BoxFit(mask, island, radii, 1)
    K = bf.kernels()
    for R, (F, V) in zip(radii, bf.apply(y, K, var)):
        cands.append((F, V, None, f"box {R}"))
    out, vo, bo, choice = lepski(cands, kappa, exact, report)
    if verbose:
        print("choice", dict(zip([c[3] for c in cands], np.bincount(choice[mask], minlength=len(cands)))))
    out = np.where(mask, np.clip(out, 0, 1), ao)
    return out.astype(np.float32), np.where(mask, np.sqrt(vo + bo * bo), 0).astype(np.float32)


def pilot_bias_denoise(ao, se, mask, guide, radii=(3, 6, 12), rho_scale=0.5, debias=True, verbose=False,
                       min_rho=2, smooth_what="square", report_raw=False, iterations=1, debias_scale=1.0,
                       pilot="today", with_ds=False, add_pilot_bias=False, spread=None, fine_bandwidths=(1.25, 2.5),
                       fine_radius=3, fine="today"):
    """Box fits whose bias is the fit of today's denoised map (a pilot with its detail) less the pilot,
    its square debiased by the pilot's variance and averaged over a window of radius rho_scale R."""
    from bench.prototypes.multiscale import fine_all

    mask = mask & guide.covered
    island = np.where(mask, guide.island, -1)
    if fine == "today":
        fc, var, exact, _ = fine_all(ao, se, mask, guide, bandwidths=fine_bandwidths, radius=fine_radius)
    else:
        from bench.prototypes.atrous import atrous_fine
        fc, var, exact, _ = atrous_fine(ao, se, mask, guide, levels=fine)
        fine_bandwidths = [f"a{lev + 1}" for lev in range(fine)]
    y = np.where(mask, ao, 0).astype(np.float64)
    cands = [(y, var, np.zeros_like(y), "raw")]
    for (F, V, B, L), b in zip(fc, fine_bandwidths):
        cands.append((F, V, B, f"fine {b}"))
    # the pilot: today's choice among these
    P, VP, BP, _ = select(cands, exact)
    BP = np.where(np.isfinite(BP), BP, 0)
    if pilot == "fine":
        P, VP = fc[0][0], fc[0][1]
    fine_cands = list(cands)
    bf = BoxFit(mask, island, radii, 1)
    K = bf.kernels()
    fits = bf.apply(y, K, var)
    if spread is not None:
        # the window's normals: 1 - |mean normal| (0 on a plane); a wide fit only where the surface is flat
        nS = [sat(np.where(mask, guide.normal[..., k], 0).astype(np.float64)) for k in range(3)]
        nN = sat(mask.astype(np.float64))
        flat = []
        for R in radii:
            n = box(nN, R)
            res = np.sqrt(sum(box(S_, R) ** 2 for S_ in nS)) / np.maximum(n, 1)
            flat.append((1 - res) <= spread)
        fits = [(np.where(fl, F, np.nan), V) for fl, (F, V) in zip(flat, fits)]
    for it in range(iterations):
        pf = bf.apply(P, K)
        cands = list(fine_cands)
        reports = [c[2] for c in cands]
        for R, (F, V), (LP, _) in zip(radii, fits, pf):
            b = LP - P + (BP if add_pilot_bias else 0)
            ok = np.isfinite(b) & mask
            rho = (max(min_rho, int(round(rho_scale * R))) if np.isscalar(R) else
                   tuple(max(1, int(round(rho_scale * r))) for r in R))
            if smooth_what == "square":
                sq = np.where(ok, b * b - (debias_scale * VP if debias else 0), 0)
                B2 = np.maximum(smooth(sq, ok, rho), 0)
                Braw = np.sqrt(np.maximum(smooth(np.where(ok, b * b, 0), ok, rho), 0))
            else:
                B2 = np.maximum(smooth(np.where(ok, b, 0), ok, rho) ** 2, 0)
                Braw = np.sqrt(B2)
            B = np.where(ok, np.sqrt(B2), np.inf)
            if with_ds:
                SF = bf.apply(np.where(np.isfinite(F), F, y), [K[radii.index(R)]], radii=[R])[0][0]
                B = np.maximum(B, np.abs(SF - F))
            cands.append((F, V, B, f"box {R}"))
            reports.append(np.where(ok, Braw, np.inf))
        out, vo, bo, choice = select(cands, exact)
        if report_raw:
            bo = np.choose(choice, [np.where(np.isfinite(r), r, 0) for r in reports])
        P, VP, BP = out, vo, np.where(np.isfinite(bo), bo, 0)
    if verbose:
        print("choice", dict(zip([c[3] for c in cands], np.bincount(choice[mask], minlength=len(cands)))))
    out = np.where(mask, np.clip(out, 0, 1), ao)
    return out.astype(np.float32), np.where(mask, np.sqrt(vo + bo * bo), 0).astype(np.float32)
