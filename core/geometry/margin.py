"""Margin: extend each UV island's texels outward so filtering and mip-maps never sample the void."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np

_EMPTY, _FILLED, _PAD, _RING = 0, 1, 2, 3
# Texels of one band at most (512 rows of a 4096-wide image): see dilate.
BAND_TEXELS = 1 << 21


def dilate(values, mask, margin, threads=1, out=None, owner=None, rank=None):
    """Fill up to ``margin`` texels around the covered ones, ring by ring.

    Each ring gives every empty texel that touches a filled one (8-neighbourhood) the mean of those
    filled neighbours, computed from the rings before it, so a margin texel takes the value of the
    nearest covered texels, as Blender's "extend" margin does. Covered texels never change; texels
    beyond the margin stay as they were.

    With ``owner`` (several targets in one image, an atlas), each covered texel belongs to one target
    (``owner`` (H, W) int, its index; -1 where ``mask`` is false) and every target's rings grow
    together, into empty texels only: a texel of a ring takes the mean of the filled neighbours of
    ONE target, the target with the most filled neighbours there (equal counts: the first in
    ``rank``, a sequence giving each target's place, lowest first; None: the lowest index), and
    then belongs to it (``owner`` is filled in for the margin too). With one target this is the
    same ring walk, the same sums, the same bits.

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
    new array; owner : None, or (H, W) int32, C-contiguous: each covered texel's target, -1
    elsewhere, updated in place with the margin's; rank : see above.

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
    labels = _labels(owner, rank, mask)
    parts = _bands(values, mask, margin, threads, labels)
    for idx, vals, *who in parts:
        flat[idx] = vals
    if owner is not None:
        lab = owner.reshape(-1)
        for idx, vals, who in parts:
            lab[idx] = labels[1][who]
    return out


def margin_texels(values, mask, margin, threads=1, owner=None, rank=None):
    """The texels :func:`dilate` fills and their values, without an image: (flat indices (n,)
    int64, values (n,) or (n, C) of values' dtype), band by band, each texel once; with ``owner``
    (see :func:`dilate`, not changed here) also each texel's target (n,) int32."""
    labels = _labels(owner, rank, mask)
    parts = _bands(values, mask, margin, threads, labels)
    if not parts:
        empty = (np.zeros(0, np.int64), np.zeros((0,) + values.shape[2:], values.dtype))
        return empty if owner is None else empty + (np.zeros(0, np.int32),)
    out = np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    if owner is None:
        return out
    return out + (labels[1][np.concatenate([p[2] for p in parts])],)


def _labels(owner, rank, mask):
    """(each covered texel's label, the target of each label) for the ring walk, or None without
    ``owner``: label = the target's place in ``rank`` (0 first), so that the lowest label wins a
    tie; texels outside ``mask`` get -1."""
    if owner is None:
        return None
    owner = np.asarray(owner)
    if owner.shape != mask.shape:
        raise ValueError(f"owner of shape {owner.shape} does not match the mask's {mask.shape}")
    n = int(owner.max(initial=-1)) + 1
    place = np.arange(n, dtype=np.int32) if rank is None else np.asarray(rank, np.int32)[:n]
    target_of = np.empty(len(place), np.int32)
    target_of[place] = np.arange(len(place), dtype=np.int32)
    lab = np.full(owner.shape, -1, np.int32)
    sel = mask & (owner >= 0)
    lab[sel] = place[owner[sel]]
    return lab, target_of


def _bands(values, mask, margin, threads, labels=None):
    """(flat indices, values) of the margin texels, a pair per band of rows (see dilate); with
    ``labels`` a triple, the texels' labels third."""
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
        idx, vals, *lab = _rings(values[w0:w1], mask[w0:w1], margin, None if labels is None else labels[0][w0:w1])
        rows = idx // w
        keep = (rows >= r0 - w0) & (rows < r1 - w0)
        return (idx[keep].astype(np.int64) + w0 * w, vals[keep], *(x[keep] for x in lab))

    # Every band is computed from ``values`` before any is written (dilate's ``out`` may be ``values``).
    if bands == 1 or int(threads) <= 1:
        return [band(i) for i in range(bands)]
    with ThreadPoolExecutor(max_workers=min(bands, int(threads)), thread_name_prefix="mc_ao-margin") as pool:
        return list(pool.map(band, range(bands)))


def _rings(values, mask, margin, labels=None):
    """The margin texels of one band: (flat indices into the band, of int32 below 2^31 texels, their
    values (n,), or (n, C) for (h, w, C) values: the channels share the rings, the counts and the
    claims; each is summed as a single channel is). With ``labels`` ((h, w) int32, each covered
    texel's label, see :func:`dilate`) also each margin texel's label: a texel takes the label with
    the most filled neighbours (the lowest on a tie) and the mean of that label's neighbours only.

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
    if labels is not None:
        L = np.full((h + 2, W2), -1, np.int32)
        L[1:-1, 1:-1] = labels
        Lf = L.reshape(-1)
        done_lab = []
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
        if labels is not None:
            lab = _claim(np.take(Lf, nb, mode="clip"), filled)
            Lf[frontier] = lab
            done_lab.append(lab)
        count = filled[0].astype(np.float32)
        for j in range(1, 8):
            count += filled[j]
        vals = []
        for Vc in Vf:
            vg = np.take(Vc, nb, mode="clip")
            if labels is not None:
                vg[~filled] = 0.0  # another target's neighbours (and empty ones) add nothing
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
        empty = (np.zeros(0, it), np.zeros((0,) + values.shape[2:], values.dtype))
        return empty if labels is None else empty + (np.zeros(0, np.int32),)
    # (row - 1) * w + (column - 1) of the padded index, in its own integer type (int32 below 2^31
    # texels, where numpy's division is several times faster than int64's).
    idx = np.concatenate(done_idx)
    vals = np.concatenate(done_val).astype(values.dtype)
    out = idx - 2 * (idx // W2) - (w + 1), vals
    return out if labels is None else out + (np.concatenate(done_lab),)


def _claim(lab, filled):
    """The label each frontier texel takes from its neighbours' labels ``lab`` (8, n), of which the
    ``filled`` (8, n) ones count: the label with the most filled neighbours, the lowest on a tie.
    ``filled`` is narrowed in place to that label's neighbours."""
    lab = np.where(filled, lab, np.int32(-1))
    best = np.full(lab.shape[1], -1, np.int32)
    most = np.zeros(lab.shape[1], np.int32)
    for j in range(8):
        votes = (lab == lab[j]).sum(axis=0, dtype=np.int32)
        better = filled[j] & ((votes > most) | ((votes == most) & (lab[j] < best)))
        best[better], most[better] = lab[j][better], votes[better]
    filled &= lab == best
    return best
