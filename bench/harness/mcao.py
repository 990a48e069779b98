"""mc_ao's side of the comparison: the add-on's Bake AO operator and core.bake_ao on the same arrays."""

import time

import numpy as np

_registered = False
#: Wall and process-CPU seconds of the last operator bake (see bench.comparators.cycles.LAST).
LAST = {"wall": None, "cpu": None}


def register(bpy):
    """Register the checkout's add-on (top-level ``mc_ao``) once in this bpy session."""
    global _registered
    if not _registered and not hasattr(bpy.types.Scene, "mc_ao"):
        import mc_ao

        mc_ao.register()
    _registered = True


def operator_bake(bpy, obj, resolution, samples, threads, max_distance, margin=16, seed=0, source="SOBOL",
                  target_error=0.0, min_samples=16):
    """bpy.ops.object.mc_ao_bake() of ``obj`` alone (every visible object occludes it).

    Returns (ao (H, W) float32 from the image's R channel, wall seconds of the operator call).
    """
    from .scene import read_ao, select_only

    register(bpy)
    s = bpy.context.scene.mc_ao
    s.samples = samples
    s.min_samples = min(min_samples, samples)
    s.target_error = target_error
    s.resolution = resolution
    s.height = 0
    s.max_distance = max_distance
    s.source = source
    s.distribution = "COSINE"
    s.occluders = "VISIBLE"
    s.margin = margin
    s.float_buffer = True
    s.save_to_file = False
    s.seed = seed
    s.threads = threads
    s.image_name = ""
    select_only(bpy, obj)
    c0, t0 = time.process_time(), time.perf_counter()
    res = bpy.ops.object.mc_ao_bake()
    seconds = time.perf_counter() - t0
    LAST.update(wall=seconds, cpu=time.process_time() - c0)
    if res != {"FINISHED"}:
        raise RuntimeError(f"mc_ao_bake returned {res}")
    return read_ao(bpy.data.images[f"{obj.name}_AO"]), seconds


#: With ``python -m bench --workers``: core bakes on that many worker processes of one thread each
#: instead of ``threads`` threads of this process (the same bits; see core.workers).
WORKERS = 1


def core_bake(target, occluders, **kw):
    """core.bake_ao with the benchmark's defaults (cosine directions, no margin unless asked)."""
    from core import bake_ao

    kw.setdefault("margin", 0)
    if WORKERS > 1 and "workers" not in kw:
        kw.update(workers=WORKERS, threads=1)
    c0 = time.process_time()
    r = bake_ao(target, occluders, **kw)
    r.cpu_seconds = time.process_time() - c0  # process CPU seconds, all threads
    return r
