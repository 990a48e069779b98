"""Does adaptive sampling pay? Time to the same RMSE, adaptive against the best fixed sample count.

For each scene: a reference (exact where known, else a long bake with its own seed), a series of
fixed-sample bakes (16 .. 1024 spp) and a series of adaptive bakes (target_error 0.04 .. 0.005, cap
4096), all with the defaults otherwise. Each adaptive point's RMSE is looked up on the fixed series
(log-log interpolation of RMSE against time): the fixed bake that reaches the same RMSE, and the
ratio of the two times (adaptive / fixed: below 1 means adaptive pays). Times are CPU seconds of
bakes on one thread (``TIMING_THREADS``), fastest of the repeats, the fixed and adaptive bakes of a
scene interleaved in every repeat: the work each bake does. With two
threads on this 2-core machine the process CPU time of a 96^2 to 128^2 bake was 1.5 to 2 times its
one-thread time and moved by +-30% from run to run (GIL hand-offs, two threads on two cores beside
other work), which drowned the comparison (the box at t=0.04: 1.05, then 1.33 for the same bakes).
References are baked with all the threads asked for.

The fixed series uses core.bake_ao's defaults, replicates=2 (an error map, as every adaptive bake has);
the add-on's fixed bakes without an error map use replicates=1, which gives 1.16-1.20 times less RMSE
at equal rays with Sobol' (the section's last line), a gain adaptive sampling does not have.

Scenes:

- suzanne: the benchmark's scene (Suzanne over a plane and two blocks, AO distance 1.5), target Suzanne;
- room: sample_scenes/room.blend, target Room (the walls), AO distance 1: open walls, dark corners;
- box: a plane with a box resting on it, AO distance half the box's height: open floor far away, a
  fully occluded footprint, a contact shadow;
- disk: a plane under a hovering 64-gon, no distance: every texel partly occluded with similar variance.
  No allocation gains much there; for independent samples the bound on the gain at equal RMSE is
  E[var] / E[sd]^2 over the texels (var = AO (1 - AO) of the cosine estimator), reported beside it.

Also the cost of the error model at equal rays: RMSE of replicates=2 (the default) over replicates=1,
per source, on the disk scene.

Run alone: ``.venv/bin/python -m bench.sections.adaptive [--quick]`` (bpy needed for suzanne and room).
"""

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from core import Mesh, bake_ao  # noqa: E402
from core.montecarlo.analytic import polygon_form_factor, regular_polygon, texel_mean  # noqa: E402

from ..harness.common import log  # noqa: E402
from ..harness.mcao import core_bake  # noqa: E402

QUAD = np.array([[0, 1, 2], [0, 2, 3]])
FULL = dict(res=96, fixed=(16, 32, 64, 128, 256, 512, 1024), targets=(0.04, 0.02, 0.01, 0.005), cap=4096,
            ref_spp=8192, repeats=2, cost_spp=(64, 256, 1024), cost_seeds=3)
QUICK = dict(res=48, fixed=(16, 64, 256), targets=(0.04, 0.01), cap=1024, ref_spp=2048, repeats=1,
             cost_spp=(64,), cost_seeds=1)


def _plane(size=1.0):
    P = np.array([[0, 0, 0], [size, 0, 0], [size, size, 0], [0, size, 0]], float)
    return Mesh(P, QUAD, uvs=P[QUAD][:, :, :2] / size, name="plane")


def _box(lo, hi):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    P = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], float)
    F = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                  [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
    return Mesh(P, F, name="box")


def numpy_scenes(res):
    """(name, target, occluders, max_distance, exact or None) of the scenes that need no Blender."""
    lid = regular_polygon(0.3, 0.25, 64, centre=(0.5, 0.5))
    disk = Mesh(lid, np.array([[0, i, i + 1] for i in range(1, 63)]), name="disk")
    truth = texel_mean(lambda p: 1.0 - polygon_form_factor(p, lid), res, res)
    box = _box((0.35, 0.35, 0.0), (0.65, 0.65, 0.3))
    return [("box", _plane(), [box], 0.15, None), ("disk", _plane(), [disk], math.inf, truth)]


def room_scene(bpy):
    """The room scene as (name, target, occluders, max_distance, exact or None): sample_scenes/room.blend
    opened in ``bpy`` (the file stays open), read back through the add-on's extraction."""
    from ..harness import scene

    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / "room.blend"), load_ui=False)
    ta, oa = scene.scene_arrays(bpy, "Room")
    target, occluders = scene.core_meshes(ta, oa)
    return ("room", target, occluders, 1.0, None)


def blender_scenes(ctx):
    """The benchmark scene and the room, read back through the add-on's extraction."""
    from ..harness import scene

    out = [("suzanne", ctx.target, ctx.occluders, scene.DISTANCE, None), room_scene(ctx.bpy)]
    ctx.restore_scene()
    return out


def _rmse(a, b, sel):
    d = a[sel].astype(np.float64) - b[sel]
    return float(np.sqrt(np.mean(d * d)))


def _fixed_cpu_at(fixed, rmse):
    """CPU seconds of the fixed series at ``rmse`` (log-log interpolation; None outside the series)."""
    r = np.log([p["rmse"] for p in fixed])
    t = np.log([p["cpu_seconds"] for p in fixed])
    order = np.argsort(r)
    r, t = r[order], t[order]
    x = math.log(rmse)
    if x < r[0] or x > r[-1]:
        return None
    return float(math.exp(np.interp(x, r, t)))


#: Threads of the timed bakes (see the module docstring).
TIMING_THREADS = 1


def adaptive_scene(name, target, occluders, distance, truth, cfg, threads, clock=None):
    res = cfg["res"]
    kw = dict(resolution=res, threads=TIMING_THREADS)
    if truth is None:
        ref = core_bake(target, occluders, max_distance=distance, samples=cfg["ref_spp"], seed=987654321,
                        resolution=res, threads=threads)
        truth, mask, ref_noise = ref.ao.astype(np.float64), ref.mask, float(np.sqrt(np.mean(ref.stderr[ref.mask] ** 2)))
    else:
        mask, ref_noise = np.ones_like(truth, bool), 0.0
    # Every bake of the scene once per repeat, fixed and adaptive interleaved, the fastest repeat
    # kept: a machine that slows down for a while slows both series, not one.
    runs = [dict(samples=spp) for spp in cfg["fixed"]]
    runs += [dict(samples=cfg["cap"], min_samples=16, target_error=t) for t in cfg["targets"]]
    best = [None] * len(runs)
    for _ in range(cfg["repeats"]):
        for i, args in enumerate(runs):
            r = core_bake(target, occluders, max_distance=distance, seed=5, **args, **kw)
            if best[i] is None:
                best[i] = r
            else:
                best[i].cpu_seconds = min(best[i].cpu_seconds, r.cpu_seconds)
                best[i].seconds = min(best[i].seconds, r.seconds)
    nf = len(cfg["fixed"])
    fixed = [dict(samples=spp, cpu_seconds=r.cpu_seconds, seconds=r.seconds, rmse=_rmse(r.ao, truth, mask))
             for spp, r in zip(cfg["fixed"], best[:nf])]
    adaptive = []
    for t, r in zip(cfg["targets"], best[nf:]):
        e = _rmse(r.ao, truth, mask)
        at = _fixed_cpu_at(fixed, e)
        n = r.samples[r.mask]
        adaptive.append(dict(target_error=t, cpu_seconds=r.cpu_seconds, seconds=r.seconds, rmse=e,
                             mean_samples=float(n.mean()), at_min=float(np.mean(n == 16)),
                             at_cap=float(np.mean(n == cfg["cap"])),
                             miss=float(np.mean(np.abs(r.ao[mask] - truth[mask]) > t)),
                             fixed_cpu_seconds=at, ratio=(r.cpu_seconds / at) if at else None))
    row = dict(scene=name, resolution=res, distance=distance, reference_noise=ref_noise, fixed=fixed,
               adaptive=adaptive)
    # The best any allocation can do for independent samples (cosine terms are 0 or 1: var = AO (1 - AO)):
    # n proportional to each texel's sd reaches the fixed count's RMSE with E[sd]^2 / E[var] of its samples.
    p = truth[mask]
    var = p * (1 - p)
    row["gain_bound_independent"] = float(var.mean() / np.mean(np.sqrt(var)) ** 2)
    ratios = [a["ratio"] for a in adaptive if a["ratio"] is not None]
    row["best_ratio"] = min(ratios) if ratios else None
    row["worst_ratio"] = max(ratios) if ratios else None
    if clock is not None:
        log(f"adaptive, {name}: adaptive / fixed CPU time at equal RMSE "
            + ", ".join(f"t={a['target_error']}: {a['ratio']:.2f}" if a["ratio"] else f"t={a['target_error']}: -"
                        for a in adaptive), clock)
    return row


def replicate_cost(cfg, threads, res):
    """RMSE at equal rays, replicates=2 over replicates=1, per source (the disk scene, exact truth)."""
    name, target, occ, distance, truth = numpy_scenes(res)[1]
    out = {}
    for source in ("sobol", "halton", "stratified", "independent"):
        rows = []
        for spp in cfg["cost_spp"]:
            e = {}
            for reps in (1, 2):
                errs = [bake_ao(target, occ, resolution=res, samples=spp, source=source, seed=s, replicates=reps,
                                margin=0, threads=threads).ao - truth for s in range(cfg["cost_seeds"])]
                e[reps] = float(np.sqrt(np.mean(np.square(errs))))
            rows.append(dict(samples=spp, rmse_1=e[1], rmse_2=e[2], ratio=e[2] / e[1]))
        out[source] = rows
    return out


def adaptive(ctx):
    """The section, as bench/harness/run.py calls it."""
    cfg = ctx.cfg["adaptive"]
    scenes = numpy_scenes(cfg["res"]) + blender_scenes(ctx)
    rows = [adaptive_scene(*s, cfg, ctx.threads, ctx.clock) for s in scenes]
    return {"scenes": rows, "replicate_cost": replicate_cost(cfg, ctx.threads, cfg["res"]),
            "measure": f"CPU seconds of {TIMING_THREADS}-thread bakes, fastest of repeats; RMSE over covered texels "
                       "against the exact "
                       "values (disk) or a reference bake with its own seed"}


def main(argv=None):
    import argparse

    from ..harness.common import Clock

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--no-blender", action="store_true", help="only the scenes that need no Blender")
    a = p.parse_args(argv)
    cfg = QUICK if a.quick else FULL
    clock = Clock()
    scenes = numpy_scenes(cfg["res"])
    if not a.no_blender:
        import os
        import tempfile

        os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="mc_ao_bench_blender_"))
        from ..harness.context import Context

        ctx = Context({}, a.threads)
        scenes += blender_scenes(ctx)
    for s in scenes:
        row = adaptive_scene(*s, cfg, a.threads, clock)
        for f in row["fixed"]:
            print(f"  {row['scene']:8s} fixed {f['samples']:5d} spp  cpu {f['cpu_seconds']:7.2f} s  RMSE {f['rmse']:.5f}")
        for ad in row["adaptive"]:
            print(f"  {row['scene']:8s} adaptive t={ad['target_error']:<6} cpu {ad['cpu_seconds']:7.2f} s  "
                  f"RMSE {ad['rmse']:.5f}  spp {ad['mean_samples']:7.1f}  at min {ad['at_min']:.0%}  "
                  f"miss {ad['miss']:.3f}  fixed cpu at that RMSE "
                  f"{ad['fixed_cpu_seconds'] or float('nan'):7.2f} s  ratio {ad['ratio'] or float('nan'):.2f}")
        print(f"  {row['scene']}: the best allocation needs E[sd]^2/E[var] = {1 / row['gain_bound_independent']:.3f} "
              "of the fixed count's samples (independent samples)")
    for source, rows in replicate_cost(cfg, a.threads, cfg["res"]).items():
        print(f"  replicates 2 vs 1, {source}: " + ", ".join(f"{r['samples']} spp {r['ratio']:.3f}" for r in rows))


if __name__ == "__main__":
    main()
