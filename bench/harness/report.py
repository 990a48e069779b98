"""The benchmark's printed table, from the results dictionary that run.py also writes as JSON."""


def _fmt(v, spec):
    if v is None:
        return "-"
    try:
        return format(v, spec)
    except (TypeError, ValueError):
        return str(v)


def _grid(headers, rows):
    cols = [headers] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cols) for i in range(len(headers))]
    line = "  ".join(h.rjust(w) for h, w in zip(headers, widths))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cols[1:]]
    return ["  " + x for x in out]


def _md(d, digits=5):
    """'+0.00012 +- 0.00008 (z +1.5)' from a mean_diff dictionary."""
    if not d or d.get("n", 0) < 2:
        return "-"
    return f"{d['mean']:+.{digits}f} +- {d['se']:.{digits}f} (z {d['z']:+.1f}, n {d['n']})"


def table(data):
    m, r = data["machine"], data["results"]
    L = [f"mc_ao benchmark ({data['mode']} mode), {data['started']}, {data['duration_s']:.0f} s",
         f"machine: {m['cpu']}, {m['cores']} cores, {m['memory_gib']} GiB; Python {m['python']}, numpy {m['numpy']}, "
         f"embreex {m.get('embreex', '?')}; Blender {data['blender']} (bpy); commit {data['git']['commit']}"
         f"{' (core/ modified)' if data['git']['core_dirty'] else ''}",
         f"threads {data['threads']} for both bakers; load average at start {data['load_average_start']}, "
         f"end {data['load_average_end']} (a shared machine: fastest repeat counts)", ""]

    es = r.get("equal_samples")
    if es:
        L.append("1. Equal samples (Suzanne over plane + blocks; Cycles CPU bake type AO vs mc_ao's Bake AO operator; "
                 f"margin {es['margin']})")
        rows = [[f"{x['resolution']}^2", x["samples"], _fmt(x["cycles_s"], ".2f"), _fmt(x["mc_operator_s"], ".2f"),
                 _fmt(x["mc_core_s"], ".2f"), x["cycles_texels"], x["mc_texels"], _fmt(x["cycles_tsps"] / 1e6, ".2f"),
                 _fmt(x["mc_tsps"] / 1e6, ".2f"), _fmt(x["ratio_tsps"], ".2f") + "x", _fmt(x["ratio_time"], ".2f") + "x",
                 _fmt(100 * x["mc_core_trace_share"], ".0f") + "%"] for x in es["rows"]]
        for row, x in zip(rows, es["rows"]):
            row.insert(-1, _fmt(x.get("ratio_cpu"), ".2f") + "x")
        L += _grid(["res", "spp", "Cycles s", "mc op s", "mc core s", "Cyc texels", "mc texels", "Cyc Mts/s",
                    "mc Mts/s", "ts/s ratio", "time ratio", "CPU ratio", "in embree"], rows)
        L.append("  (Mts/s = million texel-samples per second, each baker's own covered texels; time ratio = "
                 "Cycles s / mc op s for the same image; CPU ratio = the same with process CPU seconds, steadier "
                 "when a neighbour takes a core)")
        L.append("")

    dn = r.get("dense")
    if dn:
        L.append(f"1b. Equal samples on {dn['scene']} ({dn['triangles']} triangles, smooth), {dn['resolution']}^2 x "
                 f"{dn['samples']} spp, AO distance {dn['distance']}")
        L += _grid(["Cycles s", "mc op s", "mc core s", "time ratio", "CPU ratio", "core ratio", "core in embree"],
                   [[_fmt(dn["cycles_s"], ".2f"), _fmt(dn["mc_operator_s"], ".2f"), _fmt(dn["mc_core_s"], ".2f"),
                     _fmt(dn["ratio_time"], ".2f") + "x", _fmt(dn["ratio_cpu"], ".2f") + "x",
                     _fmt(dn["ratio_core"], ".2f") + "x", _fmt(100 * dn["mc_core_trace_share"], ".0f") + "%"]])
        L.append("")

    ee = r.get("equal_error")
    if ee:
        ref = ee["reference"]
        L.append(f"2. Equal error ({ee['resolution']}^2, RMSE vs mc_ao sobol {ref['samples']} spp reference, "
                 f"its rms stderr {ref['rms_stderr']:.5f}; {ee['texels']['interior']} interior texels)")
        series = ee["series"]
        names = list(series)
        width = max(len(series[n]) for n in names)
        rows = []
        for n in names:
            pts = series[n]
            rows.append([n] + [f"{p['rmse']:.4f}@{p['seconds']:.2f}s" for p in pts] + [""] * (width - len(pts)))
        L += _grid(["series"] + [f"pt{i + 1}" for i in range(width)], rows)
        L.append("  (points: Cycles and fixed series at " + ", ".join(str(s) for s in data["config"]["cyc_spp"])
                 + " spp (mc: " + ", ".join(str(s) for s in data["config"]["mc_spp"]) + "); adaptive at target_error "
                 + ", ".join(str(e) for e in data["config"]["adaptive_errors"])
                 + f", cap {data['config']['adaptive_cap']})")
        c = ee.get("cycles_at_128")
        if c:
            fit = ee.get("fitted", {})
            cf = fit.get("cycles_fit", {})
            L.append(f"  Cycles at 128 spp: RMSE {c['rmse']:.5f} in {c['seconds']:.2f} s measured, "
                     f"{cf.get('t128_s', float('nan')):.2f} s from its time fit (a + b spp). mc_ao to that RMSE:")
            rows = []
            for k, v in ee["mc_time_to_cycles128_rmse"].items():
                f = fit.get(k, {})
                rows.append([k, _fmt(v["seconds"], ".3f"), _fmt(v["ratio"], ".3f"), _fmt(f.get("samples"), ".0f"),
                             _fmt(f.get("seconds"), ".3f"), _fmt(f.get("ratio"), ".3f")])
            for row, k in zip(rows, ee["mc_time_to_cycles128_rmse"]):
                row.append(_fmt(fit.get(k, {}).get("ratio_cpu"), ".3f"))
            L += _grid(["mc_ao config", "s (measured)", "x Cycles", "spp needed", "s (fitted)", "x Cycles (fitted)",
                        "x Cycles (CPU s)"], rows)
            tx = ee["texels"]
            if cf and fit.get("sobol"):
                L.append(f"  time fits: Cycles {cf['a_s']:.3f} s + {1e3 * cf['b_s_per_spp']:.2f} ms/spp "
                         f"({tx['cycles_mask'] / cf['b_s_per_spp'] / 1e6:.2f} M texel-samples/s marginal); mc_ao sobol "
                         f"{fit['sobol']['a_s']:.3f} s + {1e3 * fit['sobol']['b_s_per_spp']:.2f} ms/spp "
                         f"({tx['mc_mask'] / fit['sobol']['b_s_per_spp'] / 1e6:.2f} M texel-samples/s marginal)")
        L.append("")

    ag = r.get("agreement")
    if ag:
        L.append("3. Agreement (mean Cycles - mc_ao over texels both cover, +- standard error)")
        s = ag["suzanne"]
        for key, label in (("terminator_offset_0", "Suzanne, Cycles terminator offset 0"),
                           ("terminator_offset_default_0.1", "Suzanne, Cycles default terminator offset 0.1")):
            L.append(f"  {label}: interior {_md(s[key]['interior'])}; island-edge {_md(s[key]['edge'])}")
            L.append("     by shading-normal tilt: " + "; ".join(
                f"{b['tilt_deg'][0]}-{b['tilt_deg'][1]} deg {b['mean']:+.4f} (z {b['z']:+.1f})"
                for b in s[key]["by_normal_tilt"] if b.get("n", 0) > 1))
        L.append(f"  coverage: {s['texels_common']} texels both, {s['texels_mc_only']} mc_ao only (partly covered), "
                 f"{s['texels_cycles_only']} Cycles only")
        p = ag["plane"]
        L.append(f"  plane, open texels: {_md(p['open'])}")
        L.append(f"  plane, texels across block walls: {_md(p['texels_across_block_walls'])}; on the triangle "
                 f"diagonal: {_md(p['texels_on_the_triangle_diagonal'])}")
        lid = ag["lid"]
        L.append(f"  lid (exact 1 - F, {lid['resolution']}^2 x {lid['samples']}): mc - exact(texel) "
                 f"{_md(lid['mc_minus_exact'])}")
        L.append(f"     Cycles - exact(texel) {_md(lid['cycles_minus_exact'])}; Cycles - exact(central half of "
                 f"the texel) {_md(lid['cycles_minus_exact_central_half'])}")
        d = ag["distance"]
        L.append(f"  finite distance (exact (h/d)^2 = {d['exact']:.4f}): Cycles - exact {_md(d['cycles_minus_exact'])}; "
                 f"mc - exact {_md(d['mc_minus_exact'])}")
        sp = ag["sample_placement"]
        L.append(f"  Cycles sample placement (emission bakes of a step crossing one texel): {sp['reading']}; "
                 f"Non-Color float values untouched: {sp['non_color_values_untouched']}")
        cc = ag["coplanar_contact"]
        L.append(f"  blocks resting exactly on the plane (coplanar faces): under the blocks Cycles "
                 f"{cc['cycles_mean_under']:.3f}, mc_ao {cc['mc_mean_under']:.3f}")
        L.append("")

    ce = r.get("ceiling")
    if ce:
        L.append("4. Ceiling: one thread, the bake against embreex alone replaying the bake's own rays (recorded "
                 "through core.bake_ao(on_rays=...))")
        rows = []
        for sc in ce["scenes"]:
            b = sc["bake"]
            rows.append([sc["scene"], f"{sc['resolution']}^2 x {sc['samples']}", sc["rays"], _fmt(b["seconds"], ".2f"),
                         _fmt(b["cpu_seconds"], ".2f"), _fmt(100 * sc["share_wall"], ".0f") + "%",
                         _fmt(100 * sc["share_cpu"], ".0f") + "%", _fmt(sc["alone_1"]["seconds"], ".2f"),
                         _fmt(sc["alone_2"]["seconds"], ".2f"), _fmt(sc["bake_over_alone"], ".2f") + "x",
                         _fmt(sc["bake_over_alone_cpu"], ".2f") + "x"])
        L += _grid(["scene", "bake", "rays", "bake s", "bake CPU s", "in embree", "(CPU)", "alone 1 thr s",
                    "alone 2 thr s", "bake/alone", "(CPU)"], rows)
        pr = ce["profile"]
        L.append(f"  profile ({pr['resolution']}^2 x {pr['samples']}, Suzanne scene, 1 thread, {pr['cpu_seconds']:.2f} s "
                 "thread CPU; own time by file):")
        L += _grid(["where", "seconds", "share"], [[g["where"], _fmt(g["seconds"], ".3f"), _fmt(100 * g["share"], ".1f") + "%"]
                                                 for g in pr["by_file"][:8]])
        L.append("  top functions (own time):")
        L += _grid(["function", "calls", "tottime", "cumtime"],
                   [[f["function"][-70:], f["ncalls"], _fmt(f["tottime"], ".3f"), _fmt(f["cumtime"], ".3f")]
                    for f in pr["top_functions"][:10]])
        L.append("")

    th, rs, tr, mem = r.get("threads"), r.get("resolution"), r.get("triangles"), r.get("memory")
    if th or rs or tr or mem:
        L.append("5. Scaling (core.bake_ao)")
        rows = []
        if th:
            for x in th["rows"]:
                rows.append([f"threads {x['threads']}", f"{x['resolution']}^2 x {x['samples']}", _fmt(x["seconds"], ".2f"),
                             _fmt(x["mtexel_samples_per_s"], ".2f"), _fmt(x["mrays_per_s"], ".2f"),
                             _fmt(100 * x["trace_share"], ".0f") + "%"])
        if rs:
            for x in rs["rows"] + rs["one_sample"]:
                rows.append([f"resolution {x['resolution']}", f"{x['resolution']}^2 x {x['samples']}",
                             _fmt(x["seconds"], ".2f"), _fmt(x["mtexel_samples_per_s"], ".2f"),
                             _fmt(x["mrays_per_s"], ".2f"), _fmt(100 * x["trace_share"], ".0f") + "%"])

        if mem and "peak_rss_mib" in mem:
            rows.append([f"resolution {mem['resolution']}", f"{mem['resolution']}^2 x {mem['samples']}",
                         _fmt(mem["bake_seconds"], ".2f"), _fmt(mem["texel_samples_per_s"] / 1e6, ".2f"),
                         _fmt(mem["rays"] / mem["bake_seconds"] / 1e6, ".2f"), _fmt(100 * mem["trace_share"], ".0f") + "%"])
        if tr:
            for x in tr["rows"]:
                rows.append([f"triangles {x['triangles']}", f"{x['resolution']}^2 x {x['samples']}",
                             _fmt(x["seconds"], ".2f"), _fmt(x["mtexel_samples_per_s"], ".2f"),
                             _fmt(x["mrays_per_s"], ".2f"), _fmt(100 * x["trace_share"], ".0f") + "%"])
        L += _grid(["case", "bake", "seconds", "Mts/s", "Mrays/s", "in embree"], rows)
        if rs:
            L += [f"  fixed cost (1 spp, bake time less embreex time per thread): " + ", ".join(
                f"{x['resolution']}^2 {x['fixed_seconds']:.2f} s of {x['seconds']:.2f} s" for x in rs["one_sample"])]
        if tr and len(tr["rows"]) >= 2:
            L.append(f"  triangles: {tr['rows'][-1]['triangles']} take {tr['rows'][-1]['seconds'] / tr['rows'][0]['seconds']:.2f}x "
                     f"the time of {tr['rows'][0]['triangles']} ({tr['scene']})")
            if all("seconds_all" in x for x in tr["rows"]):
                L.append("  triangles, every repeat (the fastest counts; a process's first bake of a large mesh pays this VM's "
                         "first touch of memory): " + "; ".join(
                             f"{x['triangles']} " + ", ".join(f"{v:.2f}" for v in x["seconds_all"]) + " s" for x in tr["rows"]))
        if th:
            L.append(f"  speed-up 1 -> 2 threads: {th['speedup_1_to_2']:.2f}x (CPU/wall of the 2-thread bake "
                     f"{th['rows'][1]['cpu_per_wall']:.2f}); embreex alone on the bake's own rays, interleaved: "
                     f"{th['embree_alone_speedup_1_to_2']:.2f}x; ratio {th['relative_to_embree']:.2f}")
        if mem and "peak_rss_mib" in mem:
            L.append(f"  peak memory {mem['resolution']}^2 x {mem['samples']}: {mem['peak_rss_mib']:.0f} MiB RSS "
                     f"({mem['rss_before_mib']:.0f} MiB before the bake, fresh process, no bpy); highest RSS while "
                     f"tracing {mem.get('peak_rss_tracing_mib', float('nan')):.0f} MiB, after tracing (result planes, "
                     f"margin) {mem.get('peak_rss_after_tracing_mib', float('nan')):.0f} MiB")
        elif mem:
            L.append(f"  memory: {mem.get('skipped') or mem.get('error', '')[:200]}")
        L.append("")

    st = r.get("statistics")
    if st:
        L.append(f"5b. Statistics on the analytic scene ({st['scene']}, {st['resolution']}^2; core only)")
        L += _grid(["source"] + [f"RMSE @{n}" for n in st["samples"]] + ["slope", "mean error"],
                   [[k] + [_fmt(e, ".5f") for e in v["rmse"]] + [_fmt(v["slope"], "+.2f"),
                    f"{v['mean_error']:+.6f}"] for k, v in st["sources"].items()])
        L.append("")

    ad = r.get("adaptive")
    if ad:
        L.append("5c. Adaptive sampling against fixed sample counts (CPU seconds of one-thread bakes at "
                 "equal RMSE, adaptive / fixed: below 1 pays)")
        rows = []
        for sc in ad["scenes"]:
            for a in sc["adaptive"]:
                rows.append([sc["scene"], a["target_error"], _fmt(a["rmse"], ".5f"), _fmt(a["mean_samples"], ".0f"),
                             f"{100 * a['at_min']:.0f}%", _fmt(a["miss"], ".3f"), _fmt(a["cpu_seconds"], ".2f"),
                             _fmt(a["fixed_cpu_seconds"], ".2f"), _fmt(a["ratio"], ".2f")])
        L += _grid(["scene", "target", "RMSE", "spp", "at min", "miss > t", "cpu s", "fixed cpu s", "ratio"], rows)
        bounds = [sc for sc in ad["scenes"] if "gain_bound_independent" in sc]
        if bounds:
            L.append("  the best any allocation can do (independent samples: n proportional to each texel's sd), as a "
                     "share of the fixed count's samples, E[sd]^2/E[var]: "
                     + ", ".join(f"{sc['scene']} {1 / sc['gain_bound_independent']:.2f}" for sc in bounds))
        cost = ad.get("replicate_cost", {})
        if cost:
            L.append("  the error model's cost: RMSE with replicates=2 over replicates=1 at equal rays (disk scene): "
                     + "; ".join(f"{src} " + ", ".join(f"{x['ratio']:.2f}@{x['samples']}" for x in rows_)
                                 for src, rows_ in cost.items()))
        L.append("")

    dv = r.get("device")
    if dv:
        L.append(f"6. Threads on the device machine ({dv.get('machine', '?')}; measured {dv.get('when', '?')}, "
                 "merged from bench/results/device.json)")
        if dv.get("rows"):
            base = dv["rows"][0]["seconds"]
            L += _grid(["threads", "seconds", "speed-up", "Mrays/s", "in embree", "embreex alone", "outside embree",
                        "serial share"],
                       [[x["threads"], _fmt(x["seconds"], ".2f"), _fmt(base / x["seconds"], ".2f") + "x",
                         _fmt(x["mrays_per_s"], ".2f"), _fmt(100 * x["trace_share"], ".0f") + "%",
                         _fmt(x.get("embree_alone_speedup"), ".2f") + "x",
                         _fmt(x.get("outside_embree_speedup"), ".2f") + "x",
                         _fmt(x.get("outside_embree_serial_share"), ".2f")] for x in dv["rows"]])
            L.append("  (speed-ups from the first row; embreex alone: synthetic rays of the scene; outside embree: the "
                     "same bake with Embree's answer a constant, and Amdahl's serial share of it)")
        else:
            L.append(f"  {dv.get('note', 'no rows')}")
        L.append("")

    tg = data.get("targets")
    if tg:
        L.append("Targets ('before': results/before-kernel.json, the core before the kernel's rewrite (run of "
                 "2026-11-23), or the figures stated with the targets where that run did not measure them)")
        L += _grid(["target", "wanted", "before", "now", "met"],
                   [[t["name"], t["target"], t.get("before", "-"), t["value"], "yes" if t["met"] else "NO"] for t in tg])
    return "\n".join(L)
