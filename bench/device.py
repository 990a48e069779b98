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
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

SCENE = Path(__file__).resolve().parent / "data" / "scene_suzanne.npz"


def embree_alone(target, occluders, threads_list, rays=1 << 22, chunk=1 << 16):
    from bench.ceiling import _embree_scene, _replay

    class Ctx:
        pass

    ctx = Ctx()
    ctx.target = target
    from bench.ceiling import _synthetic_rays

    chunks = _synthetic_rays(ctx, rays, chunk)
    scene = _embree_scene([target] + list(occluders))
    rows = []
    for n in threads_list:
        sec, occ = min(_replay(scene, chunks, n) for _ in range(2))
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
    bake_ao(target, occ, resolution=64, samples=4, threads=1, max_distance=distance)  # warm up
    rows = []
    for n in args.threads:
        r = bake_ao(target, occ, resolution=args.res, samples=args.spp, threads=n, max_distance=distance, margin=16)
        rows.append({"threads": n, "seconds": r.seconds, "rays": r.rays, "mrays_per_s": r.rays / r.seconds / 1e6,
                     "trace_share": r.trace_seconds / (r.seconds * r.threads)})
        print(f"threads {n:2d}: {r.seconds:7.2f} s  {rows[-1]['mrays_per_s']:6.2f} Mrays/s  "
              f"{100 * rows[-1]['trace_share']:.0f}% in embreex", file=sys.stderr, flush=True)
    data = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
            "python": sys.version.split()[0], "numpy": np.__version__,
            "when": time.strftime("%Y-%m-%dT%H:%M:%S"), "resolution": args.res, "samples": args.spp,
            "rows": rows, "embree_alone": embree_alone(target, occ, args.threads)}
    text = json.dumps(data, indent=1)
    out = args.out or (os.path.join(os.environ["OUT"], "device.json") if os.environ.get("OUT") else None)
    if out:
        Path(out).write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
