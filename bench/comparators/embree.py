"""Raw Embree, the ceiling mc_ao is measured against: embreex alone tracing the rays a bake traces
(recorded through core.bake_ao's public ``on_rays`` hook) or rays like them, on 1..n threads."""

import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..harness import mcao
from ..harness.scene import DISTANCE


def record_rays(target, occluders, **kw):
    """One bake through the public on_rays hook: every chunk of rays it hands to Embree."""
    chunks = []

    def keep(batch):
        chunks.append((np.array(batch.origins, np.float32), np.array(batch.directions, np.float32),
                       np.array(batch.tfar, np.float32)))

    r = mcao.core_bake(target, occluders, on_rays=keep, **kw)
    return chunks, r


def occlusion_scene(meshes):
    """The committed Embree scene the bake itself traces its occlusion rays in (core.tracing.tracer.Tracer:
    the same robust mode)."""
    from core.tracing.tracer import OCCLUSION_ROBUST, embree_scene as build

    return build(meshes, robust=OCCLUSION_ROBUST)[0]


def replay(scene, chunks, threads):
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


def synthetic_rays(target, n, chunk, distance=DISTANCE):
    """Rays like a bake's (area-uniform points on the target, cosine directions), for machines where
    only embreex's own scaling is wanted (bench/sections/device.py)."""
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


def normalized(target, occluders):
    """The bake's own frame (core.pipeline.prologue.normalized_scene), so that replayed rays hit the same scene."""
    from core.pipeline.prologue import normalized_scene

    t, occ, _ = normalized_scene(target, list(occluders))
    return [t] + occ
