"""Thread scaling of core.bake_ao alone, for the many-core device machine (no Blender there).

    python -m bench.device [--res 1024] [--spp 64] [--threads 1 2 4 8 16] [--out FILE]

Bakes the benchmark scene saved by ``python -m bench`` (bench/data/scene_suzanne.npz, target
Suzanne and its occluders) at each thread count, and replays embreex alone on synthetic rays of the
same scene at each thread count, so that the core's scaling can be told from Embree's. Writes JSON
(to --out, else $OUT/device.json, else stdout); copy it to bench/results/device.json and the next
``python -m bench`` merges it into its table.
"""

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

SCENE = Path(__file__).resolve().parent / "data" / "scene_suzanne.npz"


def embree_alone(target, occluders, threads_list, rays=1 << 22, chunk=1 << 16, distance=1.5):
    """embreex alone on synthetic rays of the scene (area-uniform origins, cosine directions), at
    each thread count: the scaling a GIL-free caller gets on this machine."""
    from bench.ceiling import _normalized, _replay, _synthetic_rays, embree_scene

    meshes = _normalized(target, occluders)
    chunks = _synthetic_rays(meshes[0], rays, chunk, distance)
    scene = embree_scene(meshes)
    rows = []
    for n in threads_list:
        sec, cpu, occ = min(_replay(scene, chunks, n) for _ in range(2))
        rows.append({"threads": n, "seconds": sec, "mrays_per_s": rays / sec / 1e6})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description="core.bake_ao thread scaling")
    ap.add_argument("--res", type=int, default=1024)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    from bench.memprobe import load_scene
    from core import bake_ao

    target, occ, distance = load_scene(SCENE)
    bake_ao(target, occ, resolution=args.res, samples=4, threads=1, max_distance=distance)  # warm up: pool, BVH
    rows = []
    alone = embree_alone(target, occ, args.threads, distance=distance)
    for n, a in zip(args.threads, alone):
        c0 = time.process_time()
        r = bake_ao(target, occ, resolution=args.res, samples=args.spp, threads=n, max_distance=distance, margin=16)
        cpu = time.process_time() - c0
        rows.append({"threads": n, "seconds": r.seconds, "rays": r.rays, "mrays_per_s": r.rays / r.seconds / 1e6,
                     "trace_share": r.trace_seconds / (r.seconds * r.threads), "cpu_seconds": cpu,
                     "trace_cpu_share": r.trace_cpu_seconds / cpu if cpu > 0 else None,
                     "embree_alone_mrays_per_s": a["mrays_per_s"]})
        print(f"threads {n:2d}: {r.seconds:7.2f} s  {rows[-1]['mrays_per_s']:6.2f} Mrays/s  "
              f"{100 * rows[-1]['trace_share']:.0f}% in embreex; embreex alone {a['mrays_per_s']:.2f} Mrays/s",
              file=sys.stderr, flush=True)
    base, base_alone = rows[0]["seconds"], alone[0]["seconds"]
    for row, a in zip(rows, alone):
        row["speedup"] = base / row["seconds"]
        row["embree_alone_speedup"] = base_alone / a["seconds"]
    data = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
            "python": sys.version.split()[0], "numpy": np.__version__,
            "when": time.strftime("%Y-%m-%dT%H:%M:%S"), "resolution": args.res, "samples": args.spp,
            "rows": rows, "embree_alone": alone}
    text = json.dumps(data, indent=1)
    out = args.out or (os.path.join(os.environ["OUT"], "device.json") if os.environ.get("OUT") else None)
    if out:
        Path(out).write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
