"""The denoiser's filter: candidate filters over the surface, each texel weighed by its error, and per texel
the candidate of least estimated error (its noise and bias)."""

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from .guide import RADIUS
from .wide import SHAPES, WideFits, choose_wide, groups


#: Candidate bandwidths, in texels of world size (the raw value is a candidate too). A third between
#: them (1.77) changed neither RMSE nor z on the exact scenes and Suzanne, and cost a third more.
BANDWIDTHS = (1.25, 2.5)
#: Normal similarity: weight exp(-NORMAL_SHARPNESS (1 - n_i . n_j)).
NORMAL_SHARPNESS = 40.0
#: The AO term's scale kappa, in standard deviations of the pilot's difference, and how far (in units
#: of d^2 / (2 kappa^2 var)) it stays flat: the weight is 1 for differences within 2 sqrt(3) = 3.5
#: standard deviations, so noise alone hardly changes it (weights that follow the noise would make
#: the propagated variance too small), and falls off beyond, at a step such as a contact shadow.
RANGE_SIGMAS = 2.0
RANGE_FLAT = 3.0
#: Bandwidth (texels) of the pilot whose differences the AO term compares: narrow, so steps stay steep.
PILOT_BANDWIDTH = 1.0
#: Its window radius: 3 x 3 (weights 0.61 beside, 0.37 diagonally; 5 x 5 was dearer and no better:
#: RMSE on the exact scenes 0.0132 and 0.0106 against 0.0127 and 0.0105).
PILOT_RADIUS = 1
#: Factor on the double-smoothing bias estimate. S (S y) - S y is exact for a Gaussian kernel on a
#: locally quadratic AO; where edge-stopping weights and the window cut the kernel it may fall short.
#: Measured (z sd on the exact scenes at 64^2, 16 samples, six seeds; box on a plane, polygon over a
#: plane): window radius 3, factor 1: 1.00 and 0.98 (Suzanne at 256^2 against a 1024-sample
#: reference: 1.02-1.04); 1.25: 0.95 and 0.95; 1.5: 0.91 and 0.92. With radius 4 (a Gaussian of
#: 2.5 texels cut less) factor 1 fell short, 1.09 and 1.10, and took 1.5. No factor is needed here.
BIAS_SCALE = 1.0
#: Rows per band of the filter: bounds its working memory and orders its float32 additions (a
#: constant, so that the result is the same bits for any number of threads).
BAND_ROWS = 64
#: Columns without a covered texel that split a band into ranges filtered apart (at least
#: 2 radius + 1, see :meth:`_Features.segments`): the empty columns between islands are skipped,
#: and narrower gaps are not worth the calls of one more range.
SEGMENT_GAP = 16


@dataclass
class DenoiseInfo:
    """What :func:`denoise` chose: ``choice`` (H, W) int8, the candidate each texel took (0: its raw
    value; k <= len(bandwidths): bandwidth ``bandwidths[k - 1]``; beyond, a wide fit over one of the
    rectangles ``shapes[k - 1 - len(bandwidths)]``, a group of :mod:`.wide`'s shapes); ``variance``
    and ``bias`` (H, W) float32, the parts of the reported error (stderr^2 = variance + bias^2)."""

    choice: np.ndarray
    variance: np.ndarray
    bias: np.ndarray
    bandwidths: tuple
    shapes: tuple = ()


class _Features:
    """The guide's per-texel features padded by the window radius, float32, one array per component;
    texels outside ``mask`` are off every island."""

    def __init__(self, guide, mask, r, image=False):
        pad = lambda a, v=0: np.pad(a, r, constant_values=v)  # noqa: E731
        self.r, self.h, self.w = r, guide.height, guide.width
        self.island = pad(np.where(mask, guide.island, -1).astype(np.int32), -1)
        self.p = [pad(guide.position[..., c].astype(np.float32)) for c in range(3)]
        self.n = [pad(guide.normal[..., c].astype(np.float32)) for c in range(3)]
        s64 = guide.scale.astype(np.float64)
        self.inv_s2 = pad(np.where(s64 > 0, 1.0 / np.maximum(s64, 1e-150) ** 2, 0.0).astype(np.float32))
        if image:  # the broken filter of the tests: image positions, one island, flat normals
            H, W = self.island.shape
            self.island = np.where(self.island >= 0, 0, -1).astype(np.int32)
            Y, X = np.mgrid[0:H, 0:W].astype(np.float32)
            self.p = [X, Y, np.zeros_like(X)]
            self.n = [np.zeros_like(X), np.zeros_like(X), np.ones_like(X)]
            self.inv_s2 = np.ones_like(X)

    def band(self, rows, dy, dx, cols=None):
        """(centre, neighbour) slices of the padded arrays for the band ``rows`` (its columns ``cols``,
        default all) and offset (dy, dx)."""
        r = self.r
        a, b = (0, self.w) if cols is None else cols
        c = (slice(rows.start + r, rows.stop + r), slice(r + a, r + b))
        o = (slice(rows.start + r + dy, rows.stop + r + dy), slice(r + a + dx, r + b + dx))
        return c, o

    def segments(self, rad):
        """Per band of :data:`BAND_ROWS` rows, the column ranges [a, b) that hold its covered texels:
        runs of columns with a covered texel in the band's rows, joined across gaps of fewer than
        ``max(2 rad + 1, SEGMENT_GAP)`` columns. A pair of texels counts only when both are covered,
        so the band's pairs all have their centre in a range, and with gaps of 2 rad + 1 or more no
        texel is within ``rad`` columns of two ranges: filtering each range alone adds the same
        terms to every texel in the same order as filtering the whole band (the same bits)."""
        h, w, r = self.h, self.w, self.r
        cov = self.island[r:r + h, r:r + w] >= 0
        starts = np.arange(0, h, BAND_ROWS)
        any_col = np.logical_or.reduceat(cov, starts, axis=0) if h else np.zeros((0, w), bool)
        gap = max(2 * rad + 1, SEGMENT_GAP)
        out = []
        for row in any_col:
            cols = np.flatnonzero(row)
            if not len(cols):
                out.append([])
                continue
            cut = np.flatnonzero(np.diff(cols) > gap) + 1
            lo = cols[np.concatenate([[0], cut])]
            hi = cols[np.concatenate([cut - 1, [len(cols) - 1]])] + 1
            out.append(list(zip(lo.tolist(), hi.tolist())))
        return out

    def direct(self, c, o):
        """Neighbours in the image window: on the centre's island, squared surface distance (in
        texels, the mean of both texels' squared inverse sizes) and normals' cosine; all symmetric in the pair."""
        valid = (self.island[o] == self.island[c]) & (self.island[c] >= 0)
        d2 = np.zeros(valid.shape, np.float32)
        for k in range(3):
            t = self.p[k][o] - self.p[k][c]
            d2 += t * t
        d2 *= self.inv_s2[c] + self.inv_s2[o]  # symmetric: the mean of both texels' scales, times 2
        d2 *= np.float32(0.5)
        dot = self.n[0][o] * self.n[0][c] + self.n[1][o] * self.n[1][c] + self.n[2][o] * self.n[2][c]
        return valid, d2, dot

    def pairs(self, rec, src):
        """The same for halo pairs (flat indices of the unpadded image): squared distance, cosine."""
        w, r = self.w, self.r
        wp = w + 2 * r
        ci = (rec // w + r) * wp + rec % w + r
        oi = (src // w + r) * wp + src % w + r
        d2 = np.zeros(len(rec), np.float32)
        for k in range(3):
            a = self.p[k].reshape(-1)
            t = np.take(a, oi) - np.take(a, ci)
            d2 += t * t
        d2 *= np.take(self.inv_s2.reshape(-1), ci)
        dot = sum(np.take(self.n[k].reshape(-1), oi) * np.take(self.n[k].reshape(-1), ci) for k in range(3))
        return d2, dot


def _offsets(r):
    return [(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)]


def _halo_pairs(guide, mask, r, F):
    """The halo entries that stand in for a texel's neighbours in its window (the receiver on the
    halo's island, both covered), every window offset at once, sorted by receiver (offsets in window
    order within one): (receiver flat index, source flat index, squared distance, cosine, Chebyshev
    length of the offset)."""
    h, w = guide.height, guide.width
    keep = mask.reshape(-1)[guide.halo_source]
    ty, tx = guide.halo_row[keep], guide.halo_col[keep]
    hisl, hsrc = guide.halo_island[keep], guide.halo_source[keep]
    # The islands padded by 2 r (-1 beyond the image): halo texels lie up to r beyond it, their
    # receivers up to r further, and every lookup stays inside without a bounds test.
    p = 2 * r
    wp = w + 2 * p
    isl = np.pad(np.where(mask, guide.island, -1).astype(np.int32), p, constant_values=-1).reshape(-1)
    at = (ty + p) * wp + (tx + p)
    recs, srcs, lens = [], [], []
    for dy, dx in _offsets(r):
        ok = np.flatnonzero(isl[at - (dy * wp + dx)] == hisl)
        recs.append((ty[ok] - dy) * w + (tx[ok] - dx))
        srcs.append(hsrc[ok])
        lens.append(np.full(len(ok), max(abs(dy), abs(dx)), np.int8))
    rec, src, cheb = np.concatenate(recs), np.concatenate(srcs), np.concatenate(lens)
    order = np.argsort(rec, kind="stable")
    rec, src, cheb = rec[order], src[order], cheb[order]
    return (rec, src) + F.pairs(rec, src) + (cheb,)


def _accumulate(acc, g, x, here, there, c, o, tmp, mirrored):
    """One offset's weights ``g`` of the texel pairs (c, o) into a band's sums: ``acc[here] += g``, or
    ``g * x[o]`` where a plane ``x`` is gathered; with ``mirrored`` (an offset other than zero) the
    pair's other texel too, ``acc[there] += g`` (or ``g * x[c]``). ``tmp`` takes the products."""
    if x is None:
        acc[here] += g
        if mirrored:
            acc[there] += g
    else:
        acc[here] += np.multiply(g, x[o], out=tmp)
        if mirrored:
            acc[there] += np.multiply(g, x[c], out=tmp)


def _filter(F, halo, weights, gathers, radius=None, threads=1):
    """sum_j w_ij x_j for every texel i, every candidate weight and every value x.

    ``weights(valid, d2, dot, c, o)`` gives the list of candidate weight arrays for neighbours in the
    image (``c``, ``o`` index padded images; for halo pairs ``valid`` is None and ``c``, ``o`` are
    flat indices of the unpadded image); ``gathers`` is a list of (candidate, padded array, power):
    each accumulates sum_j w_ij^power x_j (x None: the weights alone) over the offsets within
    ``radius`` (default: the features' radius).

    The weights in the image are symmetric (w_ij = w_ji), so each pair of texels is weighed once,
    at the offsets of one half-plane, and adds to both its texels: half the weights' work. Bands of
    rows are the outer loop and offsets the inner, so a band's accumulators (its rows and the
    ``radius`` rows either side that its pairs reach) stay in cache; bands go to ``threads`` threads
    (numpy releases the GIL in its loops) and are added into the image in their order, so the result
    does not depend on the threads.
    """
    h, w, r = F.h, F.w, F.r
    rad = r if radius is None else radius
    flat = [None if x is None else x[r:r + h, r:r + w].reshape(-1) for _, x, _ in gathers]
    segments = F.segments(rad)
    half = [(0, 0)] + [(dy, dx) for dy, dx in _offsets(rad) if dy > 0 or (dy == 0 and dx > 0)]

    def band(y0):
        rows = slice(y0, min(h, y0 + BAND_ROWS))
        n = rows.stop - rows.start
        out = []
        for a, b in segments[y0 // BAND_ROWS]:
            m = b - a
            loc = [np.zeros((n + 2 * rad, m + 2 * rad), np.float32) for _ in gathers]
            tmp = np.empty((n, m), np.float32)
            lc = (slice(rad, rad + n), slice(rad, rad + m))
            for dy, dx in half:
                c, o = F.band(rows, dy, dx, (a, b))
                ws = weights(*F.direct(c, o), c, o)
                lo = (slice(rad + dy, rad + dy + n), slice(rad + dx, rad + dx + m))
                sq = {}
                for acc, (k, x, power) in zip(loc, gathers):
                    if power == 1:
                        g = ws[k]
                    else:
                        if k not in sq:
                            sq[k] = np.multiply(ws[k], ws[k])
                        g = sq[k]
                    _accumulate(acc, g, x, lc, lo, c, o, tmp, dy or dx)
            out.append((a, loc))
        return out

    total = [np.zeros((h + 2 * rad, w + 2 * rad), np.float32) for _ in gathers]
    starts = list(range(0, h, BAND_ROWS))
    pool = ThreadPoolExecutor(threads) if threads > 1 and len(starts) > 1 else None
    try:
        for y0, parts in zip(starts, pool.map(band, starts) if pool else map(band, starts)):
            for a, loc in parts:
                for t, l in zip(total, loc):
                    t[y0:y0 + l.shape[0], a:a + l.shape[1]] += l
    finally:
        if pool:
            pool.shutdown()
    out = [t[rad:rad + h, rad:rad + w].copy() for t in total]
    if halo and len(halo[0]):
        rec, src, d2, dot, cheb = halo
        if rad < F.r:
            sel = cheb <= rad
            rec, src, d2, dot = rec[sel], src[sel], d2[sel], dot[sel]
        if len(rec):
            # Each receiver's halo terms summed in their order (reduceat over the sorted receivers),
            # then added once.
            starts = np.flatnonzero(np.r_[True, rec[1:] != rec[:-1]])
            urec = rec[starts]
            ws = weights(None, d2, dot, rec, src)
            for acc, fx, (k, x, power) in zip(out, flat, gathers):
                g = ws[k] if power == 1 else ws[k] * ws[k]
                v = g if fx is None else g * np.take(fx, src)
                acc.reshape(-1)[urec] += np.add.reduceat(v, starts)
    return out


def _candidates_and_bias(F, halo, weights, K, yp, vp, y, var, threads=1, bias=True):
    """The candidates' sums and their bias pass in one sweep over the bands, with each band's weights
    kept between the two (the same weights serve both): W_k, Y_k, V_k (sum w, w y, w^2 sigma^2),
    F_k = Y_k / W_k (y where W_k = 0) and S_k = sum w F_k (None without ``bias``), each (H, W).

    With symmetric weights at the offsets of a half-plane (dy >= 0), a band's pairs reach the
    ``radius`` rows below it only, so once a band's sums are added, every row above its last is
    final: the bias pass of a band runs as soon as the next band's sums are in. Halo terms (whose
    sources may be anywhere) are added before the bands (sums) and after them (bias). Bands go to
    ``threads`` threads a few at a time and are added in their order: the same bits for any count.
    """
    h, w, r = F.h, F.w, F.r
    half = [(0, 0)] + [(dy, dx) for dy, dx in _offsets(r) if dy > 0 or (dy == 0 and dx > 0)]
    segments = F.segments(r)
    tot = [np.zeros((h + 2 * r, w + 2 * r), np.float32) for _ in range(3 * K)]  # W, Y, V per candidate
    S = [np.zeros((h + 2 * r, w + 2 * r), np.float32) for _ in range(K)] if bias else None
    Fp = [np.zeros((h + 2 * r, w + 2 * r), np.float32) for _ in range(K)]
    inner = (slice(r, r + h), slice(r, r + w))
    yf, vf = yp[inner].reshape(-1), vp[inner].reshape(-1)

    hal = None
    if halo and len(halo[0]):
        rec, src, d2, dot, _ = halo
        starts = np.flatnonzero(np.r_[True, rec[1:] != rec[:-1]])
        urec = rec[starts]
        ws = weights(None, d2, dot, rec, src)
        ys, vs = np.take(yf, src), np.take(vf, src)
        for k in range(K):
            for j, v in enumerate((ws[k], ws[k] * ys, ws[k] * ws[k] * vs)):
                part = np.zeros(h * w, np.float32)  # (a padded image's inner block is no flat view)
                part[urec] = np.add.reduceat(v, starts)
                tot[3 * k + j][inner] += part.reshape(h, w)
        hal = (src, starts, urec, ws)

    def sums(y0):
        rows = slice(y0, min(h, y0 + BAND_ROWS))
        n = rows.stop - rows.start
        out = []
        for a, b in segments[y0 // BAND_ROWS]:
            m = b - a
            loc = [np.zeros((n + 2 * r, m + 2 * r), np.float32) for _ in range(3 * K)]
            tmp = np.empty((n, m), np.float32)
            g2 = np.empty((n, m), np.float32)
            lc = (slice(r, r + n), slice(r, r + m))
            cache = []
            for dy, dx in half:
                c, o = F.band(rows, dy, dx, (a, b))
                ws = weights(*F.direct(c, o), c, o)
                cache.append(ws)
                lo = (slice(r + dy, r + dy + n), slice(r + dx, r + dx + m))
                for k in range(K):
                    g = ws[k]
                    np.multiply(g, g, out=g2)
                    for j, (gg, x) in enumerate(((g, None), (g, yp), (g2, vp))):
                        _accumulate(loc[3 * k + j], gg, x, lc, lo, c, o, tmp, dy or dx)
            out.append((a, loc, cache))
        return out

    def smooth(y0, parts):
        rows = slice(y0, min(h, y0 + BAND_ROWS))
        n = rows.stop - rows.start
        out = []
        for a, _, cache in parts:
            b = a + cache[0][0].shape[1]
            m = b - a
            loc = [np.zeros((n + 2 * r, m + 2 * r), np.float32) for _ in range(K)]
            tmp = np.empty((n, m), np.float32)
            lc = (slice(r, r + n), slice(r, r + m))
            for (dy, dx), ws in zip(half, cache):
                c, o = F.band(rows, dy, dx, (a, b))
                lo = (slice(r + dy, r + dy + n), slice(r + dx, r + dx + m))
                for k in range(K):
                    loc[k][lc] += np.multiply(ws[k], Fp[k][o], out=tmp)
                    if dy or dx:
                        loc[k][lo] += np.multiply(ws[k], Fp[k][c], out=tmp)
            out.append((a, loc))
        return out

    done = [0]  # rows whose F_k are final

    def finalize(upto):
        a, b = done[0], min(h, upto)
        if b <= a:
            return
        for k in range(K):
            W_, Y_ = tot[3 * k][r + a:r + b, r:r + w], tot[3 * k + 1][r + a:r + b, r:r + w]
            with np.errstate(invalid="ignore", divide="ignore"):
                Fp[k][r + a:r + b, r:r + w] = np.where(W_ > 0, Y_ / W_, y[a:b])
        done[0] = b

    def add_smooth(y0, parts):
        for a, loc in parts:
            for t, l in zip(S, loc):
                t[y0:y0 + l.shape[0], a:a + l.shape[1]] += l

    starts = list(range(0, h, BAND_ROWS))
    pool = ThreadPoolExecutor(threads) if threads > 1 and len(starts) > 1 else None
    try:
        ahead = max(1, threads)
        futures = {}

        def submit(i):
            if i < len(starts) and i not in futures:
                futures[i] = pool.submit(sums, starts[i]) if pool else None

        for i in range(ahead):
            submit(i)
        previous = None
        for i, y0 in enumerate(starts):
            parts = futures.pop(i).result() if pool else sums(y0)
            submit(i + ahead)
            for a, loc, _ in parts:
                for t, l in zip(tot, loc):
                    t[y0:y0 + l.shape[0], a:a + l.shape[1]] += l
            finalize(y0 + BAND_ROWS)
            if bias and previous is not None:
                add_smooth(previous[0], smooth(*previous))
            previous = (y0, parts)
        finalize(h)
        if bias and previous is not None:
            add_smooth(previous[0], smooth(*previous))
    finally:
        if pool:
            pool.shutdown()
    if bias and hal is not None:
        src, starts_, urec, ws = hal
        for k in range(K):
            Fk_flat = Fp[k][inner].reshape(-1)
            part = np.zeros(h * w, np.float32)
            part[urec] = np.add.reduceat(ws[k] * np.take(Fk_flat, src), starts_)
            S[k][inner] += part.reshape(h, w)
    out = [t[inner] for t in tot]  # views of the padded sums: no copies
    Fk = [f[inner] for f in Fp]
    return out[0::3], out[1::3], out[2::3], Fk, (None if S is None else [t[inner] for t in S])


def _trusted_zeros(F, var, r=2):
    """The variance of texels whose error is 0 (every sample and every texel of the bake's pooling
    window agreed) raised to the mean variance of the texels within ``r`` (Chebyshev, same island)
    whose error is not 0: the bake's window stops at its 16 x 16 blocks, so a texel at a block's
    edge beside a varying region may report 0 though its value is not exact. Zero stays zero only
    where the whole neighbourhood agrees."""
    h, w, R = F.h, F.w, F.r
    wp = w + 2 * R
    vp = np.pad(var, R).reshape(-1)
    isl = F.island.reshape(-1)
    # Only the covered texels whose error is 0 (a gather over their windows: usually few of them).
    idx = np.flatnonzero((var == 0) & (F.island[R:R + h, R:R + w] >= 0))
    pi = (idx // w + R) * wp + idx % w + R
    total = np.zeros(len(idx), np.float32)
    count = np.zeros(len(idx), np.float32)
    own = isl[pi]
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            po = pi + dy * wp + dx
            v = vp[po]
            ok = (isl[po] == own) & (v > 0)
            total += np.where(ok, v, 0)
            count += ok
    out = var.astype(np.float32, copy=True)
    flat = out.reshape(-1)
    flat[idx] = np.where(count > 0, total / np.maximum(count, 1), flat[idx])
    return out


def denoise(ao, stderr, mask, guide, *, bandwidths=BANDWIDTHS, radius=RADIUS, normal_sharpness=NORMAL_SHARPNESS,
            range_sigmas=RANGE_SIGMAS, range_flat=RANGE_FLAT, pilot_bandwidth=PILOT_BANDWIDTH,
            bias_scale=BIAS_SCALE, margin=0, threads=2, neighbours="surface", use_error=True, use_bias=True,
            shapes=SHAPES):
    """Denoise a baked AO map over the surface; return it with its standard error.

    Parameters
    ----------
    ao, stderr : (H, W) the bake's estimate and its standard error (:class:`core.BakeResult`).
    mask : (H, W) bool, the covered texels (only these are filtered and used).
    guide : :class:`SurfaceGuide` of the same resolution (:func:`surface_guide`), built with a halo
        radius of at least ``radius``.
    bandwidths : candidate filter widths, in texels of each texel's world size.
    radius : window radius in texels (image offsets -radius..radius).
    normal_sharpness : beta of the normal weight exp(-beta (1 - n_i . n_j)).
    range_sigmas, range_flat : the AO term exp(-max(0, d^2 / (2 kappa^2 (v_i + v_j)) - flat)) of the
        pilot's difference d: flat (weight 1) up to sqrt(2 flat) kappa standard deviations, so that
        noise alone hardly moves the weights; kappa = range_sigmas.
    pilot_bandwidth : bandwidth of the pilot (geometry only) that the AO term compares.
    bias_scale : factor on the double-smoothing bias estimate (see the module docstring).
    margin : re-dilate this many texels around the covered ones (as the bake does); 0: texels outside
        the mask keep their input value.
    threads : bands of rows filtered at the same time (numpy releases the GIL in its loops); the
        result does not depend on it (bands are added in their order).
    neighbours : 'surface' (the filter); 'image' only for the tests that break it on purpose: the
        image window's texels whatever their island, by image distance, nothing across seams.
    use_error, use_bias : off only in the tests that break the filter on purpose: without the error
        every texel takes the widest candidate whatever its standard error; without the bias the
        reported error is the propagated variance alone.
    shapes : the wide candidates' rectangles (half-widths in texels along x and y; :mod:`.wide`), taken
        after the fine candidates with the fine result as their pilot; () for the fine stage alone.

    Returns
    -------
    (ao, stderr, info): (H, W) float32 denoised AO in [0, 1] and its standard error (0 outside the
    mask), and a :class:`DenoiseInfo`. Deterministic: no randomness, the same bits for any
    ``threads``; each texel depends only on the texels within a few window radii and their halo.
    """
    ao = np.asarray(ao)
    h, w = ao.shape
    if (guide.height, guide.width) != (h, w):
        raise ValueError(f"the guide is {guide.width} x {guide.height}, the map {w} x {h}")
    r = int(radius)
    if r < 2:
        raise ValueError(f"the window radius must be at least 2 texels, got {radius}")
    if neighbours not in ("surface", "image"):
        raise ValueError(f"neighbours must be 'surface' or 'image', got {neighbours!r}")
    use_halo = neighbours == "surface"
    if use_halo and r > guide.halo_radius:
        raise ValueError(f"the window radius {r} exceeds the guide's halo radius {guide.halo_radius}")
    mask = np.asarray(mask, bool) & guide.covered
    F = _Features(guide, mask, r, image=not use_halo)
    halo = _halo_pairs(guide, mask, r, F) if use_halo else ()
    y = np.where(mask, ao, 0).astype(np.float32)
    var = np.where(mask, np.asarray(stderr, np.float32) ** 2, 0).astype(np.float32)
    exact = var == 0
    var = _trusted_zeros(F, var) if use_error else var
    exact &= var == 0
    bws = [float(b) for b in bandwidths]
    K = len(bws)
    inv2h2 = [np.float32(0.5 / (b * b)) for b in bws]
    halving = all(abs(bws[k + 1] / bws[k] - math.sqrt(2)) < 1e-3 for k in range(K - 1))
    pilot = np.float32(0.5 / float(pilot_bandwidth) ** 2)
    beta = np.float32(normal_sharpness)
    zero = np.float32(0)
    P = lambda a: np.pad(a, r)  # noqa: E731
    yp, vp = P(y), P(var)

    def geometric(valid, d2, dot, c, o):
        g = np.exp(-(d2 * pilot + beta * (1.0 - dot)))
        return [g if valid is None else np.where(valid, g, zero)]

    # The pilot (geometry only, narrow): what the AO term compares, and its variance.
    Wg, Yg, Vg = _filter(F, halo, geometric, [(0, None, 1), (0, yp, 1), (0, vp, 2)], radius=min(r, PILOT_RADIUS),
                         threads=threads)
    with np.errstate(invalid="ignore", divide="ignore"):
        G = P(np.where(Wg > 0, Yg / Wg, 0).astype(np.float32))
        vG = P(np.where(Wg > 0, Vg / (Wg * Wg), 0).astype(np.float32))
    Gf, vGf = G[r:r + h, r:r + w].reshape(-1), vG[r:r + h, r:r + w].reshape(-1)
    k2 = np.float32(2.0 * range_sigmas ** 2)
    flat, eps = np.float32(range_flat), np.float32(1e-12)

    def candidates(valid, d2, dot, c, o):
        if valid is None:
            gi, gj, vi, vj = Gf[c], Gf[o], vGf[c], vGf[o]
        else:
            gi, gj, vi, vj = G[c], G[o], vG[c], vG[o]
        base = beta * (1.0 - dot) + np.maximum((gi - gj) ** 2 / (k2 * (vi + vj) + eps) - flat, zero)
        if valid is not None:
            base = np.where(valid, base, np.float32(np.inf))  # exp(-inf) = 0: not a neighbour
        if not halving:
            return [np.exp(-(d2 * inv + base)) for inv in inv2h2]
        # Bandwidths a factor sqrt(2) apart: exp(-d2 inv_k) is the widest's factor E raised to
        # 1, 2, 4, ...: two exponentials for every candidate.
        E = np.exp(-(d2 * inv2h2[-1]))
        g = np.exp(-base)
        g *= E
        out = [g]
        for _ in range(K - 1):
            g = g * E
            out.append(g)
            E = E * E
        return out[::-1]

    # The candidates F_k = S_k y, their variance, then their bias S_k F_k - F_k (same weights).
    Wk, Yk, Vk, Fk, Sk = _candidates_and_bias(F, halo, candidates, K, yp, vp, y, var, threads=threads,
                                              bias=bool(use_bias))
    with np.errstate(invalid="ignore", divide="ignore"):
        Vark = [np.where(Wk[k] > 0, Vk[k] / (Wk[k] * Wk[k]), var).astype(np.float32) for k in range(K)]
    if use_bias:
        with np.errstate(invalid="ignore", divide="ignore"):
            Bk = [(np.float32(bias_scale) * np.where(Wk[k] > 0, Sk[k] / Wk[k] - Fk[k], 0)).astype(np.float32)
                  for k in range(K)]
    else:
        Bk = [np.zeros((h, w), np.float32) for _ in range(K)]

    # Each texel takes the least V + B^2, its raw value (sigma^2, 0) among the candidates.
    if use_error:
        best, choice = var.copy(), np.zeros((h, w), np.int8)
        for k in range(K):
            m = Vark[k] + Bk[k] * Bk[k]
            take = m < best
            best = np.where(take, m, best)
            choice[take] = k + 1
        choice[exact] = 0
    else:
        choice = np.full((h, w), K, np.int8)
    out, varo, bias = y.copy(), var.copy(), np.zeros((h, w), np.float32)
    for k in range(K):
        take = choice == k + 1
        out[take], varo[take], bias[take] = Fk[k][take], Vark[k][take], Bk[k][take]
    shapes = tuple(tuple(int(r) for r in sh) for sh in shapes) if use_halo and use_error else ()
    if shapes:
        # The wide candidates, with the fine result as their pilot (its detail tells their bias).
        fits = WideFits(y, var, mask, np.where(mask, guide.island, -1), guide.normal, out, varo, shapes=shapes)
        best = (varo + bias * bias).astype(np.float32)
        bias2 = (bias * bias).astype(np.float32)
        sign = np.sign(bias).astype(np.float32)
        choose_wide(best, out, varo, bias2, choice, exact, mask, fits, K + 1, threads=threads)
        bias = np.where(choice > K, np.sqrt(bias2), np.abs(bias) * sign).astype(np.float32)
    out = np.clip(out, 0.0, 1.0)
    se = np.sqrt(varo + bias * bias)
    res = np.where(mask, out, np.asarray(ao, np.float32)).astype(np.float32)
    se = np.where(mask, se, 0).astype(np.float32)
    if margin:
        from ...geometry.margin import dilate
        dilate(res, mask, int(margin), threads=threads, out=res)
    info = DenoiseInfo(choice=np.where(mask, choice, 0).astype(np.int8),
                       variance=np.where(mask, varo, 0).astype(np.float32),
                       bias=np.where(mask, bias, 0).astype(np.float32), bandwidths=tuple(bws),
                       shapes=groups(shapes))
    return res, se, info


__all__ = [
    "BANDWIDTHS", "NORMAL_SHARPNESS", "RANGE_SIGMAS", "RANGE_FLAT", "PILOT_BANDWIDTH", "PILOT_RADIUS", "BIAS_SCALE",
    "BAND_ROWS", "SEGMENT_GAP", "DenoiseInfo", "denoise"
]
