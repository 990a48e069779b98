"""Bakes that the denoiser prototypes filter, cached: the bench's three scenes (Suzanne, the room,
dense.blend) as core meshes, a noisy bake of each (two replicates, margin 0, as denoise=True takes
it), a converged reference of its own seed that no filter touched, and the guide.

    .venv/bin/python -m bench.prototypes.denoise_data --cache /var/tmp/denoise-cache --resolution 256 512

The meshes come from Blender once (bpy; ``--meshes``), as the operator extracts them; everything
else is numpy and the core.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

SCENES = ("suzanne", "room", "dense")


def extract_meshes(cache):
    """Each scene's target and occluders as the operator extracts them, to ``cache``/scene_NAME.npz."""
    import bpy

    from bench.sections.denoise import _open_scene

    for name in SCENES:
        _, target, occ, dist = _open_scene(bpy, name)
        d = dict(P=target.positions, F=target.triangles, UV=target.uvs, N=target.normals, distance=dist,
                 occluders=len(occ))
        for i, o in enumerate(occ):
            d[f"O{i}P"], d[f"O{i}F"] = o.positions, o.triangles
        np.savez(Path(cache) / f"scene_{name}.npz", **d)


def load_scene(cache, name):
    """(target, occluders, AO distance) of a cached scene."""
    from core import Mesh

    z = np.load(Path(cache) / f"scene_{name}.npz")
    target = Mesh(z["P"], z["F"], z["UV"], z["N"], name=name)
    occ = [Mesh(z[f"O{i}P"], z[f"O{i}F"], name=f"{name}_occluder{i}") for i in range(int(z["occluders"]))]
    return target, occ, float(z["distance"])


def bake(cache, name, res, samples, seed, replicates=2, threads=2, **kw):
    """The cached bake (ao, stderr, mask, samples, seconds) of a scene; baked and kept if missing."""
    from core import bake_ao

    extra = "".join(f"_{k}{v}" for k, v in sorted(kw.items()))
    path = Path(cache) / f"bake_{name}_{res}_{samples}_{seed}_r{replicates}{extra}.npz"
    if not path.exists():
        target, occ, dist = load_scene(cache, name)
        c = time.process_time()
        r = bake_ao(target, occ, resolution=res, samples=samples, max_distance=dist, seed=seed, threads=threads,
                    margin=0, replicates=replicates, **kw)
        np.savez(path, ao=r.ao, stderr=r.stderr, mask=r.mask, samples=r.samples, cpu=time.process_time() - c)
    z = np.load(path)
    return {k: z[k] for k in z.files}


def reference(cache, name, res, samples=2048):
    return bake(cache, name, res, samples, seed=10_001)


def guide(cache, name, res):
    """core.post.denoise.surface_guide of the scene's target (pickled in the cache)."""
    import pickle

    from core.post import denoise as D

    path = Path(cache) / f"guide_{name}_{res}.pkl"
    if not path.exists():
        target, _, _ = load_scene(cache, name)
        g = D.surface_guide(target, res)
        path.write_bytes(pickle.dumps(g))
    return pickle.loads(path.read_bytes())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=Path("/var/tmp/denoise-cache"))
    ap.add_argument("--resolution", type=int, nargs="+", default=[256, 512])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--samples", type=int, nargs="+", default=[16])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--reference-samples", type=int, default=2048)
    ap.add_argument("--meshes", action="store_true", help="extract the meshes from Blender first")
    a = ap.parse_args(argv)
    a.cache.mkdir(parents=True, exist_ok=True)
    if a.meshes:
        extract_meshes(a.cache)
    for res in a.resolution:
        for name in a.scenes:
            guide(a.cache, name, res)
            for n in a.samples:
                for s in a.seeds:
                    bake(a.cache, name, res, n, s)
            reference(a.cache, name, res, a.reference_samples)
            print(name, res, "ready", flush=True)


if __name__ == "__main__":
    main()
