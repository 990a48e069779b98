"""What the analytic ground plane (core.tracing.ground) costs a bake: time(ground='auto') / time(no ground).

    .venv/bin/python -m bench.sections.ground            # 256^2 x 64, 512^2 x 64: about 2 minutes on 2 cores
    .venv/bin/python -m bench.sections.ground --quick    # 256^2 x 64

The bench's Suzanne scene (``bench/data/scene_suzanne.npz``: Suzanne and its three occluders, its AO
distance), 2 threads, the same seed; ``ground='auto'`` puts the plane at Suzanne's lowest point, so
that it takes part (rays cross it, points near it are probed for contact). Every ray the tracer is
given is tested against the plane (a crossing test on the origin's and end's z), the rays that cross
it are not handed to Embree, and contact probes include it. The target: at most 10% more than the
same bake without a ground. Repeated, interleaved (ground first, then none; then the other way),
median wall and process CPU seconds; the ratio's CPU figure is the one a busy neighbour on a shared
machine inflates least.

Writes bench/results/ground.json (``--quick``: ground-quick.json). Never a timed assertion.
"""

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness.common import RESULTS, git_state, load_average, machine  # noqa: E402
from bench.sections.maps import load_scene  # noqa: E402
from core import bake_ao  # noqa: E402

SIZES = [(256, 64), (512, 64)]
QUICK = [(256, 64)]


def measure(res, spp, repeats, threads):
    target, occ, dist = load_scene()
    kw = dict(resolution=res, samples=spp, max_distance=dist, threads=threads, seed=1)
    runs = {"ground": [], "none": []}
    bake_ao(target, occ, ground="auto", **kw)  # warm
    for i in range(repeats):
        for name in (("ground", "none") if i % 2 == 0 else ("none", "ground")):
            w, c = time.perf_counter(), time.process_time()
            r = bake_ao(target, occ, ground="auto" if name == "ground" else None, **kw)
            runs[name].append((time.perf_counter() - w, time.process_time() - c, r.rays, float(r.ao[r.mask].mean())))
    med = {k: (statistics.median(x[0] for x in v), statistics.median(x[1] for x in v)) for k, v in runs.items()}
    return {"resolution": res, "samples": spp, "threads": threads, "repeats": repeats,
            "ground_wall_s": round(med["ground"][0], 4), "none_wall_s": round(med["none"][0], 4),
            "ground_cpu_s": round(med["ground"][1], 4), "none_cpu_s": round(med["none"][1], 4),
            "ratio_wall": round(med["ground"][0] / med["none"][0], 3),
            "ratio_cpu": round(med["ground"][1] / med["none"][1], 3),
            "mean_ao_ground": round(runs["ground"][0][3], 4), "mean_ao_none": round(runs["none"][0][3], 4),
            "runs": {k: [[round(x[0], 4), round(x[1], 4)] for x in v] for k, v in runs.items()}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-save", action="store_true")
    args = ap.parse_args(argv)
    load_before = load_average()
    rows = []
    for res, spp in (QUICK if args.quick else SIZES):
        rows.append(measure(res, spp, args.repeats, args.threads))
        r = rows[-1]
        print(f"{res}^2 x {spp}: ground {r['ground_wall_s']:.3f} s, none {r['none_wall_s']:.3f} s, ratio "
              f"{r['ratio_wall']:.3f} (CPU {r['ratio_cpu']:.3f}); mean AO {r['mean_ao_ground']} against "
              f"{r['mean_ao_none']}", flush=True)
    record = {"section": "ground", "what": "time(bake_ao ground='auto') / time(bake_ao no ground), Suzanne scene, "
              "median of interleaved runs; target <= 1.10", "rows": rows, "machine": machine(),
              "load_before": load_before, "load_after": load_average(), **git_state(),
              "command": "python -m bench.sections.ground" + (" --quick" if args.quick else "")}
    if not args.no_save:
        RESULTS.mkdir(exist_ok=True)
        name = "ground-quick.json" if args.quick else "ground.json"
        (RESULTS / name).write_text(json.dumps(record, indent=1) + "\n")
    return record


if __name__ == "__main__":
    main()
