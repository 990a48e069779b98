"""The one pipeline every bake runs: check, prologue, target, execute, finish.

:func:`run` bakes a checked :class:`core.base.request.BakeRequest` of any kind:

1. check: the meshes and arrays against the request (:func:`core.pipeline.prologue.check`);
2. prologue: the scene in the target's frame, the automatic extrusion, memory and cancellation
   (:class:`core.pipeline.prologue.Prologue`);
3. target: what the bake fills, laid out (:class:`Texels`: an image's UV triangles and tiles;
   :class:`Corners`: face corners' sample points), its stores, and the job a worker rebuilds it from;
4. execute: the tiles on this process's threads, on worker processes or on a Dask cluster
   (:func:`core.execution.executor.bake_tiles`, which knows no bake kinds);
5. finish: per quantity, the denoiser, the margin, Fix Seams, the bent normals, the metadata, the report
   and its warnings (:func:`finish`).

UDIM tiles are images of their own, each through steps 2 to 5 with its own seed
(:mod:`core.geometry.uvtiles`), then denoised and their seams fixed together across the tiles, and
stacked (:func:`_udim`). Several quantities (``request.quantities``) share every step but their rays
(:mod:`core.targets.maps`).
"""

import dataclasses
import functools
import hashlib
import time

import numpy as np

from .._version import __version__
from ..base.machine import cpu_count
from ..engine.settings import BakeSettings, auto_tile_shape
from ..engine.thickness import resolved as thickness_resolved
from ..base.request import BakeRequest
from ..execution.contracts import Remote
from ..execution import cost as cost_mod
from ..execution.executor import bake_tiles, clamp_processes, in_process, parallel_of, worker_count
from ..execution.pool import pool_for
from ..geometry.margin import dilate
from ..geometry.mesh import Mesh
from ..geometry.uvtiles import covered_tiles, shifted, tile_seed
from ..highpoly.stage import finish_report
from ..post import bent as bent_mod
from ..post import denoise as denoise_mod
from ..post import fixseams
from ..post.denoise import aim as aim_mod
from ..base.errors import MeshError, SettingsError
from ..targets.atlas import Atlas
from ..targets.corners import vertex_bake
from ..targets.texels import ImageStore, layout_data, texel_bake
from . import remote
from .prologue import Prologue, check
from .remote import mesh_data
from .result import BakeReport, BakeResult, empty_reason, seam_report


def run(request, target, occluders=(), *, highpoly=None, cage=None, bent_space=None, corners=None, progress=None,
        cancel=None, on_tile=None, on_rays=None):
    """Bake ``request`` (checked): {quantity: BakeResult}, one per quantity of
    ``request.all_quantities``. The arguments are :func:`core.bake`'s. A list of targets (or a
    :class:`core.targets.atlas.Atlas`) is an atlas (:mod:`core.pipeline.atlas`)."""
    # a thickness map's distance, decided once from the target(s), before any worker sees the request
    request = thickness_resolved(request, target.targets if isinstance(target, Atlas) else target)
    if isinstance(target, (list, tuple, Atlas)):
        from .atlas import run_atlas, run_udim_atlas

        return (run_udim_atlas if request.kind == "udim" else run_atlas)(request, Atlas.of(target), occluders, highpoly=highpoly, cage=cage, bent_space=bent_space,
                         progress=progress, cancel=cancel, on_tile=on_tile, on_rays=on_rays, remote=REMOTE)
    if request.kind == "udim":
        return _udim(request, target, occluders, highpoly, cage, bent_space, progress, cancel, on_tile, on_rays)
    t_start = time.perf_counter()
    checked = check(request, target, occluders, highpoly, cage, bent_space, corners)
    pro = Prologue(checked, request, cancel)
    s = BakeSettings.of(request)
    scene = _scene_token(checked)
    choice = parallel_of(request.workers, request.threads, s, pro.triangle_counts, _work(request, checked, s), REMOTE,
                         scene)
    processes, per_worker = choice.processes, choice.threads
    made = (Corners if request.kind == "corners" else Texels)(pro, s, processes, per_worker, checked, on_tile)
    made.parallel, made.scene = choice, scene
    pro.check_memory(made.planned)
    pro.check_cancel()
    if getattr(made, "aims", False):
        rays, trace_s, trace_cpu, counters, fallback = _aimed(made, processes, per_worker, progress, cancel, on_rays)
    else:
        rays, trace_s, trace_cpu, counters, fallback = bake_tiles(REMOTE, made.bake, made.keys, processes, per_worker,
                                                                  made.job, made.store, progress, cancel, on_rays)
    quantities = request.all_quantities
    if len(quantities) == 1:
        counters = {quantities[0]: dict(counters, rays=rays, trace_seconds=trace_s, trace_cpu_seconds=trace_cpu)}
    else:  # the processes' memory, once for the whole bake: each map's report has it
        memory = counters.pop("worker_memory", [])
        counters = {q: dict(counters[q], worker_memory=memory) for q in quantities}
    results = {q: finish(made, q, counters[q], fallback, t_start) for q in made.checked_order(counters)}
    clamped = clamped_note(request, processes, per_worker, pro.triangle_counts)
    if clamped is not None:
        for r in results.values():
            r.report.warn(clamped)
    return results


def clamped_note(request, processes, threads, triangles):
    """The warning of a bake that asked for more worker processes than it takes, saying why; or None."""
    asked = request.workers
    if isinstance(asked, bool) or not isinstance(asked, int) or asked <= processes:
        return None
    _, why = clamp_processes(asked, threads, triangles)
    return f"asked for {asked} worker processes, baked on {processes}: {why}"


def _work(request, checked, s):
    """What :func:`core.execution.executor.parallel_of` weighs threads against worker processes by (a
    :class:`core.execution.cost.Work`), for a bake whose workers and threads are both automatic."""
    if request.workers != "auto" or request.threads is not None:
        return None
    others = [*(checked.s2a.highs if checked.s2a else ()),
              *((checked.s2a.cage,) if checked.s2a is not None and checked.s2a.cage is not None else ())]
    meshes = [checked.target, *checked.occluders, *others]
    job_bytes = sum(a.nbytes for m in meshes for a in mesh_data(m).values() if isinstance(a, np.ndarray))
    triangles = (checked.target.triangle_count, sum(o.triangle_count for o in checked.occluders),
                 sum(m.triangle_count for m in others))
    if request.kind == "corners":
        return cost_mod.Work(len(checked.corners), s.samples, triangles, job_bytes=job_bytes)
    # An image's job carries the target's layout in place of its UVs (Texels.job).
    job_bytes += cost_mod.LAYOUT_BYTES_PER_TRIANGLE * triangles[0] - checked.target.uvs.nbytes
    return cost_mod.Work(cost_mod.covered_texels(checked.target.uvs, s.width, s.height), s.samples, triangles,
                         s.width, s.height, job_bytes)


def _scene_token(checked):
    """A function giving the bake's scene token (:func:`core.pipeline.remote.scene_key_of`, computed once,
    when first asked for): what tells a worker that the scene it keeps is this bake's. None for
    selected to active (its workers keep no scene)."""
    if checked.s2a is not None:
        return None
    return functools.lru_cache(maxsize=1)(functools.partial(remote.scene_key_of, [checked.target, *checked.occluders]))


def _merged(a, b):
    """Two passes' counters as one: numbers added, lists joined, dicts merged key by key."""
    if isinstance(a, dict):
        return {k: _merged(a[k], b[k]) if k in a and k in b else a.get(k, b.get(k)) for k in {**a, **b}}
    if isinstance(a, list):
        return a + b
    if isinstance(a, (int, float, np.integer, np.floating)) and not isinstance(a, bool):
        return a + b
    return a


def _aimed(made, processes, per_worker, progress, cancel, on_rays):
    """A denoised bake with a noise target (:mod:`core.post.denoise.aim`): every texel's first round,
    the denoiser's error of that map, then the texels whose denoised error misses the target baked
    again with the counts it asks. Returns :func:`core.execution.executor.bake_tiles`' tuple for
    both passes together."""
    s = made.lanes[made.base].s
    first = -(-min(s.min_samples, s.samples) // s.replicates)
    cap = -(-s.samples // s.replicates)
    share = first / cap  # the first pass's part of the progress
    w, h = s.width, s.height
    made.bake.aim(first)
    one = bake_tiles(REMOTE, made.bake, made.keys, processes, per_worker, made.job, made.store,
                     None if progress is None else (lambda f: progress(share * f)), cancel, on_rays)
    img = made.images[made.base]
    guide = denoise_mod.surface_guide(made.pro.target, (w, h), texels=made.guide, tris=made.uvtris)
    _, _, info = denoise_mod.denoise(img.ao, img.se, img.mask, guide, threads=s.threads)
    rate = 0.5 if s.source == "independent" else 0.75
    goal = aim_mod.goal_counts(info.variance, info.bias, img.se.astype(np.float64) ** 2, img.mask, first,
                               s.target_error, cap, rate)
    keys = [k for k in made.keys if goal[made.bake.rect(k)[:2]].any()]
    if not keys:
        return one
    made.bake.aim(goal.reshape(-1), again=True)
    two = bake_tiles(REMOTE, made.bake, keys, processes, per_worker, made.job, made.store,
                     None if progress is None else (lambda f: progress(share + (1 - share) * f)), cancel, on_rays)
    return (one[0] + two[0], one[1] + two[1], one[2] + two[2], _merged(one[3], two[3]), one[4] or two[4])


class Texels:
    """The target of an image bake: its layout (:func:`core.targets.texels.texel_bake`: UV triangles,
    tiles, surface table), one :class:`core.targets.texels.ImageStore` per quantity, and its job."""

    def __init__(self, pro, s, processes, per_worker, checked, on_tile):
        request = pro.request
        self.pro, self.request, self.checked = pro, request, checked
        self.maps = request.quantities is not None
        quantities = request.all_quantities
        w, h = s.width, s.height
        if not in_process(processes) and request.tile_size is None:
            # Tiles for every thread of every worker, two each at least (they are dealt as workers free up).
            total = worker_count(processes) * per_worker
            tw, th = auto_tile_shape(w, h, 2 * total, s.samples)
            s = dataclasses.replace(s, tile_size=tw, tile_height=th, threads=min(total, cpu_count()))
        self.planned = s  # the settings memory is checked with (the layout may shrink the tiles further)
        # The denoiser's guide per texel (triangle, surface point, normal), filled in by the base
        # quantity's tiles from their fragments (selected to active rasterises without locating: the
        # denoiser then finds the texels' triangles itself).
        self.guide = ((np.full(h * w, -1, np.int32), np.zeros((h * w, 3), np.float32),
                       np.zeros((h * w, 3), np.float32)) if request.denoise and pro.s2a is None else None)
        self.bake = bake = texel_bake(pro, s, quantities, request.bent_normals, guide=self.guide is not None)
        self.lanes = bake.lanes if len(quantities) > 1 else {s.quantity: bake}
        self.base = s.quantity
        self.keys = sorted(bake.bins)
        self.uvtris = bake.uvtris
        self.images = {q: ImageStore(b, w, h, b.bent_normals, pro.s2a is not None,
                                     None if on_tile is None else on_tile if not self.maps
                                     else functools.partial(on_tile, q),
                                     self.guide if q == self.base else None)
                       for q, b in self.lanes.items()}

    @property
    def aims(self):
        """Whether the bake aims its samples at the denoised map's error (:mod:`core.post.denoise.aim`):
        denoise with a noise target (not selected to active: its tiles give no guide)."""
        s = self.lanes[self.base].s
        return (self.request.denoise and s.target_error > 0 and self.guide is not None
                and min(s.min_samples, s.samples) < s.samples)

    def store(self, out):
        """Put a tile's values (:class:`core.engine.tilebaker.TileOut`) in each quantity's images."""
        if len(self.lanes) > 1:
            for q, o in self.bake.outs(out).items():
                self.images[q].store(o)
        else:
            self.images[self.base].store(out)

    def job(self):
        """What a worker rebuilds this bake from: the input as given, plain data, with the tiles and the
        extrusion this process chose."""
        request, checked, s2a = self.request, self.checked, self.pro.s2a
        root = self.lanes[self.base]
        plain = request.replace(tile_size=root.s.tile_shape, extrusion=request.extrusion if s2a is None
                                else s2a.world.extrusion).to_dict()
        # The target without its UVs: the workers bake from this process's UV triangles and tiles.
        return dict(request=plain, target=dict(mesh_data(checked.target), uvs=None), layout=layout_data(root),
                    occluders=[mesh_data(o) for o in checked.occluders],
                    highpoly=None if s2a is None else [mesh_data(m) for m in checked.s2a.highs],
                    cage=None if s2a is None or checked.s2a.cage is None else mesh_data(checked.s2a.cage),
                    guide=self.guide is not None and not root.again, goal=root.goal, again=root.again,
                    scene_key=None if self.scene is None else self.scene())

    def checked_order(self, counters):
        """The quantities in order, after refusing a bake that covered nothing (or, with selected to
        active, whose matching rays found nothing): ``extra`` per quantity, the matching's report."""
        self.extra = {}
        for q in self.request.all_quantities:
            img = self.images[q]
            if self.pro.s2a is not None:
                self.extra[q] = finish_report(counters[q], img.miss, img.mask, self.pro.s2a)
            elif not img.mask.any() and not self.request.empty_ok:
                raise self.pro.nothing_covered(self.lanes[q].s, self.uvtris)
        return self.request.all_quantities

    def result(self, q, counters, t_start):
        """Quantity ``q``'s BakeResult from its filled images: denoise, margin, Fix Seams (on the map and
        its error, after the margin, whose texels it may change), bent normals (not fixed: tangent frames
        differ across seams)."""
        img, s, pro = self.images[q], self.lanes[q].s, self.pro
        ao, se, mask, bent = img.ao, img.se, img.mask, img.bent
        w, h = s.width, s.height
        raw_ao = raw_se = None
        if self.request.denoise:
            raw_ao, raw_se = ao.copy(), se.copy()
            if s.margin > 0:
                dilate(raw_ao, mask, s.margin, threads=s.threads, out=raw_ao)
            guide = denoise_mod.surface_guide(pro.target, (w, h), texels=self.guide, tris=self.uvtris)
            ao, se, info = denoise_mod.denoise(ao, se, mask, guide, threads=s.threads)
        if s.margin > 0:
            dilate(ao, mask, s.margin, threads=s.threads, out=ao)
        # over the covered texels and the margin's, never those beyond it
        fix = fixseams.fix_baked(pro.target, ao, se, mask, margin=s.margin) if self.request.fix_seams else None
        if bent is not None:
            bent, _ = bent_mod.dilate_directions(bent, mask, s.margin, s.threads)
        seconds = time.perf_counter() - t_start
        rays = counters["rays"]
        metadata = dict(s.metadata(s.max_distance), version=__version__, rays=rays)
        report = BakeReport(covered_texels=int(mask.sum()), degenerate_uv_triangles=self.uvtris.degenerate,
                            degenerate_triangles=self.uvtris.degenerate_space,
                            uv_outside_triangles=self.uvtris.outside, overlapping_texels=img.overlap,
                            worker_memory=counters.get("worker_memory", []), **seam_report(fix))
        if fix is not None:
            metadata["fix_seams"] = True
        return BakeResult(ao=ao, mask=mask, stderr=se, samples=img.count, rays=rays, seconds=seconds,
                          trace_seconds=counters["trace_seconds"], threads=s.threads, metadata=metadata, report=report,
                          trace_cpu_seconds=counters["trace_cpu_seconds"], bent=bent, miss=img.miss,
                          missed=counters["missed"] if pro.s2a is not None else 0, raw_ao=raw_ao, raw_stderr=raw_se)


class Corners:
    """The target of a corner bake (colour attributes): the sample points of the corners
    (:func:`core.targets.corners.vertex_bake`), their values per quantity, and its job."""

    def __init__(self, pro, s, processes, per_worker, checked, on_tile):
        request = pro.request
        self.pro, self.request, self.checked = pro, request, checked
        self.maps = request.quantities is not None
        quantities = request.all_quantities
        self.planned = s
        self.bake = bake = vertex_bake(pro, s, pro.corners, quantities, request.merge, request.bent_normals)
        self.lanes = bake.lanes if len(quantities) > 1 else {s.quantity: bake}
        self.base = s.quantity
        root = self.lanes[self.base]
        self.keys = list(range(len(root.blocks)))
        m = len(root.p)
        self.values = {q: dict(ao=np.zeros(m, np.float32), se=np.zeros(m, np.float32), count=np.zeros(m, np.int32),
                               bent=np.zeros((m, 3), np.float32) if b.bent_normals else None)
                       for q, b in self.lanes.items()}

    def store(self, out):
        for q, o in (self.bake.outs(out) if len(self.lanes) > 1 else {self.base: out}).items():
            v, ids = self.values[q], o.texels
            v["ao"][ids], v["se"][ids], v["count"][ids] = o.ao, o.stderr, o.samples
            if v["bent"] is not None:
                v["bent"][ids] = o.bent

    def job(self):
        """What a worker rebuilds this bake from (plain data)."""
        root = self.lanes[self.base]
        return dict(request=self.request.to_dict(), target=mesh_data(self.checked.target),
                    occluders=[mesh_data(o) for o in self.checked.occluders], corners=self.pro.corners,
                    block=root.block, scene_key=None if self.scene is None else self.scene())

    def checked_order(self, counters):
        return self.request.all_quantities

    def result(self, q, counters, t_start):
        """Quantity ``q``'s BakeResult per corner from its points' values: the denoiser over the mesh."""
        ls, v, pro = self.lanes[q].s, self.values[q], self.pro
        root = self.lanes[self.base]
        unit, m = root.unit, len(root.p)
        metadata = dict(ls.metadata(ls.max_distance), version=__version__, rays=counters["rays"])
        for key in ("margin", "resolution"):
            metadata.pop(key, None)
        metadata["sample_points"] = m
        report = BakeReport(corners=len(pro.corners), sample_points=m, degenerate_corners=root.flat,
                            worker_memory=counters.get("worker_memory", []))
        out_ao, out_se, raw_ao, raw_se = v["ao"][unit], v["se"][unit], None, None
        if self.request.denoise:
            raw_ao, raw_se = out_ao, out_se
            out_ao, out_se, _ = denoise_mod.denoise_vertices(pro.target, raw_ao, raw_se, unit, pro.corners)
        return BakeResult(ao=out_ao, mask=np.ones(len(unit), bool), stderr=out_se, samples=v["count"][unit],
                          unit=unit, raw_ao=raw_ao, raw_stderr=raw_se, rays=counters["rays"],
                          seconds=time.perf_counter() - t_start, trace_seconds=counters["trace_seconds"],
                          threads=ls.threads, trace_cpu_seconds=counters["trace_cpu_seconds"], metadata=metadata,
                          report=report, bent=None if v["bent"] is None else v["bent"][unit])


def finish(made, q, counters, fallback, t_start):
    """Quantity ``q``'s result of the bake ``made`` (:class:`Texels` or :class:`Corners`): the target's
    own, then what every bake adds: the quantities baked together, denoise, the ground's height, the
    selected-to-active report and its warnings, and the warning of a bake that could not use its
    worker processes."""
    r = made.result(q, counters, t_start)
    s, pro = made.lanes[q].s, made.pro
    if made.maps:
        r.metadata["quantities"] = ",".join(made.request.all_quantities)
    denoised = [("denoise", True)] if made.request.denoise else []
    ground = [("ground_height", pro.ground_height(s)[0])] if s.ground is not None else []
    # The order metadata has always had in the files: an image's says denoise first, a PLY's the ground.
    r.metadata.update(ground + denoised if made.request.kind == "corners" else denoised + ground)
    if pro.s2a is not None:
        r.metadata.update(pro.s2a.metadata())
        extra = dict(made.extra[q])
        warnings = extra.pop("warnings")
        r.report = dataclasses.replace(r.report, **extra)
        r.report.warn(*warnings)  # beside any other warning of the bake (a list, empty when none)
    r.report.parallel = made.parallel.report()
    if fallback is not None:
        r.report.warn(f"baked on {s.threads} threads of this process, not in worker processes: {fallback}")
        r.report.parallel.update(processes=1, threads=s.threads, why=f"{s.threads} threads of this process: "
                                 f"the worker processes could not be used ({fallback})")
    return r


# -- other processes ---------------------------------------------------------------------------------------

def self_test():
    """A digest of a tiny bake (a plane under a lid, 16^2 x 8, one thread): what every worker and the
    parent must agree on before a pool is used (the same numpy, Embree and instruction paths)."""
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    lid = Mesh(p * [0.6, 0.6, 0] + [0.2, 0.2, 0.3], f, name="lid")
    r = run(BakeRequest(resolution=16, samples=8, threads=1), Mesh(p, f, uvs=p[f][:, :, :2], name="plane"), [lid])["ao"]
    return hashlib.sha256(r.ao.tobytes() + r.stderr.tobytes()).hexdigest()


#: What runs a bake's tiles in other processes: worker processes boot into :mod:`core.pipeline.entry`;
#: a Dask worker runs :func:`core.pipeline.remote.dask_tile`.
REMOTE = Remote(entry="pipeline.entry", self_test=self_test, dask_tile=remote.dask_tile)


def pool(workers, threads):
    """The persistent pool of ``workers`` worker processes of ``threads`` threads each that bakes run on
    (:func:`core.execution.pool.pool_for`), started now if it is not running."""
    return pool_for(workers, threads, REMOTE)


# -- UDIM tiles -------------------------------------------------------------------------------------------

def _udim(request, target, occluders, highpoly, cage, bent_space, progress, cancel, on_tile, on_rays):
    """A UDIM bake: every tile an image bake of its own (the UVs shifted onto it, its own seed), then
    the tiles denoised together across their seams, and each quantity's tiles stacked."""
    if not isinstance(target, Mesh):
        raise SettingsError(f"the target must be a core.Mesh, got {type(target).__name__}")
    # Denoised across the tiles' seams once every tile is baked (each tile alone would stop at its border).
    denoise, margin = request.denoise, request.margin
    tile_request = request.replace(kind="image", tiles=None, empty_ok=True, denoise=False,
                                   margin=0 if denoise else margin, fix_seams=False)
    coverage = covered_tiles(target, request.resolution)
    todo = coverage.tiles if request.tiles is None else list(request.tiles)
    weight = np.array([coverage.area.get(t, 0.0) for t in todo]) + 1e-12
    weight /= weight.sum()
    done = np.concatenate([[0.0], np.cumsum(weight)])
    quantities = request.all_quantities
    maps = request.quantities is not None
    results = {q: {} for q in quantities}
    for i, tile in enumerate(todo):
        def tile_progress(f, i=i):
            if progress is not None:
                progress(min(done[i] + weight[i] * f, 1.0))

        def tile_block(*args, tile=tile):
            if not maps:
                on_tile(tile, *args)
            else:
                on_tile(args[0], tile, *args[1:])

        baked = run(tile_request.replace(seed=tile_seed(request.seed, tile)), shifted(target, tile), occluders,
                    highpoly=highpoly, cage=cage, bent_space=bent_space, progress=tile_progress, cancel=cancel,
                    on_tile=None if on_tile is None else tile_block, on_rays=on_rays)
        for q in quantities:
            results[q][tile] = baked[q]
    return {q: _assemble(target, request.resolution, results[q], todo, coverage, denoise, margin, request.fix_seams)
            for q in quantities}


def _denoise_tiles(target, resolution, results, margin):
    """Denoise the tiles' maps together (:func:`core.post.denoise.denoise_udim`: across the seams between
    tiles too), keeping each tile's raw map (margin dilated) in ``raw_ao`` and ``raw_stderr``."""
    tiles = sorted(results)
    guide = denoise_mod.udim_guide(target, tiles, resolution)
    out = denoise_mod.denoise_udim({t: (results[t].ao, results[t].stderr, results[t].mask) for t in tiles}, guide,
                                   margin=margin)
    for t in tiles:
        r = results[t]
        r.raw_ao, r.raw_stderr = r.ao, r.stderr
        if margin > 0:
            r.raw_ao = dilate(r.raw_ao.copy(), r.mask, margin)
        r.ao, r.stderr = out[t][0], out[t][1]
        r.metadata.update(denoise=True, margin=margin)


def _fix_tiles(target, results, margin):
    """Fix the seams of the tiles' maps together (the tiles' shared edges too), each tile's ``ao`` and
    ``stderr`` in place, over their covered texels and ``margin``; the :class:`core.post.fixseams.SeamFix`."""
    tiles = sorted(results)
    ao = np.stack([results[t].ao for t in tiles])
    se = np.stack([results[t].stderr for t in tiles])
    fix = fixseams.fix_baked(target, ao, se, np.stack([results[t].mask for t in tiles]), tiles=tiles, margin=margin)
    for i, t in enumerate(tiles):
        results[t].ao, results[t].stderr = ao[i], se[i]
        results[t].metadata["fix_seams"] = True
    return fix


def _assemble(target, resolution, results, todo, coverage, denoise, margin, fix_seams):
    """One quantity's UDIM result from its tiles' results."""
    if denoise and results:
        _denoise_tiles(target, resolution, results, margin)
    fix = _fix_tiles(target, results, margin) if fix_seams and results else None
    report = {}
    for r in results.values():
        for key, value in r.report.items():
            if key in ("degenerate_uv_triangles", "degenerate_triangles", "extrusion", "extrusion_served"):
                report[key] = value  # the same in every tile (the extrusion is measured on the whole mesh)
            elif key == "warnings":
                report[key] = report.get(key, []) + [w for w in value if w not in report.get(key, [])]
            elif key == "parallel":  # each tile chooses; the last tile's choice stands for the bake
                report[key] = value
            elif key == "worker_memory":  # per process, the tile bake of its largest peak
                best = {e["process"]: e for e in report.get(key, [])}
                for e in value:
                    if ((best.get(e["process"]) or {}).get("peak") or 0) <= (e.get("peak") or 0):
                        best[e["process"]] = e
                report[key] = list(best.values())
            elif key != "uv_outside_triangles":
                report[key] = report.get(key, 0) + value
    report["uv_outside_udim_triangles"] = coverage.outside
    report["tiles"] = list(todo)
    report.update(seam_report(fix))
    parts = list(results.values())
    if not any(r.mask.any() for r in parts):
        reason = empty_reason(report.get("degenerate_triangles", 0), report.get("degenerate_uv_triangles", 0), 0,
                              coverage.outside)
        raise MeshError(f"mesh {target.name!r}: the bake covered no texel of the UDIM tiles "
                        f"{', '.join(map(str, todo))} ({reason}): nothing was written" if parts
                        else f"mesh {target.name!r}: the bake covered no texel (no UDIM tile): nothing was written")

    def stack(name):
        return np.stack([getattr(r, name) for r in parts])

    return BakeResult(ao=stack("ao"), mask=stack("mask"), stderr=stack("stderr"), samples=stack("samples"),
                      rays=sum(r.rays for r in parts), seconds=sum(r.seconds for r in parts),
                      trace_seconds=sum(r.trace_seconds for r in parts), threads=parts[0].threads,
                      trace_cpu_seconds=sum(r.trace_cpu_seconds for r in parts), metadata=dict(parts[0].metadata),
                      report=BakeReport(**report), tiles=results,
                      bent=stack("bent") if parts[0].bent is not None else None,
                      raw_ao=stack("raw_ao") if parts[0].raw_ao is not None else None,
                      raw_stderr=stack("raw_stderr") if parts[0].raw_stderr is not None else None)


__all__ = ["run", "finish", "Texels", "Corners", "self_test", "REMOTE", "pool"]
