"""Bench section: mc_ao's surface-space denoiser against raw bakes and Open Image Denoise.

On the bench's Suzanne scene (bench/data/scene_suzanne.npz: Suzanne with smart-project UVs over a
plane and two blocks, as the add-on extracts it), one noisy bake at --samples is denoised by
core.post.denoise and by Open Image Denoise (pyoidn: RT, RT with the surface normals as an auxiliary
image, RTLightmap; each on the bake's image with its 16-texel margin) and compared with a converged
reference of its own seed that no filter touched: RMSE over the covered texels, over island-border
texels (covered texels with an uncovered 8-neighbour), and across UV seams (mean |difference| of the
texel pairs the guide links, against the reference's own), plus the denoiser's z = error / reported
error. Times: CPU seconds of this process.

``--cycles``: the equal-error table against Cycles' AO bake (bpy) on the Suzanne scene, the room and
dense.blend, in one run (:func:`cycles_equal_error`). ``--cost-resolution N``: what denoise=True adds
to a 64-sample bake at N^2, and with ``--cost-against COMMIT`` that commit's core in the same run
(:func:`cost`).

    .venv/bin/python -m bench.sections.denoise [--resolution 256] [--samples 16] [--reference-samples 1024]
                                             [--json out.json] [--reference-cache DIR]
                                             [--picture docs/denoise.png] [--equal-error]
    .venv/bin/python -m bench.sections.denoise --cycles --resolution 512 --reference-samples 2048
    .venv/bin/python -m bench.sections.denoise --resolution 0 --cost-resolution 4096 --cost-against COMMIT
                                             --cost-repeats 2 [--cost-samples 16]
    .venv/bin/python -m bench.sections.denoise --done-when --resolutions 256 512 --reference-samples 2048
                                             --reference-cache DIR --json bench/results/denoise-done.json

``--done-when``: the equal-error figures against Cycles (:func:`done_when`): the add-on's operator with Denoise on against
Cycles, each against its own converged image; the high-gradient check; OIDN RTLightmap; z.
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from core import Mesh, bake_ao  # noqa: E402
from core.post import denoise as D  # noqa: E402

SCENE = ROOT / "bench" / "data" / "scene_suzanne.npz"


def load_scene(path=SCENE):
    z = np.load(path)
    target = Mesh(z["P"], z["F"], z["UV"], z["N"], name="Suzanne")
    occ = [Mesh(z[f"O{i}P"], z[f"O{i}F"], name=f"occluder{i}") for i in range(int(z["occluders"]))]
    return target, occ, float(z["distance"])


class Clock:
    """Wall and CPU seconds of a block."""

    def __enter__(self):
        self.w, self.c = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall, self.cpu = time.perf_counter() - self.w, time.process_time() - self.c


def border(mask):
    """Covered texels with an uncovered 8-neighbour (or on the image's edge)."""
    p = np.pad(mask, 1)
    out = np.zeros_like(mask)
    h, w = mask.shape
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out |= ~p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
    return out & mask


def oidn_filters():
    try:
        import pyoidn
    except Exception as e:  # not installed: the table says so
        return {}, f"pyoidn not available ({e})"

    def run(ao, filter_type, normal=None):
        rgb = np.ascontiguousarray(np.repeat(ao[..., None], 3, axis=2).astype(np.float32))
        kw = {"filter_type": filter_type}
        if normal is not None:  # RT takes normals only beside an albedo: a white one
            kw["normal"] = np.ascontiguousarray(normal.astype(np.float32))
            kw["albedo"] = np.ones_like(rgb)
        else:
            kw["hdr"] = filter_type == "RTLightmap"
        if filter_type == "RTLightmap":
            kw.pop("hdr", None)
        return pyoidn.denoise(rgb, **kw)[..., 0]

    return {
        "OIDN RT": lambda ao, g: run(ao, "RT"),
        "OIDN RT + normals": lambda ao, g: run(ao, "RT", g.normal),
        "OIDN RTLightmap": lambda ao, g: run(ao, "RTLightmap"),
    }, getattr(pyoidn, "__version__", "")


class _Ref:
    def __init__(self, z):
        self.ao, self.stderr, self.mask = z["ao"], z["stderr"], z["mask"]


def picture(path, maps, ref, mask, crop=None):
    """A PNG: the maps side by side (top), their |error| against the reference x 5 (bottom), on the
    covered texels (grey elsewhere); row 0 of the maps is v = 0, as core.files.imageio writes it."""
    from core.files.imageio import write_image

    h, w = ref.shape
    rows, cols = crop or (slice(0, h), slice(0, w))
    gap = 4
    tiles = []
    for img in maps:
        top = np.where(mask, img, 0.25)[rows, cols]
        err = np.where(mask, np.minimum(5 * np.abs(img - ref), 1.0), 0.25)[rows, cols]
        tiles.append(np.concatenate([err, np.full((gap, top.shape[1]), 1.0), top], axis=0))  # bottom row first
    out = tiles[0]
    for t in tiles[1:]:
        out = np.concatenate([out, np.full((out.shape[0], gap), 1.0), t], axis=1)
    write_image(path, out.astype(np.float32), bits=8)


def compare(res, samples, ref_samples, seed=1, threads=2, cache=None, picture_path=None):
    target, occ, dist = load_scene()
    path = None if cache is None else Path(cache) / f"denoise_reference_{res}_{ref_samples}_{seed}.npz"
    if path is not None and path.exists():
        ref = _Ref(np.load(path))
    else:
        ref = bake_ao(target, occ, resolution=res, samples=ref_samples, max_distance=dist, seed=10_000 + seed,
                      threads=threads)
        if path is not None:
            np.savez(path, ao=ref.ao, stderr=ref.stderr, mask=ref.mask)
    with Clock() as tb:
        raw = bake_ao(target, occ, resolution=res, samples=samples, max_distance=dist, seed=seed, threads=threads)
    with Clock() as t8:
        raw8 = bake_ao(target, occ, resolution=res, samples=8 * samples, max_distance=dist, seed=seed + 1,
                       threads=threads)
    mask = raw.mask & ref.mask
    edge = border(raw.mask) & mask
    with Clock() as tg:
        guide = D.surface_guide(target, res)
    with Clock() as td:
        dn, dn_se, info = D.denoise(raw.ao, raw.stderr, raw.mask, guide, margin=16)
    a, b = guide.links[:, 0], guide.links[:, 1]
    keep = mask.reshape(-1)[a] & mask.reshape(-1)[b]
    a, b = a[keep], b[keep]

    def metrics(img):
        e = (img - ref.ao)[mask]
        f = img.reshape(-1)
        return {"rmse": float(np.sqrt(np.mean(e ** 2))),
                "border_rmse": float(np.sqrt(np.mean(((img - ref.ao)[edge]) ** 2))),
                "seam_mean_abs_diff": float(np.mean(np.abs(f[a] - f[b])))}

    rows = {f"raw {samples}": dict(metrics(raw.ao), cpu=tb.cpu),
            f"raw {8 * samples}": dict(metrics(raw8.ao), cpu=t8.cpu),
            f"mc_ao denoise ({samples})": dict(metrics(dn), cpu=tb.cpu + tg.cpu + td.cpu)}
    filters, version = oidn_filters()
    shown = [raw.ao, dn]
    for name, f in filters.items():
        with Clock() as t:
            out = f(raw.ao, guide)
        rows[f"{name} ({samples})"] = dict(metrics(out), cpu=tb.cpu + t.cpu)
        if name == "OIDN RTLightmap":
            shown.append(out)
    if picture_path is not None:
        picture(picture_path, shown + [ref.ao], ref.ao, mask)
    r = ref.ao.reshape(-1)
    seam_ref = float(np.mean(np.abs(r[a] - r[b])))
    sel = mask & (dn_se > 0)
    z = (dn - ref.ao)[sel] / np.sqrt(dn_se[sel].astype(np.float64) ** 2 + ref.stderr[sel].astype(np.float64) ** 2)
    return {"resolution": res, "samples": samples, "reference_samples": ref_samples, "covered": int(mask.sum()),
            "border_texels": int(edge.sum()), "seam_pairs": int(len(a)), "seam_reference": seam_ref,
            "reference_rmse_floor": float(np.sqrt(np.mean(ref.stderr[mask].astype(np.float64) ** 2))),
            "z_sd": float(z.std()), "z_mean": float(z.mean()), "z_over_4": float(np.mean(np.abs(z) > 4)),
            "choice": np.bincount(info.choice[raw.mask], minlength=len(info.bandwidths) + 1).tolist(),
            "guide_cpu": tg.cpu, "denoise_cpu": td.cpu, "bake_cpu": tb.cpu, "oidn": version, "rows": rows}


#: What one cost measurement runs, in a process of its own whose ``core`` is the tree measured (this
#: one, or an earlier commit's, unpacked): a bake of argv[5] samples, the same bake with denoise=True, and the
#: guide and the filter on their own (surface_guide from the mesh, then denoise of the plain bake).
#: Prints one JSON line of CPU seconds (process time: every thread, steadier than wall time on a
#: shared machine).
_COST_RUN = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
from core import Mesh, bake_ao
from core.post import denoise as D
z = np.load(sys.argv[2])
target = Mesh(z["P"], z["F"], z["UV"], z["N"], name="Suzanne")
occ = [Mesh(z[f"O{i}P"], z[f"O{i}F"], name=f"occluder{i}") for i in range(int(z["occluders"]))]
res, threads, dist, samples = int(sys.argv[3]), int(sys.argv[4]), float(z["distance"]), int(sys.argv[5])
out = {}
def clock(name, f):
    c, w = time.process_time(), time.perf_counter()
    r = f()
    out[name + "_cpu"], out[name + "_wall"] = time.process_time() - c, time.perf_counter() - w
    return r
bake = lambda dn: bake_ao(target, occ, resolution=res, samples=samples, max_distance=dist, seed=3, threads=threads,
                          denoise=dn)
raw = clock("bake", lambda: bake(False))
clock("bake_denoise", lambda: bake(True))
guide = clock("guide", lambda: D.surface_guide(target, res))
clock("filter", lambda: D.denoise(raw.ao, raw.stderr, raw.mask, guide, threads=threads))
print(json.dumps(out))
"""


def _tree(commit, into):
    """``core`` of ``commit`` unpacked into the folder ``into`` (git archive); returns the folder."""
    import io
    import subprocess
    import tarfile

    data = subprocess.run(["git", "-C", str(ROOT), "archive", commit, "core"], check=True,
                          capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(data)) as t:
        t.extractall(into)
    return into


def cost(res, threads=2, against=None, repeats=1, samples=64):
    """CPU seconds of the denoiser against a bake of ``samples`` of the same map, on the same cores: the
    bake with denoise=True less the plain bake (what denoising adds to a bake), and the guide and
    filter alone. With ``against`` (a commit), that commit's core is measured in the same run, the
    two alternating ``repeats`` times; the least of the repeats counts (the others measure the
    machine's other work), every repeat kept."""
    import subprocess
    import tempfile

    trees = [("this tree", str(ROOT))]
    tmp = None
    if against:
        tmp = tempfile.TemporaryDirectory()
        trees.insert(0, (against, _tree(against, tmp.name)))
    runs = {name: [] for name, _ in trees}
    try:
        for _ in range(repeats):
            for name, root in trees:
                p = subprocess.run([sys.executable, "-c", _COST_RUN, root, str(SCENE), str(res), str(threads), str(samples)],
                                   check=True, capture_output=True, text=True)
                runs[name].append(json.loads(p.stdout.strip().splitlines()[-1]))
                print(f"  cost {res}^2, {name}: {runs[name][-1]}", flush=True)
    finally:
        if tmp is not None:
            tmp.cleanup()
    mt = res * res / 1e6
    out = {"resolution": res, "threads": threads, "samples": samples, "repeats": repeats, "versions": {}}
    for name, rs in runs.items():
        best = {k: min(r[k] for r in rs) for k in rs[0]}
        added = best["bake_denoise_cpu"] - best["bake_cpu"]
        out["versions"][name] = dict(
            best, runs=rs, added_cpu=added, ratio_cpu=added / best["bake_cpu"],
            ratio_parts_cpu=(best["guide_cpu"] + best["filter_cpu"]) / best["bake_cpu"],
            ratio_filter_cpu=best["filter_cpu"] / best["bake_cpu"],
            cpu_per_megatexel=added / mt, filter_cpu_per_megatexel=best["filter_cpu"] / mt)
    return out


def cost_table(c):
    lines = [f"Cost at {c['resolution']}^2 (Suzanne, {c['threads']} threads, {c['samples']} samples; CPU s, least of "
             f"{c['repeats']} runs):", "",
             f"| core | {c['samples']}-sample bake | with denoise=True | added | added / bake | guide alone | "
             "filter alone | filter / bake | added per megatexel |", "|---|---|---|---|---|---|---|---|---|"]
    for name, v in c["versions"].items():
        lines.append(f"| {name} | {v['bake_cpu']:.1f} | {v['bake_denoise_cpu']:.1f} | {v['added_cpu']:.1f} | "
                     f"{100 * v['ratio_cpu']:.0f}% | {v['guide_cpu']:.1f} | {v['filter_cpu']:.1f} | "
                     f"{100 * v['ratio_filter_cpu']:.0f}% | "
                     f"{v['cpu_per_megatexel']:.2f} |")
    return "\n".join(lines)


def equal_error(res, ref_samples, seed=1, threads=2, cache=None, raw_samples=(32, 64, 128, 256),
                dn_samples=(8, 16, 32)):
    """RMSE and CPU seconds of raw bakes and of denoised ones at several sample counts (same scene,
    reference as compare's): the CPU time at which each reaches raw 128's RMSE, by interpolation in
    log-log between the counts that bracket it."""
    target, occ, dist = load_scene()
    path = None if cache is None else Path(cache) / f"denoise_reference_{res}_{ref_samples}_{seed}.npz"
    if path is not None and path.exists():
        ref = _Ref(np.load(path))
    else:
        ref = bake_ao(target, occ, resolution=res, samples=ref_samples, max_distance=dist, seed=10_000 + seed,
                      threads=threads)
    with Clock() as tg:
        guide = D.surface_guide(target, res)
    rows = []
    for kind, counts in (("raw", raw_samples), ("denoised", dn_samples)):
        for n in counts:
            with Clock() as tb:
                r = bake_ao(target, occ, resolution=res, samples=n, max_distance=dist, seed=seed + n, threads=threads)
            cpu, img = tb.cpu, r.ao
            if kind == "denoised":
                with Clock() as td:
                    img = D.denoise(r.ao, r.stderr, r.mask, guide, threads=threads)[0]
                cpu += tg.cpu + td.cpu
            m = r.mask & ref.mask
            rows.append({"kind": kind, "samples": n, "cpu": cpu,
                         "rmse": float(np.sqrt(np.mean((img - ref.ao)[m].astype(np.float64) ** 2)))})
    goal = next(x["rmse"] for x in rows if x["kind"] == "raw" and x["samples"] == 128)

    def time_at(kind):
        pts = sorted((x["rmse"], x["cpu"]) for x in rows if x["kind"] == kind)
        for (e0, t0), (e1, t1) in zip(pts, pts[1:]):
            if e0 <= goal <= e1:
                f = (math.log(goal) - math.log(e0)) / (math.log(e1) - math.log(e0))
                return math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0)))
        return None

    t_raw, t_dn = time_at("raw"), time_at("denoised")
    return {"resolution": res, "rows": rows, "goal_rmse": goal, "raw_cpu_at_goal": t_raw, "denoised_cpu_at_goal": t_dn,
            "ratio": (t_dn / t_raw) if t_raw and t_dn else None}


# --- equal error against Cycles, in one run ---------------------------------------------------------

#: The scenes of the equal-error table: (name, how to open it in bpy, target object, AO distance).
CYCLES_SCENES = ("suzanne", "room", "dense")


def _open_scene(bpy, name):
    """Open ``name`` in bpy: (the target object, its core.Mesh, the occluders' core.Meshes, AO distance).
    suzanne: the bench's scene (bench.harness.scene); room: sample_scenes/room.blend (walls, distance
    1); dense: sample_scenes/dense.blend (524k-triangle terrain, distance 1)."""
    from bench.harness import scene as S

    if name == "suzanne":
        S.reset_blender(bpy)
        objs = S.build_scene(bpy)
        obj, target_name, dist = objs["Suzanne"], "Suzanne", S.DISTANCE
    else:
        blend, target_name = {"room": ("room.blend", "Room"), "dense": ("dense.blend", "Terrain")}[name]
        bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / blend), load_ui=False)
        dist = 1.0
        if bpy.context.scene.world is None:
            bpy.context.scene.world = bpy.data.worlds.new("World")
        bpy.context.scene.world.light_settings.distance = dist
        obj = bpy.data.objects[target_name]
    ta, oa = S.scene_arrays(bpy, target_name)
    target, occ = S.core_meshes(ta, oa)
    return obj, target, occ, dist


def _series_time(pts, goal, key):
    """The ``key`` time at which a series [(samples, rmse, {times})] reaches ``goal`` RMSE (log-log
    interpolation between the counts that bracket it; None if it does not)."""
    from bench.harness.common import interp_time_at

    return interp_time_at([p[key] for p in pts], [p["rmse"] for p in pts], goal)


def cycles_equal_error(res=512, ref_samples=2048, threads=2, cache=None, scenes=CYCLES_SCENES,
                       cycles_samples=(32, 64, 128, 256), raw_samples=(16, 32, 64, 128, 256),
                       dn_samples=(8, 16, 32, 64), seed=1, picture_path=None):
    """Per scene, in one run: Cycles' AO bake at ``cycles_samples``, mc_ao raw and denoised, and Open
    Image Denoise (RT, RTLightmap) on mc_ao's noisy bakes, each against an mc_ao reference of
    ``ref_samples`` that no filter touched. The time to reach Cycles 128's RMSE (over interior texels:
    covered by both bakers with every 8-neighbour too, as bench.sections.equal measures) for each,
    over Cycles 128's time; CPU seconds of this process (Cycles bakes in it too) and wall seconds.
    Raw bakes take one replicate (the add-on's bake without an error map, lowest noise); denoised
    ones two (the filter needs the error). OIDN sees the same noisy bake as the denoiser, dilated 16
    texels (without a margin it darkens borders); its time is the bake's plus its own."""
    import bpy

    from bench.comparators import cycles
    from bench.harness.common import erode
    from core.geometry.margin import dilate

    filters, version = oidn_filters()
    filters = {k: v for k, v in filters.items() if k in ("OIDN RT", "OIDN RTLightmap")}
    out = {"resolution": res, "reference_samples": ref_samples, "threads": threads, "oidn": version, "scenes": {}}
    for name in scenes:
        obj, target, occ, dist = _open_scene(bpy, name)
        path = None if cache is None else Path(cache) / f"denoise_cycles_ref_{name}_{res}_{ref_samples}.npz"
        if path is not None and path.exists():
            ref = _Ref(np.load(path))
        else:
            ref = bake_ao(target, occ, resolution=res, samples=ref_samples, max_distance=dist, seed=10_000 + seed,
                          threads=threads, margin=0)
            if path is not None:
                np.savez(path, ao=ref.ao, stderr=ref.stderr, mask=ref.mask)
        cycles.bake(bpy, obj, 32, 32, 1, threads)  # warm up (kernels, BVH) outside the measurements
        cyc = {}
        for n in cycles_samples:
            ao, wall = cycles.bake(bpy, obj, res, res, n, threads, seed=11, margin=0, sentinel=-1.0)
            cyc[n] = (ao, wall, cycles.LAST["cpu"])
        cmask = cyc[cycles_samples[0]][0] >= 0
        maps = {}
        for n in raw_samples:
            with Clock() as t:
                r = bake_ao(target, occ, resolution=res, samples=n, max_distance=dist, seed=seed + n, threads=threads,
                            margin=0, replicates=1)
            maps[("raw", n)] = (r.ao, t.wall, t.cpu)
        guide = None
        for n in dn_samples:
            with Clock() as t:
                r = bake_ao(target, occ, resolution=res, samples=n, max_distance=dist, seed=seed + 100 + n,
                            threads=threads, margin=0, denoise=True)
            maps[("denoised", n)] = (r.ao, t.wall, t.cpu)
            # The same noisy bake for OIDN: its time is the bake's without the filter (measured: the
            # raw bake's share, from the bake with denoise off at this count).
            with Clock() as tb:
                bake_ao(target, occ, resolution=res, samples=n, max_distance=dist, seed=seed + 100 + n,
                        threads=threads, margin=0)
            padded = r.raw_ao.copy()
            dilate(padded, r.mask, 16, out=padded)
            for fname, f in filters.items():
                with Clock() as tf:
                    img = f(padded, None)
                maps[(fname, n)] = (img, tb.wall + tf.wall, tb.cpu + tf.cpu)
            if n == 16:
                maps[("raw replicates 2", n)] = (r.raw_ao, tb.wall, tb.cpu)
        mask = ref.mask & cmask
        inner = erode(mask)
        edge = border(ref.mask) & mask
        if guide is None:
            guide = D.surface_guide(target, res)
        a, b = guide.links[:, 0], guide.links[:, 1]
        keep = mask.reshape(-1)[a] & mask.reshape(-1)[b]
        a, b = a[keep], b[keep]

        def metrics(img):
            f = np.asarray(img, np.float64).reshape(-1)
            e = np.asarray(img, np.float64) - ref.ao
            return {"rmse": float(np.sqrt(np.mean(e[inner] ** 2))), "rmse_common": float(np.sqrt(np.mean(e[mask] ** 2))),
                    "border_rmse": float(np.sqrt(np.mean(e[edge] ** 2))),
                    "seam_mean_abs_diff": float(np.mean(np.abs(f[a] - f[b]))) if len(a) else None}

        rows = []
        for n, (ao, wall, cpu) in cyc.items():
            rows.append(dict(metrics(ao), kind="Cycles", samples=n, wall=wall, cpu=cpu))
        for (kind, n), (ao, wall, cpu) in maps.items():
            rows.append(dict(metrics(ao), kind=kind, samples=n, wall=wall, cpu=cpu))
        goal_row = next(x for x in rows if x["kind"] == "Cycles" and x["samples"] == 128)
        goal = goal_row["rmse"]
        matched = {}
        for kind in ["raw", "denoised"] + list(filters):
            pts = [x for x in rows if x["kind"] == kind]
            t_cpu, t_wall = _series_time(pts, goal, "cpu"), _series_time(pts, goal, "wall")
            matched[kind] = {"cpu": t_cpu, "wall": t_wall,
                             "ratio_cpu": None if t_cpu is None else t_cpu / goal_row["cpu"],
                             "ratio_wall": None if t_wall is None else t_wall / goal_row["wall"]}
        r = ref.ao.reshape(-1)
        out["scenes"][name] = {
            "triangles": int(target.triangle_count), "distance": dist, "texels_interior": int(inner.sum()),
            "texels_common": int(mask.sum()), "texels_border": int(edge.sum()), "seam_pairs": int(len(a)),
            "seam_reference": float(np.mean(np.abs(r[a] - r[b]))) if len(a) else None,
            "reference_rmse_floor": float(np.sqrt(np.mean(ref.stderr[inner].astype(np.float64) ** 2))),
            "goal_rmse": goal, "cycles128_cpu": goal_row["cpu"], "cycles128_wall": goal_row["wall"],
            "rows": rows, "matched": matched}
        if picture_path is not None and name == "suzanne":
            pick = [maps[("raw replicates 2", 16)][0], maps[("denoised", 16)][0]]
            if ("OIDN RTLightmap", 16) in maps:
                pick.append(maps[("OIDN RTLightmap", 16)][0])
            picture(picture_path, pick + [ref.ao], ref.ao, ref.mask)
        print(cycles_table(name, out["scenes"][name]), flush=True)
    return out


# --- equal error against Cycles: the operator with Denoise on against Cycles, each against its own converged image --

def _gradient(img, mask):
    """|grad| per texel of ``img`` (central differences between covered texels, one-sided at borders)."""
    h, w = img.shape
    f = np.pad(np.asarray(img, np.float64), 1)
    m = np.pad(mask, 1)
    c = (slice(1, h + 1), slice(1, w + 1))
    out = np.zeros((h, w))
    for lo, hi in (((slice(0, h), slice(1, w + 1)), (slice(2, h + 2), slice(1, w + 1))),
                   ((slice(1, h + 1), slice(0, w)), (slice(1, h + 1), slice(2, w + 2)))):
        a, b = m[lo], m[hi]
        d = np.where(a & b, (f[hi] - f[lo]) / 2, np.where(b, f[hi] - f[c], np.where(a, f[c] - f[lo], 0.0)))
        out += d * d
    return np.sqrt(out)


def _cached(path, make):
    """``make()``'s dict of arrays, kept in ``path`` (an .npz) when a path is given."""
    if path is not None and Path(path).exists():
        z = np.load(path)
        return {k: z[k] for k in z.files}
    out = make()
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, **out)
    return out


def _load():
    import os

    return [round(x, 2) for x in os.getloadavg()]


def done_when(res=512, scenes=CYCLES_SCENES, threads=2, ref_samples=2048, cycles_ref_samples=2048, cache=None,
              cycles_samples=(32, 64, 128, 256), raw_samples=(16, 32, 64, 128, 256), dn_samples=(8, 16, 32, 64),
              aimed_targets=(0.06, 0.04, 0.03, 0.02), aimed_samples=256, seed=1):
    """The equal-error figures in one run, per scene: Cycles' AO bake at ``cycles_samples`` against a Cycles
    bake of ``cycles_ref_samples``; the add-on's operator (bpy.ops.object.mc_ao_bake, Processes =
    ``threads``) with Denoise on at ``dn_samples`` and off at ``raw_samples``, against a core bake of
    ``ref_samples`` that no filter touched; Open Image Denoise RTLightmap on the same noisy bake as a
    denoised one (core, two replicates, its margin dilated 16 texels). Each baker against its own
    converged image, over the texels both cover away from island borders (interior); borders apart.
    The "aimed" series: the operator with Denoise on and a Noise Threshold at each of ``aimed_targets``
    (Min Samples 16, Samples ``aimed_samples``): adaptive sampling aimed at the denoised map's error
    (core.post.denoise.aim).

    - time to Cycles 128's RMSE over Cycles 128's time (CPU seconds of Blender's process and the
      operator's worker processes; log-log interpolation between sample counts);
    - the high-gradient check: RMSE over the 10% of interior texels with the largest gradient of mc_ao's
      converged image, denoised at each count against the raw operator at the same CPU time
      (interpolated in log-log over the raw series);
    - z sd of (denoised - reference) / sqrt(stderr^2 + reference stderr^2) (core bake, 16 samples);
    - the machine's load average before and after each scene.
    """
    import bpy

    from bench.comparators import cycles
    from bench.harness import mcao
    from bench.harness.common import erode, interp_time_at
    from core.geometry.margin import dilate

    filters, version = oidn_filters()
    rtl = filters.get("OIDN RTLightmap")
    out = {"resolution": res, "threads": threads, "reference_samples": ref_samples,
           "cycles_reference_samples": cycles_ref_samples, "oidn": version, "scenes": {}}
    for name in scenes:
        load0 = _load()
        obj, target, occ, dist = _open_scene(bpy, name)
        key = lambda what: None if cache is None else Path(cache) / f"done_{what}_{name}_{res}.npz"  # noqa: E731
        ref = _cached(key(f"mcao{ref_samples}"), lambda: (lambda r: {"ao": r.ao, "stderr": r.stderr, "mask": r.mask})(
            bake_ao(target, occ, resolution=res, samples=ref_samples, max_distance=dist, seed=10_000 + seed,
                    threads=threads, margin=0)))
        cycles.bake(bpy, obj, 32, 32, 1, threads)  # warm-up (kernels, BVH) outside the measurements
        mcao.operator_bake(bpy, obj, 32, 1, threads, dist, margin=0)
        cref = _cached(key(f"cycles{cycles_ref_samples}"), lambda: {"ao": cycles.bake(
            bpy, obj, res, res, cycles_ref_samples, threads, seed=97, margin=0, sentinel=-1.0)[0]})
        rows = []
        for n in cycles_samples:
            ao, wall = cycles.bake(bpy, obj, res, res, n, threads, seed=11, margin=0, sentinel=-1.0)
            rows.append(dict(kind="Cycles", samples=n, ao=ao, cpu=cycles.LAST["cpu"], wall=wall))
        for kind, counts, dn in (("raw", raw_samples, False), ("denoised", dn_samples, True)):
            for n in counts:
                ao, wall = mcao.operator_bake(bpy, obj, res, n, threads, dist, margin=0, seed=seed + n, denoise=dn)
                rows.append(dict(kind=kind, samples=n, ao=ao, cpu=mcao.LAST["cpu"], wall=wall))
        for target_error in aimed_targets:
            ao, wall = mcao.operator_bake(bpy, obj, res, aimed_samples, threads, dist, margin=0, seed=seed + 1000,
                                          denoise=True, target_error=target_error, min_samples=16)
            rows.append(dict(kind="aimed", samples=aimed_samples, target_error=target_error, ao=ao,
                             cpu=mcao.LAST["cpu"], wall=wall))
        # The core's denoised bake at 16 samples: its error for z, its raw estimate for OIDN.
        c0, w0 = mcao.process_cpu(), time.perf_counter()
        r16 = bake_ao(target, occ, resolution=res, samples=16, max_distance=dist, seed=seed + 16, threads=threads,
                      margin=0, denoise=True)
        dn_cpu = mcao.process_cpu() - c0
        if rtl is not None:
            with Clock() as t:
                padded = r16.raw_ao.copy()
                dilate(padded, r16.mask, 16, out=padded)
                img = rtl(padded, None)
            base = next(x for x in rows if x["kind"] == "denoised" and x["samples"] == 16)
            rows.append(dict(kind="OIDN RTLightmap", samples=16, ao=img, cpu=base["cpu"] + t.cpu,
                             wall=base["wall"] + t.wall, note="the operator's denoised 16's time plus OIDN's"))
        cmask = cref["ao"] >= 0
        common = cmask & ref["mask"]
        inner = erode(common)
        edge = border(ref["mask"]) & common
        grad = _gradient(ref["ao"], ref["mask"])
        steep = inner & (grad >= np.quantile(grad[inner], 0.9))

        def rm(e, sel):
            return float(np.sqrt(np.mean(e[sel] ** 2)))

        for x in rows:
            truth = cref["ao"] if x["kind"] == "Cycles" else ref["ao"]
            e = np.asarray(x.pop("ao"), np.float64) - truth
            x.update(rmse=rm(e, inner), rmse_border=rm(e, edge), rmse_steep=rm(e, steep), rmse_common=rm(e, common))
        goal_row = next(x for x in rows if x["kind"] == "Cycles" and x["samples"] == 128)
        goal = goal_row["rmse"]
        matched = {}
        for kind in ("raw", "denoised", "aimed"):
            pts = [x for x in rows if x["kind"] == kind]
            if not pts:
                continue
            t = interp_time_at([p["cpu"] for p in pts], [p["rmse"] for p in pts], goal)
            matched[kind] = {"cpu": t, "ratio": None if t is None else t / goal_row["cpu"]}
        raw_pts = [x for x in rows if x["kind"] == "raw"]
        steep_check = []
        for x in (r for r in rows if r["kind"] in ("denoised", "aimed")):
            # the raw series' steep RMSE at the denoised bake's CPU time (log-log between its counts)
            ts = np.log([p["cpu"] for p in raw_pts])
            es = np.log([p["rmse_steep"] for p in raw_pts])
            at = float(np.exp(np.interp(np.log(x["cpu"]), ts, es)))
            steep_check.append({"kind": x["kind"], "samples": x["samples"], "target_error": x.get("target_error"),
                                "cpu": x["cpu"], "denoised": x["rmse_steep"],
                                "raw_at_same_cpu": at, "ok": x["rmse_steep"] <= at,
                                "extrapolated": not (ts.min() <= np.log(x["cpu"]) <= ts.max())})
        sel = inner & (r16.stderr > 0)
        z = (r16.ao - ref["ao"])[sel] / np.sqrt(r16.stderr[sel].astype(np.float64) ** 2
                                                 + ref["stderr"][sel].astype(np.float64) ** 2)
        out["scenes"][name] = {
            "triangles": int(target.triangle_count), "distance": dist, "texels_interior": int(inner.sum()),
            "texels_border": int(edge.sum()), "texels_steep": int(steep.sum()), "goal_rmse": goal,
            "cycles128_cpu": goal_row["cpu"], "rows": rows, "matched": matched, "steep_check": steep_check,
            "z_sd": float(z.std()), "z_mean": float(z.mean()), "core_denoised16_cpu": dn_cpu,
            "load_before": load0, "load_after": _load()}
        print(done_table(name, out["scenes"][name]), flush=True)
    return out


def done_table(name, c):
    fmt = lambda v, f="{:.3f}": "-" if v is None else f.format(v)  # noqa: E731
    lines = [f"\n{name}: {c['texels_interior']} interior texels ({c['texels_border']} border, {c['texels_steep']} "
             f"steepest 10%); Cycles 128: RMSE {c['goal_rmse']:.4f} against Cycles' own converged image, "
             f"{c['cycles128_cpu']:.1f} CPU s; load {c['load_before']} -> {c['load_after']}",
             "", "| map | samples | RMSE (interior) | border | steepest 10% | CPU s | wall s |", "|---|---|---|---|---|---|---|"]
    for x in c["rows"]:
        kind = x["kind"] if x.get("target_error") is None else f"{x['kind']} (threshold {x['target_error']})"
        lines.append(f"| {kind} | {x['samples']} | {x['rmse']:.4f} | {x['rmse_border']:.4f} | "
                     f"{x['rmse_steep']:.4f} | {x['cpu']:.2f} | {x['wall']:.2f} |")
    lines += ["", "Time to Cycles 128's RMSE over Cycles 128's (CPU): " + "; ".join(
        f"{k} {fmt(v['ratio'])}x" for k, v in c["matched"].items()),
        "Steepest 10%, denoised against raw at the same CPU time: " + "; ".join(
        f"{s.get('kind', 'denoised')} {s['samples'] if s.get('target_error') is None else s['target_error']}: "
        f"{s['denoised']:.4f} vs {s['raw_at_same_cpu']:.4f}{' (extrapolated)' if s['extrapolated'] else ''}"
        for s in c["steep_check"]),
        f"z sd (core, denoised 16, against the reference): {c['z_sd']:.3f} (mean {c['z_mean']:+.3f})"]
    return "\n".join(lines)


def cycles_table(name, c):
    fmt = lambda v, f="{:.3f}": "-" if v is None else f.format(v)  # noqa: E731
    lines = [f"\n{name}: {c['texels_interior']} interior texels ({c['texels_border']} border, {c['seam_pairs']} seam "
             f"pairs, reference seam |diff| {fmt(c['seam_reference'], '{:.4f}')}); reference RMSE floor "
             f"{c['reference_rmse_floor']:.4f}; Cycles 128: RMSE {c['goal_rmse']:.4f}, {c['cycles128_cpu']:.1f} CPU s",
             "", "| map | samples | RMSE (interior) | all | border | seams | CPU s | wall s |",
             "|---|---|---|---|---|---|---|---|"]
    for x in c["rows"]:
        lines.append(f"| {x['kind']} | {x['samples']} | {x['rmse']:.4f} | {x['rmse_common']:.4f} | "
                     f"{x['border_rmse']:.4f} | {fmt(x['seam_mean_abs_diff'], '{:.4f}')} | {x['cpu']:.2f} | "
                     f"{x['wall']:.2f} |")
    lines += ["", "Time to Cycles 128's RMSE, over Cycles 128's (CPU, wall): " + "; ".join(
        f"{k} {fmt(v['ratio_cpu'])}x, {fmt(v['ratio_wall'])}x" for k, v in c["matched"].items())]
    return "\n".join(lines)


def table(c):
    lines = [f"Suzanne scene {c['resolution']}^2, {c['covered']} covered texels ({c['border_texels']} on island "
             f"borders, {c['seam_pairs']} texel pairs across UV seams); reference {c['reference_samples']} samples "
             f"(its own RMSE about {c['reference_rmse_floor']:.4f}); seam |diff| of the reference "
             f"{c['seam_reference']:.4f}.",
             "",
             "| map | RMSE | border RMSE | seam mean abs diff | CPU s (bake + filter) |",
             "|---|---|---|---|---|"]
    for name, m in c["rows"].items():
        lines.append(f"| {name} | {m['rmse']:.4f} | {m['border_rmse']:.4f} | {m['seam_mean_abs_diff']:.4f} | "
                     f"{m['cpu']:.2f} |")
    lines += ["", f"mc_ao denoise: z sd {c['z_sd']:.3f}, mean {c['z_mean']:+.3f}, "
                  f"|z| > 4 on {100 * c['z_over_4']:.2f}% "
                  f"(z against the reference, both errors); candidates taken (raw, then by bandwidth) {c['choice']}; "
                  f"guide {c['guide_cpu']:.2f} s + filter {c['denoise_cpu']:.2f} s CPU against the bake's "
                  f"{c['bake_cpu']:.2f} s."]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--reference-samples", type=int, default=1024)
    ap.add_argument("--cost-resolution", type=int, default=0, help="also measure the cost at this size (0: skip)")
    ap.add_argument("--cost-against", default=None, help="a commit whose core's cost is measured in the same run")
    ap.add_argument("--cost-repeats", type=int, default=1)
    ap.add_argument("--cost-samples", type=int, default=64, help="the samples of the bake the cost is measured against")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--reference-cache", type=Path, default=None, help="folder to keep the reference bake in")
    ap.add_argument("--equal-error", action="store_true",
                    help="also: CPU time to reach raw 128's RMSE, raw against denoised")
    ap.add_argument("--cycles", action="store_true",
                    help="the equal-error table against Cycles (bpy) on the Suzanne scene, the room and dense.blend")
    ap.add_argument("--scenes", nargs="+", default=list(CYCLES_SCENES))
    ap.add_argument("--done-when", action="store_true",
                    help="the equal-error figures: the operator with Denoise on against Cycles, each against its own "
                         "converged image, at --resolution (several allowed with --resolutions)")
    ap.add_argument("--resolutions", type=int, nargs="+", default=None)
    ap.add_argument("--cycles-reference-samples", type=int, default=2048)
    ap.add_argument("--picture", type=Path, default=None,
                    help="PNG: raw, mc_ao denoised, OIDN RTLightmap, reference; |error| x 5 below")
    a = ap.parse_args(argv)
    out = {}
    if a.done_when:
        out["done_when"] = [done_when(r, a.scenes, threads=a.threads, ref_samples=a.reference_samples,
                                      cycles_ref_samples=a.cycles_reference_samples, cache=a.reference_cache)
                            for r in (a.resolutions or [a.resolution])]
        if a.json:
            a.json.write_text(json.dumps(out, indent=1))
        return out
    if a.resolution and not a.cycles:
        out["compare"] = compare(a.resolution, a.samples, a.reference_samples, threads=a.threads,
                                 cache=a.reference_cache, picture_path=a.picture)
        print(table(out["compare"]))
    if a.cost_resolution:
        c = cost(a.cost_resolution, threads=a.threads, against=a.cost_against, repeats=a.cost_repeats,
                 samples=a.cost_samples)
        out["cost"] = c
        print("\n" + cost_table(c))
    if a.equal_error:
        e = equal_error(a.resolution, a.reference_samples, threads=a.threads, cache=a.reference_cache)
        out["equal_error"] = e
        print(f"\nEqual error at {e['resolution']}^2 (raw 128's RMSE {e['goal_rmse']:.4f}):")
        print("| map | samples | RMSE | CPU s |\n|---|---|---|---|")
        for x in e["rows"]:
            print(f"| {x['kind']} | {x['samples']} | {x['rmse']:.4f} | {x['cpu']:.2f} |")
        fmt = lambda v: "-" if v is None else f"{v:.2f}"  # noqa: E731
        print(f"CPU s to reach it: raw {fmt(e['raw_cpu_at_goal'])}, denoised {fmt(e['denoised_cpu_at_goal'])}"
              f" (ratio {fmt(e['ratio'])})")
    if a.cycles:
        out["cycles"] = cycles_equal_error(a.resolution or 512, a.reference_samples, threads=a.threads,
                                           cache=a.reference_cache, scenes=a.scenes, picture_path=a.picture)
    if a.json:
        a.json.write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
