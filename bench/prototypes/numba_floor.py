"""A measured prototype: bench.sections.floor's per-ray stages as one compiled loop (numba).

Not part of mc_ao and not run by the bench or the tests: it needs numba, which is no dependency of
mc_ao. Run it in an environment of its own:

    python3.11 -m venv /tmp/nbve && /tmp/nbve/bin/pip install numpy==1.26.4 numba embreex
    /tmp/nbve/bin/python -m bench.prototypes.numba_floor

For the interior texels of :mod:`bench.sections.floor` (a whole texel inside one triangle, its samples one
piece), the same data and the same arithmetic as the floor's numpy stages (gather of the pool's
features, the texel's shift, offset and turn, the map; for smooth triangles the finish of
:func:`core.engine.kernel.smooth_cosine_rays`), fused into one loop per ray with numba, compiled
``nogil``. It checks its rays against the numpy stages' and prints nanoseconds a ray, to set beside
bench.sections.floor's numpy floor and Embree's time per ray.
"""

import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numba as nb  # noqa: E402
import numpy as np  # noqa: E402

from bench.sections.floor import N_RAYS, SPAN, Chunk, prepare  # noqa: E402
from core.engine.kernel import FAR  # noqa: E402


@nb.njit(nogil=True)
def rays(planes, pattern, order, shift, corner, cos_t, sin_t, mt, s, k, smooth, reach, org, dirs, tfar, below):
    """Origins and directions (n, 3) float32 of texels ``s``, ``k`` samples each; with ``smooth``,
    the directions about each sample's interpolated normal, their ``tfar`` and ``below``."""
    pu0, pu1 = planes[0].view(np.uint32), planes[1].view(np.uint32)
    low, rf = np.float32(reach / FAR), np.float32(reach)
    for i in range(len(s)):
        tx = s[i]
        base = pattern[tx] * SPAN + (order[tx] & ~(k - 1))
        c0, c1, cs, sn, sh0, sh1, m = corner[tx, 0], corner[tx, 1], cos_t[tx], sin_t[tx], shift[tx, 0], shift[tx, 1], mt[tx]
        for j in range(k):
            r, n = base + j, i * k + j
            a = np.float32(pu0[r] ^ sh0) * np.float32(2.0 ** -32) + c0
            b = np.float32(pu1[r] ^ sh1) * np.float32(2.0 ** -32) + c1
            f0, f1, f2 = planes[3, r], planes[4, r], planes[5, r]
            g0, g1 = f0 * cs - f1 * sn, f1 * cs + f0 * sn
            for c in range(3):
                org[n, c] = m[c, 2] + a * m[c, 0] + b * m[c, 1]
            if not smooth:
                for c in range(3):
                    dirs[n, c] = g0 * m[3 + c, 3] + g1 * m[3 + c, 4] + f2 * m[3 + c, 5]
                continue
            n0, n1, n2 = (m[3, 2] + a * m[3, 0] + b * m[3, 1], m[4, 2] + a * m[4, 0] + b * m[4, 1],
                          m[5, 2] + a * m[5, 0] + b * m[5, 1])
            length = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            d0 = (g0 * m[6, 3] + g1 * m[6, 4] + f2 * m[6, 5]) * length + n0
            d1 = (g0 * m[7, 3] + g1 * m[7, 4] + f2 * m[7, 5]) * length + n1
            d2 = (g0 * m[8, 3] + g1 * m[8, 4] + f2 * m[8, 5]) * length + n2
            dirs[n, 0], dirs[n, 1], dirs[n, 2] = d0, d1, d2
            size2 = d0 * d0 + d1 * d1 + d2 * d2
            vg = g0 * m[10, 3] + g1 * m[10, 4] + f2 * m[10, 5]
            bl = (vg * length + (m[9, 2] + a * m[9, 0] + b * m[9, 1]) <= 0) or size2 < 1e-20
            below[n] = bl
            tfar[n] = 0.0 if bl else rf / max(np.sqrt(size2), low)
    return 0


def measure(k, columns, calls=16, repeats=5):
    c = Chunk(k, columns)
    smooth = columns == 11
    s = c.texels(1)
    prepare(c, "finish" if smooth else "map", s)
    if smooth:
        c.finish_planes(s)
    else:
        c.map_planes_blas(s)
    n = len(s) * k
    out = [(np.empty((n, 3), np.float32), np.empty((n, 3), np.float32), np.empty(n, np.float32), np.empty(n, bool))
           for _ in range(2)]
    args = (c.planes, c.pattern, c.order, c.shift, c.corner, c.cos, c.sin, c.mt)
    org, dirs, tfar, below = out[0]
    rays(*args, s, k, smooth, 1.0, org, dirs, tfar, below)
    want = [c.y[0:3].reshape(3, -1).T, (c.dirs if smooth else c.y[3:6]).reshape(3, -1).T]
    err = max(np.abs(org - want[0]).max(), np.abs(dirs - want[1]).max())
    if smooth:
        assert np.array_equal(below, c.below.reshape(-1))
    sets = [c.texels(i) for i in range(calls)]

    def work(o):
        for ss in sets:
            rays(*args, ss, k, smooth, 1.0, *o)

    one = two = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        work(out[0])
        one = min(one, time.perf_counter() - t)
        ts = [threading.Thread(target=work, args=(o,)) for o in out]
        t = time.perf_counter()
        [x.start() for x in ts]
        [x.join() for x in ts]
        two = min(two, time.perf_counter() - t)
    return err, one / (calls * N_RAYS), 2 * one / two


def main():
    print(f"numba {nb.__version__}, numpy {np.__version__}; chunks of {N_RAYS} rays")
    for columns, shading in ((6, "flat"), (11, "smooth")):
        for k in (32, 64):
            err, sec, scale = measure(k, columns)
            print(f"  {shading:6s} K={k}: {sec * 1e9:5.1f} ns a ray (largest difference from the numpy stages "
                  f"{err:.1e}); two threads {scale:.2f}x one")
    return 0


if __name__ == "__main__":
    sys.exit(main())
