"""The denoiser's wide candidates: first-order fits over rectangles of one island, at a cost that does
not grow with their size.

Each wide candidate fits a plane, a + b u + c v (u, v texel offsets), by least squares to the texels
of one island inside a rectangle of the image around the texel (local-linear regression with a box
kernel; normalized convolution of first order with the coverage as certainty, Knutsson and Westin
1993). First order, so a rectangle cut by the island's border, or lying along a gradient, leaves no
bias from the gradient: the fit extrapolates it. Rectangles long along one image axis follow
structure that runs along it (walls, floors and corners unwrapped along the UV axes keep their AO
gradients across the long side).

Cost. The fit is linear in the map, with weights fixed by the coverage: its value at a texel is
sum_j l_j y_j with l_j = c0 + c1 u_j + c2 v_j, its variance sum_j l_j^2 sigma_j^2 (the texels'
errors are independent). Both come from sums over the rectangle of 1, x, y, xx, xy, yy times the
texel's coverage, value and variance. Those sums are taken over cells of 2 x 2 texels (4 x 4 for the
largest rectangles; from the 2 x 2 cells' moments), then over a rectangle of cells by running sums:
each candidate costs the same for any rectangle. A texel's rectangle is its cell's (aligned to cells,
so up to half a cell off the texel's centre); its cell's plane is evaluated at the texel.

Bias. A plane errs where the AO curves or changes within the rectangle, and that decides whether the
wide fit helps. It is estimated from the fine stage's result P (:func:`core.post.denoise.denoise`'s
own candidates, which keep detail at the scale of a few texels): the same fit applied to P, less P,
squared, less a share of P's variance (the noise of P that the difference keeps), averaged over the
rectangle. Double smoothing (the fit of the fit) misses detail finer than the rectangle; P has it.
The squared residuals need no pass over the texels: per cell they are sums of the plane's terms
against the cell's moments of P, P^2 and the coverage.

Where it is not used: texels whose rectangle holds texels of another island (a cell holds one island:
where two meet, the one with more texels there), and rectangles whose surface is not flat
(1 - |mean normal| above FLATNESS): AO on a curved or displaced surface varies with the geometry at
the scale of a texel, which a plane over tens of texels cannot follow and the fine result's detail
underrates. Seams are island borders here; the fine stage reaches across them.
"""

from concurrent.futures import ThreadPoolExecutor

import numpy as np

#: The rectangles of the wide candidates: half-widths in texels (along x, along y). Measured
#: (docs/denoise.md): these six do as well as twelve (squares 3 to 24, rectangles 1:6 and 1:4 both
#: ways) in the room and on Suzanne at 512^2.
SHAPES = ((6, 6), (2, 12), (12, 2), (12, 12), (4, 24), (24, 4))
#: The most 1 - |mean normal| over a rectangle for its fit to be a candidate (0 on a plane; 0.003
#: is a normal spread of about 4.4 degrees). Without it the wide fits took dense.blend's displaced
#: terrain (RMSE 0.0138 -> 0.0151 at 512^2).
FLATNESS = 0.003
#: Share of the fine result's variance taken from the squared difference before it is averaged:
#: E[(fit(P) - P)^2] = bias^2 + about var(P). Measured on the exact scenes and the bench's: 0.5
#: chooses well; 1 (unbiased for a lone texel) chooses the wide fits too often.
PILOT_DEBIAS = 0.5
#: Rows of 4 x 4 cells per band (bounds the working memory; bands go to threads and do not depend on
#: each other, so the result is the same bits for any number of threads).
BAND_CELLS = 64
#: The fewest texels a rectangle must hold for its fit to be a candidate.
MIN_TEXELS = 6


def cell_side(shape):
    """Side in texels of the cells a shape's sums are taken over: 2 up to a half-width of 12, else 4."""
    return 2 if max(shape) <= 12 else 4


def _window(c, r, axis):
    """From running sums ``c`` (n + 1 entries along ``axis``, 0 or 1, the first 0): the sums over index
    - r .. index + r clipped to the n entries, c[min(j + r + 1, n)] - c[max(j - r, 0)] for j < n.
    The inner entries by slices (a gather along the rows' axis costs several times a slice), each
    entry the same subtraction."""
    n = c.shape[axis] - 1
    if n <= 2 * r + 1:
        hi = np.minimum(np.arange(n) + r + 1, n)
        lo = np.maximum(np.arange(n) - r, 0)
        return c[hi] - c[lo] if axis == 0 else c[:, hi] - c[:, lo]

    def at(lo, hi):
        return (slice(lo, hi),) if axis == 0 else (slice(None), slice(lo, hi))

    out = np.empty((n, c.shape[1]) if axis == 0 else (c.shape[0], n))
    np.subtract(c[at(2 * r + 1, None)], c[at(0, n - 2 * r)], out=out[at(r, n - r)])  # j in [r, n - r)
    np.subtract(c[at(r + 1, 2 * r + 1)], c[at(0, 1)], out=out[at(0, r)])  # j < r: from the first entry
    np.subtract(c[at(n, None)], c[at(n - 2 * r, n - r)], out=out[at(n - r, None)])  # j >= n - r: to the last
    return out


def _run(a, r, axis):
    """Sums over index - r .. index + r (clipped to the array) along ``axis`` (0 or 1)."""
    n = a.shape[axis]
    c = np.zeros((n + 1, a.shape[1]) if axis == 0 else (a.shape[0], n + 1))
    np.cumsum(a, axis=axis, out=c[1:] if axis == 0 else c[:, 1:])
    return _window(c, r, axis)


def _rect(q, rx, ry, rows):
    """Sums over rectangles of (2 rx + 1) x (2 ry + 1) cells of every array of ``q`` (a dict), for the
    cell rows ``rows`` (a slice of q's rows, which must hold ry more rows either side where the map has
    them)."""
    return {k: _run(_run(a, rx, 1), ry, 0)[rows] for k, a in q.items()}


class _Rects:
    """:func:`_rect` of one dict of arrays for several rectangles: the running sums along rows are
    taken once, those along columns once per half-width along x."""

    def __init__(self, q):
        self.c = {}
        for k, a in q.items():
            c = np.zeros((a.shape[0], a.shape[1] + 1))
            np.cumsum(a, axis=1, out=c[:, 1:])
            self.c[k] = c
        self.w = next(iter(q.values())).shape[1]
        self.cols = {}

    def sums(self, rx, ry, rows):
        if rx not in self.cols:
            out = {}
            for k, c in self.c.items():
                a = _window(c, rx, 1)
                cc = np.zeros((a.shape[0] + 1, a.shape[1]))
                np.cumsum(a, axis=0, out=cc[1:])
                out[k] = cc
            self.cols[rx] = out
        idx = np.arange(rows.start, rows.stop)
        n = next(iter(self.c.values())).shape[0]
        hi = np.minimum(idx + ry + 1, n)
        lo = np.maximum(idx - ry, 0)
        return {k: cc[hi] - cc[lo] for k, cc in self.cols[rx].items()}


def _moments2(a):
    """Moments about the centres of 2 x 2 cells of (H, W) ``a`` (H, W even): sums of a, a u, a v, a uv
    (u, v = -1/2 or +1/2; a uu and a vv are a quarter of the sum)."""
    a00, a01, a10, a11 = a[0::2, 0::2], a[0::2, 1::2], a[1::2, 0::2], a[1::2, 1::2]
    s = a00 + a01 + a10 + a11
    u = 0.5 * ((a01 + a11) - (a00 + a10))
    v = 0.5 * ((a10 + a11) - (a00 + a01))
    uv = 0.25 * ((a00 + a11) - (a01 + a10))
    return s, u, v, uv


def _up(c):
    """Moments about 4 x 4 cells' centres from those of their 2 x 2 cells (a dict of (s, u, v, uu, uv,
    vv) lists, each (h, w) even): each small cell's moments shifted by its centre's offset (+-1)."""
    out = {}
    for k, (s, u, v, uu, uv, vv) in c.items():
        parts = []
        for dy, dx, sl in ((-1, -1, (slice(0, None, 2), slice(0, None, 2))), (-1, 1, (slice(0, None, 2), slice(1, None, 2))),
                           (1, -1, (slice(1, None, 2), slice(0, None, 2))), (1, 1, (slice(1, None, 2), slice(1, None, 2)))):
            S, U, V, UU, UV, VV = s[sl], u[sl], v[sl], uu[sl], uv[sl], vv[sl]
            parts.append((S, U + dx * S, V + dy * S, UU + 2 * dx * U + S, UV + dx * V + dy * U + dx * dy * S,
                          VV + 2 * dy * V + S))
        out[k] = [sum(p[i] for p in parts) for i in range(6)]
    return out


class WideFits:
    """The wide candidates of one map: built once per map (coverage, islands, normals, values,
    variances, the fine result), then :meth:`bands` yields, band by band, the best wide candidate of
    each cell side per texel: (F, V, B^2).

    Arrays are (H, W); ``island`` -1 where not covered; ``pilot`` and ``pilot_var`` the fine stage's
    chosen value and its variance."""

    def __init__(self, y, var, mask, island, normal, pilot, pilot_var, shapes=SHAPES, flatness=FLATNESS,
                 debias=PILOT_DEBIAS):
        h, w = y.shape
        self.h, self.w = h, w
        self.shapes = tuple(tuple(int(r) for r in s) for s in shapes)
        self.flatness, self.debias = flatness, debias
        # Padded to multiples of 4 (uncovered).
        self.H, self.W = -(-h // 4) * 4, -(-w // 4) * 4
        pad = lambda a, v=0: np.pad(np.asarray(a), ((0, self.H - h), (0, self.W - w)), constant_values=v)  # noqa: E731
        mask = np.asarray(mask, bool)
        self.island = pad(np.where(mask, island, -1), -1).astype(np.int64)
        self.normal = [pad(np.where(mask, normal[..., k], 0).astype(np.float64)) for k in range(3)]
        self.y = pad(np.where(mask, y, 0).astype(np.float64))
        self.var = pad(np.where(mask, var, 0).astype(np.float64))
        self.pilot = pad(np.where(mask, pilot, 0).astype(np.float64))
        self.pilot_var = pad(np.where(mask, pilot_var, 0).astype(np.float64))

    # --- cells ---

    def _cells(self, rows):
        """The 2 x 2 cells of texel rows ``rows`` (a slice, even bounds): per cell its island (-1: none)
        and its members' moments about its centre, and the members (texel rows, W)."""
        isl = self.island[rows]
        blocks = [isl[0::2, 0::2], isl[0::2, 1::2], isl[1::2, 0::2], isl[1::2, 1::2]]
        hi = np.maximum.reduce(blocks)
        big = np.iinfo(np.int64).max
        lo = np.minimum.reduce([np.where(b >= 0, b, big) for b in blocks])
        n_hi = sum((b == hi).astype(np.int64) for b in blocks)
        n_lo = sum(((b >= 0) & (b == lo)).astype(np.int64) for b in blocks)
        own = np.where(n_hi >= n_lo, hi, lo)
        own = np.where(hi >= 0, own, -1)
        member = (isl >= 0) & (isl == np.repeat(np.repeat(own, 2, 0), 2, 1))
        m = member.astype(np.float64)
        quarter = lambda mom: (mom[0], mom[1], mom[2], 0.25 * mom[0], mom[3], 0.25 * mom[0])  # noqa: E731
        c = {"m": quarter(_moments2(m))}
        for name, a in (("f", self.y), ("v", self.var), ("p", self.pilot)):
            c[name] = quarter(_moments2(a[rows] * m))
        scal = {"nx": self.normal[0][rows] * m, "ny": self.normal[1][rows] * m, "nz": self.normal[2][rows] * m,
                "pp": self.pilot[rows] ** 2 * m, "w": self.pilot_var[rows] * m}
        s = {k: _moments2(a)[0] for k, a in scal.items()}
        return own, c, s, member

    def _cells4(self, own2, c2, s2):
        """4 x 4 cells from 2 x 2 ones: a 4 x 4 cell holds the 2 x 2 cells of its most common island (by
        texels); returns (own, moments, scalars, which 2 x 2 cells it holds)."""
        n2 = c2["m"][0]
        q = [(slice(0, None, 2), slice(0, None, 2)), (slice(0, None, 2), slice(1, None, 2)),
             (slice(1, None, 2), slice(0, None, 2)), (slice(1, None, 2), slice(1, None, 2))]
        # the island with the most texels among the four: compare each candidate's total
        cand = [own2[sl] for sl in q]
        tot = [sum(np.where(cand[j] == cand[i], n2[q[j]], 0.0) for j in range(4)) for i in range(4)]
        best = cand[0].copy()
        bt = np.where(cand[0] >= 0, tot[0], -1.0)
        for i in range(1, 4):
            better = (cand[i] >= 0) & (tot[i] > bt)
            best = np.where(better, cand[i], best)
            bt = np.where(better, tot[i], bt)
        keep2 = (own2 >= 0) & (own2 == np.repeat(np.repeat(best, 2, 0), 2, 1))
        k2 = keep2.astype(np.float64)
        c = _up({k: [a * k2 for a in mom] for k, mom in c2.items()})
        s = {k: sum((a * k2)[sl] for sl in q) for k, a in s2.items()}
        return np.where(c["m"][0] > 0, best, -1), c, s, keep2

    # --- fits ---

    @staticmethod
    def _sums(own, c, s, side, first):
        """The cells' sums about the map's origin (from their moments about the cells' centres), for
        :class:`_Rects`: coverage, position and second moments, island and its square, normals, value,
        variance, fine result."""
        hc, wc = own.shape
        Xc = (np.arange(wc, dtype=np.float64) + 0.5) * side
        Yc = (np.arange(first, first + hc, dtype=np.float64) + 0.5)[:, None] * side

        def glob(mom, full=True):
            S, U, V, UU, UV, VV = mom
            g = (S, U + Xc * S, V + Yc * S)
            if full:
                g += (UU + 2 * Xc * U + Xc * Xc * S, UV + Xc * V + Yc * U + Xc * Yc * S, VV + 2 * Yc * V + Yc * Yc * S)
            return g

        gm, gv = glob(c["m"]), glob(c["v"])
        gf, gp = glob(c["f"], False), glob(c["p"], False)
        isl = np.where(own >= 0, own, 0).astype(np.float64)
        return {"n": gm[0], "x": gm[1], "y": gm[2], "xx": gm[3], "xy": gm[4], "yy": gm[5],
                "i": isl * gm[0], "ii": isl * isl * gm[0], "nx": s["nx"], "ny": s["ny"], "nz": s["nz"],
                "f": gf[0], "xf": gf[1], "yf": gf[2], "v": gv[0], "xv": gv[1], "yv": gv[2], "xxv": gv[3],
                "xyv": gv[4], "yyv": gv[5], "p": gp[0], "xp": gp[1], "yp": gp[2]}

    def _fits(self, own, rects, shape, side, rows, first):
        """Per cell of ``rows`` (a slice of the cell arrays; ``first`` the arrays' first cell row in the
        map; ``rects`` their :class:`_Rects`): the plane of the map (a, b, c) about the cell's centre,
        that of the fine result, the map's plane's covariance C (00 01 02 11 12 22) and whether the
        fit is a candidate."""
        rx, ry = shape[0] // side, shape[1] // side
        wc = own.shape[1]
        R = rects.sums(rx, ry, rows)
        X0 = (np.arange(wc, dtype=np.float64) + 0.5) * side
        Y0 = (np.arange(first + rows.start, first + rows.stop, dtype=np.float64) + 0.5)[:, None] * side
        n = R["n"]
        su, sv = R["x"] - n * X0, R["y"] - n * Y0
        suu = R["xx"] - 2 * X0 * R["x"] + n * X0 * X0
        suv = R["xy"] - X0 * R["y"] - Y0 * R["x"] + n * X0 * Y0
        svv = R["yy"] - 2 * Y0 * R["y"] + n * Y0 * Y0
        # A = M^-1 of M = [[n, su, sv], [su, suu, suv], [sv, suv, svv]] by cofactors.
        c00 = suu * svv - suv * suv
        c01 = sv * suv - su * svv
        c02 = su * suv - sv * suu
        c11 = n * svv - sv * sv
        c12 = su * sv - n * suv
        c22 = n * suu - su * su
        det = n * c00 + su * c01 + sv * c02
        k = own[rows].astype(np.float64)
        spread = R["ii"] - 2 * k * R["i"] + k * k * n
        resultant = np.sqrt(R["nx"] ** 2 + R["ny"] ** 2 + R["nz"] ** 2)
        # (texels on one line leave det 0, or a rounding's worth above it: then the plane's variance
        # is huge and it is never chosen)
        ok = ((own[rows] >= 0) & (np.abs(spread) < 0.5) & (n >= MIN_TEXELS) & (det > 0)
              & (1.0 - resultant / np.maximum(n, 1) <= self.flatness))
        with np.errstate(invalid="ignore", divide="ignore"):
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        A = (c00 * inv, c01 * inv, c02 * inv, c11 * inv, c12 * inv, c22 * inv)

        def solve(b0, b1, b2):
            return (A[0] * b0 + A[1] * b1 + A[2] * b2, A[1] * b0 + A[3] * b1 + A[4] * b2,
                    A[2] * b0 + A[4] * b1 + A[5] * b2)

        plane = solve(R["f"], R["xf"] - X0 * R["f"], R["yf"] - Y0 * R["f"])
        pplane = solve(R["p"], R["xp"] - X0 * R["p"], R["yp"] - Y0 * R["p"])
        # C = A Q A with Q = sum sigma^2 (1, u, v)(1, u, v)^T
        v0 = R["v"]
        vu, vv = R["xv"] - X0 * v0, R["yv"] - Y0 * v0
        vuu = R["xxv"] - 2 * X0 * R["xv"] + X0 * X0 * v0
        vuv = R["xyv"] - X0 * R["yv"] - Y0 * R["xv"] + X0 * Y0 * v0
        vvv = R["yyv"] - 2 * Y0 * R["yv"] + Y0 * Y0 * v0
        Q = ((v0, vu, vv), (vu, vuu, vuv), (vv, vuv, vvv))
        Am = ((A[0], A[1], A[2]), (A[1], A[3], A[4]), (A[2], A[4], A[5]))
        AQ = [[Am[i][0] * Q[0][j] + Am[i][1] * Q[1][j] + Am[i][2] * Q[2][j] for j in range(3)] for i in range(3)]
        C = tuple(AQ[i][0] * Am[0][j] + AQ[i][1] * Am[1][j] + AQ[i][2] * Am[2][j]
                  for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
        return plane, pplane, C, ok

    def _bias2(self, c, s, pplane, ok, shape, side, rows, cols_rows):
        """Squared bias per cell of ``rows`` (a slice of the pplane/ok arrays' rows, which hold ry more
        rows either side where the map has them): the fine result's squared residual from its plane at
        every member texel, less a share of its variance, averaged over the rectangle.

        ``cols_rows``: the rows of the cell arrays ``c``, ``s`` that pplane's rows are."""
        rx, ry = shape[0] // side, shape[1] // side
        a, b, cc = pplane
        n, nu, nv, nuu, nuv, nvv = (x[cols_rows] for x in c["m"])
        p, pu, pv = (x[cols_rows] for x in c["p"][:3])
        pp, w = s["pp"][cols_rows], s["w"][cols_rows]
        # sum over the cell's members of (a + b u + c v - P)^2 - debias var(P)
        lp2 = (a * a * n + 2 * a * b * nu + 2 * a * cc * nv + b * b * nuu + 2 * b * cc * nuv + cc * cc * nvv)
        lpp = a * p + b * pu + cc * pv
        q = np.where(ok, lp2 - 2 * lpp + pp - self.debias * w, 0.0)
        cnt = np.where(ok, n, 0.0)
        S = _rect({"q": q, "n": cnt}, rx, ry, rows)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.maximum(np.where(S["n"] > 0, S["q"] / np.maximum(S["n"], 1), 0.0), 0.0)

    def _band(self, c0, c1):
        """The texels of 4 x 4 cell rows [c0, c1) (texel rows [4 c0, 4 c1)): per cell side (2, then 4)
        the best wide candidate of its shapes per texel, (F, V, B^2) each (texel rows, W), F NaN where
        none."""
        sides = sorted({cell_side(sh) for sh in self.shapes})
        reach = {sd: max([sh[1] // sd for sh in self.shapes if cell_side(sh) == sd], default=0) for sd in sides}
        # Texel rows of the band and 2 ry rows of cells either side (the bias averages planes that reach ry).
        halo = max([2 * reach[sd] * sd for sd in sides], default=0)
        halo = -(-halo // 4) * 4
        t0, t1 = max(c0 * 4 - halo, 0), min(c1 * 4 + halo, self.H)
        own2, c2, s2, member2 = self._cells(slice(t0, t1))
        out = []
        for sd in sides:
            if sd == 2:
                own, c, s, member = own2, c2, s2, member2
            else:
                # 4 x 4 cells from the 2 x 2 ones (t0 is a multiple of 4)
                own, c, s, keep2 = self._cells4(own2, c2, s2)
                member = member2 & np.repeat(np.repeat(keep2, 2, 0), 2, 1)
            first = t0 // sd
            hc = own.shape[0]
            b0, b1 = c0 * 4 // sd - first, c1 * 4 // sd - first  # the band's cell rows in these arrays
            ry = reach[sd]
            e1 = slice(max(b0 - ry, 0), min(b1 + ry, hc))  # rows whose planes the band's bias averages
            best = None
            rects = _Rects(self._sums(own, c, s, sd, first))
            for shape in (sh for sh in self.shapes if cell_side(sh) == sd):
                plane, pplane, C, ok = self._fits(own, rects, shape, sd, e1, first)
                B2 = self._bias2(c, s, pplane, ok, shape, sd, slice(b0 - e1.start, b1 - e1.start), e1)
                sel = slice(b0 - e1.start, b1 - e1.start)
                plane = tuple(x[sel] for x in plane)
                C = tuple(x[sel] for x in C)
                okb = ok[sel]
                # the cell's mean squared error over its four (or sixteen) positions, to choose a shape
                cn = c["m"][0][b0:b1]
                with np.errstate(invalid="ignore", divide="ignore"):
                    mean_v = C[0] + (C[3] * c["m"][3][b0:b1] + C[5] * c["m"][5][b0:b1] + 2 * C[4] * c["m"][4][b0:b1]
                                     + 2 * C[1] * c["m"][1][b0:b1] + 2 * C[2] * c["m"][2][b0:b1]) / np.maximum(cn, 1)
                mse = np.where(okb, mean_v + B2, np.inf)
                if best is None:
                    best = [mse, plane, C, B2, okb]
                else:
                    take = mse < best[0]
                    best[0] = np.where(take, mse, best[0])
                    best[1] = tuple(np.where(take, x, y) for x, y in zip(plane, best[1]))
                    best[2] = tuple(np.where(take, x, y) for x, y in zip(C, best[2]))
                    best[3] = np.where(take, B2, best[3])
                    best[4] = best[4] | okb
            _, plane, C, B2, okb = best
            nb, nc = b1 - b0, own.shape[1]
            du = np.arange(sd, dtype=np.float64) - (sd - 1) / 2.0
            DU, DV = du[None, None, None, :], du[None, :, None, None]
            pick = lambda a: a[:, None, :, None]  # noqa: E731
            F = pick(plane[0]) + pick(plane[1]) * DU + pick(plane[2]) * DV
            V = (pick(C[0]) + 2 * pick(C[1]) * DU + 2 * pick(C[2]) * DV + pick(C[3]) * DU * DU
                 + 2 * pick(C[4]) * DU * DV + pick(C[5]) * DV * DV)
            tb = slice(c0 * 4 - t0, c1 * 4 - t0)
            mb = member[tb].reshape(nb, sd, nc, sd)
            use = pick(okb) & mb
            hb = nb * sd
            out.append((np.where(use, F, np.nan).reshape(hb, self.W), np.where(use, np.maximum(V, 0.0), np.inf)
                        .reshape(hb, self.W), np.broadcast_to(pick(B2), F.shape).reshape(hb, self.W)))
        return out

    def bands(self, threads=1):
        """Yields (texel rows, [(F, V, B^2) per cell side]) band by band, in order (rows of the padded
        map; the caller keeps the first H)."""
        n4 = self.H // 4
        starts = list(range(0, n4, BAND_CELLS))
        work = lambda c0: self._band(c0, min(c0 + BAND_CELLS, n4))  # noqa: E731
        if threads > 1 and len(starts) > 1:
            with ThreadPoolExecutor(threads) as pool:
                for c0, res in zip(starts, pool.map(work, starts)):
                    yield slice(c0 * 4, min(c0 + BAND_CELLS, n4) * 4), res
        else:
            for c0 in starts:
                yield slice(c0 * 4, min(c0 + BAND_CELLS, n4) * 4), work(c0)


def groups(shapes):
    """The shapes by cell side (2, then 4): the wide candidates a texel's choice names."""
    sides = sorted({cell_side(sh) for sh in shapes})
    return tuple(tuple(sh for sh in shapes if cell_side(sh) == sd) for sd in sides)


def choose_wide(best, out, varo, bias2, choice, exact, mask, fits, first_choice, threads=1):
    """Update a selection (least V + B^2 so far: ``best``, its value ``out``, variance ``varo``, squared
    bias ``bias2``, ``choice``; all (H, W), changed in place) with the wide candidates of ``fits``
    (:class:`WideFits`): the best of the cell side 2 is choice ``first_choice``, of side 4
    ``first_choice + 1``. Exact texels keep theirs."""
    h, w = best.shape
    keep = mask & ~exact
    for rows, cands in fits.bands(threads):
        r = slice(rows.start, min(rows.stop, h))
        n = r.stop - r.start
        if n <= 0:
            continue
        for k, (F, V, B2) in enumerate(cands):
            F, V, B2 = F[:n, :w], V[:n, :w], B2[:n, :w]
            mse = V + B2
            take = keep[r] & np.isfinite(F) & (mse < best[r])
            best[r] = np.where(take, mse, best[r])
            out[r] = np.where(take, F, out[r])
            varo[r] = np.where(take, V, varo[r])
            bias2[r] = np.where(take, B2, bias2[r])
            choice[r] = np.where(take, first_choice + k, choice[r])


__all__ = ["SHAPES", "FLATNESS", "PILOT_DEBIAS", "WideFits", "choose_wide", "cell_side", "groups"]
