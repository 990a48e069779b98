"""Agreement: do mc_ao and Cycles compute the same AO, and where they do not, which one is wrong.

Checks, each against its noise (z = mean difference / its standard error over texels):

- the benchmark scene, Suzanne (smooth) and the plane, Cycles as the benchmark bakes it and with
  Blender's default shadow-terminator geometry offset, split by how far shading normals tilt;
- analytic scenes where the exact AO is known: a plane under a hovering square (1 - Lambert's polygon
  form factor) and a plane under a large lid with a finite AO distance ((h / d)^2);
- how Cycles places a texel's samples (centre or jittered, which footprint) and whether it touches
  the values of a Non-Color float image, from an emission bake of a step;
- blocks resting exactly on the plane (coplanar faces), where the answer is ill-posed.
"""

import numpy as np

from ..comparators import cycles
from ..harness import mcao
from ..harness.common import erode, log, mean_diff, rmse
from ..harness.geometry import normal_tilt_degrees, texel_centres
from ..harness.scene import (DISTANCE, LID_HEIGHT, _mesh_object, build_scene, core_meshes, lid_scene, lid_truth,
                    reset_blender, scene_arrays)

TILT_BINS = ((0, 2), (2, 5), (5, 10), (10, 20), (20, 90))


def _suzanne(ctx):
    bpy, cfg = ctx.bpy, ctx.cfg
    res, threads = cfg["ee_res"], ctx.threads
    obj = ctx.objs["Suzanne"]
    ref = getattr(ctx, "ref", None)
    if ref is None:
        ref = mcao.core_bake(ctx.target, ctx.occluders, resolution=res, samples=cfg["ref_spp"], threads=threads,
                             max_distance=DISTANCE, seed=987654321)
    cyc0 = getattr(ctx, "cycles_hi", None)
    if cyc0 is None:
        cyc0, _ = cycles.bake(bpy, obj, res, res, cfg["cyc_check_spp"], threads, seed=12, sentinel=-1.0)
    cyc_default, _ = cycles.bake(bpy, obj, res, res, cfg["cyc_check_spp"], threads, seed=13, sentinel=-1.0,
                                 terminator_offset=0.1)
    cyc_mask = cyc0 >= 0
    common = cyc_mask & ref.mask
    interior = erode(common)
    edge = common & ~interior
    t = ctx.target
    _, _, nrm, fn = texel_centres(t.positions, t.triangles, t.uvs, t.normals, res, res)
    tilt = normal_tilt_degrees(nrm, fn)
    out = {"resolution": res, "cycles_samples": cfg["cyc_check_spp"], "mc_reference_samples": cfg["ref_spp"],
           "texels_cycles_only": int((cyc_mask & ~ref.mask).sum()),
           "texels_mc_only": int((ref.mask & ~cyc_mask).sum()),
           "texels_common": int(common.sum())}
    for label, cyc in (("terminator_offset_0", cyc0), ("terminator_offset_default_0.1", cyc_default)):
        bins = []
        for lo, hi in TILT_BINS:
            s = interior & (tilt >= lo) & (tilt < hi)
            bins.append({"tilt_deg": [lo, hi], **mean_diff(cyc, ref.ao, s)})
        out[label] = {"interior": mean_diff(cyc, ref.ao, interior), "edge": mean_diff(cyc, ref.ao, edge),
                      "rmse_interior": rmse(cyc, ref.ao, interior), "by_normal_tilt": bins}
        d = out[label]["interior"]
        log(f"agreement Suzanne, Cycles {label}: interior mean(Cycles - mc) {d['mean']:+.5f} "
            f"+- {d['se']:.5f} (z {d['z']:+.1f})", ctx.clock)
    out["mc_reference_rms_stderr"] = float(np.sqrt(np.mean(ref.stderr[interior].astype(float) ** 2)))
    return out


def _plane(ctx):
    bpy, cfg = ctx.bpy, ctx.cfg
    res, spp, threads = cfg["ag_res"], cfg["ag_spp"], ctx.threads
    obj = ctx.objs["Plane"]
    target, occ = core_meshes(*scene_arrays(bpy, "Plane"))
    cyc, _ = cycles.bake(bpy, obj, res, res, spp, threads, seed=21, sentinel=-1.0)
    r = mcao.core_bake(target, occ, resolution=res, samples=spp, threads=threads, max_distance=DISTANCE, seed=22)
    from ..harness.scene import BLOCKS, PLANE_HALF
    x = (np.arange(res) + 0.5) / res * 2 * PLANE_HALF - PLANE_HALF
    X, Y = np.meshgrid(x, x)
    h = 2 * PLANE_HALF / res
    inside = np.zeros((res, res), bool)
    wall = np.zeros((res, res), bool)
    for lo, hi in BLOCKS:
        inside |= (X > lo[0] + h) & (X < hi[0] - h) & (Y > lo[1] + h) & (Y < hi[1] - h)
        wall |= (X > lo[0] - h) & (X < hi[0] + h) & (Y > lo[1] - h) & (Y < hi[1] + h)
    wall &= ~inside
    diag = (np.abs(X - Y) < 1.5 * h) & ~wall & ~inside  # the plane's two triangles meet on its diagonal
    both = (cyc >= 0) & r.mask
    rest = both & ~wall & ~inside & ~diag
    out = {"resolution": res, "samples": spp}
    for label, s in (("open", rest), ("inside_blocks", both & inside), ("texels_across_block_walls", both & wall),
                     ("texels_on_the_triangle_diagonal", both & diag)):
        out[label] = mean_diff(cyc, r.ao, s)
    d = out["open"]
    log(f"agreement plane (open texels): mean(Cycles - mc) {d['mean']:+.5f} +- {d['se']:.5f} (z {d['z']:+.1f}); "
        f"texels across walls {out['texels_across_block_walls']['mean']:+.5f} "
        f"(z {out['texels_across_block_walls']['z']:+.1f})", ctx.clock)
    return out


def _lid_scene(bpy, lid_verts=None, distance=1e4):
    reset_blender(bpy)
    pv, pq, puv, lv, lq = lid_scene()
    if lid_verts is not None:
        lv = lid_verts
    plane = _mesh_object(bpy, "LidPlane", pv, pq, puv)
    _mesh_object(bpy, "Lid", lv, lq)
    bpy.context.scene.world.light_settings.distance = distance
    bpy.context.view_layer.update()
    target, occ = core_meshes(*scene_arrays(bpy, "LidPlane"))
    return plane, target, occ


def _analytic(ctx):
    bpy, cfg, threads = ctx.bpy, ctx.cfg, ctx.threads
    out = {}
    # 1. Plane under a hovering square, unlimited distance: AO = 1 - F (Lambert's contour integral).
    W, spp = cfg["lid_res"], cfg["lid_spp"]
    plane, target, occ = _lid_scene(bpy)
    truth = lid_truth(W, W)
    truth_half = lid_truth(W, W, footprint=0.5)
    cyc, _ = cycles.bake(bpy, plane, W, W, spp, threads, seed=31, sentinel=-1.0)
    r = mcao.core_bake(target, occ, resolution=W, samples=spp, threads=threads, seed=32)
    all_ = np.ones((W, W), bool)
    noise = float(np.sqrt(np.mean(r.stderr.astype(float) ** 2)))
    out["lid"] = {"resolution": W, "samples": spp, "exact": "texel mean of 1 - F, Gauss-Legendre 6x6",
                  "cycles_minus_exact": mean_diff(cyc, truth, all_), "mc_minus_exact": mean_diff(r.ao, truth, all_),
                  "cycles_minus_exact_central_half": mean_diff(cyc, truth_half, all_),
                  "mc_minus_exact_central_half": mean_diff(r.ao, truth_half, all_),
                  "cycles_rmse": rmse(cyc, truth, all_), "mc_rmse": rmse(r.ao, truth, all_),
                  "cycles_rmse_central_half": rmse(cyc, truth_half, all_), "mc_rms_stderr": noise}
    log(f"agreement lid (exact): Cycles - exact {out['lid']['cycles_minus_exact']['mean']:+.5f} "
        f"(z {out['lid']['cycles_minus_exact']['z']:+.1f}), mc - exact {out['lid']['mc_minus_exact']['mean']:+.5f} "
        f"(z {out['lid']['mc_minus_exact']['z']:+.1f})", ctx.clock)

    # 2. Finite AO distance: under a lid much larger than the cone the distance allows, only
    # directions with h / cos(theta) < d hit it, so AO = 1 - (1 - (h / d)^2) = (h / d)^2 exactly.
    d = cfg["dist_d"]
    big = np.array([[-20, -20, LID_HEIGHT], [21, -20, LID_HEIGHT], [21, 21, LID_HEIGHT], [-20, 21, LID_HEIGHT]], float)
    plane, target, occ = _lid_scene(bpy, big, distance=d)
    W, spp = cfg["dist_res"], cfg["dist_spp"]
    exact = (LID_HEIGHT / d) ** 2
    cyc, _ = cycles.bake(bpy, plane, W, W, spp, threads, seed=33, sentinel=-1.0)
    r = mcao.core_bake(target, occ, resolution=W, samples=spp, threads=threads, max_distance=d, seed=34)
    ex = np.full((W, W), exact)
    all_ = np.ones((W, W), bool)
    out["distance"] = {"height": LID_HEIGHT, "distance": d, "exact": exact, "resolution": W, "samples": spp,
                       "cycles_minus_exact": mean_diff(cyc, ex, all_), "mc_minus_exact": mean_diff(r.ao, ex, all_)}
    log(f"agreement distance (exact {exact:.4f}): Cycles {float(cyc.mean()):.5f}, mc {float(r.ao.mean()):.5f}",
        ctx.clock)
    return out


def _sample_placement(ctx):
    """Where Cycles puts a texel's samples: emission bakes of a step x > edge moved across one texel.

    The baked texel holds the fraction of its samples beyond the edge, so the series of bakes traces
    the distribution of sample positions across the texel: a box over the whole texel falls linearly
    from 1 to 0 as the edge crosses it, a box of width w falls over w around the centre, centre-only
    sampling jumps at 0.5. The step runs from 0.25 to 0.75 (not 0 to 1) so that any colour
    transform of the Non-Color float image would show in the flat parts.
    """
    bpy = ctx.bpy
    reset_blender(bpy)
    W, H, col = 16, 4, 8
    pv, pq, puv, _, _ = lid_scene()
    plane = _mesh_object(bpy, "StepPlane", pv, pq, puv)
    bpy.context.view_layer.update()
    image = cycles.prepare_target(bpy, plane, W, H)
    nt = plane.data.materials[0].node_tree
    nodes, links = nt.nodes, nt.links
    for n in list(nodes):
        if n.name != "bench_image":
            nodes.remove(n)
    geo = nodes.new("ShaderNodeNewGeometry")
    sep = nodes.new("ShaderNodeSeparateXYZ")
    gt = nodes.new("ShaderNodeMath")
    gt.operation = "GREATER_THAN"
    mr = nodes.new("ShaderNodeMapRange")
    mr.inputs["To Min"].default_value = 0.25
    mr.inputs["To Max"].default_value = 0.75
    em = nodes.new("ShaderNodeEmission")
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(geo.outputs["Position"], sep.inputs[0])
    links.new(sep.outputs["X"], gt.inputs[0])
    links.new(gt.outputs[0], mr.inputs["Value"])
    links.new(mr.outputs["Result"], em.inputs["Strength"])
    links.new(em.outputs[0], out.inputs["Surface"])
    nodes.active = nodes["bench_image"]
    cycles.configure(bpy, ctx.threads, ctx.cfg["placement_spp"], seed=41)
    from ..harness.scene import select_only
    select_only(bpy, plane)
    fracs = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
    beyond, flat_ok = [], True
    for f in fracs:
        gt.inputs[1].default_value = (col + f) / W
        bpy.ops.object.bake(type="EMIT", margin=0, use_clear=True, target="IMAGE_TEXTURES")
        row = cycles.read_ao(image)[H // 2]
        beyond.append((float(row[col]) - 0.25) / 0.5)
        flat_ok &= bool(np.all(row[:col] == np.float32(0.25)) and np.all(row[col + 1:] == np.float32(0.75)))
    beyond = np.array(beyond)
    mid = (beyond > 0.02) & (beyond < 0.98)
    width = None
    if mid.sum() >= 2:
        slope = np.polyfit(np.array(fracs)[mid], beyond[mid], 1)[0]
        width = float(-1.0 / slope)
    if width is None:
        reading = "texel centre only (the value jumps where the edge crosses the centre)"
    elif abs(width - 1.0) < 0.08:
        reading = "jittered uniformly over the whole texel"
    else:
        reading = f"jittered uniformly over the central {width:.2f} x {width:.2f} of the texel"
    res = {"edge_fractions": list(fracs), "fraction_of_samples_beyond_edge": [round(float(b), 4) for b in beyond],
           "footprint_width_texels": width, "reading": reading, "non_color_values_untouched": flat_ok,
           "samples": ctx.cfg["placement_spp"]}
    log(f"agreement sample placement: {reading}; Non-Color float values untouched: {flat_ok}", ctx.clock)
    return res


def _contact(ctx):
    """Blocks resting exactly on the plane: their bottom faces lie in the plane's plane."""
    bpy, cfg, threads = ctx.bpy, ctx.cfg, ctx.threads
    reset_blender(bpy)
    objs = build_scene(bpy, sink=0.0)
    res, spp = cfg["contact_res"], cfg["contact_spp"]
    target, occ = core_meshes(*scene_arrays(bpy, "Plane"))
    cyc, _ = cycles.bake(bpy, objs["Plane"], res, res, spp, threads, seed=51, sentinel=-1.0)
    r = mcao.core_bake(target, occ, resolution=res, samples=spp, threads=threads, max_distance=DISTANCE, seed=52)
    from ..harness.scene import BLOCKS, PLANE_HALF
    x = (np.arange(res) + 0.5) / res * 2 * PLANE_HALF - PLANE_HALF
    X, Y = np.meshgrid(x, x)
    h = 2 * PLANE_HALF / res
    under = np.zeros((res, res), bool)
    for lo, hi in BLOCKS:
        under |= (X > lo[0] + h) & (X < hi[0] - h) & (Y > lo[1] + h) & (Y < hi[1] - h)
    out = {"resolution": res, "samples": spp, "under_blocks": mean_diff(cyc, r.ao, under),
           "cycles_mean_under": float(cyc[under].mean()), "mc_mean_under": float(r.ao[under].mean())}
    log(f"agreement coplanar contact: under the blocks Cycles {out['cycles_mean_under']:.3f}, "
        f"mc {out['mc_mean_under']:.3f}", ctx.clock)
    return out


def agreement(ctx):
    out = {"suzanne": _suzanne(ctx), "plane": _plane(ctx)}
    out.update(_analytic(ctx))
    out["sample_placement"] = _sample_placement(ctx)
    out["coplanar_contact"] = _contact(ctx)
    ctx.restore_scene()
    return out
