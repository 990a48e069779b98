"""Where a one-thread bake's time goes, stage by stage, against the floor each stage could reach;
and the fixed cost of a bake, step by step.

Part 1, the stages (``--scene suzanne terrain``): a one-thread bake in this process (the bench's
Suzanne scene from ``bench/data/scene_suzanne.npz``, no Blender needed; the 131k-triangle terrain)
under :class:`bench.harness.stagetimer.StageTimer`: the thread CPU time of each named stage of the
core (exclusive of the stages it calls), per ray, and, for the kernel's stages, the floor that
``bench/results/floor.txt`` measured for the same stage (the cheapest numpy form of it on interior
texels, ``python -m bench.sections.floor``). Embree's share is the bake's own ``trace_cpu_seconds``
over the thread's CPU time. The floors are lower bounds for interior texels only: split texels,
located texels and per-texel work have none.

Part 2, the fixed cost (``--fixed``): the steps a bake takes before and after its rays, at a size
where the rays cost little (128^2 x 1 sample), in this process (one thread) and through the worker
processes (2 workers, warm: the pool already started, the scene kept from the last bake, as in a
session of bakes):

- in-process: each named step's thread CPU (prologue, UV triangles, bins, surface table, Embree
  scene, pattern pool, tile contexts, margin, the result), median of repeats, the Embree scene built
  anew each time (a new mesh every bake) and kept (the same mesh again);
- workers: the wall time of the whole warm bake against the in-process one, and each worker's own
  set-up steps (the same functions run here on the job a worker receives), so that every step
  done once per worker that could be done once per bake shows;
- the pool's start (spawn, import, self-test) once.

Run: ``.venv/bin/python -m bench.sections.stages [--quick] [--fixed-only | --stages-only]``; prints the
tables and writes ``bench/results/stages.{txt,json}`` unless ``--no-save``. Every figure carries the
load average it was measured at: on a shared machine read the CPU columns, not the wall ones.
"""

import argparse
import json
import os
import re
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness.common import RESULTS, git_state, load_average, machine  # noqa: E402
from bench.harness.stagetimer import StageTimer  # noqa: E402

SCENE_NPZ = ROOT / "bench" / "data" / "scene_suzanne.npz"
FLOOR_TXT = RESULTS / "floor.txt"

#: The stages of a bake's tiles, (label, core function or method), in the order a ray meets them.
#: The kernel's labels that match a floor in floor.txt say so after "kernel: ".
TILE_STAGES = [
    ("rasterise", "rasterize_tile"),
    ("sample units", "build_units"),
    ("contact probes", "contact_texels"),
    ("texel keys", "TexelPattern.keys"),
    ("tile context (triangle matrices)", "TileContext.__init__"),
    ("allocation", "allocate"),
    ("round: sort into calls, chunks", "TileBaker._trace"),
    ("kernel: gather", "Kernel._gather"),
    ("kernel: shift", "TexelPattern.shift_positions"),
    ("kernel: offset (texel space)", "Kernel._texel_space"),
    ("kernel: locate", "Kernel._locate"),
    ("kernel: map (row by row)", "Kernel._linear"),
    ("kernel: finish (smooth)", "smooth_cosine_rays"),
    ("kernel: sum", "piece_sums"),
    ("kernel: Embree call", "Tracer.occluded"),
    ("kernel: Embree call", "Tracer.visibility"),
    ("kernel: contact rays", "Tracer.contact"),
    ("kernel: the rest (turn, products of long pieces, buffers)", "Kernel.run"),
    ("estimates: add", "TexelEstimates.add"),
    ("error model", "ErrorModel.stderr"),
    ("tile: the rest (result rows)", "TexelBake.tile"),
    ("image store", "ImageStore.store"),
    ("margin", "dilate"),
]

#: The steps of a bake around its rays, (label, core function or method).
FIXED_STEPS = [
    ("request (options checked)", "_Request.__post_init__"),
    ("settings", "BakeSettings.of"),
    ("checks (meshes)", "check"),
    ("prologue (frame)", "Prologue.__init__"),
    ("UV triangles", "prepare"),
    ("tiles: fit and bins", "bin_triangles"),
    ("surface table", "SurfaceTable.build"),
    ("Embree scene", "Tracer.__init__"),
    ("pattern pool", "TexelPattern.__init__"),
    ("pool features (lift)", "_lift"),
    ("tile context (triangle matrices)", "TileContext.__init__"),
    ("rasterise", "rasterize_tile"),
    ("sample units", "build_units"),
    ("texel keys", "TexelPattern.keys"),
    ("kernel", "Kernel.run"),
    ("Embree (occlusion calls)", "Tracer.occluded"),
    ("error model", "ErrorModel.stderr"),
    ("image store", "ImageStore.store"),
    ("margin", "dilate"),
    ("result and report", "finish"),
]

#: Which floor.txt stage a kernel stage is held against (the turn and the products of long pieces
#: sit in "the rest": offset and turn's and map's floors are read against them together).
FLOOR_OF = {"kernel: gather": ["gather"], "kernel: shift": ["shift"],
            "kernel: offset (texel space)": ["offset and turn"],
            "kernel: map (row by row)": ["map"], "kernel: finish (smooth)": ["finish"], "kernel: sum": ["sum"]}


def scenes(names, quick=False):
    """{name: (target, occluders, distance)} of the bench's numpy-only scenes."""
    from core import Mesh

    from bench.harness.scene import terrain

    out = {}
    if "suzanne" in names:
        d = np.load(SCENE_NPZ)
        target = Mesh(d["P"], d["F"], d["UV"], d["N"], name="Suzanne")
        occ = [Mesh(d[f"O{i}P"], d[f"O{i}F"], name=f"occluder{i}") for i in range(int(d["occluders"]))]
        out["suzanne"] = (target, occ, float(d["distance"]))
    if "terrain" in names:
        out["terrain"] = terrain(128 if quick else 256)
    return out


def floors(path=FLOOR_TXT):
    """{(shading, K): {stage: ns a ray}} from floor.txt's '-> x ns' column."""
    out = {}
    if not path.exists():
        return out
    for line in path.read_text().splitlines():
        m = re.match(r"\s*(flat|smooth)\s+K=(\d+)\s+(.+?)\s{2,}.*->\s*([\d.]+) ns", line)
        if m:
            out.setdefault((m.group(1), int(m.group(2))), {})[m.group(3).strip()] = float(m.group(4))
    return out


def bake(target, occluders, distance, res, spp, **kw):
    from core import bake_ao

    kw = dict(dict(resolution=(res, res), samples=spp, threads=1, max_distance=distance, margin=16), **kw)
    return bake_ao(target, occluders, **kw)


def stage_profile(name, scene, res, spp, repeats):
    """The stage table of ``repeats`` one-thread bakes of ``scene`` (the fastest by thread CPU)."""
    target, occ, distance = scene
    bake(target, occ, distance, 64, spp)  # warm: imports, the pool of this sample count
    runs = []
    for _ in range(repeats):
        timer = StageTimer(TILE_STAGES)
        load0 = load_average()
        with timer.run():
            r = bake(target, occ, distance, res, spp)
        runs.append((timer, r, load0, load_average()))
    timer, r, load0, load1 = min(runs, key=lambda x: x[0].total)
    rays = r.rays
    smooth = bool(np.any(target.normals is not None))
    # Pieces of interior texels: spp / replicates samples (2 replicates by default).
    k = max(1, spp // 2)
    table = floors()
    ks = sorted({kk for sh, kk in table if sh == ("smooth" if smooth else "flat")})
    if ks:  # floor.txt has K = 32 and 64: the nearest
        k = min(ks, key=lambda kk: abs(kk - k))
    fl = table.get(("smooth" if smooth else "flat", k), {})
    rows = []
    for label, sec, calls in timer.table():
        row = {"stage": label, "seconds": sec, "calls": calls, "ns_per_ray": 1e9 * sec / rays,
               "share": sec / timer.total}
        names = FLOOR_OF.get(label)
        if names and fl:
            floor = sum(fl.get(n, 0.0) for n in names)
            if floor:
                row["floor_ns"] = floor
        rows.append(row)
    embree = r.trace_cpu_seconds
    kernel_total = sum(x["seconds"] for x in rows if x["stage"].startswith("kernel:"))
    out = {"scene": name, "triangles": int(target.triangle_count + sum(o.triangle_count for o in occ)),
           "resolution": res, "samples": spp, "rays": int(rays), "smooth": smooth, "piece_samples": k,
           "thread_cpu_seconds": timer.total, "embree_cpu_seconds": embree,
           "embree_share": embree / timer.total, "mrays_per_cpu_s": rays / timer.total / 1e6,
           "embree_ns_per_ray": 1e9 * embree / rays, "kernel_ns_per_ray": 1e9 * (kernel_total - embree) / rays,
           "floor_ns_per_ray": sum(fl.values()) if fl else None, "floors_from": f"floor.txt {('smooth' if smooth else 'flat')} K={k}",
           "stages": rows, "missing": timer.missing, "load": [load0, load1],
           "repeats": [t.total for t, *_ in runs]}
    return out


def print_stages(p, file=sys.stdout):
    print(f"\n{p['scene']} ({p['triangles']} triangles) {p['resolution']}^2 x {p['samples']}, one thread: "
          f"{p['thread_cpu_seconds']:.2f} s thread CPU, {p['rays'] / 1e6:.2f} M rays, "
          f"{p['mrays_per_cpu_s']:.2f} Mrays per CPU second; inside Embree {100 * p['embree_share']:.1f}% "
          f"({p['embree_ns_per_ray']:.0f} ns a ray); load {p['load'][0]} -> {p['load'][1]}", file=file)
    print(f"  {'stage':58s} {'s':>7s} {'share':>6s} {'ns/ray':>7s} {'floor':>6s} calls", file=file)
    for s in p["stages"]:
        floor = f"{s['floor_ns']:6.1f}" if "floor_ns" in s else "      "
        print(f"  {s['stage']:58s} {s['seconds']:7.3f} {100 * s['share']:5.1f}% {s['ns_per_ray']:7.1f} {floor} "
              f"{s['calls']}", file=file)
    if p["floor_ns_per_ray"]:
        print(f"  kernel outside Embree {p['kernel_ns_per_ray']:.1f} ns a ray against a floor of "
              f"{p['floor_ns_per_ray']:.1f} ({p['floors_from']}; interior texels only)", file=file)
    if p["missing"]:
        print(f"  names not found in the core (their time is in 'other'): {', '.join(p['missing'])}", file=file)


def _fixed_once(scene, res, spp, fresh):
    target, occ, distance = scene
    if fresh:  # a new mesh: the Embree scene and every table built anew (a moved copy of the target)
        from core import Mesh

        target = Mesh(target.positions + 0.0, target.triangles, target.uvs, target.normals, name=target.name)
    timer = StageTimer(FIXED_STEPS)
    t0 = time.perf_counter()
    with timer.run():
        r = bake(target, occ, distance, res, spp)
    return timer, time.perf_counter() - t0, r


def _capture_job(scene, res, spp, workers):
    """The job dict a worker receives for this bake (the parent's ``job()``), and the bake's wall time."""
    import core.execution.pool as W

    got = {}
    original = W.bake_tiles

    def spy(bake_, keys, processes, threads, job, *a, **kw):
        # The outer call's: a pool that starts runs the parent's self-test bake through here too.
        if "job" not in got:
            got["job"], got["processes"] = job(), processes
        return original(bake_, keys, processes, threads, job, *a, **kw)

    W.bake_tiles = spy
    try:
        t0 = time.perf_counter()
        target, occ, distance = scene
        r = bake(target, occ, distance, res, spp, workers=workers, threads=1)
        return got.get("job"), time.perf_counter() - t0, r
    finally:
        W.bake_tiles = original


def fixed_costs(scene, res=128, spp=1, repeats=7, workers=2):
    """Steps of a small bake, in this process and on ``workers`` warm worker processes."""
    import core.execution.pool as W

    out = {"resolution": res, "samples": spp, "load": [load_average()]}
    # In this process, one thread: a kept scene (the same mesh again) and a fresh one, interleaved.
    _fixed_once(scene, res, spp, False)
    kept, fresh = [], []
    for _ in range(repeats):
        kept.append(_fixed_once(scene, res, spp, False))
        fresh.append(_fixed_once(scene, res, spp, True))

    def summarise(runs):
        labels = [lab for lab, _, _ in runs[0][0].table()]
        rows = []
        for i, lab in enumerate(labels):
            secs = [t.table()[i][1] for t, _, _ in runs]
            rows.append({"step": lab, "median_ms": 1e3 * statistics.median(secs),
                         "calls": runs[0][0].table()[i][2]})
        return {"rows": rows, "thread_cpu_ms": 1e3 * statistics.median(t.total for t, _, _ in runs),
                "wall_ms": 1e3 * statistics.median(w for _, w, _ in runs), "missing": runs[0][0].missing}

    out["in_process_same_mesh"] = summarise(kept)
    out["in_process_new_mesh"] = summarise(fresh)
    # Worker processes: the pool's start once, then warm bakes against in-process ones, interleaved.
    W.shutdown()
    t0 = time.perf_counter()
    job, first, _ = _capture_job(scene, res, spp, workers)
    out["pool_start_and_first_bake_ms"] = 1e3 * first
    warm, local = [], []
    for _ in range(repeats):
        warm.append(_capture_job(scene, res, spp, workers)[1])
        local.append(_fixed_once(scene, res, spp, False)[1])
    out["workers"] = workers
    out["warm_workers_wall_ms"] = 1e3 * statistics.median(warm)
    out["in_process_wall_ms"] = 1e3 * statistics.median(local)
    # What each worker does with its job, timed here on the same job: its set-up steps.
    if job is not None:
        # As the pool sends it (core.execution.pool.Pool.run): progress counted in quanta, one thread.
        job = dict(job, quantum=1 << 62, settings=dict(job["settings"], threads=1, auto_tiles=False))
        steps = [("worker set-up: the rest", "_setup")] + FIXED_STEPS
        runs = []
        for reuse in (False, True):
            scene_state = {}
            if reuse:  # a kept scene: set up once, then again with the same meshes
                W._setup(dict(job), None, lambda w: None, scene=(W.scene_key(job), scene_state))
            timer = StageTimer(steps)
            with timer.run():
                W._setup(dict(job), None, lambda w: None, scene=(W.scene_key(job), scene_state))
            runs.append({"scene_kept": reuse, "thread_cpu_ms": 1e3 * timer.total,
                         "rows": [{"step": lab, "ms": 1e3 * s} for lab, s, _ in timer.table() if s > 0],
                         "missing": timer.missing})
        out["worker_setup"] = runs
    out["load"].append(load_average())
    return out


def print_fixed(f, file=sys.stdout):
    print(f"\nfixed cost of a {f['resolution']}^2 x {f['samples']} bake of the Suzanne scene (load {f['load'][0]} -> "
          f"{f['load'][-1]}); medians, thread CPU ms", file=file)
    a, b = f["in_process_same_mesh"], f["in_process_new_mesh"]
    print(f"  {'step':40s} {'same mesh':>10s} {'new mesh':>10s}", file=file)
    for ra, rb in zip(a["rows"], b["rows"]):
        if ra["median_ms"] < 0.05 and rb["median_ms"] < 0.05:
            continue
        print(f"  {ra['step']:40s} {ra['median_ms']:10.2f} {rb['median_ms']:10.2f}", file=file)
    print(f"  {'thread CPU in all':40s} {a['thread_cpu_ms']:10.2f} {b['thread_cpu_ms']:10.2f}", file=file)
    print(f"  {'wall':40s} {a['wall_ms']:10.2f} {b['wall_ms']:10.2f}", file=file)
    print(f"  pool start + first bake on {f['workers']} workers: {f['pool_start_and_first_bake_ms']:.0f} ms wall; "
          f"warm: {f['warm_workers_wall_ms']:.1f} ms against {f['in_process_wall_ms']:.1f} ms in this process",
          file=file)
    for run in f.get("worker_setup", []):
        print(f"  a worker's set-up of the same job, scene {'kept' if run['scene_kept'] else 'built'}: "
              f"{run['thread_cpu_ms']:.1f} ms: " + ", ".join(f"{r['step']} {r['ms']:.1f}" for r in run["rows"]),
              file=file)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="256^2 x 32, a smaller terrain, fewer repeats")
    ap.add_argument("--scene", nargs="+", default=["suzanne", "terrain"], choices=["suzanne", "terrain"])
    ap.add_argument("--resolution", type=int, default=None)
    ap.add_argument("--samples", type=int, default=None)
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--stages-only", action="store_true")
    ap.add_argument("--fixed-only", action="store_true")
    ap.add_argument("--no-save", action="store_true")
    ap.add_argument("--stem", default=None, help="results/STEM.{txt,json} (default: stages; stages-fixed with "
                    "--fixed-only, stages-tiles with --stages-only)")
    a = ap.parse_args(argv)
    a.stem = a.stem or ("stages-fixed" if a.fixed_only else "stages-tiles" if a.stages_only else "stages")
    res = a.resolution or (256 if a.quick else 512)
    spp = a.samples or (32 if a.quick else 64)
    repeats = a.repeats or (1 if a.quick else 3)
    out = {"machine": machine(), "git": git_state(), "when": time.strftime("%Y-%m-%dT%H:%M:%S")}
    lines = []

    class Tee:
        def write(self, s):
            sys.stdout.write(s)
            lines.append(s)

    tee = Tee()
    print(f"stages of a one-thread bake ({out['when']}, {out['git']['commit']}, numpy {np.__version__}, "
          f"{out['machine']['cores']} cores, {out['machine']['cpu']})", file=tee)
    sc = scenes(a.scene if not a.fixed_only else ["suzanne"], a.quick)
    if not a.fixed_only:
        out["stages"] = []
        for name in a.scene:
            p = stage_profile(name, sc[name], res, spp, repeats)
            out["stages"].append(p)
            print_stages(p, tee)
    if not a.stages_only:
        out["fixed"] = fixed_costs(sc["suzanne"], repeats=3 if a.quick else 7)
        print_fixed(out["fixed"], tee)
    if not a.no_save:
        (RESULTS / f"{a.stem}.json").write_text(json.dumps(out, indent=1, default=float))
        (RESULTS / f"{a.stem}.txt").write_text("".join(lines))
    from core.execution.pool import shutdown

    shutdown()
    return out


if __name__ == "__main__":
    main()
