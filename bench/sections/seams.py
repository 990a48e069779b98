"""Bench section: how much a baked map's UV seams show, and what Fix Seams does about it.

The seam mismatch (core.geometry.seams): every mesh edge shared in space by two triangles whose UVs
differ is sampled at 4 points a texel (the smooth ones, where both sides have one shading normal,
are those the fix makes agree; at a crease the AO may differ, and both figures are given); each point is looked up in both triangles' UVs as Blender's
Linear interpolation reads the image (texel centres at (j + 0.5) / W, the image repeating at its
border, four texels weighed by the fractions: Cycles' interp_linear, the viewport's GPU sampler at
full resolution); the mismatch is the mean |difference| over the points. Measured on the map as the
core returns it (Blender holds these floats) and on the 8-bit PNG written from it (read back).

Scenes: sample_scenes/suzanne.blend (Suzanne), room.blend (Room, AO distance 1), udim.blend (Bust,
tiles 1001 and 1002, the tiles' shared edges included), extracted through bpy as the add-on does.
Per scene at --resolution: raw bakes (fix_seams=False) at 16 and 64 samples and a 2048-sample
reference (its own seed), and the 64-sample bake with Fix Seams (the core's default): mismatch of each, |fixed - reference| and |raw 64 - reference| over
the covered texels, and whether the texels no seam lookup reads are bit-equal to the raw bake.
``--cost-resolution N``: the fix's CPU time and peak memory (tracemalloc) against a 64-sample bake
of the bench's Suzanne scene at N^2 and the bytes of its image arrays.

    .venv/bin/python -m bench.sections.seams [--resolution 256] [--reference-cache DIR]
                                           [--cost-resolution 2048] [--json results/seams.json]

Never a timed assertion: CPU seconds of this process, on a shared machine.
"""

import argparse
import json
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from core.geometry import seams as G  # noqa: E402
from core.post import fixseams as F  # noqa: E402
from bench.harness.common import git_state, load_average, machine  # noqa: E402
from core import bake_ao, bake_udim  # noqa: E402

#: (blend file, target object, AO distance (inf: none), UDIM)
SCENES = {"suzanne": ("suzanne.blend", "Suzanne", float("inf"), False),
          "room": ("room.blend", "Room", 1.0, False),
          "udim": ("udim.blend", "Bust", float("inf"), True)}


def open_scene(name):
    """(target core.Mesh, occluder core.Meshes, AO distance, UDIM) of a sample scene, through bpy."""
    import bpy

    from bench.harness import scene as H

    blend, target, dist, udim = SCENES[name]
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / blend), load_ui=False)
    ta, oa = H.scene_arrays(bpy, target)
    t, occ = H.core_meshes(ta, oa)
    return t, occ, dist, udim


def bake(target, occ, dist, udim, res, samples, seed, cache=None, tag="", fix=False):
    """(ao, stderr, mask) planes (N, H, W), and the tile numbers (None: one image), and CPU seconds;
    ``fix``: with Fix Seams (the core's pipeline), else raw."""
    path = None if cache is None else Path(cache) / f"seams_{tag}_{res}_{samples}_{seed}{'_fixed' if fix else ''}.npz"
    if path is not None and path.exists():
        z = np.load(path)
        return (z["ao"], z["stderr"], z["mask"]), (tuple(int(t) for t in z["tiles"]) if "tiles" in z.files else None), None
    c = time.process_time()
    kw = dict(resolution=res, samples=samples, max_distance=dist, seed=seed, threads=2, fix_seams=fix)
    r = bake_udim(target, occ, **kw) if udim else bake_ao(target, occ, **kw)
    cpu = time.process_time() - c
    tiles = tuple(sorted(r.tiles)) if r.tiles else None
    planes = tuple(np.asarray(a).reshape((-1,) + np.asarray(a).shape[-2:]) for a in (r.ao, r.stderr, r.mask))
    if path is not None:
        np.savez(path, ao=planes[0], stderr=planes[1], mask=planes[2], **({"tiles": tiles} if tiles else {}))
    return planes, tiles, cpu


def png_roundtrip(planes):
    """The planes as an 8-bit PNG (core.files.imageio) reads them back: what a saved 8-bit map holds."""
    from core.files.imageio import read_image, write_image

    out = np.empty_like(planes, dtype=np.float32)
    with tempfile.TemporaryDirectory() as d:
        for i, p in enumerate(planes):
            f = Path(d) / f"plane{i}.png"
            write_image(f, p.astype(np.float32), bits=8)
            out[i] = read_image(f)[0]
    return out


def scene_figures(name, res, cache=None):
    target, occ, dist, udim = open_scene(name)
    (ao64, se64, m64), tiles, cpu64 = bake(target, occ, dist, udim, res, 64, 1, cache, name)
    (ao16, _, _), _, _ = bake(target, occ, dist, udim, res, 16, 1, cache, name)
    (ref, _, mref), _, _ = bake(target, occ, dist, udim, res, 2048, 10_001, cache, name)
    (fixed, _, _), _, _ = bake(target, occ, dist, udim, res, 64, 1, cache, name, fix=True)
    L = G.seam_lookups(target, res, tiles=tiles)
    c = time.process_time()
    again, _, info = F.fix_seams(ao64, se64, m64, L)  # what the pipeline did to the raw bake
    fix_cpu = time.process_time() - c
    read = np.zeros(ao64.size, bool)
    read[L.index.reshape(-1)] = True
    untouched = ~read.reshape(ao64.shape)
    common = m64 & mref
    maps = {"raw 16": ao16, "raw 64": ao64, "raw 2048": ref, "fixed 64": fixed}
    png = {k: png_roundtrip(v) for k, v in maps.items() if k != "raw 16"}
    smooth = L.subset(~L.crease)
    quarter = 0.25 * smooth.mismatch(ref)
    out = {
        "scene": name, "resolution": res, "tiles": list(tiles) if tiles else None, "seam_edges": L.edges,
        "crease_edges": int(np.unique(L.edge[L.crease]).size), "seam_points": L.points,
        "smooth_points": smooth.points, "unknowns": info.unknowns, "iterations": info.iterations,
        "residual": info.residual, "rounds": info.rounds, "fix_cpu_s": round(fix_cpu, 3),
        "mismatch": {k: smooth.mismatch(v) for k, v in maps.items()},
        "mismatch_png8": {k: smooth.mismatch(v) for k, v in png.items()},
        "mismatch_every_edge": {k: L.mismatch(v) for k, v in maps.items()},
        "mismatch_every_edge_png8": {k: L.mismatch(v) for k, v in png.items()},
        "abs_error_vs_2048": {"raw 64": float(np.abs(ao64 - ref)[common].mean()),
                              "fixed 64": float(np.abs(fixed - ref)[common].mean())},
        "untouched_texels": int(untouched.sum()),
        "untouched_bit_equal": bool(np.array_equal(fixed[untouched].view(np.uint32),
                                                   ao64[untouched].view(np.uint32))),
        "changed_texels": int(np.count_nonzero(fixed != ao64)),
        "pipeline_is_fix_of_raw": bool(np.array_equal(again, fixed)),
    }
    smooth_any = smooth.points > 0  # else there is no seam the fix makes agree (every one a crease)
    out["done"] = {"mismatch <= raw 2048 / 4": bool(out["mismatch"]["fixed 64"] <= quarter) if smooth_any else None,
                   "png mismatch <= raw 2048 png / 4": (bool(out["mismatch_png8"]["fixed 64"]
                                                             <= 0.25 * out["mismatch_png8"]["raw 2048"])
                                                        if smooth_any else None),
                   "|fixed - ref| <= |raw 64 - ref|": bool(out["abs_error_vs_2048"]["fixed 64"]
                                                           <= out["abs_error_vs_2048"]["raw 64"])}
    return out


def script_figures(res, samples=64, reference=None):
    """Fix Seams through the add-on's script (scripts/bake_ao.py on sample_scenes/suzanne.blend, run by
    this Python with the bpy module), on and off: the mismatch on the image as Blender holds it (its
    float pixels, written as a float EXR) and on the 8-bit PNG the script writes, read back.
    ``reference``: a raw 2048-sample map of the same mesh and size, for the quarter."""
    import subprocess

    from core.files.imageio import read_image

    target, _, _, _ = open_scene("suzanne")
    L = G.seam_lookups(target, res)
    smooth = L.subset(~L.crease)
    out = {"resolution": res, "samples": samples, "points": smooth.points}
    with tempfile.TemporaryDirectory() as d:
        for fix in (False, True):
            maps = {}
            for fmt, bits in (("exr", "float"), ("png", "8")):
                folder = Path(d) / f"{fix}-{fmt}"
                cmd = [sys.executable, str(ROOT / "scripts" / "bake_ao.py"), str(ROOT / "sample_scenes" / "suzanne.blend"),
                       "--objects", "Suzanne", "--samples", str(samples), "--resolution", str(res), "--output",
                       str(folder), "--format", fmt, "--bits", bits, "--quiet"] + ([] if fix else ["--no-fix-seams"])
                subprocess.run(cmd, check=True, cwd=ROOT)
                img = read_image(next(folder.rglob(f"Suzanne_AO.{fmt}")))[0]
                maps[fmt] = img[..., 0] if img.ndim == 3 else img
            key = "fixed" if fix else "raw"
            out[f"{key} {samples}, as Blender holds it"] = smooth.mismatch(maps["exr"])
            out[f"{key} {samples}, 8-bit PNG"] = smooth.mismatch(maps["png"])
            out[f"_{key}"] = maps["exr"]
    if reference is not None:
        out["raw 2048 (core)"] = smooth.mismatch(reference)
    raw, fixed = out.pop("_raw"), out.pop("_fixed")
    read = np.zeros(raw.size, bool)
    read[L.index.reshape(-1)] = True
    untouched = ~read.reshape(raw.shape)
    out["untouched_bit_equal"] = bool(np.array_equal(raw[untouched].view(np.uint32), fixed[untouched].view(np.uint32)))
    return out


def cost(res, threads=2, margin=16):
    """CPU seconds and peak memory of Fix Seams as a bake runs it (after the margin: the lookups, the
    margin's reach at the texels they read, the solve), against a 64-sample bake of the bench's
    Suzanne scene on this process's threads; peak memory (tracemalloc) of the fix against the
    bake's image arrays (map, error, samples, mask)."""
    from bench.sections.maps import load_scene

    target, occ, dist = load_scene()
    c = time.process_time()
    r = bake_ao(target, occ, resolution=res, samples=64, max_distance=dist, seed=1, threads=threads, workers=1,
                margin=margin, fix_seams=False)
    bake_cpu = time.process_time() - c
    image_bytes = r.ao.nbytes + r.stderr.nbytes + r.samples.nbytes + r.mask.nbytes
    tracemalloc.start()
    c = time.process_time()
    info = F.fix_baked(target, r.ao, r.stderr, r.mask, margin=margin)  # as core.pipeline.run's Texels.result
    fix_cpu = time.process_time() - c
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {"resolution": res, "samples": 64, "threads": threads, "margin": margin, "bake_cpu_s": round(bake_cpu, 2),
            "fix_cpu_s": round(fix_cpu, 3), "ratio_cpu": round(fix_cpu / bake_cpu, 4), "image_array_bytes": image_bytes,
            "fix_peak_bytes": peak, "ratio_memory": round(peak / image_bytes, 3), "seam_points": info.points,
            "unknowns": info.unknowns, "iterations": info.iterations, "mismatch_before": info.before,
            "mismatch_after": info.after}


def table(record):
    lines = []
    for s in record["scenes"]:
        m, p, e = s["mismatch"], s["mismatch_png8"], s["abs_error_vs_2048"]
        a, ap = s["mismatch_every_edge"], s["mismatch_every_edge_png8"]
        lines += [f"\n{s['scene']} {s['resolution']}^2 ({s['seam_edges']} seam edges, {s['crease_edges']} of them "
                  f"creases; {s['smooth_points']} of {s['seam_points']} points smooth; {s['unknowns']} texels solved "
                  f"for, {s['iterations']} iterations, {s['fix_cpu_s']} CPU s)",
                  "| map | mismatch, smooth seams | 8-bit PNG | every seam edge | 8-bit PNG | mean abs error vs 2048 |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for k in ("raw 16", "raw 64", "raw 2048", "fixed 64"):
            lines.append(f"| {k} | {m[k]:.4f} | {p.get(k, float('nan')):.4f} | {a[k]:.4f} | "
                         f"{ap.get(k, float('nan')):.4f} | {e.get(k, float('nan')):.4f} |".replace("nan", "-"))
        lines.append(f"untouched texels bit-equal: {s['untouched_bit_equal']} ({s['untouched_texels']}); "
                     f"done: {s['done']}")
    if record.get("script"):
        lines.append("\nthrough scripts/bake_ao.py (suzanne.blend): " + ", ".join(
            f"{k} {v:.4f}" if isinstance(v, float) else f"{k} {v}" for k, v in record["script"].items()))
    if record.get("cost"):
        c = record["cost"]
        lines.append(f"\ncost at {c['resolution']}^2 x 64: fix {c['fix_cpu_s']} CPU s / bake {c['bake_cpu_s']} = "
                     f"{c['ratio_cpu']:.3f}; peak {c['fix_peak_bytes'] / 2**20:.1f} MiB / image arrays "
                     f"{c['image_array_bytes'] / 2**20:.1f} MiB = {c['ratio_memory']:.2f}")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--reference-cache", default=None, help="folder keeping the bakes between runs")
    ap.add_argument("--cost-resolution", type=int, default=0, help="0: no cost run")
    ap.add_argument("--script", action="store_true", help="also through scripts/bake_ao.py (Fix Seams on and off)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    record = {"section": "seams", "load_before": load_average(), "machine": machine(), **git_state(),
              "command": "python -m bench.sections.seams " + " ".join(argv if argv is not None else sys.argv[1:])}
    record["scenes"] = [scene_figures(name, args.resolution, args.reference_cache) for name in args.scenes]
    if args.script:
        reference = None
        if args.reference_cache:
            z = Path(args.reference_cache) / f"seams_suzanne_{args.resolution}_2048_10001.npz"
            reference = np.load(z)["ao"] if z.exists() else None
        record["script"] = script_figures(args.resolution, reference=reference)
    if args.cost_resolution:
        record["cost"] = cost(args.cost_resolution)
    record["load_after"] = load_average()
    print(table(record), flush=True)
    if args.json:
        path = Path(args.json)
        if not path.is_absolute():
            path = ROOT / "bench" / path
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(record, indent=1, default=lambda o: o.item() if hasattr(o, "item") else str(o)) + "\n")
    return record


if __name__ == "__main__":
    main()
