"""The ceiling: embreex alone tracing the bake's own rays, the share of a bake spent inside embreex,
and a profile of where the rest of the time goes."""

import cProfile
import os
import pstats
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import mcao
from .common import log
from .scene import DISTANCE


def _record_rays(ctx, res, spp):
    """Run one single-threaded bake and keep every chunk of rays it hands to Embree.

    Wraps core.bake._Tracer.visibility (a private hook; None if the core no longer has it)."""
    try:
        from core import bake as core_bake_module
        tracer_cls = core_bake_module._Tracer
        original = tracer_cls.visibility
    except AttributeError:
        return None, None
    chunks = []

    def recording(self, org, dirs):
        chunks.append((np.array(org, np.float32), np.array(dirs, np.float32), float(self.tfar)))
        return original(self, org, dirs)

    tracer_cls.visibility = recording
    try:
        r = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=spp, threads=1, max_distance=DISTANCE)
    finally:
        tracer_cls.visibility = original
    return chunks, r


def _synthetic_rays(ctx, n, chunk):
    """Rays like the bake's when its hook is gone: area-uniform points on the target, cosine directions."""
    t = ctx.target
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
    return [(org[i:i + chunk].astype(np.float32), d[i:i + chunk].astype(np.float32), DISTANCE)
            for i in range(0, n, chunk)]


def _embree_scene(meshes):
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    P = np.concatenate([m.positions for m in meshes]).astype(np.float32)
    offs = np.cumsum([0] + [len(m.positions) for m in meshes[:-1]])
    F = np.concatenate([m.triangles + o for m, o in zip(meshes, offs)]).astype(np.int32)
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, P, F)
    scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32), query="OCCLUDED",
              dists=np.ones(1, np.float32))
    return scene


def _replay(scene, chunks, threads):
    """Seconds to trace every chunk (occlusion queries), on ``threads`` threads; fraction occluded."""
    hits = [0] * len(chunks)

    def one(i):
        o, d, tf = chunks[i]
        # A fresh tfar array per call, as any caller needs (Embree may write into it).
        hits[i] = int((scene.run(o, d, query="OCCLUDED", dists=np.full(len(o), tf, np.float32)) >= 0).sum())

    t0 = time.perf_counter()
    if threads == 1:
        for i in range(len(chunks)):
            one(i)
    else:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(one, range(len(chunks))))
    seconds = time.perf_counter() - t0
    n = sum(len(o) for o, _, _ in chunks)
    return seconds, sum(hits) / max(n, 1)


def _rechunk(chunks, size):
    o = np.concatenate([c[0] for c in chunks])
    d = np.concatenate([c[1] for c in chunks])
    tf = chunks[0][2]
    return [(o[i:i + size], d[i:i + size], tf) for i in range(0, len(o), size)]


def _profile(ctx, res, spp):
    pr = cProfile.Profile()
    pr.enable()
    r = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=spp, threads=1, max_distance=DISTANCE)
    pr.disable()
    st = pstats.Stats(pr)
    total = r.seconds
    rows = []
    by_file = {}
    for (fname, line, func), (cc, nc, tt, ct, _) in st.stats.items():
        short = os.path.relpath(fname, ctx.root) if fname.startswith(str(ctx.root)) else fname
        if short.startswith(".venv") or "site-packages" in short:
            short = "numpy/other python"
        elif fname == "~":
            short = "C: " + ("embreex" if "EmbreeScene" in func or "embree" in func.lower() else
                             "numpy" if "numpy" in func else "builtin")
        rows.append({"function": f"{short}:{line}({func})", "ncalls": nc, "tottime": tt, "cumtime": ct})
        by_file[short] = by_file.get(short, 0.0) + tt
    rows.sort(key=lambda x: -x["tottime"])
    # embreex's run() is compiled Cython that cProfile does not see: its time lands in the own time of
    # the Python function that calls it. Move the measured trace time to a group of its own.
    for k in list(by_file):
        if k == "core/bake.py":
            by_file[k] -= r.trace_seconds
    by_file["embreex (scene.run, from trace_seconds)"] = r.trace_seconds
    groups = sorted(({"where": k, "seconds": v, "share": v / total} for k, v in by_file.items()),
                    key=lambda x: -x["seconds"])
    return {"resolution": res, "samples": spp, "threads": 1, "bake_seconds": total,
            "trace_seconds": r.trace_seconds, "top_functions": rows[:15], "by_file": groups[:12]}


def ceiling(ctx):
    cfg = ctx.cfg
    res, spp = cfg["ceil_res"], cfg["ceil_spp"]
    chunks, r = _record_rays(ctx, res, spp)
    recorded = chunks is not None
    if not recorded:
        log("ceiling: core.bake._Tracer.visibility not found; replaying synthetic rays", ctx.clock)
        r = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=spp, threads=1, max_distance=DISTANCE)
        chunks = _synthetic_rays(ctx, r.rays, 1 << 16)
    n = sum(len(o) for o, _, _ in chunks)
    scene = _embree_scene([ctx.target] + list(ctx.occluders))
    out = {"rays": n, "rays_source": "recorded from the bake" if recorded else "synthetic (area-uniform, cosine)",
           "chunks_in_bake": len(chunks), "bake": {"resolution": res, "samples": spp, "threads": 1,
                                                    "seconds": r.seconds, "trace_seconds": r.trace_seconds,
                                                    "mrays_per_s": r.rays / r.seconds / 1e6,
                                                    "trace_share": r.trace_seconds / r.seconds}}
    replays = []
    for threads in (1, 2):
        best = min(_replay(scene, chunks, threads) for _ in range(3))
        replays.append({"threads": threads, "chunk": "as in the bake", "seconds": best[0],
                        "mrays_per_s": n / best[0] / 1e6, "occluded_fraction": best[1]})
    for size in (1 << 12, 1 << 20):
        rc = _rechunk(chunks, size)
        best = min(_replay(scene, rc, 1) for _ in range(2))
        replays.append({"threads": 1, "chunk": size, "seconds": best[0], "mrays_per_s": n / best[0] / 1e6,
                        "occluded_fraction": best[1]})
    out["embree_alone"] = replays
    out["bake_vs_ceiling_1thread"] = out["bake"]["mrays_per_s"] / replays[0]["mrays_per_s"]
    r2 = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=spp, threads=2, max_distance=DISTANCE)
    out["bake_2threads"] = {"seconds": r2.seconds, "mrays_per_s": r2.rays / r2.seconds / 1e6,
                            "trace_share": r2.trace_seconds / (r2.seconds * r2.threads)}
    del chunks
    log(f"ceiling: embreex alone {replays[0]['mrays_per_s']:.2f} Mrays/s (1 thread), "
        f"{replays[1]['mrays_per_s']:.2f} (2 threads); bake {out['bake']['mrays_per_s']:.2f} Mrays/s, "
        f"{100 * out['bake']['trace_share']:.0f}% inside embreex", ctx.clock)
    out["profile"] = _profile(ctx, cfg["prof_res"], cfg["prof_spp"])
    return out
