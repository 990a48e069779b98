"""A bake in another process: the job (plain data) a worker rebuilds a bake from, and the worker's side.

The executor (:mod:`core.execution`) knows no bake kinds: a worker process boots into
:mod:`core.pipeline.entry`, which hands each job to :func:`build`; a Dask worker runs
:func:`dask_tile`. A job is the request as plain data (:meth:`core.base.request.BakeRequest.to_dict`,
with the tiles and the extrusion the parent chose) and the meshes as arrays (:func:`mesh_data`); an
image's target travels without its UVs, with the parent's UV triangles and tiles in their place
(``layout``, :func:`core.targets.texels.layout_data`): a worker lays nothing out again. The executor
adds ``threads`` (each worker's) and ``quantum`` (samples per progress message).

A worker keeps the last bake's occlusion scenes (Embree's, and the tracer's arrays) and traces in
them when the next bake sends the same meshes (:func:`scene_key`): an artist baking again after
changing the samples, the resolution or the distance does not wait for them. One scene at a time:
a bake of other meshes drops it before building its own (:func:`forget`), so a worker's peak does
not grow. Selected-to-active bakes keep none.
"""

import hashlib
import os
import threading

import numpy as np

from ..base.request import BakeRequest
from ..engine.scheduler import run_all
from ..engine.settings import BakeSettings
from ..execution.worker import CountingScheduler
from ..geometry.mesh import Mesh
from ..targets.corners import vertex_bake
from ..targets.atlas import AtlasBake
from ..targets.texels import texel_bake
from .prologue import Prologue, check


def mesh_data(mesh):
    """A :class:`core.Mesh` as plain data for a worker (its corner normals as given: the worker
    computes the unit ones, the same bits; none for a flat-shaded mesh)."""
    return dict(positions=mesh.positions, triangles=mesh.triangles, uvs=mesh.uvs, normals=mesh.given_normals(),
                name=mesh.name)


def _mesh(data):
    return None if data is None else Mesh(**data)


#: The last bake's occlusion scenes in this worker: ``key`` (:func:`scene_key`), ``count`` (the meshes
#: its tracer holds: the target alone, or with its occluders) and ``tracer``.
_SCENE = {}


def scene_key(job):
    """A digest of what a bake's occlusion scenes are built from: the target's and the occluders'
    positions and triangles as sent (their dtypes and shapes too). The same key, the same scenes:
    the meshes are moved into the bake's frame by the same arithmetic on the same bits. The parent
    computes it once (the job's ``scene_key``, :func:`scene_key_of`), else each worker does."""
    if job.get("kind") == "atlas":
        h = hashlib.blake2b(digest_size=20)
        h.update(b"atlas")
        return h.hexdigest()
    key = job.get("scene_key")
    return key if key is not None else scene_key_of([job["target"]] + list(job["occluders"]))


def scene_key_of(meshes):
    """:func:`scene_key` of ``meshes`` (the target, then the occluders: :func:`mesh_data` dicts or
    :class:`core.Mesh` objects)."""
    h = hashlib.blake2b(digest_size=20)
    for m in meshes:
        for name in ("positions", "triangles"):
            a = np.ascontiguousarray(m[name] if isinstance(m, dict) else getattr(m, name))
            h.update(f"{name}{a.dtype.str}{a.shape};".encode())
            h.update(memoryview(a).cast("B"))
    return h.hexdigest()


def forget(job):
    """Drop the scenes kept from the last bake unless ``job`` bakes the same meshes (before its own
    are built: a worker never holds two). Notes the job's :func:`scene_key` in it."""
    job["scene"] = scene_key(job)
    if _SCENE.get("key") != job["scene"]:
        _SCENE.clear()


def build(job, cancel, progress):
    """The bake of ``job`` in this process: (bake, its scheduler, threads). A job that :func:`forget`
    saw traces in the last bake's scenes where the meshes are the same, and keeps its own for the
    next bake; another (a Dask task's) keeps none."""
    key = job.get("scene")
    request = BakeRequest.from_dict(job["request"]).replace(threads=job["threads"])
    if job.get("kind") == "atlas":  # several targets, each part set up when its first tile comes
        _SCENE.clear()
        bake, s = build_remote(job, request, cancel, _mesh)
        bake.request_data = request.to_dict()  # the options this worker baked with, back in the report
        shared = CountingScheduler(bake.planned, progress, cancel, job["quantum"])
        bake.trace_setup(shared, cancel)
        return bake, shared, s.threads
    highpoly = job.get("highpoly")
    # An image's UV triangles and tiles come laid out by the parent, in place of the target's UVs.
    layout = job.pop("layout", None)
    # Popped: the job holds nothing of the target past its use.
    checked = check(request, _mesh(job.pop("target")), [_mesh(o) for o in job["occluders"]],
                    highpoly=None if highpoly is None else [_mesh(m) for m in highpoly], cage=_mesh(job.get("cage")),
                    corners=job.get("corners"), laid_out=layout is not None)
    pro = Prologue(checked, request, cancel)
    kept = _SCENE.get("tracer") if key is not None and pro.s2a is None and _SCENE.get("key") == key else None
    if kept is not None:
        pro.share(_SCENE["count"], kept)
    s = BakeSettings.of(request)
    if request.kind == "corners":
        bake = vertex_bake(pro, s, pro.corners, request.all_quantities, request.merge, request.bent_normals,
                           job["block"])
    else:
        bake = texel_bake(pro, s, request.all_quantities, request.bent_normals, guide=job.get("guide", False),
                          layout=layout)
        del layout
        if job.get("goal") is not None:  # counts decided before the bake (adaptive sampling aimed at the denoised map)
            bake.aim(job["goal"], again=job.get("again", False))
        pro.target.uvs = None  # a job with UVs (without a layout): they served the UV triangles the bake holds
    shared = CountingScheduler(bake.planned, progress, cancel, job["quantum"])
    bake.trace_setup(shared, cancel)
    bake.scene_reused = kept is not None and pro.shared_tracer is not None and pro.shared_tracer[1] is kept
    bake.request_data = request.to_dict()  # the options this worker baked with, back in the report
    if key is not None:
        # Keep the tracer this bake traced in as the last scene (one scene at a time: memory does not grow).
        _SCENE.clear()
        if pro.s2a is None and pro.shared_tracer is not None:
            meshes, tracer = pro.shared_tracer
            tracer.hold(meshes)  # this bake's meshes (the same bits): the last bake's go
            _SCENE.update(key=key, count=len(meshes), tracer=tracer)
    return bake, shared, s.threads


#: The bakes a Dask worker process has set up, by token (a bake's tiles reuse its scene); the last few.
_DASK_BAKES = {}
_DASK_KEEP = 2


def dask_tile(token, job, key):
    """One tile of the bake ``job`` on a Dask worker: (the tile's values, this process, its totals so
    far), as plain data. The bake is set up once per process and token; a task that is run again (its
    worker was lost) gives the same values."""
    entry = _DASK_BAKES.get(token)
    if entry is None:
        bake, shared, threads = build(dict(job), threading.Event(), lambda work: None)
        entry = _DASK_BAKES[token] = (bake, shared, threads, threading.Lock())
        while len(_DASK_BAKES) > _DASK_KEEP:
            _DASK_BAKES.pop(next(iter(_DASK_BAKES)))
    bake, shared, threads, lock = entry
    with lock:  # one tile of a bake at a time in a process (its threads share the tile's chunks)
        outs = []
        run_all(lambda k: outs.append(bake.tile(k, directions=False)), [key], threads, shared, None)
        totals = dict(rays=shared.rays, trace_seconds=shared.trace_seconds,
                      trace_cpu_seconds=shared.trace_cpu_seconds, counters=bake.start.counters())
    return vars(outs[0]), (os.getpid(), id(entry)), totals


def build_remote(job, request, cancel, mesh):
    """The atlas of ``job`` in a worker process (:func:`core.pipeline.remote.build`): an AtlasBake
    whose parts are built from the job's meshes when their first tile comes."""
    meshes = [mesh(d) for d in job["meshes"]]
    quantities = request.all_quantities
    s = BakeSettings.of(request)

    def build(i):
        p = job["parts"][i] if i in job["parts"] else job["parts"][str(i)]
        req = request.replace(tile_size=tuple(p["tile"]))
        checked = check(req, meshes[p["target"]], [meshes[k] for k in p["occluders"]],
                        highpoly=None if p["highpoly"] is None else [meshes[k] for k in p["highpoly"]],
                        cage=None if p["cage"] is None else meshes[p["cage"]])
        pro = Prologue(checked, req, cancel)
        bake = texel_bake(pro, BakeSettings.of(req), quantities, request.bent_normals, guide=job.get("guide", False))
        return bake

    return AtlasBake(build, s, job["planned"], keep_live=s.threads + 1), s


__all__ = ["mesh_data", "scene_key", "scene_key_of", "forget", "build", "dask_tile"]
