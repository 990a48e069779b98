"""AO and the thickness map from one bake (core.bake_maps) against the two bakes it replaces, as a ratio.

    .venv/bin/python -m bench.sections.maps            # 256^2 x 8, 512^2 x 16, 1024^2 x 32: about 3 minutes on 2 cores
    .venv/bin/python -m bench.sections.maps --quick    # 256^2 x 8 and 512^2 x 16

The bench's Suzanne scene (``bench/data/scene_suzanne.npz``: Suzanne and its three occluders, AO
distance from the scene), 2 threads, one replicate pair as bake_ao's default. For each size: ``maps``
is one ``bake_maps(quantities=('ao', 'thickness'))``, ``two bakes`` is ``bake_ao`` then
``bake_ao(quantity='thickness')`` with the same settings (the same bits, tests/test_maps.py).
Repeated, the two interleaved (maps first, then the pair; then the other way), median wall and
process CPU seconds of each; the ratio is maps / two bakes (below 1: the shared set-up saved that
share). What maps share: rasterising, the surface table, the tiles' sample units, the sample pattern,
the prologue; each quantity still traces its own rays, so the saving is largest where set-up is a
large share of a bake (few samples per texel) and falls towards nothing as rays dominate.

Writes bench/results/maps.json (``--quick``: maps-quick.json) and prints the table. Never a timed
assertion.
"""

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness.common import RESULTS, git_state, load_average, machine  # noqa: E402
from core import Mesh, bake_ao, bake_maps  # noqa: E402

SCENE = ROOT / "bench" / "data" / "scene_suzanne.npz"
SIZES = [(256, 8), (512, 16), (1024, 32)]
QUICK = [(256, 8), (512, 16)]


def load_scene(path=SCENE):
    z = np.load(path)
    target = Mesh(z["P"], z["F"], z["UV"], z["N"], name="Suzanne")
    occ = [Mesh(z[f"O{i}P"], z[f"O{i}F"], name=f"occluder{i}") for i in range(int(z["occluders"]))]
    return target, occ, float(z["distance"])


def timed(fn):
    w, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w, time.process_time() - c


def measure(res, spp, repeats, threads):
    target, occ, dist = load_scene()
    kw = dict(resolution=res, samples=spp, max_distance=dist, threads=threads, seed=1)

    def maps():
        bake_maps(target, occ, **kw)

    def two():
        bake_ao(target, occ, **kw)
        bake_ao(target, occ, quantity="thickness", **kw)

    maps()  # warm: the pattern tables and numpy's first calls
    runs = {"maps": [], "two": []}
    for i in range(repeats):
        order = [("maps", maps), ("two", two)] if i % 2 == 0 else [("two", two), ("maps", maps)]
        for name, fn in order:
            runs[name].append(timed(fn))
    med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v)) for k, v in runs.items()}
    return {"resolution": res, "samples": spp, "threads": threads, "repeats": repeats,
            "maps_wall_s": round(med["maps"][0], 4), "two_bakes_wall_s": round(med["two"][0], 4),
            "maps_cpu_s": round(med["maps"][1], 4), "two_bakes_cpu_s": round(med["two"][1], 4),
            "ratio_wall": round(med["maps"][0] / med["two"][0], 3),
            "ratio_cpu": round(med["maps"][1] / med["two"][1], 3),
            "runs": {k: [[round(w, 4), round(c, 4)] for w, c in v] for k, v in runs.items()}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-save", action="store_true")
    args = ap.parse_args(argv)
    sizes = QUICK if args.quick else SIZES
    load_before = load_average()
    rows = []
    for res, spp in sizes:
        repeats = args.repeats or (5 if res <= 512 else 3)
        rows.append(measure(res, spp, repeats, args.threads))
        r = rows[-1]
        print(f"{res}^2 x {spp}: maps {r['maps_wall_s']:.3f} s, two bakes {r['two_bakes_wall_s']:.3f} s, "
              f"ratio {r['ratio_wall']:.3f} (CPU {r['ratio_cpu']:.3f})", flush=True)
    record = {"section": "maps", "what": "time(bake_maps AO + thickness) / time(bake_ao + bake_ao thickness), "
              "Suzanne scene, median of interleaved runs", "rows": rows, "machine": machine(),
              "load_before": load_before, "load_after": load_average(), **git_state(),
              "command": "python -m bench.sections.maps" + (" --quick" if args.quick else "")}
    if not args.no_save:
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / ("maps-quick.json" if args.quick else "maps.json")).write_text(json.dumps(record, indent=1) + "\n")
    return record


if __name__ == "__main__":
    main()
