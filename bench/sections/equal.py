"""Equal samples (speed at the same job) and equal error (time to the same RMSE), mc_ao against Cycles.

Timing protocol: the two bakers alternate, each measurement is repeated where it is cheap, and the
fastest repeat counts (the machine is shared: the slowest repeats measure the neighbours). Every
repeat is kept in the JSON.
"""

import numpy as np

from ..comparators import cycles
from ..harness import mcao
from ..harness.common import ROOT, erode, interp_time_at, log, rmse
from ..harness.scene import DISTANCE

SOURCES = ("sobol", "stratified", "independent", "halton")


def equal_samples(ctx):
    """Same scene, resolution, samples and threads: Cycles' AO bake, mc_ao's operator, core.bake_ao."""
    bpy, cfg = ctx.bpy, ctx.cfg
    obj = ctx.objs["Suzanne"]
    spp, threads = cfg["es_spp"], ctx.threads
    # Warm both up once (kernel loading, imports, first BVH) outside the measurements.
    cycles.bake(bpy, obj, 32, 32, 1, threads)
    mcao.operator_bake(bpy, obj, 32, 1, threads, DISTANCE)
    rows = []
    for res in cfg["es_res"]:
        reps = cfg["es_repeats"].get(res, 1)
        cyc_t, op_t, core_t, shares, cyc_c, op_c = [], [], [], [], [], []
        cyc_texels = mc_texels = None
        for _ in range(reps):
            ao, t = cycles.bake(bpy, obj, res, res, spp, threads, margin=16, sentinel=None)
            cyc_t.append(t)
            cyc_c.append(cycles.LAST["cpu"])
            _, t = mcao.operator_bake(bpy, obj, res, spp, threads, DISTANCE, margin=16, fix_seams=False)
            op_t.append(t)
            op_c.append(mcao.LAST["cpu"])
            r = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=spp, threads=threads,
                               max_distance=DISTANCE, margin=16, fix_seams=False)
            core_t.append(r.seconds)
            shares.append(r.trace_seconds / (r.seconds * r.threads))
            mc_texels = int(r.mask.sum())
        # Texels Cycles bakes: those whose centre a UV triangle covers (measured once, margin 0).
        ao0, _ = cycles.bake(bpy, obj, res, res, 1, threads, margin=0, sentinel=-1.0)
        cyc_texels = int((ao0 >= 0).sum())
        tc, to, tk = min(cyc_t), min(op_t), min(core_t)
        row = {
            "resolution": res, "samples": spp, "threads": threads, "repeats": reps,
            "cycles_s": tc, "mc_operator_s": to, "mc_core_s": tk,
            "cycles_s_all": cyc_t, "mc_operator_s_all": op_t, "mc_core_s_all": core_t,
            "cycles_texels": cyc_texels, "mc_texels": mc_texels,
            "cycles_tsps": cyc_texels * spp / tc, "mc_tsps": mc_texels * spp / to,
            "mc_tsps_common": cyc_texels * spp / to,
            "ratio_time": tc / to, "ratio_tsps": (mc_texels * spp / to) / (cyc_texels * spp / tc),
            "cycles_cpu_s": min(cyc_c), "mc_operator_cpu_s": min(op_c), "ratio_cpu": min(cyc_c) / min(op_c),
            "cycles_cpu_s_all": cyc_c, "mc_operator_cpu_s_all": op_c,
            "mc_core_trace_share": float(np.median(shares)),
        }
        rows.append(row)
        log(f"equal samples {res}^2 x {spp}: Cycles {tc:.2f}s, mc_ao operator {to:.2f}s (core {tk:.2f}s), "
            f"time ratio {row['ratio_time']:.2f}, texel-samples/s ratio {row['ratio_tsps']:.2f}, "
            f"CPU-time ratio {row['ratio_cpu']:.2f}", ctx.clock)
    return {"scene": "Suzanne (smooth, subdiv 1) over a plane with two blocks; target Suzanne",
            "margin": 16, "rows": rows,
            "note": "texel-samples/s counts each baker's own texels: Cycles bakes texels whose centre a UV "
                    "triangle covers, mc_ao every texel a triangle touches (partial edge texels too); "
                    "ratio_time compares the same job (same image) and is the conservative figure."}


#: AO distance of the dense scene (a 4 x 4 terrain displaced by up to 0.6), for both bakers.
DENSE_DISTANCE = 1.0


def dense_equal_samples(ctx):
    """sample_scenes/dense.blend (524k triangles, smooth): Cycles' AO bake against mc_ao's operator and
    core.bake_ao at the same resolution, samples and threads. Restores the benchmark scene after."""
    from ..harness.scene import core_meshes, scene_arrays, select_only

    bpy, cfg = ctx.bpy, ctx.cfg
    res, spp, threads = cfg["dense_res"], cfg["dense_spp"], ctx.threads
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / "dense.blend"))
    scene = bpy.context.scene
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    scene.world.light_settings.distance = DENSE_DISTANCE
    obj = bpy.data.objects["Terrain"]
    select_only(bpy, obj)
    ta, oa = scene_arrays(bpy, "Terrain")
    target, occluders = core_meshes(ta, oa)
    cycles.bake(bpy, obj, 32, 32, 1, threads)
    mcao.operator_bake(bpy, obj, 32, 1, threads, DENSE_DISTANCE)
    cyc_t, op_t, core_t, cyc_c, op_c, shares = [], [], [], [], [], []
    for _ in range(cfg["dense_repeats"]):
        _, t = cycles.bake(bpy, obj, res, res, spp, threads, margin=16)
        cyc_t.append(t)
        cyc_c.append(cycles.LAST["cpu"])
        _, t = mcao.operator_bake(bpy, obj, res, spp, threads, DENSE_DISTANCE, margin=16, fix_seams=False)
        op_t.append(t)
        op_c.append(mcao.LAST["cpu"])
        r = mcao.core_bake(target, occluders, resolution=res, samples=spp, threads=threads,
                           max_distance=DENSE_DISTANCE, margin=16, fix_seams=False)
        core_t.append(r.seconds)
        shares.append(r.trace_seconds / (r.seconds * r.threads))
    row = {"scene": "sample_scenes/dense.blend, object Terrain", "triangles": int(target.triangle_count),
           "resolution": res, "samples": spp, "threads": threads, "distance": DENSE_DISTANCE,
           "cycles_s": min(cyc_t), "mc_operator_s": min(op_t), "mc_core_s": min(core_t),
           "cycles_s_all": cyc_t, "mc_operator_s_all": op_t, "mc_core_s_all": core_t,
           "ratio_time": min(cyc_t) / min(op_t), "ratio_cpu": min(cyc_c) / min(op_c),
           "ratio_core": min(cyc_t) / min(core_t), "mc_core_trace_share": float(np.median(shares))}
    log(f"dense.blend {res}^2 x {spp}: Cycles {row['cycles_s']:.2f}s, mc_ao operator {row['mc_operator_s']:.2f}s "
        f"(core {row['mc_core_s']:.2f}s): {row['ratio_time']:.2f}x", ctx.clock)
    ctx.restore_scene()
    return row


def _series_point(r, ref_ao, sel, label, **extra):
    return dict(label=label, seconds=r.seconds, cpu_seconds=getattr(r, "cpu_seconds", None),
                rmse=rmse(r.ao, ref_ao, sel), rays=r.rays,
                mean_samples=float(r.samples[r.mask].mean()), trace_share=r.trace_seconds / (r.seconds * r.threads),
                **extra)


def _time_fit(pts, key="seconds"):
    """Least-squares t = a + b * samples over a fixed-sample series: one noisy repeat moves it less
    than it moves a single point."""
    x = np.array([p["samples"] for p in pts], float)
    y = np.array([p[key] for p in pts], float)
    b, a = np.polyfit(x, y, 1)
    return float(a), float(b)


def _fitted_ratios(series, at128):
    """Time to Cycles' 128-spp RMSE from fitted times: each fixed series' samples at that RMSE (log-log
    interpolation of RMSE against samples), priced by its own time fit, over Cycles' fitted time at 128."""
    if at128 is None:
        return {}
    ac, bc = _time_fit(series["cycles"])
    t_cyc = ac + bc * 128
    out = {"cycles_fit": {"a_s": ac, "b_s_per_spp": bc, "t128_s": t_cyc}}
    for name, pts in series.items():
        if name == "cycles" or "+adaptive" in name:
            continue
        spp = interp_time_at([p["samples"] for p in pts], [p["rmse"] for p in pts], at128["rmse"])
        a, b = _time_fit(pts)
        t = a + b * spp if spp else None
        out[name] = {"samples": spp, "seconds": t, "ratio": t / t_cyc if t else None, "a_s": a, "b_s_per_spp": b}
        if spp and all(p.get("cpu_seconds") is not None for p in pts + series["cycles"]):
            acc, bcc = _time_fit(series["cycles"], "cpu_seconds")
            ac_, bc_ = _time_fit(pts, "cpu_seconds")
            out[name]["ratio_cpu"] = (ac_ + bc_ * spp) / (acc + bcc * 128)
    return out


def equal_error(ctx):
    """RMSE against a converged mc_ao reference, against time, for Cycles and every mc_ao configuration."""
    bpy, cfg = ctx.bpy, ctx.cfg
    obj = ctx.objs["Suzanne"]
    res, threads = cfg["ee_res"], ctx.threads
    log(f"equal error: reference, mc_ao sobol {cfg['ref_spp']} spp at {res}^2", ctx.clock)
    ref = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=cfg["ref_spp"], threads=threads,
                         max_distance=DISTANCE, seed=987654321)
    ctx.ref = ref

    # Fixed-sample points of every series, interleaved by sample count and repeated: the fastest
    # repeat counts (the RMSE is that of the first; repeats differ only in time).
    cyc, fixed = {}, {source: {} for source in SOURCES}
    cyc_mask = None
    for spp in sorted(set(cfg["cyc_spp"]) | set(cfg["mc_spp"])):
        for rep in range(cfg["ee_repeats"]):
            if spp in cfg["cyc_spp"]:
                ao, t = cycles.bake(bpy, obj, res, res, spp, threads, seed=11, margin=0, sentinel=-1.0)
                c = cycles.LAST["cpu"]
                cyc_mask = ao >= 0
                cyc[spp] = (ao if rep == 0 else cyc[spp][0], min(t, cyc[spp][1]) if rep else t,
                            min(c, cyc[spp][2]) if rep else c)
            if spp in cfg["mc_spp"]:
                for source in SOURCES:
                    # replicates=1: what the add-on bakes without an error map or adaptive sampling.
                    r = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=spp, threads=threads,
                                       max_distance=DISTANCE, source=source, seed=5, replicates=1)
                    if rep == 0:
                        fixed[source][spp] = r
                    else:
                        f = fixed[source][spp]
                        f.seconds = min(f.seconds, r.seconds)
                        f.cpu_seconds = min(f.cpu_seconds, r.cpu_seconds)
    common = cyc_mask & ref.mask
    interior = erode(common)
    ctx.cyc_mask = cyc_mask
    sel = interior
    ref_noise = float(np.sqrt(np.mean(ref.stderr[sel].astype(np.float64) ** 2)))
    cyc_series = [dict(label=f"cycles {spp}", samples=spp, seconds=t, cpu_seconds=c, rmse=rmse(ao, ref.ao, sel),
                       rmse_common=rmse(ao, ref.ao, common)) for spp, (ao, t, c) in sorted(cyc.items())]
    for p in cyc_series:
        log(f"  {p['label']:>22}: {p['seconds']:6.2f}s  RMSE {p['rmse']:.5f}", ctx.clock)

    # Cycles converged, for the agreement check (kept for bench/sections/agreement.py).
    ao_hi, t_hi = cycles.bake(bpy, obj, res, res, cfg["cyc_check_spp"], threads, seed=12, margin=0, sentinel=-1.0)
    ctx.cycles_hi = ao_hi

    series = {"cycles": cyc_series}
    for source in SOURCES:
        pts = [_series_point(r, ref.ao, sel, f"{source} {spp}", samples=spp) for spp, r in sorted(fixed[source].items())]
        series[source] = pts
        ad = []
        for err in cfg["adaptive_errors"]:
            r = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=cfg["adaptive_cap"],
                               min_samples=cfg["adaptive_min"], target_error=err, threads=threads,
                               max_distance=DISTANCE, source=source, seed=5)
            # Texels the adaptive stop let go at the minimum, and how far off they are.
            at_min = sel & (r.samples == cfg["adaptive_min"])
            ad.append(_series_point(r, ref.ao, sel, f"{source} adaptive {err}", target_error=err,
                                    stopped_at_min=float(at_min.sum() / max(sel.sum(), 1)),
                                    rmse_stopped_at_min=rmse(r.ao, ref.ao, at_min),
                                    at_cap=float((sel & (r.samples == cfg["adaptive_cap"])).sum() / max(sel.sum(), 1))))
        series[f"{source}+adaptive"] = ad
        for p in pts + ad:
            log(f"  {p['label']:>22}: {p['seconds']:6.2f}s  RMSE {p['rmse']:.5f}", ctx.clock)

    at128 = next((p for p in cyc_series if p["samples"] == 128), None)
    matched = {}
    if at128 is not None:
        for name, pts in series.items():
            if name == "cycles":
                continue
            t = interp_time_at([p["seconds"] for p in pts], [p["rmse"] for p in pts], at128["rmse"])
            matched[name] = {"seconds": t, "ratio": (t / at128["seconds"]) if t else None}
    fitted = _fitted_ratios(series, at128)
    pool = {k: v for k, v in fitted.items() if v.get("ratio") is not None}
    best_name = min(pool, key=lambda k: pool[k]["ratio"], default=None)
    best = pool.get(best_name)
    return {
        "resolution": res, "threads": threads,
        "reference": {"baker": "mc_ao core, sobol", "samples": cfg["ref_spp"], "seconds": ref.seconds,
                      "rms_stderr": ref_noise,
                      "note": "rms_stderr is the i.i.d. formula from the sample variance; for Sobol' points the "
                              "actual error is smaller"},
        "texels": {"interior": int(interior.sum()), "common": int(common.sum()),
                   "cycles_mask": int(cyc_mask.sum()), "mc_mask": int(ref.mask.sum())},
        "measure": "RMSE over interior texels (covered by both, 3x3 neighbourhood inside both masks); "
                   "mc_ao time = core.bake_ao wall time, Cycles time = bake operator wall time; fixed-sample "
                   "points: fastest of ee_repeats runs",
        "series": series,
        "cycles_at_128": at128,
        "mc_time_to_cycles128_rmse": matched,
        "fitted": fitted,
        "best": {"config": best_name, **(best or {})},
    }
