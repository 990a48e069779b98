"""Helpers the denoiser's prototypes share: summed-area tables, window sums and means, and the per-texel
choice of the candidate of least estimated error."""

import numpy as np


def sat(a):
    """Summed-area table with a zero row and column in front: S[y, x] = sum a[:y, :x]."""
    h, w = a.shape
    out = np.zeros((h + 1, w + 1))
    np.cumsum(np.cumsum(a, axis=0), axis=1, out=out[1:, 1:])
    return out


def smooth(a, mask, R):
    """Mean of ``a`` over the texels of ``mask`` in each (2R + 1)^2 window (NaN where none)."""
    s = box(sat(np.where(mask, a, 0)), R)
    n = box(sat(mask.astype(np.float64)), R)
    return np.where(n > 0, s / np.maximum(n, 1), np.nan)


def box(S, R):
    """Sums over the (2R + 1)^2 windows (clipped to the image) from a summed-area table; R may be a
    pair (Rx, Ry): (2 Rx + 1) columns by (2 Ry + 1) rows."""
    h, w = S.shape[0] - 1, S.shape[1] - 1
    Rx, Ry = (R, R) if np.isscalar(R) else R
    y0 = np.clip(np.arange(h) - Ry, 0, h)
    y1 = np.clip(np.arange(h) + Ry + 1, 0, h)
    x0 = np.clip(np.arange(w) - Rx, 0, w)
    x1 = np.clip(np.arange(w) + Rx + 1, 0, w)
    return S[y1][:, x1] - S[y0][:, x1] - S[y1][:, x0] + S[y0][:, x0]


def select(cands, exact=None):
    """Per texel the candidate (F, V, B, name) with the least V + B^2 (NaN/inf never); returns the
    chosen F, its V and B and the choice."""
    best = np.full(cands[0][0].shape, np.inf)
    out, vo, bo = [np.array(c, np.float64, copy=True) for c in cands[0][:3]]
    choice = np.zeros(best.shape, int)
    for k, (F, V, B, _) in enumerate(cands):
        mse = V + B * B
        take = np.isfinite(mse) & np.isfinite(F) & (mse < best)
        if exact is not None:
            take &= ~exact
        best = np.where(take, mse, best)
        out, vo, bo = np.where(take, F, out), np.where(take, V, vo), np.where(take, B, bo)
        choice[take] = k
    return out, vo, bo, choice
