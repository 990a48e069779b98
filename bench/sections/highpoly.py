"""Selected to Active: what the matching rays cost, in one run, as ratios.

    .venv/bin/python -m bench.sections.highpoly            # 512 x 512 at 64 and 256 spp: about 3 minutes on 2 cores
    .venv/bin/python -m bench.sections.highpoly --quick    # 256 x 256

Two bakes of a high-poly onto a low-poly (core.bake_ao with ``highpoly=``):

- terrain: ``bench.harness.scene.displaced_grid(256)`` (131072 triangles, 4 x 4, bumps of +-0.25) onto a flat
  4 x 4 plane 0.5 below it, extrusion 1, AO distance 0.5;
- rock: sample_scenes/rock.blend's Rock_high (122880 triangles) onto Rock_low (80 triangles), extrusion
  0.1, every other object occluding, unlimited AO distance, read through the add-on's own extraction
  (needs the bpy module; skipped without it).

Each bake runs on 1 thread, repeated (interleaved with the other scene), and reports the matching
stage's own time from the bake (``BakeResult.report['matching_seconds']`` and ``..._cpu_seconds``:
the check before baking, the sample points' positions, their matching rays through Embree, the hit
points and normals, contact probes) against the rest of the bake: "adds" is matching / (bake -
matching), what the stage adds to tracing and shading the AO at those points. In wall time and in
thread CPU time (the bake's process CPU: one thread), which a busy neighbour on a shared machine
does not inflate; the target, under 10% at 64 samples per texel, is read on the CPU
figure. Also the 2-thread bake, whose result is bit-identical.

Both with one replicate (what the add-on bakes without an error map or adaptive sampling: P = spp / 64
points per texel) and with two (core.bake_ao's default, the add-on's with an error map or adaptive
sampling: each replicate draws its own points, so there are twice as many, P = spp / 32, and the
matching stage costs about twice as much against the same AO rays).

Writes bench/results/highpoly.json and highpoly.txt (``--quick``: highpoly-quick.*). Never a timed
assertion.
"""

import argparse
import json
import statistics
import time

import numpy as np

from ..harness.common import RESULTS, ROOT, git_state, load_average, machine


def terrain():
    from core import Mesh

    from ..harness.scene import displaced_grid

    P, F, _ = displaced_grid(256, size=4.0, amplitude=0.25)
    high = Mesh(P, F, name="terrain_high")
    lowp = np.array([[-2, -2, -0.5], [2, -2, -0.5], [2, 2, -0.5], [-2, 2, -0.5]], float)
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    low = Mesh(lowp, tri, uvs=(lowp[tri][:, :, :2] + 2) / 4, name="terrain_low")
    return dict(target=low, occluders=[], highpoly=[high], extrusion=1.0, max_distance=0.5)


def rock():
    """rock.blend's pair through mc_ao's extraction, or None without bpy."""
    try:
        import bpy
    except ImportError:
        return None
    import sys

    sys.path.insert(0, str(ROOT))
    from core import Mesh
    from mc_ao import selected_to_active
    from mc_ao.settings import BakeSettings

    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / "rock.blend"), load_ui=False)
    low, high = bpy.data.objects["Rock_low"], bpy.data.objects["Rock_high"]
    job = selected_to_active.plan(bpy.context.evaluated_depsgraph_get(), low, [low, high],
                                  BakeSettings(use_selected_to_active=True, cage_extrusion=0.1))

    def mesh(a):
        return Mesh(a.positions, a.triangles, uvs=a.uvs, normals=a.normals, name=a.name)

    return dict(target=mesh(job.target), occluders=[mesh(o) for o in job.occluders],
                highpoly=[mesh(h) for h in job.highpoly], extrusion=job.extrusion, max_distance=float("inf"))


def bake(scene, res, spp, threads, replicates):
    from core import bake_ao

    t, c = time.perf_counter(), time.process_time()
    r = bake_ao(scene["target"], scene["occluders"], resolution=res, samples=spp, threads=threads, margin=0,
                max_distance=scene["max_distance"], highpoly=scene["highpoly"], extrusion=scene["extrusion"],
                replicates=replicates)
    return r, time.perf_counter() - t, time.process_time() - c


def measure(scenes, res, spp, repeats, replicates):
    rows = {}
    for name in scenes:
        rows[name] = {"wall": [], "cpu": [], "match": [], "match_cpu": [], "trace_cpu": []}
    for _ in range(repeats):
        for name, scene in scenes.items():  # interleaved: a busy moment hits both scenes alike
            r, wall, cpu = bake(scene, res, spp, 1, replicates)
            row = rows[name]
            row["wall"].append(wall)
            row["cpu"].append(cpu)
            row["match"].append(r.report["matching_seconds"])
            row["match_cpu"].append(r.report["matching_cpu_seconds"])
            row["trace_cpu"].append(r.trace_cpu_seconds)
            row["rays"] = r.rays
            row["matching_rays"] = r.report["matching_rays"]
            row["missed"] = r.missed
            row["points_per_texel"] = spp // r.report["directions_per_point"]
            row["result"] = r
    out = {}
    for name, row in rows.items():
        wall = statistics.median(row["wall"])
        match = statistics.median(row["match"])
        adds_cpu = statistics.median(m / (c - m) for m, c in zip(row["match_cpu"], row["cpu"]))
        r2, wall2, _ = bake(scenes[name], res, spp, 2, replicates)
        out[name] = {
            "resolution": res, "spp": spp, "replicates": replicates, "points_per_texel": row["points_per_texel"],
            "bake_seconds_1_thread": round(wall, 3), "matching_seconds": round(match, 3),
            "bake_cpu_seconds": round(statistics.median(row["cpu"]), 3),
            "matching_cpu_seconds": round(statistics.median(row["match_cpu"]), 3),
            "matching_share": round(match / wall, 4), "matching_adds": round(match / (wall - match), 4),
            "matching_adds_cpu": round(adds_cpu, 4),
            "matching_rays": row["matching_rays"], "ao_rays": row["rays"] - row["matching_rays"],
            "missed_points": row["missed"], "repeats": repeats,
            "walls": [round(w, 3) for w in row["wall"]], "matches": [round(m, 3) for m in row["match"]],
            "bake_seconds_2_threads": round(wall2, 3),
            "two_threads_bit_identical": bool(np.array_equal(r2.ao, row["result"].ao)),
        }
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="256 x 256 instead of 512 x 512")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    res = 256 if args.quick else 512
    scenes = {"terrain": terrain()}
    r = rock()
    if r is not None:
        scenes["rock"] = r
    started = time.strftime("%Y-%m-%d %H:%M")
    load_before = load_average()
    results = {(spp, R): measure(scenes, res, spp, args.repeats, R) for R in (1, 2) for spp in (64, 256)}
    record = {"started": started, "machine": machine(), "git": git_state(), "load_before": load_before,
              "load_after": load_average(),
              "target": "matching adds < 10% of the bake time at 64 spp (one replicate, the add-on's default)",
              "results": {f"{spp} spp, {R} replicate{'s' if R > 1 else ''}": v for (spp, R), v in results.items()}}
    lines = [f"bench.sections.highpoly {started}, {res} x {res}, 1 thread (median of {args.repeats}), load "
             f"{load_before} -> {record['load_after']}",
             f"{'scene':8s} {'spp':>4s} {'R':>2s} {'points':>6s} {'bake s':>7s} {'match s':>7s} {'adds':>6s} "
             f"{'cpu s':>6s} {'match':>6s} {'adds':>6s} {'matching rays':>13s} {'AO rays':>10s} {'missed':>6s} "
             f"{'2 threads s':>11s} same"]
    for (spp, R), per in results.items():
        for name, row in per.items():
            lines.append(f"{name:8s} {spp:4d} {R:2d} {row['points_per_texel']:6d} {row['bake_seconds_1_thread']:7.2f} "
                         f"{row['matching_seconds']:7.2f} {100 * row['matching_adds']:5.1f}% "
                         f"{row['bake_cpu_seconds']:6.2f} {row['matching_cpu_seconds']:6.2f} "
                         f"{100 * row['matching_adds_cpu']:5.1f}% "
                         f"{row['matching_rays']:13d} {row['ao_rays']:10d} {row['missed_points']:6d} "
                         f"{row['bake_seconds_2_threads']:11.2f} {row['two_threads_bit_identical']}")
    met = all(row["matching_adds_cpu"] < 0.10 for row in results[(64, 1)].values())
    lines.append("(bake s, match s: wall; cpu s, match: thread CPU, which a busy neighbour does not inflate; "
                 "adds = match / (bake - match))")
    lines.append(f"target: matching adds < 10% of the bake's CPU time at 64 spp, one replicate (R 1, the add-on's "
                 f"default): {'met' if met else 'MISSED'}")
    text = "\n".join(lines)
    print(text)
    stem = "highpoly-quick" if args.quick else "highpoly"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{stem}.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / f"{stem}.txt").write_text(text + "\n")


if __name__ == "__main__":
    main()
