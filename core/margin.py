"""Margin: extend each UV island's texels outward so filtering and mip-maps never sample the void."""

import numpy as np

_NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def dilate(values, mask, margin):
    """Fill up to ``margin`` texels around the covered ones, ring by ring.

    Each pass gives every empty texel that touches a filled one (8-neighbourhood) the mean of those
    filled neighbours, so a margin texel takes the value of the nearest covered texels, as Blender's
    "extend" margin does. Covered texels are never changed; texels beyond the margin stay as they were.

    Parameters
    ----------
    values : (H, W) array; mask : (H, W) bool, the covered texels; margin : rings to add.

    Returns
    -------
    A new (H, W) array of values' dtype.
    """
    out = values.astype(np.float32, copy=True)
    filled = mask.copy()
    h, w = out.shape
    for _ in range(int(margin)):
        if filled.all():
            break
        total = np.zeros((h + 2, w + 2), np.float32)
        count = np.zeros((h + 2, w + 2), np.uint8)
        src = np.where(filled, out, 0.0).astype(np.float32)
        f8 = filled.astype(np.uint8)
        for dy, dx in _NEIGHBOURS:
            total[1 + dy:h + 1 + dy, 1 + dx:w + 1 + dx] += src
            count[1 + dy:h + 1 + dy, 1 + dx:w + 1 + dx] += f8
        total, count = total[1:-1, 1:-1], count[1:-1, 1:-1]
        ring = ~filled & (count > 0)
        if not ring.any():
            break
        out[ring] = total[ring] / count[ring]
        filled |= ring
    return out.astype(values.dtype, copy=False)
