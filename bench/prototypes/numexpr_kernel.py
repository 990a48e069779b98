"""numexpr in the kernel: does fusing the kernel's elementwise passes make a whole bake 1.25x faster?

The numexpr experiment: numexpr (fused elementwise expressions, no temporaries) in the
kernel's arithmetic, adopted only if a whole one-thread bake of the bench's Suzanne scene and of the
terrain gets at least 1.25x faster. This prototype replaces, in a subclass of :class:`core.engine.kernel.Kernel`
built from the kernel's own source with three blocks swapped:

- the texel's turn of the direction features (4 numpy passes) by two numexpr expressions;
- the long pieces' batched product ``np.matmul((g, cols, 6), (g, 6, k))`` by one expression per
  output column over the feature planes, the matrix entries broadcast per piece;
- the smooth-shaded finish (:func:`core.engine.kernel.smooth_cosine_rays`, about 20 passes) by five
  expressions;

and times whole bakes, the kernel of this tree against the numexpr one, interleaved (one thread,
thread CPU of this process, median of pairs). numexpr's pool is set to one thread. What it cannot
touch: gathers (``np.take``), Embree, sorting, rasterising. The answers are compared with the numpy
kernel's (the same rays up to float32 rounding: the mean AO must agree within its error).

Run (numexpr is no dependency of the project: a folder of its own)::

    pip install --target /tmp/nx numexpr==2.14.2
    PYTHONPATH=/tmp/nx .venv/bin/python -m bench.prototypes.numexpr_kernel [--pairs 5] [--quick]

Results and the decision: bench/LOG.md, "numexpr".
"""

import argparse
import inspect
import os
import statistics
import sys
import textwrap
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

TURN_NUMPY = """        f0, f1 = x[3], x[4]
        t0 = f0 * cos_t
        t0 -= f1 * sin_t
        f1 *= cos_t
        f1 += f0 * sin_t
        f0[...] = t0
"""
TURN_NUMEXPR = """        f0, f1 = x[3], x[4]
        t0 = _ne.evaluate("f0 * cos_t - f1 * sin_t", local_dict=dict(f0=f0, f1=f1, cos_t=cos_t, sin_t=sin_t))
        _ne.evaluate("f1 * cos_t + f0 * sin_t", local_dict=dict(f0=f0, f1=f1, cos_t=cos_t, sin_t=sin_t), out=f1)
        f0[...] = t0
"""
PRODUCT_NUMPY = """                np.matmul(mt, x.transpose(1, 0, 2), out=y.reshape(len(entries), g, k).transpose(1, 0, 2))
"""
PRODUCT_NUMEXPR = """                _ne_product(mt, x, y.reshape(len(entries), g, k))
"""
FINISH_NUMPY = "smooth_cosine_rays(y, self.reach, dirs, tfar, below, length, tmp, ws.f3[:n])"
FINISH_NUMEXPR = "_ne_smooth_cosine_rays(y, self.reach, dirs, tfar, below, length, tmp, ws.f3[:n])"


def _ne_product(mt, x, y):
    """y[c] (g, k) = sum_j mt[:, c, j] x[j] over the nonzero rows of each column's form (position:
    the constant, a and b; direction: the three direction features), one expression per column."""
    import numexpr as ne

    from core.engine.kernel import CURVED_ENTRIES, FLAT_ENTRIES

    entries = CURVED_ENTRIES if mt.shape[1] == len(CURVED_ENTRIES) else FLAT_ENTRIES
    a, b, f0, f1, f2 = x[0], x[1], x[3], x[4], x[5]
    for c, rows in entries:
        m = [mt[:, c, j][:, None] for j in rows]
        if rows[0] == 2:
            ne.evaluate("m0 + a * m1 + b * m2", local_dict=dict(m0=m[0], m1=m[1], m2=m[2], a=a, b=b), out=y[c])
        else:
            ne.evaluate("f0 * m0 + f1 * m1 + f2 * m2", local_dict=dict(m0=m[0], m1=m[1], m2=m[2], f0=f0, f1=f1, f2=f2),
                        out=y[c])


def _ne_smooth_cosine_rays(y, reach, dirs, tfar, below, length, tmp, size2):
    """:func:`core.engine.kernel.smooth_cosine_rays` in five numexpr expressions (float32 throughout)."""
    import numexpr as ne

    from core.tracing.tracer import FAR

    ne.evaluate("sqrt(n0 * n0 + n1 * n1 + n2 * n2)", local_dict=dict(n0=y[3], n1=y[4], n2=y[5]), out=length)
    for c in range(3):
        ne.evaluate("v * l + n", local_dict=dict(v=y[6 + c], l=length, n=y[3 + c]), out=dirs[c])
    ne.evaluate("d0 * d0 + d1 * d1 + d2 * d2", local_dict=dict(d0=dirs[0], d1=dirs[1], d2=dirs[2]), out=size2)
    ne.evaluate("(vg * l + ng <= z) | (s2 < tiny)", local_dict=dict(vg=y[10], l=length, ng=y[9], z=np.float32(0),
                                                                     s2=size2, tiny=np.float32(1e-20)), out=below)
    if reach < FAR:
        ne.evaluate("where(bl, z, r / maximum(sqrt(s2), lo))",
                    local_dict=dict(bl=below, z=np.float32(0), r=np.float32(reach), s2=size2,
                                    lo=np.float32(reach / FAR)), out=tfar)
    else:
        ne.evaluate("where(bl, z, far)", local_dict=dict(bl=below, z=np.float32(0), far=np.float32(FAR)), out=tfar)


BLOCKS = {"turn": (TURN_NUMPY, TURN_NUMEXPR), "product": (PRODUCT_NUMPY, PRODUCT_NUMEXPR),
          "finish": (FINISH_NUMPY, FINISH_NUMEXPR)}


def numexpr_kernel_class(blocks=tuple(BLOCKS)):
    """A subclass of core.engine.kernel.Kernel whose ``run`` is the kernel's own source with ``blocks`` (of
    :data:`BLOCKS`) swapped for numexpr (fails loudly where the source no longer has them)."""
    import numexpr as ne

    import core.engine.kernel as K

    src = textwrap.dedent(inspect.getsource(K.Kernel.run))
    src = textwrap.indent(src, "    ")
    for old, new in (BLOCKS[b] for b in blocks):
        if old not in src:
            raise RuntimeError(f"core.engine.kernel.Kernel.run no longer has the block this prototype swaps:\n{old}")
        src = src.replace(old, new)
    namespace = dict(vars(K), _ne=ne, _ne_product=_ne_product, _ne_smooth_cosine_rays=_ne_smooth_cosine_rays)
    exec(compile("class _Run:\n" + src, "<numexpr kernel>", "exec"), namespace)
    return type("NumexprKernel", (K.Kernel,), {"run": namespace["_Run"].run})


def _bake(scene, res, spp, kernel_cls):
    import core.targets.texels as B
    from core import bake_ao

    target, occ, distance = scene
    original = B.Kernel
    B.Kernel = kernel_cls
    try:
        t0 = time.thread_time()
        r = bake_ao(target, occ, resolution=(res, res), samples=spp, threads=1, max_distance=distance, margin=0)
        return time.thread_time() - t0, r
    finally:
        B.Kernel = original


def main(argv=None):
    import numexpr as ne

    from bench.harness.common import load_average
    from bench.sections.stages import scenes
    from core.engine.kernel import Kernel

    ap = argparse.ArgumentParser()
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--scene", nargs="+", default=["suzanne", "terrain"])
    ap.add_argument("--blocks", nargs="+", default=list(BLOCKS), choices=list(BLOCKS),
                    help="which of the kernel's blocks numexpr computes (default: all three)")
    a = ap.parse_args(argv)
    ne.set_num_threads(1)
    res, spp = (256, 32) if a.quick else (512, 64)
    nk = numexpr_kernel_class(a.blocks)
    print(f"numexpr {ne.__version__} ({ne.get_num_threads()} thread) for {', '.join(a.blocks)}, numpy {np.__version__}; {res}^2 x {spp}, "
          f"one thread, thread CPU s, {a.pairs} interleaved pairs")
    out = {}
    for name, scene in scenes(a.scene, a.quick).items():
        _bake(scene, 64, spp, Kernel)
        _bake(scene, 64, spp, nk)
        base, fused = [], []
        load0 = load_average()
        for i in range(a.pairs):
            order = (Kernel, nk) if i % 2 == 0 else (nk, Kernel)
            for cls in order:
                t, r = _bake(scene, res, spp, cls)
                (base if cls is Kernel else fused).append((t, r))
        load1 = load_average()
        tb = statistics.median(t for t, _ in base)
        tf = statistics.median(t for t, _ in fused)
        rb, rf = base[0][1], fused[0][1]
        m = rb.mask
        diff = float(np.mean(rf.ao[m].astype(np.float64) - rb.ao[m]))
        se = float(np.sqrt(np.mean(rb.stderr[m].astype(np.float64) ** 2) / m.sum()))
        same = int(np.count_nonzero(rf.ao[m] == rb.ao[m]))
        emb_b = statistics.median(r.trace_cpu_seconds for _, r in base)
        emb_f = statistics.median(r.trace_cpu_seconds for _, r in fused)
        print(f"{name}: numpy kernel {tb:.3f} s (Embree {emb_b:.3f}), numexpr kernel {tf:.3f} s (Embree {emb_f:.3f}): "
              f"{tb / tf:.3f}x; pairs {[round(t, 3) for t, _ in base]} / {[round(t, 3) for t, _ in fused]}; "
              f"mean AO difference {diff:+.2e} (standard error of the mean {se:.1e}), {same}/{m.sum()} texels "
              f"bit-equal; load {load0} -> {load1}")
        out[name] = dict(numpy=tb, numexpr=tf, speedup=tb / tf, load=[load0, load1])
    return out


if __name__ == "__main__":
    main()
