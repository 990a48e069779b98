"""Margin: extend each UV island's texels outward so filtering and mip-maps never sample the void."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np

_EMPTY, _FILLED, _PAD, _RING = 0, 1, 2, 3
# Texels of one band at most (512 rows of a 4096-wide image): see dilate.
BAND_TEXELS = 1 << 21


def dilate(values, mask, margin, threads=1, out=None):
    """Fill up to ``margin`` texels around the covered ones, ring by ring.

    Each ring gives every empty texel that touches a filled one (8-neighbourhood) the mean of those
    filled neighbours, computed from the rings before it, so a margin texel takes the value of the
    nearest covered texels, as Blender's "extend" margin does. Covered texels never change; texels
    beyond the margin stay as they were.

    The rings are walked as lists of texel indices (a frontier), so the work grows with the islands'
    perimeter times the margin, not with the image. The image is cut into bands of rows, each
    computed with ``margin`` rows of the bands beside it (a texel's value depends on nothing farther
    than ``margin`` texels), so the result depends neither on the bands nor on the threads: at least
    one band per thread, and none above BAND_TEXELS texels. Small bands keep each band's working
    arrays (a padded copy of its values and its texels' states) in memory the process already holds:
    in a 4096^2 bake, one band of the whole image spent most of its time in the first touch of fresh
    pages (0.87-2.0 s on one thread, against 0.42-0.56 s for the same call repeated outside a bake),
    and bands of 512 rows take 0.20-0.27 s (two threads: 0.29-1.18 s, medians 0.41-0.62, ->
    0.13-0.19 s).

    Parameters
    ----------
    values : (H, W) array, or (H, W, C): C channels share the rings (the same texels; each channel
    the mean of its own values); mask : (H, W) bool, the covered texels; margin : rings to add;
    threads : bands computed at the same time; out : C-contiguous array of values' shape to write
    the result into, which may be ``values`` itself (the bake's own image: no copy of it); None: a
    new array.

    Returns
    -------
    ``out``, or a new array of values' shape and dtype.
    """
    if out is None:
        out = values.copy()
    else:
        if out.shape != values.shape or not out.flags.c_contiguous:
            raise ValueError("out must be a C-contiguous array of the values' shape")
        if out is not values:
            np.copyto(out, values)
    flat = out.reshape((-1,) + values.shape[2:])
    for idx, vals in _bands(values, mask, margin, threads):
        flat[idx] = vals
    return out


def margin_texels(values, mask, margin, threads=1):
    """The texels :func:`dilate` fills and their values, without an image: (flat indices (n,)
    int64, values (n,) or (n, C) of values' dtype), band by band, each texel once."""
    parts = _bands(values, mask, margin, threads)
    if not parts:
        return np.zeros(0, np.int64), np.zeros((0,) + values.shape[2:], values.dtype)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def _bands(values, mask, margin, threads):
    """(flat indices, values) of the margin texels, a pair per band of rows (see dilate)."""
    h, w = mask.shape
    margin = int(margin)
    if values.shape[:2] != (h, w) or values.ndim not in (2, 3):
        raise ValueError(f"values of shape {values.shape} do not match the mask's {mask.shape}")
    if margin <= 0 or not mask.any() or mask.all():
        return []
    channels = values.shape[2] if values.ndim == 3 else 1
    bands = max(int(threads), -(-h * w * channels // BAND_TEXELS))
    bands = max(1, min(bands, h // max(4 * margin, 64)))
    cuts = [h * i // bands for i in range(bands + 1)]

    def band(i):
        r0, r1 = cuts[i], cuts[i + 1]
        w0, w1 = max(0, r0 - margin), min(h, r1 + margin)
        idx, vals = _rings(values[w0:w1], mask[w0:w1], margin)
        rows = idx // w
        keep = (rows >= r0 - w0) & (rows < r1 - w0)
        return idx[keep].astype(np.int64) + w0 * w, vals[keep]

    # Every band is computed from ``values`` before any is written (dilate's ``out`` may be ``values``).
    if bands == 1 or int(threads) <= 1:
        return [band(i) for i in range(bands)]
    with ThreadPoolExecutor(max_workers=min(bands, int(threads)), thread_name_prefix="mc_ao-margin") as pool:
        return list(pool.map(band, range(bands)))


def _rings(values, mask, margin):
    """The margin texels of one band: (flat indices into the band, of int32 below 2^31 texels, their
    values (n,), or (n, C) for (h, w, C) values: the channels share the rings, the counts and the
    claims; each is summed as a single channel is).

    Neighbours are gathered as (8, n) rows (one per direction), so the sums and counts run along
    the frontier (numpy is several times slower over a short inner axis of 8), added in the same
    order as before (the same bits); each ring's next frontier is made unique by a claim array (the
    last of equal entries keeps its place), not by sorting.
    """
    h, w = mask.shape
    W2 = w + 2
    chan = values.ndim == 3
    V = np.zeros((values.shape[2] if chan else 1, h + 2, W2), np.float32)
    for c in range(len(V)):  # empty texels hold 0: sums need no mask
        np.copyto(V[c, 1:-1, 1:-1], values[..., c] if chan else values, where=mask)
    S = np.full((h + 2, W2), _PAD, np.uint8)
    S[1:-1, 1:-1] = mask
    Vf, Sf = V.reshape(len(V), -1), S.reshape(-1)
    it = np.int32 if Sf.size < 2 ** 31 else np.int64
    offsets = np.array([-W2 - 1, -W2, -W2 + 1, -1, 1, W2 - 1, W2, W2 + 1], it)
    # The claim array is V's own memory read as integers where it can be: the candidates are empty
    # texels, which hold 0 (the bits of 0 either way) and are set back to 0 once claimed, before
    # any sum reads them; a claim array of its own was a fresh image-sized array to touch.
    claim = Vf[0].view(np.int32) if it is np.int32 else np.empty(Sf.size, it)

    def unique(c):
        ar = np.arange(len(c), dtype=it)
        claim[c] = ar
        u = c[claim[c] == ar]
        claim[u] = 0
        return u

    # The first ring: the empty texels with a covered one in their 3 x 3, the covered texels
    # dilated by one (along rows, then along columns), ascending. (Listing the empty neighbours of
    # the covered texels at the islands' edges and making them unique gives the same set, at
    # twice the cost on a 4096^2 image.) Each ring's texels depend on the rings before it only,
    # never on their order.
    covered = np.zeros((h + 2, W2), bool)
    covered[1:-1, 1:-1] = mask
    near = covered.copy()
    near[:, 1:] |= covered[:, :-1]
    near[:, :-1] |= covered[:, 1:]
    near3 = near.copy()
    near3[1:] |= near[:-1]
    near3[:-1] |= near[1:]
    frontier = np.flatnonzero(near3 & (S == _EMPTY)).astype(it)
    done_idx, done_val = [], []
    for _ in range(margin):
        if not len(frontier):
            break
        nb = offsets[:, None] + frontier  # (8, n): row j, every frontier texel's neighbour j
        Sf[frontier] = _RING
        # np.take(mode="clip"): the neighbours of padded texels are always in range, and numpy's
        # fancy indexing checks each index (a third slower).
        st = np.take(Sf, nb, mode="clip")
        filled = st == _FILLED
        count = filled[0].astype(np.float32)
        for j in range(1, 8):
            count += filled[j]
        vals = []
        for Vc in Vf:
            vg = np.take(Vc, nb, mode="clip")
            # (v0 + v4) + (v2 + v6) + ((v1 + v5) + (v3 + v7)), the order of the sums before.
            val = ((vg[0] + vg[4]) + (vg[2] + vg[6])) + ((vg[1] + vg[5]) + (vg[3] + vg[7]))
            val /= count
            Vc[frontier] = val
            vals.append(val)
        Sf[frontier] = _FILLED
        done_idx.append(frontier)
        done_val.append(np.stack(vals, axis=1) if chan else vals[0])
        frontier = unique(nb[st == _EMPTY])
    if not done_idx:
        return np.zeros(0, it), np.zeros((0,) + values.shape[2:], values.dtype)
    # (row - 1) * w + (column - 1) of the padded index, in its own integer type (int32 below 2^31
    # texels, where numpy's division is several times faster than int64's).
    idx = np.concatenate(done_idx)
    vals = np.concatenate(done_val).astype(values.dtype)
    return idx - 2 * (idx // W2) - (w + 1), vals
