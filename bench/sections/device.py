"""Thread scaling of core.bake_ao alone, for the many-core device machine (no Blender there).

    python -m bench.device [--res 1024] [--spp 64] [--threads 1 2 4 8 16] [--out FILE]

Bakes the benchmark scene saved by ``python -m bench`` (bench/data/scene_suzanne.npz, target
Suzanne and its occluders) at each thread count and at each count of worker processes (--workers), and replays embreex alone on synthetic rays of the
same scene at each thread count, so that the core's scaling can be told from Embree's. At each count
the same bake also runs with Embree's answer replaced by a constant (``constant_answer``: no ray occluded;
every numpy call the bake makes, none into Embree, in every worker process too): the scaling of the work outside Embree alone, which runs in
threads of one Python process and takes turns at the GIL between its numpy calls, and the serial
share Amdahl's law gives it, (n / speed-up - 1) / (n - 1). Writes JSON
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

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

SCENE = Path(__file__).resolve().parents[1] / "data" / "scene_suzanne.npz"


def embree_alone(target, occluders, threads_list, rays=1 << 22, chunk=1 << 16, distance=1.5):
    """embreex alone on synthetic rays of the scene (area-uniform origins, cosine directions), at
    each thread count: the scaling a GIL-free caller gets on this machine."""
    from ..comparators.embree import normalized, occlusion_scene, replay, synthetic_rays

    meshes = normalized(target, occluders)
    chunks = synthetic_rays(meshes[0], rays, chunk, distance)
    scene = occlusion_scene(meshes)
    rows = []
    for n in threads_list:
        sec, cpu, occ = min(replay(scene, chunks, n) for _ in range(2))
        rows.append({"threads": n, "seconds": sec, "mrays_per_s": rays / sec / 1e6})
    return rows


def serial_share(threads, speedup):
    """Amdahl's serial share of work that runs ``speedup`` times faster on ``threads`` threads."""
    return None if threads < 2 else (threads / speedup - 1.0) / (threads - 1.0)


def _bake(target, occluders, n, processes, **kw):
    """The bake on ``n`` threads of this process, or with ``processes`` on ``n`` worker processes."""
    from core import bake_ao

    if processes:
        return bake_ao(target, occluders, workers=n, threads=1, **kw) if n > 1 else bake_ao(target, occluders,
                                                                                              threads=1, **kw)
    return bake_ao(target, occluders, threads=n, **kw)


def outside_embree(target, occluders, counts, repeats=2, processes=False, **kw):
    """Seconds of the bake with Embree answered by a constant (``constant_answer``: every query
    "not occluded" without calling Embree, in every worker too), at each thread or worker count (the
    fastest of ``repeats``; counts interleaved)."""
    best = {n: float("inf") for n in counts}
    for _ in range(repeats):
        for n in counts:
            best[n] = min(best[n], _bake(target, occluders, n, processes, constant_answer=True, **kw).seconds)
    return [best[n] for n in counts]


def scaling(target, occ, counts, alone, args, distance, processes):
    """Rows of the whole bake and of its work outside Embree at each count, with speed-ups and
    Amdahl's serial share."""
    kind = "workers" if processes else "threads"
    outside = outside_embree(target, occ, counts, processes=processes, resolution=args.res, samples=args.spp,
                             max_distance=distance, margin=16)
    _bake(target, occ, max(counts), processes, resolution=32, samples=1, max_distance=distance)  # warm pool
    rows = []
    for n, a, o in zip(counts, alone, outside):
        c0 = time.process_time()
        r = _bake(target, occ, n, processes, resolution=args.res, samples=args.spp, max_distance=distance, margin=16)
        cpu = time.process_time() - c0
        rows.append({kind: n, "threads": n, "seconds": r.seconds, "rays": r.rays,
                     "mrays_per_s": r.rays / r.seconds / 1e6, "trace_share": r.trace_seconds / (r.seconds * n),
                     "cpu_seconds": cpu, "embree_alone_mrays_per_s": a["mrays_per_s"], "outside_embree_seconds": o})
        print(f"{kind} {n:2d}: {r.seconds:7.2f} s  {rows[-1]['mrays_per_s']:6.2f} Mrays/s  "
              f"{100 * rows[-1]['trace_share']:.0f}% in embreex; embreex alone {a['mrays_per_s']:.2f} Mrays/s; "
              f"outside embreex alone {o:.2f} s", file=sys.stderr, flush=True)
    base, base_alone, base_outside = rows[0]["seconds"], alone[0]["seconds"], outside[0]
    for row, a in zip(rows, alone):
        row["speedup"] = base / row["seconds"]
        row["embree_alone_speedup"] = base_alone / a["seconds"]
        row["outside_embree_speedup"] = base_outside / row["outside_embree_seconds"]
        if counts[0] == 1:
            row["outside_embree_serial_share"] = serial_share(row["threads"], row["outside_embree_speedup"])
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description="core.bake_ao thread scaling")
    ap.add_argument("--res", type=int, default=1024)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    ap.add_argument("--workers", type=int, nargs="*", default=[1, 2, 4, 8, 16],
                    help="worker process counts (one thread each) to bake with too; none: threads only")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    from ..harness.memprobe import load_scene
    from core import bake_ao

    target, occ, distance = load_scene(SCENE)
    bake_ao(target, occ, resolution=args.res, samples=4, threads=1, max_distance=distance)  # warm up: pool, BVH
    counts = sorted(set(args.threads) | set(args.workers or ()))
    alone = embree_alone(target, occ, counts, distance=distance)
    pick = {n: a for n, a in zip(counts, alone)}
    rows = scaling(target, occ, args.threads, [pick[n] for n in args.threads], args, distance, processes=False)
    worker_rows = (scaling(target, occ, args.workers, [pick[n] for n in args.workers], args, distance, processes=True)
                   if args.workers else [])
    data = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
            "python": sys.version.split()[0], "numpy": np.__version__,
            "when": time.strftime("%Y-%m-%dT%H:%M:%S"), "resolution": args.res, "samples": args.spp,
            "rows": rows, "worker_rows": worker_rows, "embree_alone": alone,
            "note": "outside_embree: the same bake with Embree's answer replaced by a constant (no ray occluded); "
                    "serial share: Amdahl's, (n / speed-up - 1) / (n - 1), from the first row's one thread"}
    text = json.dumps(data, indent=1)
    out = args.out or (os.path.join(os.environ["OUT"], "device.json") if os.environ.get("OUT") else None)
    if out:
        Path(out).write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
