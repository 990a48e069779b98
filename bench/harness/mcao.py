"""mc_ao's side of the comparison: the add-on's Bake AO operator and core.bake_ao on the same arrays."""

import os
import time

import numpy as np

_registered = False
#: Wall and process-CPU seconds of the last operator bake (see bench.comparators.cycles.LAST).
LAST = {"wall": None, "cpu": None}


def _children_cpu():
    """CPU seconds (user + system) so far of this process's living children: the worker processes a
    bake runs on (a persistent pool, so they are not reaped and getrusage's RUSAGE_CHILDREN misses
    them). 0 where /proc is not there."""
    me, total = str(os.getpid()), 0
    try:
        names = os.listdir("/proc")
    except OSError:
        return 0.0
    for name in names:
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[1] == me:  # fields after the name: state, ppid, ..., utime (12), stime (13)
            total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


def process_cpu():
    """CPU seconds of this process and of the worker processes it started (see _children_cpu)."""
    return time.process_time() + _children_cpu()


def register(bpy):
    """Register the checkout's add-on (top-level ``mc_ao``) once in this bpy session."""
    global _registered
    if not _registered and not hasattr(bpy.types.Scene, "mc_ao"):
        import mc_ao

        mc_ao.register()
    _registered = True


def operator_bake(bpy, obj, resolution, samples, threads, max_distance, margin=16, seed=0, source="SOBOL",
                  target_error=0.0, min_samples=16, denoise=False, fix_seams=None):
    """bpy.ops.object.mc_ao_bake() of ``obj`` alone (every visible object occludes it), on ``threads``
    cores as the operator's defaults use them: ``threads`` worker processes of one thread each (Threads
    is each process's threads; Threads 2 with Processes automatic would bake in Blender's process).
    ``fix_seams``: True or False, or None for the panel's default (on).

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
    s.denoise = bool(denoise)
    if fix_seams is not None:
        s.fix_seams = bool(fix_seams)
    s.processes = threads
    s.threads = 1
    s.image_name = ""
    select_only(bpy, obj)
    c0, t0 = process_cpu(), time.perf_counter()
    res = bpy.ops.object.mc_ao_bake()
    seconds = time.perf_counter() - t0
    LAST.update(wall=seconds, cpu=process_cpu() - c0)
    if res != {"FINISHED"}:
        raise RuntimeError(f"mc_ao_bake returned {res}")
    return read_ao(bpy.data.images[f"{obj.name}_AO"]), seconds


#: With ``python -m bench --workers``: core bakes on that many worker processes of one thread each
#: instead of ``threads`` threads of this process (the same bits; see core.execution.pool).
WORKERS = 1


def core_bake(target, occluders, **kw):
    """core.bake_ao with the benchmark's defaults (cosine directions, no margin unless asked)."""
    from core import bake_ao

    kw.setdefault("margin", 0)
    if WORKERS > 1 and "workers" not in kw:
        kw.update(workers=WORKERS, threads=1)
    c0 = process_cpu()
    r = bake_ao(target, occluders, **kw)
    r.cpu_seconds = process_cpu() - c0  # CPU seconds of every thread and worker process
    return r
