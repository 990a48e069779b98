"""The ceiling: a bake against Embree alone tracing the bake's own rays, the share of a bake spent
inside embreex, and a profile of where the rest of the time goes.

For each scene (the benchmark's Suzanne scene and a dense terrain), one thread:

- the bake, timed (wall and process CPU), with embreex's own time from ``BakeResult.trace_seconds``
  (wall) and ``trace_cpu_seconds`` (thread CPU): the share inside embreex;
- the same bake once more with ``on_rays`` (core.tracing.RayBatch) recording every chunk of rays;
- embreex alone replaying those chunks, 1 and 2 threads, interleaved with repeats of the bake: the
  bake's rays/s against embreex's on the very same rays, fastest repeat each.
"""

import cProfile
import os
import pstats
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import mcao
from .common import log
from .scene import DISTANCE, displaced_grid


def _record_rays(target, occluders, **kw):
    """One bake through the public on_rays hook: every chunk of rays it hands to Embree."""
    chunks = []

    def keep(batch):
        chunks.append((np.array(batch.origins, np.float32), np.array(batch.directions, np.float32),
                       np.array(batch.tfar, np.float32)))

    r = mcao.core_bake(target, occluders, on_rays=keep, **kw)
    return chunks, r


def embree_scene(meshes):
    """The committed Embree scene the bake itself traces its occlusion rays in (core.tracing.Tracer:
    the same robust mode)."""
    from core.tracing import OCCLUSION_ROBUST, embree_scene as build

    return build(meshes, robust=OCCLUSION_ROBUST)[0]


def _replay(scene, chunks, threads):
    """(wall seconds, process CPU seconds, occluded fraction) of embreex tracing every chunk on
    ``threads`` threads. The rays are in the bake's own (normalised) frame; so is the scene."""
    hits = [0] * len(chunks)

    def one(i):
        o, d, tf = chunks[i]
        # A fresh tfar array per call, as any caller needs (Embree may write into it).
        hits[i] = int((scene.run(o, d, query="OCCLUDED", dists=tf.copy()) >= 0).sum())

    c0, t0 = time.process_time(), time.perf_counter()
    if threads == 1:
        for i in range(len(chunks)):
            one(i)
    else:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(one, range(len(chunks))))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    n = sum(len(o) for o, _, _ in chunks)
    return seconds, cpu, sum(hits) / max(n, 1)


def _synthetic_rays(target, n, chunk, distance=DISTANCE):
    """Rays like a bake's (area-uniform points on the target, cosine directions), for machines where
    only embreex's own scaling is wanted (bench/device.py)."""
    t = target
    rng = np.random.default_rng(0)
    p = t.positions[t.triangles]
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    tri = rng.choice(len(area), n, p=area / area.sum())
    a, b = rng.random(n), rng.random(n)
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    org = p[tri, 0] + a[:, None] * (p[tri, 1] - p[tri, 0]) + b[:, None] * (p[tri, 2] - p[tri, 0])
    nrm = t.face_normals[tri]
    v = rng.normal(size=(n, 3))
    d = nrm + v / np.linalg.norm(v, axis=1, keepdims=True)  # cosine-distributed about nrm
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    org = org + nrm * 1e-5
    return [(org[i:i + chunk].astype(np.float32), d[i:i + chunk].astype(np.float32),
             np.full(min(chunk, n - i), distance, np.float32)) for i in range(0, n, chunk)]


def _normalized(target, occluders):
    """The bake's own frame (core.bake._normalized_scene), so that replayed rays hit the same scene."""
    from core.bake import _normalized_scene

    t, occ, _ = _normalized_scene(target, list(occluders))
    return [t] + occ


def _profile(ctx, target, occluders, res, spp, distance):
    pr = cProfile.Profile(timer=time.thread_time)
    pr.enable()
    r = mcao.core_bake(target, occluders, resolution=res, samples=spp, threads=1, max_distance=distance)
    pr.disable()
    st = pstats.Stats(pr)
    total = sum(tt for (_, _, _), (_, _, tt, _, _) in st.stats.items())
    rows, by_file = [], {}
    for (fname, line, func), (cc, nc, tt, ct, _) in st.stats.items():
        short = os.path.relpath(fname, ctx.root) if fname.startswith(str(ctx.root)) else fname
        if short.startswith(".venv") or "site-packages" in short:
            short = "numpy/other python"
        elif fname == "~":
            short = "C: " + ("numpy" if "numpy" in func else "builtin")
        rows.append({"function": f"{short}:{line}({func})", "ncalls": nc, "tottime": tt, "cumtime": ct})
        by_file[short] = by_file.get(short, 0.0) + tt
    rows.sort(key=lambda x: -x["tottime"])
    # embreex's run() is compiled Cython that cProfile does not see: its time lands in the own time of
    # core/tracing.py. Move the measured (thread CPU) trace time to a group of its own.
    if "core/tracing.py" in by_file:
        by_file["core/tracing.py"] -= r.trace_cpu_seconds
    by_file["embreex (scene.run, from trace_cpu_seconds)"] = r.trace_cpu_seconds
    groups = sorted(({"where": k, "seconds": v, "share": v / total} for k, v in by_file.items()),
                    key=lambda x: -x["seconds"])
    return {"resolution": res, "samples": spp, "threads": 1, "cpu_seconds": total, "bake_seconds": r.seconds,
            "trace_cpu_seconds": r.trace_cpu_seconds, "top_functions": rows[:15], "by_file": groups[:12]}


def _scene_ceiling(ctx, name, target, occluders, distance, res, spp, repeats):
    meshes = _normalized(target, occluders)
    kw = dict(resolution=res, samples=spp, threads=1, max_distance=distance, margin=16)
    mcao.core_bake(target, occluders, **dict(kw, resolution=64))  # warm up (pool, imports)
    chunks, rec = _record_rays(target, occluders, **kw)
    n = sum(len(o) for o, _, _ in chunks)
    scene = embree_scene(meshes)
    bakes, alone1, alone2 = [], [], []
    for _ in range(repeats):
        r = mcao.core_bake(target, occluders, **kw)
        bakes.append(dict(seconds=r.seconds, cpu_seconds=r.cpu_seconds, trace_seconds=r.trace_seconds,
                          trace_cpu_seconds=r.trace_cpu_seconds, rays=r.rays))
        alone1.append(_replay(scene, chunks, 1))
        alone2.append(_replay(scene, chunks, 2))
    best = min(bakes, key=lambda b: b["seconds"])
    best_cpu = min(bakes, key=lambda b: b["cpu_seconds"])
    a1 = min(alone1, key=lambda x: x[0])
    a1c = min(x[1] for x in alone1)
    a2 = min(alone2, key=lambda x: x[0])
    out = {"scene": name, "triangles": int(sum(m.triangle_count for m in meshes)), "resolution": res,
           "samples": spp, "rays": n, "bake": best, "bake_all": bakes,
           "share_wall": best["trace_seconds"] / best["seconds"],
           "share_cpu": best_cpu["trace_cpu_seconds"] / best_cpu["cpu_seconds"],
           "bake_mrays_per_s": best["rays"] / best["seconds"] / 1e6,
           "alone_1": {"seconds": a1[0], "cpu_seconds": a1c, "mrays_per_s": n / a1[0] / 1e6, "occluded": a1[2]},
           "alone_2": {"seconds": a2[0], "mrays_per_s": n / a2[0] / 1e6},
           "bake_over_alone": best["seconds"] / a1[0], "bake_over_alone_cpu": best_cpu["cpu_seconds"] / a1c}
    log(f"ceiling {name} {res}^2 x {spp}: bake {best['seconds']:.2f}s, {100 * out['share_wall']:.0f}% in embreex "
        f"(CPU {100 * out['share_cpu']:.0f}%); embreex alone on the same rays {a1[0]:.2f}s "
        f"(bake / alone {out['bake_over_alone']:.2f}x, CPU {out['bake_over_alone_cpu']:.2f}x)", ctx.clock)
    del chunks
    return out


def terrain(n=256):
    """The dense terrain: a displaced grid of 2 n^2 triangles (131k for n = 256), its own occluder."""
    from core import Mesh

    P, F, UV = displaced_grid(n)
    return Mesh(P, F, UV, name=f"terrain{2 * n * n}"), [], 0.5


def ceiling(ctx):
    cfg = ctx.cfg
    res, spp = cfg["ceil_res"], cfg["ceil_spp"]
    out = {"scenes": []}
    out["scenes"].append(_scene_ceiling(ctx, "Suzanne scene", ctx.target, ctx.occluders, DISTANCE, res, spp,
                                        cfg["ceil_repeats"]))
    t, occ, d = terrain(cfg["terrain_n"])
    out["scenes"].append(_scene_ceiling(ctx, f"terrain ({t.triangle_count} triangles)", t, occ, d, res, spp,
                                        cfg["ceil_repeats"]))
    out["profile"] = _profile(ctx, ctx.target, ctx.occluders, cfg["prof_res"], cfg["prof_spp"], DISTANCE)
    return out
