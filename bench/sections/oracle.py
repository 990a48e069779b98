"""The most any allocation of samples could save: an oracle that knows each texel's expected error.

The target asks adaptive sampling to reach the best fixed sample count's RMSE in at most 0.6 of its
time on the Suzanne and room scenes. This measures what the best possible allocation of the same
sampler reaches, so that the adaptive section's ratios can be read against it:

- Fixed bakes at n = 16, 32, ..., 1024 samples per texel with ``SEEDS`` seeds, with core.bake_ao's
  defaults (Sobol', two replicates: the adaptive section's fixed series, and what every adaptive
  bake samples). A texel's samples depend only on (texel, sample index, seed), so the bake at n is
  each texel's estimate after its first n samples, whatever other texels take: any adaptive bake of
  power-of-two counts is a choice of one of these estimates per texel.
- Each texel's expected squared error at each n: the mean over the seeds of (ao - truth)^2 (truth:
  exact for the disk, else the adaptive section's own reference, a long bake with its own seed).
- The oracle: every texel starts at 16; a greedy allocation then moves, one texel at a time, the
  texel whose next count up (any higher power of two) buys the most error per added sample. Along
  the way it records (mean samples, mean squared error); at each fixed count's RMSE it reads off the
  samples it needed.

The oracle knows each texel's error in advance (from the very seeds it is scored on), which no
sampler can: it is a bound, not a method. It ignores an adaptive bake's own costs (rounds, error
estimates), so in time an adaptive bake does worse still. For independent samples the bound has a
closed form, E[sd]^2 / E[var] (n proportional to each texel's sd), printed beside it; the oracle
measures the same question for the sampler the bakes really use.

Run: ``.venv/bin/python -m bench.sections.oracle [--quick] [--no-blender]`` (the room needs bpy; the Suzanne
scene comes from ``bench/data/scene_suzanne.npz``, the benchmark's scene as the add-on extracts it).
"""

import heapq
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from core import bake_ao  # noqa: E402

from .adaptive import numpy_scenes, room_scene  # noqa: E402
from ..harness.common import Clock, log  # noqa: E402

FULL = dict(res=96, counts=(16, 32, 64, 128, 256, 512, 1024), seeds=8, ref_spp=8192)
QUICK = dict(res=48, counts=(16, 32, 64, 128, 256), seeds=2, ref_spp=2048)
REF_SEED = 987654321  # the adaptive section's reference seed


def _bake(target, occluders, distance, res, samples, seed, threads):
    return bake_ao(target, occluders, resolution=res, samples=samples, seed=seed, max_distance=distance,
                   margin=0, threads=threads)


def squared_errors(target, occluders, distance, truth, cfg, threads):
    """(seeds, texels, levels) squared error of each covered texel at each count, per seed; and the
    truth of the covered texels."""
    res, counts = cfg["res"], cfg["counts"]
    if truth is None:
        ref = _bake(target, occluders, distance, res, cfg["ref_spp"], REF_SEED, threads)
        truth, mask = ref.ao.astype(np.float64), ref.mask
    else:
        mask = None
    out = np.empty((cfg["seeds"], 0, len(counts)))
    for j, n in enumerate(counts):
        for seed in range(cfg["seeds"]):
            r = _bake(target, occluders, distance, res, n, 100 + seed, threads)
            if mask is None:
                mask = r.mask
            if j == 0 and seed == 0:
                out = np.empty((cfg["seeds"], int(mask.sum()), len(counts)))
            out[seed, :, j] = (r.ao[mask].astype(np.float64) - truth[mask]) ** 2
    return out, truth[mask]


def model_errors(sq, counts):
    """Each texel's expected squared error as c_i n^-a: a from the fixed bakes' mean error against n
    (least squares in log-log), c_i from all of the texel's levels and seeds (a texel's error at one
    count and seed alone is too noisy to allocate by: an allocation that trusts it picks lucky
    counts, and is scored on that luck)."""
    n = np.asarray(counts, np.float64)
    mean = sq.mean(axis=(0, 1))
    a = -np.polyfit(np.log(n), np.log(mean), 1)[0]
    c = (sq * n ** a).mean(axis=(0, 2))
    return c[:, None] * n ** -a, a


def allocate(err, counts, level_of=None):
    """Greedy allocation on ``err`` (texels, levels), non-increasing along the levels: every texel
    starts at counts[0]; each move takes the texel whose next level buys the most error per added
    sample. Returns the levels after every move as (moves, texel, level) for replay."""
    counts = np.asarray(counts, np.float64)
    m, L = err.shape
    gain = (err[:, :-1] - err[:, 1:]) / (counts[1:] - counts[:-1])  # (m, L - 1)
    heap = [(-gain[i, 0], i, 1) for i in range(m) if L > 1]
    heapq.heapify(heap)
    moves = []
    while heap:
        _, i, k = heapq.heappop(heap)
        moves.append((i, k))
        if k + 1 < L:
            heapq.heappush(heap, (-gain[i, k], i, k + 1))
    return moves


def replay(moves, err, counts):
    """(mean samples, mean squared error) of ``err`` along the allocation ``moves``."""
    counts = np.asarray(counts, np.float64)
    m = err.shape[0]
    level = np.zeros(m, np.int64)
    total_n, total_e = counts[0] * m, float(err[:, 0].sum())
    curve = [(total_n / m, total_e / m)]
    for i, k in moves:
        j = level[i]
        total_n += counts[k] - counts[j]
        total_e += err[i, k] - err[i, j]
        level[i] = k
        curve.append((total_n / m, total_e / m))
    return np.array(curve)


def oracle_scene(name, target, occluders, distance, truth, cfg, threads):
    sq, p = squared_errors(target, occluders, distance, truth, cfg, threads)
    half = cfg["seeds"] // 2
    model, a = model_errors(sq[:half], cfg["counts"])  # learnt on half the seeds
    scored = sq[half:].mean(axis=0)                    # scored on the others
    curve = replay(allocate(model, cfg["counts"]), scored, cfg["counts"])
    rows = []
    for j, n in enumerate(cfg["counts"][1:], start=1):
        fixed = float(scored[:, j].mean())
        reach = np.flatnonzero(curve[:, 1] <= fixed)
        need = float(curve[reach[0], 0]) if len(reach) else math.nan
        rows.append(dict(samples=n, rmse=math.sqrt(fixed), oracle_samples=need, ratio=need / n))
    var = np.clip(p, 0, 1) * (1 - np.clip(p, 0, 1))
    vary = float(np.mean((p > 0) & (p < 1)))
    return dict(scene=name, texels=int(len(p)), fixed=rows, varying=vary, rate=a,
                bound_independent=float(np.mean(np.sqrt(var)) ** 2 / var.mean()))


def main(argv=None):
    import argparse

    from ..harness.memprobe import load_scene

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--no-blender", action="store_true", help="leave out the room (it needs bpy)")
    a = p.parse_args(argv)
    cfg = QUICK if a.quick else FULL
    clock = Clock()
    t, o, d = load_scene(ROOT / "bench" / "data" / "scene_suzanne.npz")
    scenes = numpy_scenes(cfg["res"]) + [("suzanne", t, o, d, None)]
    if not a.no_blender:
        import bpy

        scenes.append(room_scene(bpy))
    print(f"oracle allocation, {cfg['res']}^2, counts {cfg['counts']}, {cfg['seeds']} seeds: the samples per texel "
          "an allocation knowing each texel's expected error needs for the fixed count's RMSE")
    for s in scenes:
        row = oracle_scene(*s, cfg, a.threads)
        log(f"oracle, {row['scene']} done", clock)
        print(f"  {row['scene']:8s} texels {row['texels']}, AO strictly between 0 and 1 in {row['varying']:.0%}; "
              f"independent-sample bound E[sd]^2/E[var] {row['bound_independent']:.2f}; "
              f"mean squared error ~ n^-{row['rate']:.2f}")
        for f in row["fixed"]:
            print(f"  {row['scene']:8s} fixed {f['samples']:5d} spp  RMSE {f['rmse']:.5f}  oracle "
                  f"{f['oracle_samples']:7.1f} spp  ratio {f['ratio']:.2f}")


if __name__ == "__main__":
    main()
