"""Scaling of core.bake_ao: threads, resolution, triangle count, and the peak memory of a 4096^2 bake."""

import json
import subprocess
import sys

from ..comparators.embree import normalized, occlusion_scene, record_rays, replay
from ..harness import mcao
from ..harness.common import ROOT, log
from ..harness.scene import DISTANCE, displaced_grid


def _bake_row(r, **extra):
    texels = int(r.mask.sum())
    return dict(seconds=r.seconds, texels=texels, rays=r.rays, threads=r.threads,
                cpu_seconds=getattr(r, "cpu_seconds", None), trace_cpu_seconds=r.trace_cpu_seconds,
                mtexel_samples_per_s=texels * r.samples[r.mask].mean() / r.seconds / 1e6 if texels else 0.0,
                mrays_per_s=r.rays / r.seconds / 1e6, trace_share=r.trace_seconds / (r.seconds * r.threads),
                **extra)


def threads(ctx):
    """1 against 2 threads, interleaved with embreex alone replaying the bake's own rays on 1 and 2
    threads as a calibration: on a shared machine the second core is not always free, and the
    calibration shows how much of it was at that moment."""
    import time

    cfg = ctx.cfg
    res, spp = cfg["thr_res"], cfg["thr_spp"]
    kw = dict(resolution=res, samples=spp, max_distance=DISTANCE, margin=16)
    chunks, _ = record_rays(ctx.target, ctx.occluders, threads=1, **kw)
    scene = occlusion_scene(normalized(ctx.target, ctx.occluders))
    times = {1: [], 2: []}
    calib = {1: [], 2: []}
    cpu = {}
    rows = {}
    for _ in range(cfg["thr_repeats"]):
        for n in (1, 2):
            calib[n].append(replay(scene, chunks, n)[0])
            c0 = time.process_time()
            r = mcao.core_bake(ctx.target, ctx.occluders, threads=n, **kw)
            c = time.process_time() - c0
            times[n].append(r.seconds)
            if n not in rows or r.seconds < rows[n]["seconds"]:
                rows[n] = _bake_row(r, resolution=res, samples=spp)
                cpu[n] = c / r.seconds
    del chunks
    for n in (1, 2):
        rows[n]["cpu_per_wall"] = cpu[n]
    embree_speedup = min(calib[1]) / min(calib[2])
    speedup = rows[1]["seconds"] / rows[2]["seconds"]
    out = {"resolution": res, "samples": spp, "rows": [rows[1], rows[2]], "seconds_all": times,
           "speedup_1_to_2": speedup, "embree_alone_seconds_all": calib, "embree_alone_speedup_1_to_2": embree_speedup,
           "relative_to_embree": speedup / embree_speedup,
           "note": "cpu_per_wall: process CPU seconds per wall second during the bake (2.0 = both cores busy); "
                   "embree_alone_speedup: embreex alone on the bake's own rays, 1 -> 2 threads, interleaved"}
    log(f"threads: 1 -> {rows[1]['seconds']:.2f}s, 2 -> {rows[2]['seconds']:.2f}s, speed-up "
        f"{speedup:.2f}x (embreex alone {embree_speedup:.2f}x; bake CPU/wall {cpu[2]:.2f})", ctx.clock)
    return out


def resolution(ctx):
    cfg = ctx.cfg
    rows = []
    for res in cfg["scale_res"]:
        r = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=cfg["scale_spp"], threads=ctx.threads,
                           max_distance=DISTANCE, margin=16)
        rows.append(_bake_row(r, resolution=res, samples=cfg["scale_spp"]))
        log(f"resolution {res}^2 x {cfg['scale_spp']}: {r.seconds:.2f}s", ctx.clock)
    # One sample per texel isolates the per-texel work (rasterising, units, margin): the bake's time
    # less its time inside embreex (per thread) is the fixed cost of the image's size.
    fixed = []
    for res in cfg["scale_res_1spp"]:
        r = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=1, threads=ctx.threads,
                           max_distance=DISTANCE, margin=16)
        fixed.append(_bake_row(r, resolution=res, samples=1,
                               fixed_seconds=r.seconds - r.trace_seconds / r.threads))
        log(f"resolution {res}^2 x 1: {r.seconds:.2f}s, of which outside embreex {fixed[-1]['fixed_seconds']:.2f}s",
            ctx.clock)
    return {"rows": rows, "one_sample": fixed}


def triangles(ctx):
    from core import Mesh

    cfg = ctx.cfg
    rows = []
    for n in cfg["tri_n"]:
        P, F, UV = displaced_grid(n)
        mesh = Mesh(P, F, UV, name=f"grid{n}")
        # The fastest of the repeats counts, as everywhere in the bench. The first bake of a large
        # mesh in a process is slower here for a reason of this machine's, not the code's: this VM
        # backs its memory on first touch (a fresh 256 MB array fills in 300 ms the first time, 50
        # ms after), and a million triangles' arrays are more than the process held before.
        seconds = []
        for _ in range(cfg["tri_repeats"]):
            r = mcao.core_bake(mesh, [], resolution=cfg["tri_res"], samples=cfg["tri_spp"], threads=ctx.threads,
                               max_distance=0.5, margin=0)
            seconds.append(r.seconds)
            if r.seconds <= min(seconds):
                best = r
        rows.append(_bake_row(best, triangles=len(F), resolution=cfg["tri_res"], samples=cfg["tri_spp"],
                              seconds_all=seconds))
        log(f"triangles {len(F)}: {best.seconds:.2f}s ({100 * rows[-1]['trace_share']:.0f}% in embreex; "
            f"every repeat {', '.join(f'{x:.2f}' for x in seconds)} s)", ctx.clock)
    return {"scene": "displaced grid (smooth bumps), self-occluding, max distance 0.5", "rows": rows}


def memory(ctx):
    cfg = ctx.cfg
    if not cfg["mem_res"]:
        return {"skipped": "quick mode"}
    path = ctx.scene_npz()
    cmd = [sys.executable, "-m", "bench.harness.memprobe", str(path), str(cfg["mem_res"]), str(cfg["mem_spp"]),
           str(ctx.threads)]
    log(f"memory: {cfg['mem_res']}^2 x {cfg['mem_spp']} in a fresh process", ctx.clock)
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=1800)
    if p.returncode != 0:
        return {"error": p.stderr[-2000:]}
    out = json.loads(p.stdout.strip().splitlines()[-1])
    out["texel_samples_per_s"] = out["texels"] * out["samples"] / out["bake_seconds"]
    log(f"memory: peak RSS {out['peak_rss_mib']:.0f} MiB ({out['rss_before_mib']:.0f} MiB before the bake), "
        f"{out['bake_seconds']:.1f}s", ctx.clock)
    return out
