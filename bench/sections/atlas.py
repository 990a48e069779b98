"""Atlases: mc_ao's atlas against Cycles baking the same objects into one shared image, and a rebake of
what changed against a full bake.

    .venv/bin/python -m bench.sections.atlas            # 512^2 x 128 against Cycles; ten boxes at 1024 x 512
    .venv/bin/python -m bench.sections.atlas --quick    # 256^2 x 64; ten boxes at 512 x 256

Agreement. ``sample_scenes/atlas.blend``'s Base and Column (their UVs in two quarters of one square),
baked by ``scripts/bake_ao.py FILE --objects Base Column --atlas Atlas --format exr`` (the command the
issue names) and by Cycles with both selected, each object's material's active Image Texture node
holding one new float Non-Color image (bench.comparators.cycles.bake_shared): the same samples and AO
distance 1, 2 threads. The mean of (Cycles - mc_ao) over the texels both cover, away from island
borders (one texel eroded: Cycles samples a texel's centre, mc_ao its covered footprint), per object
and together, with its standard error (texels taken as independent).

Rebake. Ten boxes in a row, each within AO reach (distance 0.7) of its neighbours only, into one
atlas; one box moved: the rebake from the first bake's record (core.Atlas(keep=...)) against a full
bake of the moved scene, interleaved, the median of the repeats (wall and process CPU seconds); the
two are checked equal array for array each time, and the rebake's report must list the moved box and
its two neighbours.

Writes bench/results/atlas.json (``--quick``: atlas-quick.json) and prints a table. Never a timed assertion.
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness.common import RESULTS, erode, git_state, load_average, machine, mean_diff  # noqa: E402

SCENE = ROOT / "sample_scenes" / "atlas.blend"
OBJECTS = ("Base", "Column")
DISTANCE = 1.0


def mc_atlas(resolution, samples, threads, folder):
    """mc_ao's atlas of OBJECTS through the script: (ao (H, W), the record's owner map, its names)."""
    import OpenImageIO as oiio

    import core

    out = Path(folder)
    cmd = [sys.executable, str(ROOT / "scripts" / "bake_ao.py"), str(SCENE), "--objects", *OBJECTS, "--atlas",
           "Atlas", "--format", "exr", "--bits", "float", "--resolution", str(resolution), "--samples", str(samples),
           "--max-distance", str(DISTANCE), "--margin", "0", "--threads", str(threads), "--processes", "1",
           "--output", str(out), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=3600, cwd=ROOT)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"bake_ao.py failed: {proc.stderr}")
    # OpenImageIO's row 0 is the image's top: flip to Blender's pixel order (row 0 = v = 0).
    ao = oiio.ImageBuf(str(out / "Atlas.exr")).get_pixels(oiio.FLOAT)[::-1, :, 0]
    record = core.AtlasRecord.read(out / "Atlas.atlas.npz")
    mask = np.zeros(record.owner.size, bool)
    mask[record.covered[record.mask]] = True
    return ao, record.owner, mask.reshape(record.owner.shape), record.names, seconds


def cycles_atlas(resolution, samples, threads):
    """Cycles' AO bake of OBJECTS into one shared float Non-Color image: (ao, mask, seconds)."""
    import bpy

    from bench.comparators import cycles

    bpy.ops.wm.open_mainfile(filepath=str(SCENE), load_ui=False)
    objs = [bpy.data.objects[n] for n in OBJECTS]
    return cycles.bake_shared(bpy, objs, resolution, resolution, samples, threads, distance=DISTANCE, seed=7)


def agreement(resolution, samples, threads):
    with tempfile.TemporaryDirectory() as folder:
        mc, owner, mc_mask, names, mc_seconds = mc_atlas(resolution, samples, threads, folder)
    cyc, cyc_mask, cyc_seconds = cycles_atlas(resolution, samples, threads)
    both = erode(mc_mask & cyc_mask)
    out = {"resolution": resolution, "samples": samples, "distance": DISTANCE, "objects": list(OBJECTS),
           "seconds": {"mc_ao_script": round(mc_seconds, 2), "cycles_bake": round(cyc_seconds, 2)},
           "all": mean_diff(cyc, mc, both), "texels_mc_only": int((mc_mask & ~cyc_mask).sum()),
           "texels_cycles_only": int((cyc_mask & ~mc_mask).sum())}
    for k, name in enumerate(names):
        out[name] = mean_diff(cyc, mc, both & (owner == k))
    return out


def boxes(moved=None, dx=0.05):
    """Ten boxes in a row (tests/test_atlas.py's), box ``moved`` shifted by ``dx``."""
    sys.path.insert(0, str(ROOT / "tests"))
    from test_atlas import box

    return [box(f"Box{k}", (k * 1.0 + (dx if k == moved else 0.0), 0.0, 0.2), 0.2, k) for k in range(10)]


def timed(fn):
    w, c = time.perf_counter(), time.process_time()
    value = fn()
    return value, time.perf_counter() - w, time.process_time() - c


def rebake(resolution, samples, threads, repeats):
    import core

    kw = dict(resolution=resolution, samples=samples, seed=2, margin=4, threads=threads, max_distance=0.7)
    first = core.bake_ao(boxes(), [], **kw)
    walls = {"partial": [], "full": []}
    cpus = {"partial": [], "full": []}
    report = None
    for r in range(repeats):
        order = ("partial", "full") if r % 2 == 0 else ("full", "partial")
        got = {}
        for which in order:
            if which == "partial":
                fn = lambda: core.bake_ao(core.Atlas(boxes(moved=5), keep=first.record), [], **kw)  # noqa: E731
            else:
                fn = lambda: core.bake_ao(boxes(moved=5), [], **kw)  # noqa: E731
            got[which], wall, cpu = timed(fn)
            walls[which].append(wall)
            cpus[which].append(cpu)
        for name in ("ao", "stderr", "samples", "mask", "owner"):
            if not np.array_equal(getattr(got["partial"], name), getattr(got["full"], name)):
                raise AssertionError(f"the rebake's {name} differs from the full bake's")
        report = got["partial"].report["atlas"]
    if report["baked"] != ["Box4", "Box5", "Box6"]:
        raise AssertionError(f"the rebake baked {report['baked']}, not Box4, Box5, Box6")
    med = {k: statistics.median(v) for k, v in walls.items()}
    cmed = {k: statistics.median(v) for k, v in cpus.items()}
    return {"resolution": list(resolution), "samples": samples, "threads": threads, "repeats": repeats,
            "baked": report["baked"], "why": report["why"], "equal_arrays": True,
            "wall_seconds": {k: round(v, 3) for k, v in med.items()},
            "cpu_seconds": {k: round(v, 3) for k, v in cmed.items()},
            "ratio_wall": round(med["partial"] / med["full"], 3), "ratio_cpu": round(cmed["partial"] / cmed["full"], 3)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-cycles", action="store_true", help="the rebake only")
    args = parser.parse_args(argv)
    res, spp = (256, 64) if args.quick else (512, 128)
    rres = (512, 256) if args.quick else (1024, 512)
    out = {"machine": machine(), "git": git_state(), "load_before": load_average()}
    if not args.no_cycles:
        out["agreement"] = agreement(res, spp, args.threads)
    out["rebake"] = rebake(rres, 16, args.threads, args.repeats)
    out["load_after"] = load_average()
    path = RESULTS / ("atlas-quick.json" if args.quick else "atlas.json")
    path.write_text(json.dumps(out, indent=1, default=float) + "\n")
    if "agreement" in out:
        a = out["agreement"]
        print(f"agreement, {a['resolution']}^2 x {a['samples']}, distance {a['distance']}: mean(Cycles - mc_ao)")
        for key in ("all", *OBJECTS):
            d = a[key]
            print(f"  {key:8s} {d['mean']:+.5f} +- {d['se']:.5f} over {d['n']} texels (z {d['z']:+.1f})")
    r = out["rebake"]
    print(f"rebake of ten boxes, one moved ({r['resolution'][0]}x{r['resolution'][1]} x {r['samples']}, "
          f"{r['threads']} threads): baked {', '.join(r['baked'])}; wall {r['wall_seconds']['partial']:.2f} s "
          f"against {r['wall_seconds']['full']:.2f} s full ({r['ratio_wall']:.2f}x), CPU "
          f"{r['cpu_seconds']['partial']:.2f} against {r['cpu_seconds']['full']:.2f} s ({r['ratio_cpu']:.2f}x); "
          f"arrays equal")
    print(f"wrote {path.relative_to(ROOT)} (load {out['load_before']} -> {out['load_after']})")


if __name__ == "__main__":
    main()
