"""The executor: who bakes a bake's tiles (this process's threads, worker processes, a Dask cluster).

It knows no bake kinds: it is given a bake set up after its prologue, the keys of its tiles, what a
worker rebuilds the bake from (the job, plain data) and where each tile's values go, and it bakes
the tiles here (:func:`core.engine.scheduler.run_all`), on the pool of worker processes
(:mod:`core.execution.pool`) or on a Dask cluster (:mod:`core.execution.dask`). How many processes
and threads: :func:`processes_of` (``workers='auto'``: :func:`auto_workers`, from the cores and the
memory model of :mod:`core.execution.cost`).
"""

import numpy as np

from ..base.errors import SettingsError
from ..base.machine import cpu_count, memory_limit
from ..base.request import is_dask_client
from ..engine.scheduler import Scheduler, run_all
from ..engine.settings import TILE_TRIANGLES, auto_tile_shape
from . import cost as cost_mod
from .dask import run_dask
from .memory import memory_entry
from .pool import pool_for, pool_ready, pool_state


def auto_workers(triangles, cores=None, memory=None):
    """(workers, threads each) for a bake of ``triangles``: a count (every mesh, costed as the
    target's) or (target, occluder, high-poly) triangles. One worker a core, fewer with more threads
    each where memory holds fewer copies of the scene (threads share one): the workers and what the
    parent adds while they bake within 80% of ``memory`` (None: :func:`memory_limit`, the machine's
    available memory or what its container's cgroup has left, whichever is less)."""
    cores = cpu_count() if cores is None else cores
    memory = memory_limit() if memory is None else memory
    target, occluders, highpoly = (int(triangles), 0, 0) if np.ndim(triangles) == 0 else map(int, triangles)
    # core.execution.cost's measured figures: each worker's peak (its tables and Embree scenes, its interpreter
    # and sample pool), and the parent's share while they bake.
    per_worker = cost_mod.process_bytes(target, occluders, highpoly)
    parent = cost_mod.parent_bytes(target, occluders + highpoly)
    workers = cores if memory is None else max(1, min(cores, int((memory * 0.8 - parent) // per_worker)))
    return workers, max(1, cores // workers)


def clamp_processes(asked, threads, triangles, cores=None, memory=None):
    """(processes, why fewer than ``asked`` or None): at most as many worker processes of ``threads``
    threads as the cores hold, and as many as the memory holds by :mod:`core.execution.cost`'s model
    (each worker's copy of the scene, the parent's share) within 80% of it; at least one."""
    cores = cpu_count() if cores is None else cores
    memory = memory_limit() if memory is None else memory
    target, occluders, highpoly = (int(triangles), 0, 0) if np.ndim(triangles) == 0 else map(int, triangles)
    by_cores = max(1, cores // max(1, int(threads)))
    out, why = min(int(asked), by_cores), []
    if out < asked:
        why.append(f"{cores} cores at {int(threads)} thread{'s' if threads != 1 else ''} each")
    if memory is not None:
        per_worker = cost_mod.process_bytes(target, occluders, highpoly)
        parent = cost_mod.parent_bytes(target, occluders + highpoly)
        fit = max(1, int((memory * 0.8 - parent) // per_worker))
        if fit < out:
            out = fit
            why.append(f"memory for {fit} ({memory / 2 ** 30:.1f} GiB available, about "
                       f"{per_worker / 2 ** 20:.0f} MiB each)")
    return out, ("; ".join(why) if out < asked else None)


def processes_of(workers, threads, settings, triangles, work=None, remote=None, scene=None):
    """(processes, threads each) of a bake given ``workers`` (1, N or 'auto', checked) and the
    ``threads`` argument: with workers, ``threads`` counts each worker's threads (None: one each, or
    what 'auto' picks); workers=1 is this process with ``settings.threads``. The arguments after
    ``triangles`` are :func:`parallel_of`'s (without them 'auto' bakes on :func:`auto_workers`' processes)."""
    choice = parallel_of(workers, threads, settings, triangles, work, remote, scene)
    return choice.processes, choice.threads


def parallel_of(workers, threads, settings, triangles, work=None, remote=None, scene=None):
    """Where a bake's tiles run, and why: a :class:`core.execution.cost.ParallelChoice`.

    ``workers`` 1 or N, or 'auto' with ``threads`` given, are taken as asked (see :func:`processes_of`).
    'auto' with ``threads`` None weighs this process's threads against :func:`auto_workers`' processes
    by the time each would take (:func:`core.execution.cost.choose_parallel`), given ``work`` (a
    :class:`core.execution.cost.Work`) and the state of the pool ``remote`` runs on
    (:func:`core.execution.pool.pool_state`: its start if none runs, measured in this process when one
    has started before; the Embree scenes its workers keep when ``scene``, the bake's scene token, is
    theirs). Without ``work``, 'auto' takes :func:`auto_workers`' processes."""
    if is_dask_client(workers):
        return cost_mod.ParallelChoice(workers, 1 if threads is None else settings.threads, "a Dask cluster, as asked")
    if workers == 1:
        n = settings.threads
        return cost_mod.ParallelChoice(1, n, f"{_threads(n)} of this process, as asked")
    if workers != "auto":
        n = 1 if threads is None else settings.threads
        processes, fewer = clamp_processes(workers, n, triangles)
        where = f"{processes} worker processes of {_threads(n)} each" if processes > 1 else f"{_threads(n)} of this process"
        return cost_mod.ParallelChoice(processes, n, f"{where}, as asked" if fewer is None
                                       else f"{where}, not the {workers} asked for: {fewer}")
    processes, per_worker = auto_workers(triangles)
    if threads is not None:
        # Threads asked for each: as many workers as the cores hold at that many threads each.
        n = settings.threads
        processes = max(1, min(processes, cpu_count() // n))
        return cost_mod.ParallelChoice(processes, n, f"{processes} worker processes of {_threads(n)} each: as many "
                                       f"as the cores hold at the {_threads(n)} asked for" if processes > 1
                                       else f"{_threads(n)} of this process, as asked")
    if work is None or processes <= 1 or remote is None:
        return cost_mod.ParallelChoice(processes, per_worker, f"{processes} worker processes of "
                                       f"{_threads(per_worker)} each, from the cores and the memory" if processes > 1
                                       else f"{_threads(per_worker)} of this process: the memory holds one copy "
                                       "of the scene")
    state, detail = pool_state(processes, per_worker, remote)
    cores = cpu_count()
    if state == "failed":
        return cost_mod.ParallelChoice(1, cores, f"{_threads(cores)} of this process: the worker processes failed "
                                       f"their self-test earlier ({detail})")
    if state == "running":
        start = 0.0
    else:  # measured when a pool started before in this process, else the model's workers side by side
        start = detail if detail is not None else cost_mod.WORKER_START_SECONDS * processes / min(processes, cores)
    kept = state == "running" and scene is not None and detail == (scene() if callable(scene) else scene)
    return cost_mod.choose_parallel(work, cores, (processes, per_worker), start, kept,
                                    tiles=_tile_count(work, processes * per_worker, settings))


def _tile_count(work, threads, settings):
    """About how many tiles worker processes of ``threads`` threads in all get (the pipeline's rule: two
    tiles a thread at least, fewer triangles each on dense meshes)."""
    if settings.tile_size is not None and not settings.auto_tiles:
        tw, th = settings.tile_shape
    else:
        tw, th = auto_tile_shape(work.width, work.height, 2 * threads, work.samples)
    tiles = -(-work.width // tw) * -(-work.height // th)
    return max(tiles, -(-int(work.triangles[0]) // TILE_TRIANGLES))


def _threads(n):
    return f"{n} thread{'s' if n != 1 else ''}"


def in_process(processes):
    """Whether a bake of :func:`processes_of`'s ``processes`` runs in this process."""
    return not is_dask_client(processes) and processes == 1


def worker_count(processes):
    """How many processes bake the tiles (a Dask cluster's workers now)."""
    if is_dask_client(processes):
        return max(1, len(processes.scheduler_info().get("workers", {})))
    return processes


def run_tiles(remote, processes, threads, job, keys, planned, store, progress, cancel):
    """Bake ``keys`` of ``job`` on the local pool or a Dask cluster (:func:`core.execution.dask.run_dask`)."""
    if is_dask_client(processes):
        return run_dask(processes, remote.dask_tile, job, keys, planned, store, progress, cancel, threads)
    return pool_for(processes, threads, remote).run(job, keys, planned, store, progress, cancel)


def bake_tiles(remote, bake, keys, processes, threads, job, store, progress, cancel, on_rays=None):
    """Bake ``keys`` of ``bake`` (any bake set up after its prologue: ``planned``, ``s.threads``,
    ``trace_setup``, ``tile``, ``start.counters()``) in this process on ``bake.s.threads`` threads, or on
    ``processes`` worker processes of ``threads`` threads (or a Dask cluster) that run ``remote`` (a
    :class:`core.execution.contracts.Remote`); ``store`` each tile's :class:`core.engine.tilebaker.TileOut`.
    ``job()`` makes the plain data workers rebuild the bake from (only when they bake). Where a local
    pool cannot be used (its self-test failed), this process bakes.

    Returns (rays, trace seconds, trace CPU seconds, the start stage's counters, the reason the pool
    was not used or None). The counters hold ``worker_memory``: a :func:`memory_entry` of this
    process, then one of each worker process that baked."""
    fallback = usable_pool(remote, processes, threads)
    if fallback is None and not in_process(processes):
        if on_rays is not None:
            raise SettingsError("on_rays sees the rays of this process only: bake with workers=1 to record them")
        rays, seconds, cpu, counters = run_tiles(remote, processes, threads, job(), keys, bake.planned, store, progress,
                                                 cancel)
        counters["worker_memory"] = [memory_entry("parent", (bake,))] + counters.get("worker_memory", [])
        return rays, seconds, cpu, counters, None
    shared = Scheduler(bake.planned, progress, cancel)
    bake.trace_setup(shared, cancel, on_rays)
    run_all(lambda key: store(bake.tile(key)), keys, bake.s.threads, shared, progress)
    counters = bake.start.counters()
    counters["worker_memory"] = [memory_entry("parent", (bake,))]
    return shared.rays, shared.trace_seconds, shared.trace_cpu_seconds, counters, fallback


def usable_pool(remote, processes, threads):
    """None when the local pool of ``processes`` started and passed its self-test (or the tiles go to
    a Dask cluster), else the reason it cannot be used (the bake then runs on threads)."""
    if in_process(processes) or is_dask_client(processes):
        return None
    try:
        return pool_for(processes, threads, remote).failed
    except OSError as e:  # the interpreter could not be started at all
        return f"worker processes could not be started ({e})"


__all__ = ["auto_workers", "clamp_processes", "processes_of", "parallel_of", "in_process", "worker_count", "run_tiles",
           "bake_tiles", "usable_pool", "pool_ready"]
