#!/usr/bin/env python3
"""Make the README's pictures from the repository's own code (needs requirements-docs.txt).

    .venv/bin/pip install -r requirements-docs.txt
    .venv/bin/python docs/make_figures.py [convergence] [gallery]

convergence  docs/convergence.png: RMSE against samples per texel for each sample source on the
             analytic scene (a plane under a hovering 64-gon, exact AO from Lambert's formula),
             with the Monte Carlo N^-1/2 slope drawn for reference.
gallery      docs/gallery.png: the baked AO of every sample scene's objects, through
             scripts/bake_ao.py (the add-on's own geometry gathering).
adaptive     docs/adaptive.png: an adaptive bake's AO, its standard-error map and how many samples each
             texel took (a plane with a box resting on it and a disk hovering over it, AO distance
             0.25: open floor stops at the minimum, the contact shadow and the disk's shade take more).
cycles       docs/cycles_vs_mc_ao.png: Suzanne of suzanne.blend baked by Cycles' AO bake and by this
             add-on's operator at the same resolution, samples and threads, with the times and the
             difference (bench/comparators/cycles.py runs Cycles as the benchmark does).
selected     docs/selected_to_active.png: rock.blend's 123k-triangle Rock_high baked onto its
             80-triangle Rock_low by scripts/bake_ao.py --match-suffix _high _low; Cycles renders of
             the high-poly under a white sky (direct light only: its AO) and of the low-poly showing
             the baked texture, and the texture itself.
"""

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from core import Mesh, bake_ao  # noqa: E402
from core.montecarlo.analytic import plane_under_polygon_ao, regular_polygon  # noqa: E402
from core.files.imageio import read_image  # noqa: E402

# The analytic sample scene's numbers (sample_scenes/make_scenes.py: ANALYTIC).
HALF, RADIUS, HEIGHT, VERTS = 1.0, 0.5, 0.4, 64
SOURCES = ["independent", "stratified", "halton", "sobol"]


def analytic_scene():
    P = np.array([[-HALF, -HALF, 0], [HALF, -HALF, 0], [HALF, HALF, 0], [-HALF, HALF, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    plane = Mesh(P, F, uvs=(P[F][:, :, :2] + HALF) / (2 * HALF), name="Plane")
    poly = regular_polygon(RADIUS, HEIGHT, VERTS)
    fan = np.array([[0, i, i + 1] for i in range(1, VERTS - 1)])
    return plane, Mesh(poly, fan, name="Disk"), poly


def convergence(res=64, ns=(4, 8, 16, 32, 64, 128, 256, 512, 1024), seeds=3):
    plane, disk, poly = analytic_scene()
    truth = plane_under_polygon_ao(poly, res, res, bounds=(-HALF, -HALF, HALF, HALF))
    table = {}
    for source in SOURCES:
        rmse = []
        for n in ns:
            errs = [bake_ao(plane, [disk], resolution=res, samples=n, source=source, margin=0, seed=s).ao - truth
                    for s in range(seeds)]
            rmse.append(float(np.sqrt(np.mean(np.square(errs)))))
        slope = float(np.polyfit(np.log(ns), np.log(rmse), 1)[0])
        table[source] = {"rmse": rmse, "slope": slope}
        print(f"{source:12s} slope {slope:+.3f}  rmse " + " ".join(f"{e:.2e}" for e in rmse))
    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    for source in SOURCES:
        ax.loglog(ns, table[source]["rmse"], "o-", ms=3, label=f"{source} (slope {table[source]['slope']:+.2f})")
    ref = table["independent"]["rmse"][0] * (np.array(ns) / ns[0]) ** -0.5
    ax.loglog(ns, ref, "k--", lw=1, label="N$^{-1/2}$ reference")
    ax.set_xlabel("samples per texel")
    ax.set_ylabel("RMSE against the exact AO")
    ax.set_title(f"Analytic scene, {res}x{res} texels, mean of {seeds} seeds")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "convergence.png")
    (ROOT / "docs" / "convergence.json").write_text(json.dumps({"samples": list(ns), **table}, indent=1))


# (scene, objects, extra arguments): the room is closed, so without a distance limit it is all 0;
# the rock is Selected to Active (Rock_high baked onto Rock_low, paired by name).
ROCK_ARGS = ["--match-suffix", "_high", "_low", "--extrusion", "0.1"]
GALLERY = [("suzanne.blend", ["Suzanne", "Ground"], []),
           ("room.blend", ["Room", "Table", "Crate"], ["--max-distance", "1.0"]),
           ("analytic.blend", ["Plane"], []), ("dense.blend", ["Terrain"], []),
           ("rock.blend", ["Rock_low"], ROCK_ARGS)]
TITLES = {"Rock_low": "Rock_high onto Rock_low"}


def gallery(res=256, samples=64):
    panels = []
    with tempfile.TemporaryDirectory() as tmp:
        for blend, objects, extra in GALLERY:
            out = Path(tmp) / blend
            cmd = [sys.executable, str(ROOT / "scripts" / "bake_ao.py"), str(ROOT / "sample_scenes" / blend),
                   "--objects", *objects, "--resolution", str(res), "--samples", str(samples),
                   "--output", str(out), "--format", "exr", "--quiet", *extra]
            subprocess.run(cmd, check=True)
            for obj in objects:
                img, _ = read_image(out / f"{obj}_AO.exr")
                panels.append((f"{blend}: {TITLES.get(obj, obj)}", img if img.ndim == 2 else img[..., 0]))
    cols = 4
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(2.2 * cols, 2.4 * rows), dpi=90)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, (title, img) in zip(axes.ravel(), panels):
        ax.imshow(img, cmap="gray", vmin=0, vmax=1, origin="lower", interpolation="nearest")
        ax.set_title(title, fontsize=7)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "gallery.png")


def cycles_side_by_side(res=256, samples=128, threads=2):
    import bpy

    from bench.comparators import cycles
    from bench.harness import mcao

    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / "suzanne.blend"))
    bpy.context.scene.world = bpy.data.worlds.new("World") if bpy.context.scene.world is None else bpy.context.scene.world
    bpy.context.scene.world.light_settings.distance = 10.0
    obj = bpy.data.objects["Suzanne"]
    # sentinel -1: texels Cycles leaves alone (no triangle at their centre) keep it
    cyc, cyc_s = cycles.bake(bpy, obj, res, res, samples, threads, margin=0, sentinel=-1.0)
    both = cyc >= 0
    mcao.register(bpy)
    mc, mc_s = mcao.operator_bake(bpy, obj, res, samples, threads, max_distance=10.0, margin=0)[:2]
    fig, axes = plt.subplots(1, 3, figsize=(9, 3.4), dpi=90)
    diff = np.where(both, cyc - mc, 0.0)
    mean, se = diff[both].mean(), diff[both].std() / np.sqrt(both.sum())
    for ax, img, title in [(axes[0], np.maximum(cyc, 0), f"Cycles AO bake: {cyc_s:.1f} s"),
                           (axes[1], mc, f"mc_ao: {mc_s:.1f} s"),
                           (axes[2], np.clip(diff, -0.1, 0.1),
                            f"Cycles - mc_ao (+-0.1), mean {mean:+.4f} +- {se:.4f}")]:
        ax.imshow(img, cmap="gray" if "+-" not in title else "RdBu", origin="lower",
                  vmin=-0.1 if "+-" in title else 0, vmax=0.1 if "+-" in title else 1, interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.suptitle(f"Suzanne, {res}x{res}, {samples} samples per texel, {threads} threads, same machine and run",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "cycles_vs_mc_ao.png")
    print(f"Cycles {cyc_s:.2f} s, mc_ao {mc_s:.2f} s, mean difference {mean:+.5f} +- {se:.5f} over {both.sum()} texels")


def adaptive_maps(res=256, target=0.01, cap=2048):
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    ground = Mesh(P, quad, uvs=P[quad][:, :, :2], name="Ground")
    lo, hi = (0.2, 0.25, 0.0), (0.45, 0.55, 0.2)
    B = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])], float)
    box = Mesh(B, np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4], [2, 6, 7],
                            [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]]), name="Box")
    poly = regular_polygon(0.15, 0.12, 48, centre=(0.72, 0.45))
    disk = Mesh(poly, np.array([[0, i, i + 1] for i in range(1, 47)]), name="Disk")
    r = bake_ao(ground, [box, disk], resolution=res, samples=cap, min_samples=16, target_error=target,
                max_distance=0.25, seed=1)
    fig, axes = plt.subplots(1, 3, figsize=(10.5, 3.6), dpi=90)
    n = r.samples.astype(float)
    for ax, img, title, kw in [
            (axes[0], r.ao, "AO", dict(cmap="gray", vmin=0, vmax=1)),
            (axes[1], r.stderr, f"standard error (target {target} is the 95% half-width)",
             dict(cmap="magma", vmin=0, vmax=target / 1.5)),
            (axes[2], np.log2(n), f"samples per texel (log2; mean {n.mean():.0f}, {np.mean(n == 16):.0%} at 16)",
             dict(cmap="viridis", vmin=4, vmax=np.log2(cap)))]:
        im = ax.imshow(img, origin="lower", interpolation="nearest", **kw)
        ax.set_title(title, fontsize=9)
        ax.axis("off")
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
    fig.suptitle(f"Adaptive bake, {res}x{res}, noise threshold {target}, {r.seconds:.1f} s, "
                 f"{r.rays / 1e6:.1f} M rays (fixed {cap} samples: {res * res * cap / 1e6:.0f} M)", fontsize=9)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "adaptive.png")
    print(f"adaptive: mean {n.mean():.1f} samples, {np.mean(n == 16):.0%} at the minimum, {r.seconds:.2f} s")


def _render(bpy, path, width, height, samples):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 0  # direct light from a uniform white sky only: the render is AO x albedo
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "Standard"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    img = plt.imread(str(path))
    return img[..., :3].mean(axis=2)


def selected_to_active_figure(res=512, samples=128, width=360, height=300, render_samples=64):
    """The rock's high-poly, its low-poly with the baked AO, and the baked texture (see the docstring)."""
    import bpy
    from mathutils import Vector

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        cmd = [sys.executable, str(ROOT / "scripts" / "bake_ao.py"), str(ROOT / "sample_scenes" / "rock.blend"),
               *ROCK_ARGS, "--resolution", str(res), "--samples", str(samples), "--output", str(out),
               "--format", "exr", "--quiet", "--summary-json", str(out / "summary.json")]
        subprocess.run(cmd, check=True)
        record = json.loads((out / "summary.json").read_text())["objects"][0]
        baked = out / "Rock_low_AO.exr"
        texture = np.squeeze(read_image(baked)[0])
        bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / "rock.blend"))
        scene = bpy.context.scene
        world = bpy.data.worlds.new("Sky")
        world.use_nodes = True
        world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
        scene.world = world
        bpy.ops.object.camera_add(location=(2.3, -2.3, 1.7))
        camera = bpy.context.active_object
        camera.rotation_euler = (Vector((0.0, 0.0, 0.5)) - camera.location).to_track_quat("-Z", "Y").to_euler()
        camera.data.lens = 60
        scene.camera = camera
        white = bpy.data.materials.new("White")
        white.use_nodes = True
        white.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (1, 1, 1, 1)
        high, low, ground = (bpy.data.objects[n] for n in ("Rock_high", "Rock_low", "Ground"))
        evaluated = high.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        evaluated.calc_loop_triangles()
        triangles = len(evaluated.loop_triangles)
        for obj in (high, ground):
            obj.data.materials.clear()
            obj.data.materials.append(white)
        shown = bpy.data.materials.new("Baked AO")
        shown.use_nodes = True
        nodes, links = shown.node_tree.nodes, shown.node_tree.links
        nodes.clear()
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images.load(str(baked))
        tex.image.colorspace_settings.name = "Non-Color"
        emit = nodes.new("ShaderNodeEmission")
        result = nodes.new("ShaderNodeOutputMaterial")
        links.new(tex.outputs["Color"], emit.inputs["Color"])
        links.new(emit.outputs["Emission"], result.inputs["Surface"])
        low.data.materials.clear()
        low.data.materials.append(shown)
        low.hide_render = True
        a = _render(bpy, out / "high.png", width, height, render_samples)
        low.hide_render, high.hide_render = False, True
        b = _render(bpy, out / "low.png", width, height, render_samples)
    fig, axes = plt.subplots(1, 3, figsize=(10.5, 4.0), dpi=90)
    for ax, img, title in [
            (axes[0], a, f"Rock_high: {triangles} triangles\n(Cycles, white sky, direct light: its AO)"),
            (axes[1], b, "Rock_low: 80 triangles\nwith the baked AO as its colour"),
            (axes[2], texture, f"Rock_low_AO, {res}x{res}, {samples} spp\n{record['seconds']:.1f} s, "
                               f"{record['missed_sample_points']} of {record['matching_rays']} points missed")]:
        ax.imshow(img, cmap="gray", vmin=0, vmax=1, origin="lower" if img is texture else "upper",
                  interpolation="nearest")
        ax.set_title(title, fontsize=8)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "selected_to_active.png")
    print(f"rock: {record['seconds']:.2f} s, {record['missed_sample_points']} of {record['matching_rays']} "
          "sample points missed")


if __name__ == "__main__":
    which = sys.argv[1:] or ["convergence", "gallery", "cycles", "selected", "adaptive"]
    if "adaptive" in which:
        adaptive_maps()
    if "convergence" in which:
        convergence()
    if "gallery" in which:
        gallery()
    if "cycles" in which:
        cycles_side_by_side()
    if "selected" in which:
        selected_to_active_figure()
