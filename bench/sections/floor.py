"""The least numpy work a ray needs, and the share of a bake inside Embree it leaves.

The target asks for at least 80% of a one-thread bake's time inside embreex (the whole bake within
1.3x of embreex alone on the same rays), on the bench's Suzanne scene and a dense terrain. That is
a budget: everything else may cost at most a quarter of Embree's time per ray. This measures, on
the simplest texels there are (a whole texel inside one triangle, its samples one piece), the
cheapest form found of each numpy stage a ray of :mod:`core.engine.kernel` goes through, in the same run
as Embree's own time per ray on each scene's bake:

- gather: the sample's pool features (a texel's aligned block of a pattern), as (n, 6) rows or as
  planes;
- shift: the texel's digital shift of the two position coordinates, and their conversion to float;
- offset and turn: the texel's position in its triangle, its random turn of the frame;
- map: the per-triangle linear map to origin and direction (6 columns flat, 11 smooth: the sample's
  own interpolated normal), as a batched product of rows, as one BLAS product per texel on planes,
  or as elementwise passes over planes;
- finish (smooth only): normalise the interpolated normal, form the direction, its length and the
  below-the-surface test;
- sum: each texel's count of unoccluded rays.

Each stage's cheapest form is counted even where forms could not be combined (rows for one, planes
for the next), so the sum is a lower bound for these texels; split and located texels, the texels'
keys, rasterising, units and margins cost more on top. The share it allows, E / (E + floor) with E
Embree's time per ray, is then an upper bound on what a numpy kernel of this design can reach.

Run: ``.venv/bin/python -m bench.sections.floor [--quick]`` (no Blender); prints the table and writes
``bench/results/floor.txt`` unless ``--no-save``.
"""

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from core.engine.kernel import CURVED_ENTRIES, FLAT_ENTRIES, Kernel, _row_table, smooth_cosine_rays  # noqa: E402

N_RAYS = 1 << 16          # rays per call, as core.bake_ao's chunk_rays
POOL = 1 << 18            # pool points, as core.engine.patterns.POOL_POINTS
SPAN = 1024
TEXELS = 1 << 15


class Chunk:
    """One call's worth of interior texels of K samples each, with the kernel's per-texel choices."""

    def __init__(self, k, columns, seed=1):
        rng = np.random.default_rng(seed)
        self.k, self.cols = k, columns
        self.t = N_RAYS // k
        rows = rng.random((POOL, 6)).astype(np.float32)
        rows[:, 0:2].view(np.uint32)[...] = rng.integers(0, 2 ** 32, (POOL, 2), dtype=np.uint32)
        rows[:, 2] = 1.0
        self.rows = rows
        self.planes = np.ascontiguousarray(rows.T)
        self.pattern = rng.integers(0, POOL // SPAN, TEXELS)
        self.order = rng.integers(0, SPAN, TEXELS)
        self.shift = rng.integers(0, 2 ** 32, (TEXELS, 2), dtype=np.uint32)
        turn = rng.random(TEXELS) * 2 * np.pi
        self.cos, self.sin = np.cos(turn).astype(np.float32), np.sin(turn).astype(np.float32)
        self.corner = rng.random((TEXELS, 2)).astype(np.float32)
        # Per texel a matrix with the kernel's nonzero entries (core.engine.kernel's FLAT_ENTRIES or
        # CURVED_ENTRIES), as rows (6, cols), transposed (cols, 6) and as the kernel's entry table.
        self.entries = CURVED_ENTRIES if columns == 11 else FLAT_ENTRIES
        m = np.zeros((TEXELS, 6, columns), np.float32)
        for c, rows_c in self.entries:
            m[:, rows_c, c] = rng.standard_normal((TEXELS, 3)).astype(np.float32)
        self.m = m
        self.mt = np.ascontiguousarray(m.transpose(0, 2, 1))
        self.table = _row_table(self.mt, self.entries)  # (entries, texels)
        t, k = self.t, self.k
        self.x_rows = np.empty((t, k, 6), np.float32)
        self.x = np.empty((6, t, k), np.float32)
        self.y_rows = np.empty((t, k, columns), np.float32)
        self.y = np.empty((columns, t, k), np.float32)
        self.tmp = np.empty((3, t, k), np.float32)
        self.dirs = np.empty((3, t, k), np.float32)
        self.tfar = np.empty((t, k), np.float32)
        self.below = np.empty((t, k), bool)

    def texels(self, i):
        return (np.arange(self.t) * 7 + i * self.t) % TEXELS

    def _blocks(self, s):
        first = self.pattern[s] * SPAN + ((0 ^ self.order[s]) & ~(self.k - 1))
        return first // self.k

    # -- the stages, each form computing the same numbers --------------------------------------

    def gather_rows(self, s):
        np.take(self.rows.reshape(-1, self.k, 6), self._blocks(s), axis=0, out=self.x_rows, mode="clip")

    def gather_planes(self, s):
        b = self._blocks(s)
        for j in range(6):
            np.take(self.planes[j].reshape(-1, self.k), b, axis=0, out=self.x[j], mode="clip")

    def shift_rows(self, s):
        xu = self.x_rows.view(np.uint32)
        for c in (0, 1):
            np.bitwise_xor(xu[:, :, c], self.shift[s, c, None], out=xu[:, :, c])
            np.copyto(self.x_rows[:, :, c], xu[:, :, c], casting="unsafe")
            self.x_rows[:, :, c] *= np.float32(2.0 ** -32)

    def shift_planes(self, s):
        xu = self.x.view(np.uint32)
        for c in (0, 1):
            np.bitwise_xor(xu[c], self.shift[s, c, None], out=xu[c])
            np.copyto(self.x[c], xu[c], casting="unsafe")
            self.x[c] *= np.float32(2.0 ** -32)

    def offset_turn_planes(self, s):
        x, t0, t1 = self.x, self.tmp[0], self.tmp[1]
        x[0] += self.corner[s, 0, None]
        x[1] += self.corner[s, 1, None]
        c, sn = self.cos[s, None], self.sin[s, None]
        np.multiply(x[3], c, out=t0)
        np.multiply(x[4], sn, out=t1)
        t0 -= t1
        x[4] *= c
        np.multiply(x[3], sn, out=t1)
        x[4] += t1
        x[3] = t0

    def map_rows(self, s):
        np.matmul(self.x_rows, self.m[s], out=self.y_rows)

    def map_planes_blas(self, s):
        np.matmul(self.mt[s], self.x.transpose(1, 0, 2), out=self.y.transpose(1, 0, 2))

    def map_planes_elementwise(self, s):
        # The kernel's own code (core.engine.kernel.Kernel._linear), each texel's entries broadcast.
        Kernel._linear(np.take(self.table, s, axis=1)[:, :, None], self.entries, self.x, self.y, self.tmp[0])

    def finish_planes(self, s):
        # The kernel's own code (core.engine.kernel.smooth_cosine_rays), with the reach of a finite distance.
        smooth_cosine_rays(self.y, 1.0, self.dirs, self.tfar, self.below, self.tmp[2], self.tmp[0], self.tmp[1])

    def sum(self, s):
        return self.below.view(np.uint8).reshape(self.t, self.k).sum(axis=1, dtype=np.int64).astype(np.float64)


def stage_forms(columns):
    forms = {"gather": ("gather_rows", "gather_planes"), "shift": ("shift_rows", "shift_planes"),
             "offset and turn": ("offset_turn_planes",),
             "map": ("map_rows", "map_planes_blas", "map_planes_elementwise")}
    if columns == 11:
        forms["finish"] = ("finish_planes",)
    forms["sum"] = ("sum",)
    return forms


#: What each stage reads, made fresh before every timed call (stages work in place).
PIPELINE = ("gather", "shift", "offset and turn", "map", "finish", "sum")


def prepare(chunk, stage, s):
    """Run the stages before ``stage`` on texels ``s``, in both layouts, so its inputs are real."""
    before = PIPELINE[:PIPELINE.index(stage)]
    if "gather" in before:
        chunk.gather_rows(s)
        chunk.gather_planes(s)
    if "shift" in before:
        chunk.shift_rows(s)
        chunk.shift_planes(s)
    if "offset and turn" in before:
        chunk.offset_turn_planes(s)
        chunk.x_rows[...] = chunk.x.transpose(1, 2, 0)
    if "map" in before:
        chunk.map_planes_blas(s)
    if "finish" in before:
        if chunk.cols == 11:
            chunk.finish_planes(s)
        else:
            np.less(chunk.y[5], 0.2, out=chunk.below)


def time_form(chunk, stage, name, calls, repeats):
    """Seconds per ray of one form of ``stage``: the fastest of ``repeats`` runs over ``calls``
    chunks, each call timed alone on inputs made fresh by the stages before it."""
    f = getattr(chunk, name)
    sets = [chunk.texels(i) for i in range(calls)]
    best = float("inf")
    for _ in range(repeats):
        total = 0.0
        for s in sets:
            prepare(chunk, stage, s)
            t = time.perf_counter()
            f(s)
            total += time.perf_counter() - t
        best = min(best, total)
    return best / (calls * N_RAYS)


def embree_per_ray(quick):
    """Embree's CPU per ray in one-thread bakes of the bench's Suzanne scene and the terrain."""
    from core import bake_ao

    from ..harness.memprobe import load_scene
    from ..harness.scene import terrain

    res, spp = (256, 32) if quick else (512, 64)
    out = {}
    for name, (target, occ, dist) in (("Suzanne scene", load_scene(str(ROOT / "bench" / "data" / "scene_suzanne.npz"))),
                                      ("terrain", terrain())):
        r = bake_ao(target, occ, resolution=res, samples=spp, threads=1, max_distance=dist, margin=0)
        out[name] = r.trace_cpu_seconds / r.rays
    return out, f"{res}^2 x {spp}"


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer chunks and repeats, smaller bakes")
    ap.add_argument("--no-save", action="store_true", help="do not write bench/results/floor.txt")
    args = ap.parse_args(argv)
    calls, repeats = (4, 3) if args.quick else (16, 7)
    lines = [f"numpy per-ray floor of interior texels (bench.sections.floor{' --quick' if args.quick else ''}), "
             f"{time.strftime('%Y-%m-%dT%H:%M:%S')}; numpy {np.__version__}; chunks of {N_RAYS} rays, pool {POOL} points"]
    floors = {}
    for columns, shading in ((6, "flat"), (11, "smooth")):
        for k in (32, 64):
            chunk = Chunk(k, columns)
            total = 0.0
            for stage, names in stage_forms(columns).items():
                times = {n: time_form(chunk, stage, n, calls, repeats) * 1e9 for n in names}
                best = min(times.values())
                total += best
                lines.append(f"  {shading:6s} K={k:2d} {stage:16s} " + "  ".join(f"{n} {v:5.1f}" for n, v in times.items())
                             + f"  -> {best:5.1f} ns")
            floors[(shading, k)] = total
            lines.append(f"  {shading:6s} K={k:2d} floor {total:5.1f} ns a ray")
    embree, bake = embree_per_ray(args.quick)
    lines.append(f"Embree per ray (thread CPU, one-thread bakes at {bake}): "
                 + ", ".join(f"{n} {v * 1e9:.1f} ns" for n, v in embree.items()))
    for name, shading in (("Suzanne scene", "smooth"), ("terrain", "flat")):
        e = embree[name] * 1e9
        for k in (32, 64):
            f = floors[(shading, k)]
            lines.append(f"  {name} ({shading}), K={k}: share at most {100 * e / (e + f):.1f}% "
                         f"(bake/alone at least {(e + f) / e:.2f}x), its interior texels alone")
    text = "\n".join(lines)
    print(text)
    if not args.no_save:
        out = ROOT / "bench" / "results" / "floor.txt"
        out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
