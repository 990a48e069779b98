"""Cycles' own AO bake, driven through bpy under the conditions the benchmark compares at.

CPU, a fixed thread count, no denoising, no adaptive sampling, bake type 'AO' into the active Image
Texture node of the target's material, a Non-Color 32-bit float image read back with
``image.pixels.foreach_get``. The AO distance is ``scene.world.light_settings.distance``.
"""

import time

import numpy as np

from ..harness.scene import read_ao, select_only

BAKE_IMAGE = "bench_cycles_AO"
#: Wall and process-CPU seconds of the last bake (CPU time counts every thread of this process and
#: hardly grows when a neighbour takes a core away, so it is the steadier figure on a shared machine).
LAST = {"wall": None, "cpu": None}


def configure(bpy, threads, samples, seed=0, light_paths_off=True):
    """Set the render settings of a Cycles CPU AO bake.

    ``light_paths_off`` sets every bounce limit to 0: an AO bake needs none, and Cycles otherwise also
    continues each path from the baked surface (measured: see bench/README.md). Off is the fairer,
    faster Cycles.
    """
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = int(samples)
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.seed = int(seed)
    c.use_animated_seed = False
    if light_paths_off:
        c.max_bounces = 0
        c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = c.volume_bounces = 0
        c.transparent_max_bounces = 0
    scene.render.threads_mode = "FIXED"
    scene.render.threads = int(threads)
    return scene


def prepare_target(bpy, obj, width, height):
    """Give ``obj`` a material whose active node is an Image Texture of a new float, Non-Color image."""
    image = bpy.data.images.get(BAKE_IMAGE)
    if image is not None:
        bpy.data.images.remove(image)
    image = bpy.data.images.new(BAKE_IMAGE, width, height, alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    mat = bpy.data.materials.get("bench_bake") or bpy.data.materials.new("bench_bake")
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    node = nodes.get("bench_image") or nodes.new("ShaderNodeTexImage")
    node.name = "bench_image"
    node.image = image
    nodes.active = node
    node.select = True
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    return image


#: Object.shadow_terminator_geometry_offset that the benchmark bakes with. Blender's default, 0.1,
#: moves the origin of grazing AO rays on smooth-shaded triangles up to the smooth (interpolated-
#: normal) surface, which brightens AO where shading normals tilt from the face normals; mc_ao
#: traces from the true surface. 0 makes Cycles compute the AO of the surface itself (measured in
#: bench/sections/agreement.py), so both bakers estimate the same number.
TERMINATOR_OFFSET = 0.0


def bake(bpy, obj, width, height, samples, threads, seed=0, margin=0, sentinel=None, light_paths_off=True,
         terminator_offset=TERMINATOR_OFFSET):
    """One Cycles AO bake of ``obj``; returns (ao (H, W) float32, wall seconds of the bake operator).

    ``sentinel``: fill the image with this value first and bake with use_clear off, so that texels
    Cycles leaves alone (no triangle at their centre, when margin is 0) keep it.
    ``terminator_offset``: the target's shadow_terminator_geometry_offset (None: leave it).
    """

    if terminator_offset is not None:
        obj.shadow_terminator_geometry_offset = float(terminator_offset)
    configure(bpy, threads, samples, seed, light_paths_off)
    image = prepare_target(bpy, obj, width, height)
    if sentinel is not None:
        image.pixels.foreach_set(np.full(width * height * 4, sentinel, np.float32))
    select_only(bpy, obj)
    scene = bpy.context.scene
    scene.render.bake.margin = margin
    scene.render.bake.margin_type = "EXTEND"
    c0, t0 = time.process_time(), time.perf_counter()
    res = bpy.ops.object.bake(type="AO", margin=margin, margin_type="EXTEND", use_clear=sentinel is None,
                              target="IMAGE_TEXTURES", use_selected_to_active=False)
    seconds = time.perf_counter() - t0
    LAST.update(wall=seconds, cpu=time.process_time() - c0)
    if res != {"FINISHED"}:
        raise RuntimeError(f"Cycles bake failed: {res}")
    return read_ao(image), seconds


SHARED_IMAGE = "bench_cycles_shared_AO"


def bake_shared(bpy, objs, width, height, samples, threads, distance=None, seed=0, margin=0, sentinel=-1.0,
                light_paths_off=True, terminator_offset=TERMINATOR_OFFSET):
    """One Cycles AO bake of every object of ``objs`` into ONE shared image, as Cycles bakes an atlas:
    all of them selected, each with one material whose active Image Texture node holds the same new
    float, Non-Color image. Returns (ao (H, W) float32, mask (H, W) bool of the texels Cycles wrote,
    wall seconds of the bake operator).

    The image is first filled with ``sentinel`` and baked with use_clear off, so the texels no object
    covers keep it (the mask; with ``margin`` 0 only the covered texels change). ``distance``: the AO
    distance (scene.world.light_settings.distance), None to leave it."""
    configure(bpy, threads, samples, seed, light_paths_off)
    scene = bpy.context.scene
    if distance is not None:
        if scene.world is None:
            scene.world = bpy.data.worlds.new("bench_world")
        scene.world.light_settings.distance = float(distance)
    image = bpy.data.images.get(SHARED_IMAGE)
    if image is not None:
        bpy.data.images.remove(image)
    image = bpy.data.images.new(SHARED_IMAGE, width, height, alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(np.full(width * height * 4, sentinel, np.float32))
    mat = bpy.data.materials.get("bench_shared") or bpy.data.materials.new("bench_shared")
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    node = nodes.get("bench_shared_image") or nodes.new("ShaderNodeTexImage")
    node.name = "bench_shared_image"
    node.image = image
    nodes.active = node
    for o in bpy.context.view_layer.objects:
        o.select_set(o in objs)
    for obj in objs:
        if terminator_offset is not None:
            obj.shadow_terminator_geometry_offset = float(terminator_offset)
        obj.data.materials.clear()
        obj.data.materials.append(mat)
    bpy.context.view_layer.objects.active = objs[0]
    scene.render.bake.margin = margin
    scene.render.bake.margin_type = "EXTEND"
    c0, t0 = time.process_time(), time.perf_counter()
    res = bpy.ops.object.bake(type="AO", margin=margin, margin_type="EXTEND", use_clear=False,
                              target="IMAGE_TEXTURES", use_selected_to_active=False)
    seconds = time.perf_counter() - t0
    LAST.update(wall=seconds, cpu=time.process_time() - c0)
    if res != {"FINISHED"}:
        raise RuntimeError(f"Cycles bake failed: {res}")
    ao = read_ao(image)
    return ao, ao != sentinel, seconds
