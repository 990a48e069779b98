"""The bake pipeline: from a target mesh and its occluders to an ambient occlusion texture.

For a surface point x with shading normal n, AO(x) = (1/pi) * integral over the hemisphere of
V(x, w) cos(theta) dw, V = 1 where the ray from x along w meets nothing within max_distance. A texel's
value is the mean AO over the part of the surface its square covers.

One bake, per tile of texels (tiles go to worker threads; nothing a texel draws depends on which):

    core.geometry.raster      which pieces of which triangles each texel covers
    core.geometry.surface     sample units: affine maps from the unit square / triangle to the surface, normals
    core.engine.patterns    each texel's 4D sample points (direction, position in the texel)
    core.engine.kernel      rays of a chunk of units in one matrix product; Embree through core.tracing.tracer
    core.engine.estimators  per-texel sums, standard errors, and the rounds adaptive sampling takes
    core.geometry.margin      extends the islands into the margin

Estimators: cosine-weighted directions (p = cos/pi) give the term V(w), variance AO(1 - AO), exactly
0 on open surfaces; uniform directions (p = 1/(2 pi)) give 2 cos(theta) V(w). Both estimate the same
AO. Rays leave from the surface point pushed off along the geometric normal, on the side the shading
normal faces; a direction from the shading hemisphere that points below the geometric surface
(possible where interpolated normals bend away from the face) counts as occluded without being
traced: that is what a ray leaving the true surface would meet first, the surface itself, and it
keeps AO continuous across smooth-shaded terminators.
"""

import dataclasses
import functools
import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from ..post import bent as bent_mod
from .._version import __version__
from ..base.errors import BakeCancelled, BakeMemoryError, MeshError, SettingsError
from ..engine.estimators import ErrorModel, interval_half_width
from ..engine.kernel import Kernel
from ..geometry.margin import dilate
from ..geometry.mesh import Mesh, mesh_list
from ..engine.patterns import TexelPattern
from ..geometry import raster as R
from ..geometry.raster import bin_triangles, prepare
from ..engine.scheduler import is_cancelled
from ..engine.settings import (DISTRIBUTIONS, MAX_RESOLUTION, MAX_SAMPLES, SAMPLE_PIECE, BakeSettings, auto_tile_shape,
                       available_memory, estimate_memory)
from ..geometry.surface import SurfaceTable
from ..engine.tilebaker import SurfaceStart, TileBaker
from ..tracing.tracer import Tracer
from ..tracing import ground as _ground
from ..highpoly import match as _highpoly
from ..execution import workers as _workers


@dataclass
class BakeResult:
    """What a bake returns. Arrays are (H, W), row 0 is v = 0 (Blender's pixel order).

    ao : float32 in [0, 1]; covered texels hold their estimate, margin texels the dilated value,
        the rest 0.
    mask : bool, texels a UV triangle covers.
    stderr : float32, each covered texel's standard error (0 elsewhere): the error its estimate
        makes, with replicates (see :func:`bake_ao`); an upper bound for the quasi-Monte Carlo
        sources without (``metadata['error_estimate']`` says which).
    samples : int32, samples taken per covered texel (0 elsewhere).
    rays : rays handed to Embree (a direction below the geometric surface goes with length 0 and
        counts as occluded).
    seconds : wall time of the bake; trace_seconds : time inside embreex, summed over threads;
    trace_cpu_seconds : the same in thread CPU time (steadier on a shared machine).
    metadata : settings and version, for image files.
    miss : selected to active only (else None): bool, texels a UV triangle covers where no sample
        point's matching ray found the high-poly surface; they are not in ``mask`` (the margin
        fills them). See :mod:`core.highpoly.match`.
    missed : selected to active only: sample points whose matching ray missed (each point carries a
        block of samples, ``report['directions_per_point']``; none of them is traced).
    report : counts of what the input held: degenerate UV triangles skipped, triangles of zero area
        in space skipped (they have no surface), triangles with UVs
        outside [0, 1] (only their part inside the image is baked), texels covered by more than one
        UV island (averaged over all surfaces covering them), covered texels. ``worker_memory``:
        one dict per process that held the bake (this one, ``process`` 'parent', then each worker,
        'worker N'): ``rss`` and ``peak`` resident bytes (VmRSS and VmHWM; a worker's peak is its
        bake's own, from ``start``, its size before it built the scene; ``ready``, after), and
        ``held``, the bytes of the arrays its bake holds (meshes, tables; Embree's scenes are not
        arrays and are in ``ready - start``, unless the worker kept them from its last bake):
        :func:`core.execution.workers.memory_entry`; a worker's also ``tiles`` (how many it baked) and
        ``scene_reused`` (whether it traced in the Embree scenes it kept from its last bake of the
        same meshes).
    bent : None, or with ``bent_normals``, (H, W, 3) float32 unit bent normals in the bake's
        ``bent_space`` (covered and margin texels; zero elsewhere), see :mod:`core.post.bent`.

    raw_ao, raw_stderr : with ``denoise``, the estimate and its error before the filter (``ao`` and
        ``stderr`` are then the denoised map and its error); None otherwise.

    The same type for every target. Mesh corners (:func:`core.bake_vertex_ao`): the arrays are per
    corner, (C,) (``bent`` (C, 3)), ``mask`` all true, and ``unit`` (C,) int64 names the sample point
    whose estimate each corner has (corners of one vertex and one normal share one). UDIM tiles
    (:func:`core.bake_udim`): ``tiles`` maps each tile number to its own BakeResult, the arrays are the
    tiles' stacked, (N, H, W) in the order of ``tiles``, and the times and rays are their sums.
    """

    ao: np.ndarray
    mask: np.ndarray
    stderr: np.ndarray
    samples: np.ndarray
    rays: int
    seconds: float
    trace_seconds: float
    threads: int
    trace_cpu_seconds: float = 0.0
    metadata: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)
    bent: np.ndarray = None
    miss: np.ndarray = None
    missed: int = 0
    unit: np.ndarray = None
    tiles: dict = None
    raw_ao: np.ndarray = None
    raw_stderr: np.ndarray = None

    @property
    def rays_per_second(self):
        return self.rays / self.seconds if self.seconds > 0 else float("nan")


#: Occluders farther than this many target sizes from the target are refused: float32 rays cannot
#: hold both (and so far away they cannot occlude it measurably).
MAX_SCENE_SPAN = 1e15


def _frame(target):
    """(centre, unit) of the frame :func:`_normalized_scene` moves a bake into."""
    lo, hi = target.positions.min(axis=0), target.positions.max(axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        unit = float(np.max(hi - lo))
    if not math.isfinite(unit):
        raise MeshError(f"mesh {target.name!r} spans more than the largest float ({unit}); scale it down")
    if unit <= 0 or unit < np.finfo(np.float64).tiny * 1e3:
        unit = 1.0  # a point: every triangle is degenerate and skipped anyway
    return (lo + hi) / 2.0, unit


def _normalized_scene(target, occluders):
    """The target and its occluders in a frame centred on the target and scaled to its size.

    AO does not depend on the unit (max_distance scales with it), but float32 rays do: a scene
    modelled in metres at 1e13 or at 1e-14 loses the offsets that keep rays off their own surface.
    In this frame the target spans about 1 around the origin whatever units the input used.
    Occluders that are the target again (the same object or the same surface) are dropped: a
    surface coinciding with the target would hide every ray.

    Returns (target, occluders, unit): the world length of one unit of the new frame.
    """
    kept = []
    for o in occluders:
        if o is target or target.same_geometry(o) or any(o is k or k.same_geometry(o) for k in kept):
            continue
        kept.append(o)
    centre, unit = _frame(target)
    scene = []
    for o in kept:
        m = o.transformed(centre, unit)
        far = float(np.abs(m.positions).max())
        if not far < MAX_SCENE_SPAN:
            raise MeshError(
                f"occluder {o.name!r} reaches {far:.3g} times the size of {target.name!r} away from it; "
                "ray tracing in single precision cannot hold both: leave it out of the occluders"
            )
        scene.append(m)
    return target.transformed(centre, unit), scene, unit




def empty_reason(no_area=0, no_uv_area=0, outside=0, outside_udim=0):
    """Why a bake covered nothing, from the counts its report gives (one wording for the core and the
    add-on)."""
    reasons = [f"{n} {text}" for n, text in (
        (no_area, "of its triangles have no area"),
        (no_uv_area, "of its UV triangles have no area in the UV map"),
        (outside, "of its UV triangles lie outside the image's UV square [0, 1]"),
        (outside_udim, "of its UV triangles lie outside the UDIM tiles 1001 to 2000")) if n]
    return "; ".join(reasons) or "its UV triangles are too small to cover a texel centre at this resolution"


class Prologue:
    """What every bake does before its first ray, whatever its target (texels, UDIM tiles, mesh
    corners, selected to active): check the meshes and the target-specific settings, move the scene
    into the target's frame (:func:`_normalized_scene`), check memory and cancellation, and build the
    occlusion tracer. Raises the errors :func:`bake_ao` lists, before any heavy work.

    Attributes: target, occluders (normalised), unit (world length of one unit of the frame), s2a (the
    normalised :class:`core.highpoly.match.SelectedToActive` or None), bent_space (checked).
    """

    def __init__(self, target, occluders, settings, cancel, *, uvs=True, highpoly=None, extrusion=None,
                 max_ray_distance=0.0, cage=None, bent_normals=False, bent_space=None):
        if not isinstance(target, Mesh):
            raise SettingsError(f"the target must be a core.Mesh, got {type(target).__name__}")
        if uvs and target.uvs is None:
            raise MeshError(f"mesh {target.name!r} has no UVs: the baker needs a UV map to know where each texel lies")
        occluders = mesh_list(occluders)
        self.cancel = cancel
        self.s2a = None
        if bent_normals and settings.quantity != "ao":
            raise SettingsError(f"bent normals come with quantity='ao' only, not {settings.quantity!r}: bake them "
                                "in an AO bake")
        if highpoly is not None:  # selected to active: checked here, before any work
            if bent_normals:
                raise SettingsError("bent normals are not baked with selected to active (highpoly): bake them "
                                    "from the high-poly object itself, or bake AO only")
            s2a = _highpoly.SelectedToActive.check(target, highpoly, extrusion, max_ray_distance, cage)
            occluders = s2a.occluders_of(occluders)
            self.s2a = s2a.normalized(*_frame(target), MAX_SCENE_SPAN)
        self.bent_space = bent_mod.check_space(bent_space, target) if bent_normals else None
        self.name = target.name
        self.frame = _frame(target)
        self.target, self.occluders, self.unit = _normalized_scene(target, occluders)
        if self.s2a is not None:
            self.s2a.resolve(self.target)  # an automatic extrusion, measured from the meshes

    @property
    def triangle_count(self):
        """Triangles of every mesh the bake holds (target, occluders, high-poly meshes and cage)."""
        return (self.target.triangle_count + sum(o.triangle_count for o in self.occluders)
                + (self.s2a.triangle_count if self.s2a else 0))

    @property
    def triangle_counts(self):
        """(target, occluders, high-poly meshes and cage) triangles: :mod:`core.execution.cost` prices them apart."""
        return (self.target.triangle_count, sum(o.triangle_count for o in self.occluders),
                self.s2a.triangle_count if self.s2a else 0)

    def check_memory(self, s):
        """Refuse a texel bake that would not fit in the memory available (BakeMemoryError)."""
        tri_total = self.triangle_count
        need = estimate_memory(s.width, s.height, tri_total, s.threads, s.chunk_rays, s.samples, s.source,
                               s.replicates, s.tile_shape[0] * s.tile_shape[1])
        avail = available_memory()
        if avail is not None and need > avail:
            raise BakeMemoryError(f"a {s.width} x {s.height} bake of {tri_total} triangles needs about "
                                  f"{need / 2**30:.2f} GiB, but only {avail / 2**30:.2f} GiB is available; "
                                  "lower the resolution")

    def check_cancel(self):
        if is_cancelled(self.cancel):
            raise BakeCancelled("the bake was cancelled before it started")

    def ground_height(self, s):
        """(world height, height in the bake's frame) of the ground plane (:mod:`core.tracing.ground`), or
        (None, None). 'auto': the lowest point of the surface whose AO is baked (the high-poly
        meshes' with selected to active, else the target's)."""
        if s.ground is None:
            return None, None
        centre, unit = self.frame
        if s.ground == "auto":
            baked = self.s2a.highs if self.s2a is not None else [self.target]
            low = min(float(m.positions[:, 2].min()) for m in baked)
            return float(centre[2]) + low * unit, low
        return s.ground, _ground.frame_height(s.ground, centre[2], unit)

    def tracer(self, s):
        """The occlusion tracer of the target and its occluders (and the ground), in the bake's frame;
        for a thickness map, of the target alone (:mod:`core.engine.thickness`). A second quantity of the
        same bake whose rays see the same meshes (a thickness map beside AO without occluders) shares
        the first one's Embree scenes (:meth:`core.tracing.tracer.Tracer.sharing`)."""
        meshes = [self.target] if s.quantity == "thickness" else [self.target] + self.occluders
        ground = None if s.quantity == "thickness" else self.ground_height(s)[1]
        last = getattr(self, "_tracer", None)
        if last is not None and len(last[0]) == len(meshes) and all(a is b for a, b in zip(last[0], meshes)):
            tracer = last[1].sharing(s.ignore_backfaces, s.falloff, s.max_distance / self.unit, ground=ground)
        else:
            tracer = Tracer(meshes, s.ignore_backfaces, s.falloff, s.max_distance / self.unit, ground=ground)
            self._tracer = (meshes, tracer)
        tracer.constant_answer = s.constant_answer
        return tracer

    def nothing_covered(self, s, uvtris):
        """The error of a texel bake that covered no texel, saying why (the counts of the UV triangles)."""
        return MeshError(f"mesh {self.name!r}: the bake covered no texel of the {s.width} x {s.height} image "
                         f"({empty_reason(uvtris.degenerate_space, uvtris.degenerate, uvtris.outside)}): "
                         "nothing was written")


@dataclass
class TileOut:
    """One tile's values, as the baker hands them to whoever assembles the images (this process or,
    from a worker process, plain arrays). ``texels`` flat ids; ``lost`` the texels none of whose
    sample points found a surface (selected to active: uncovered); ``sums``, ``tri``, ``weights``:
    the bent-normal sums and where each texel's normal is interpolated (None without bent normals)."""

    key: tuple
    texels: np.ndarray
    ao: np.ndarray
    stderr: np.ndarray
    samples: np.ndarray
    lost: np.ndarray
    overlapping: int = 0
    sums: np.ndarray = None
    tri: np.ndarray = None
    weights: np.ndarray = None
    bent: np.ndarray = None
    maps: dict = None  # a bake of several quantities: the tile of each other quantity, as plain data
    guide: tuple = None  # the denoiser's guide of the texels (core.post.denoise.tile_guide); None without denoise


class TexelBake:
    """A texel bake set up after its prologue: the layout (UV triangles, surface table, tiles), and after
    :meth:`trace_setup` the tracing (scene, pattern, kernel, start stage, tile baker). The same object
    bakes tiles in this process and in a worker process (:mod:`core.execution.workers`), which builds it again
    from the same input and settings: the same tiles, the same bits."""

    def __init__(self, pro, s, bent_normals=False, guide=False):
        self.pro, self.bent_normals, self.guide = pro, bool(bent_normals), bool(guide)
        self.uvtris = prepare(pro.target, s.width, s.height)
        self.s = s.fit_tiles(R.uv_centres(self.uvtris))  # automatic tiles of dense meshes: fewer triangles each
        self.bins = bin_triangles(self.uvtris, s.width, s.height, self.s.tile_shape)
        # Planned work: a tile's texels are unknown before rasterising, so count each tile's bounding
        # rectangle's texels times samples, and credit what it did not cover as it is rasterised.
        self.planned = sum(self.rect(key)[2] for key in self.bins) * self.s.samples

    def lane(self, s, bent_normals=False):
        """The bake of another quantity over this one's layout (UV triangles, tiles, surface table:
        taken once), with settings ``s`` (:func:`core.targets.maps.lane_settings` of this bake's)."""
        out = object.__new__(TexelBake)
        out.pro, out.uvtris, out.bins, out.planned = self.pro, self.uvtris, self.bins, self.planned
        out.s, out.bent_normals, out.root, out.guide = s, bool(bent_normals), self, False
        return out

    @functools.cached_property
    def table(self):
        """The target's surface table, built where tiles are baked (a parent whose workers bake them
        never needs it: hundreds of bytes a triangle it does not hold)."""
        root = self.__dict__.get("root")  # another quantity's bake over the same layout (:meth:`lane`)
        return root.table if root is not None else SurfaceTable.build(self.pro.target, self.uvtris)

    def rect(self, key):
        """Rows, columns and texel count of tile ``key``."""
        x0, y0, x1, y1 = self.s.tile_bounds(key)
        return slice(y0, y1), slice(x0, x1), (x1 - x0) * (y1 - y0)

    def trace_setup(self, shared, cancel, on_rays=None, pattern=None):
        """The tracing: scene, sample pattern (``pattern``: another quantity's of the same bake, the
        same points), kernel, start stage and tile baker."""
        pro, s = self.pro, self.s
        stage = None if pro.s2a is None else _highpoly.HighPolyStage(
            pro.s2a, pro.target, pro.occluders, self.uvtris, self.table, self.bins, s, pro.unit,
            lambda: is_cancelled(cancel), ground=pro.ground_height(s)[1],
            occluding=s.quantity == "ao")
        tracer = pro.tracer(s) if stage is None else stage.scene.tracer
        tracer.constant_answer = s.constant_answer
        if pattern is None:
            pattern = TexelPattern(s.source, s.seed, s.replicate_samples, pool_points=s.pool_points())
        self.pattern = pattern
        kernel = Kernel(pattern, tracer, s.distribution, on_rays=on_rays)
        # Located samples take one matrix form for the whole bake (see core.engine.kernel.TileContext).
        self.start = (SurfaceStart(self.table, tracer, located_curved=bool(np.any(self.table.smooth[self.uvtris.valid])))
                      if stage is None else stage.start())
        self.baker = TileBaker(self.uvtris, self.table, kernel, tracer, pattern, s, shared, self.start,
                               bent=self.bent_normals)
        self.errors = ErrorModel(s, grouped=self.start.grouped)
        self.shared = shared

    def layout(self, key):
        """Tile ``key``'s fragments and sample units (:meth:`core.engine.tilebaker.TileBaker.layout`)."""
        return self.baker.layout(key, self.bins[key])

    def tile(self, key, directions=True, layout=None):
        """Bake tile ``key``: its :class:`TileOut`. ``directions``: turn bent-normal sums into unit
        directions here (False: leave the sums, for the process that assembles the images);
        ``layout``: the tile's :meth:`layout`, taken already for another quantity."""
        s, w = self.s, self.s.width
        frag, est, sums = self.baker.bake(key, self.bins[key], layout)
        self.shared.advance((self.rect(key)[2] - len(frag.texels)) * s.samples)
        t = frag.texels
        if not len(t):
            e = np.zeros(0, np.float32)
            return TileOut(key, t, e, e, np.zeros(0, np.int32), np.zeros(0, bool))
        rows, cols = t // w, t % w
        lost = self.start.lost(est)
        se = self.errors.stderr(est, cols, rows).astype(np.float32)
        se[lost] = 0.0
        out = TileOut(key, t, np.clip(est.mean, 0.0, 1.0).astype(np.float32), se, est.n.astype(np.int32), lost,
                      int((frag.coverage > 1.0 + R.OVERLAP_REPORT_AREA).sum()))
        if self.guide:  # what the denoiser needs of these texels, from their fragments
            from ..post.denoise import tile_guide

            out.guide = tile_guide(frag, self.uvtris, self.pro.target, w)
        if sums is not None:
            out.sums = sums
            out.tri = bent_mod.primary_pieces(frag, w)
            out.weights = bent_mod.barycentric(self.table.corners_xy, out.tri, cols + 0.5, rows + 0.5)
            if directions:
                self.directions(out)
        return out

    def directions(self, out):
        """The tile's bent normals from its sums, in the bake's space (:func:`core.post.bent.texel_directions`)."""
        out.bent = bent_mod.texel_directions(out.sums, out.tri, out.weights, self.pro.target.normals,
                                             self.pro.bent_space)
        out.sums = out.tri = out.weights = None


def bake_ao(target, occluders=(), resolution=(1024, 1024), samples=256, *, min_samples=16, target_error=0.0,
            max_distance=float("inf"), distribution="cosine", source="sobol", margin=16, seed=0, threads=None,
            ignore_backfaces=False, falloff=0.0, replicates=2, progress=None, cancel=None, on_tile=None,
            tile_size=None, chunk_rays=1 << 16, on_rays=None, bent_normals=False, bent_space=None, highpoly=None,
            extrusion=None, max_ray_distance=0.0, cage=None, empty_ok=False, workers=1, ground=None, quantity="ao",
            constant_answer=False, denoise=False):
    """Bake ambient occlusion of ``target`` into a (H, W) texture over its UVs.

    With ``highpoly``, bake the AO of the high-poly meshes into the target's UVs instead (Blender's
    "Selected to Active"): each sample point of the target is moved to the high-poly surface by
    Cycles' rules and AO is evaluated there (:mod:`core.highpoly.match` says exactly how).

    Parameters
    ----------
    target : Mesh with UVs. It always occludes itself.
    occluders : Meshes (UVs not needed) that also block rays, in the same world space.
    resolution : int or (width, height) in texels.
    samples : the most samples per texel (every texel takes exactly this many when adaptive is off).
    min_samples : with adaptive sampling, what every texel takes before it may stop.
    target_error : adaptive sampling when > 0: a texel stops once the half-width of its 95%
        confidence interval is at most this (in AO units: 0.01 means its AO is known to +-0.01, 95%
        of the time), after ``min_samples`` and rounds that grow its count to what its interval
        predicts (see :class:`core.engine.adaptive.SamplingPlan`). With replicates (the default) the
        interval comes from the pooled error estimate of :mod:`core.engine.estimators`: texels whose whole
        neighbourhood agrees (open, or fully occluded) stop at ``min_samples``, texels whose samples
        agree beside varying ones go on. Without (``replicates=1``) it is Agresti and Coull's
        interval for independent samples, which never stops an open texel before about
        2.7 / target_error samples. 0 turns adaptive sampling off.
    max_distance : occluders farther than this along a ray do not count (world units).
    distribution : 'cosine' (importance sampling, default) or 'uniform' (weight 2 cos theta).
    source : 'sobol' (Owen-scrambled, default), 'stratified', 'independent' or 'halton'.
    margin : texels to extend each UV island by, from the nearest covered texel.
    seed : non-negative integer; the same seed gives a bit-identical result for any thread count.
    threads : worker threads (None: every core this process may use).
    ignore_backfaces : hits on the back of a triangle (its winding's normal facing along the ray)
        do not occlude; the ray continues past them.
    falloff : 0 for plain AO; p > 0 weighs a hit at distance t by (1 - t / max_distance)^p, so
        distant occluders darken less (needs a finite max_distance).
    replicates : how many independent randomisations a texel's samples are split into (1 to 16,
        at most ``samples``). With 2 (the default) or more, ``stderr`` is the error the texel's
        estimate really makes, for every sample source (the spread between replicates, pooled over
        neighbouring texels: :mod:`core.engine.estimators`), at a cost in noise: two sets of N/2 points
        are a worse set than one of N (measured at equal rays: Sobol' 1.16-1.20 times the RMSE,
        Halton 1.14-1.19, stratified 1.29-1.31, independent 1.0). With 1 the noise is lowest and
        ``stderr`` is the independent-sample formula: exact for independent samples, 2 to 3 times
        too large for the quasi-Monte Carlo sources.
    progress : called as progress(fraction) from worker threads, one call at a time, after every
        chunk of rays and every finished tile (not on a clock: the calls a bake makes do not depend
        on the machine's speed), and once with 1.0 at the end. Throttle any drawing in the callback.
    cancel : a threading.Event or a callable returning True to stop; checked between chunks of
        rays. A cancelled bake raises BakeCancelled and returns nothing.
    on_tile : called as on_tile(rows, cols, ao_block) from worker threads when a tile of texels is
        final (before margin dilation); ``rows``, ``cols`` are slices of the (H, W) result.
    tile_size, chunk_rays : the unit of work a thread takes, in texels: a side (square tiles) or
        (columns, rows), rounded up to multiples of 16 (None: :func:`core.engine.settings.auto_tile_shape`
        of the resolution, threads and samples), and rays traced per call into Embree (bounds memory;
        a thread with no tile left traces chunks of the tiles still running). Neither changes the
        result: texels draw their samples by (texel, index) alone, and each tile adds its chunks'
        sums in the same order whichever thread traced them.
    on_rays : called as on_rays(batch) from worker threads after every call into Embree, with a
        :class:`core.tracing.tracer.RayBatch` (origins, directions, lengths, Embree's answer, the texel and
        sample index of every ray, the call's time). Its arrays are valid during the call only.
    bent_normals : also estimate each texel's bent normal from the same rays (no extra ray):
        ``BakeResult.bent``. See :mod:`core.post.bent`.
    bent_space : the space of the bent normals: None (world space), a (3, 3) matrix (M b,
        normalised; Blender's object space is the inverse of the object's matrix) or a
        :class:`core.post.bent.TangentFrames` (tangent space, Blender's normal-map convention).
    highpoly : None, or a Mesh or a list of Meshes (corner normals used, UVs not needed) whose AO is
        baked into the target's UVs. The high-poly meshes occlude, as do the ``occluders``; the target
        and the cage never do (left out of the occluders if they are among them).
    extrusion : with ``highpoly``, the distance (world units, >= 0) the matching rays start out from the
        target's surface along its interpolated normal, pointing back along it (Cycles' Extrusion);
        None or 'auto' (the default): measured from the meshes, the smallest distance that lets the
        matching rays start outside the high-poly where it bulges out of the target without
        starting beyond another part of it in concave places (:func:`core.highpoly.match.auto_extrusion`).
        ``report['extrusion']`` and ``metadata['extrusion']`` give the distance used (world units),
        ``metadata['extrusion_auto']`` whether it was measured. Whatever the extrusion, more than 1%
        of the matching rays meeting the high-poly from behind (they start inside it: the bright or
        dark blobs of a too small extrusion) puts a warning naming the object in
        ``report['warnings']``.
    max_ray_distance : with ``highpoly``, the longest matching ray (world units, measured from where it
        starts), 0 for no limit.
    cage : with ``highpoly``, None or a Mesh of the target's topology (same vertex count and triangles,
        vertices moved): the matching rays go from the cage's points towards the target's (the
        extrusion is then not used).
    empty_ok : a bake whose UVs cover no texel returns an all-zero result instead of raising
        MeshError (a UDIM tile listed but not touched, which Cycles clears).
    ground : None (no ground), 'auto' or a height (world units): an analytic infinite ground plane
        z = height (world up is +z, Blender's) that occludes as a huge plane mesh would, without
        triangles; 'auto' puts it at the lowest point of the baked surface (the target's; with
        ``highpoly``, the high-poly meshes'). Faces lying on it are in contact (occluded). With a
        falloff, a ray meeting it is weighed by its distance. See :mod:`core.tracing.ground`. Recorded in
        ``metadata['ground']`` ('none', 'auto' or 'height') and ``metadata['ground_height']``.
    quantity : 'ao' (default) or 'thickness': the thickness map, AO with the normal inverted (rays
        into the mesh, in the hemisphere about the inverted shading normal, up to ``max_distance``),
        occluded by the target alone (with ``highpoly``, the high-poly meshes alone): black = thin,
        white = thick, as Substance's thickness baker. ``ao`` then holds it, with the same estimator,
        error map and adaptive sampling. The occluders play no part; ``ground``, ``ignore_backfaces``
        and ``bent_normals`` are refused with it. See :mod:`core.engine.thickness` (definition, open
        meshes, smooth-shading terminators). Recorded in ``metadata['quantity']``.
    workers : 1 (this process, ``threads`` threads), N worker processes (``threads`` threads each,
        None: one), 'auto' (from the cores and the memory: :func:`core.execution.workers.auto_workers`), or a
        ``distributed.Client``: the tiles as tasks on its Dask cluster (a lost worker's tiles are
        redone). The same bits for any workers x threads x tiling on one machine, and across
        machines whose CPUs take the same instruction paths (:mod:`core.execution.workers`).
    denoise : filter the estimate over the surface (:mod:`core.post.denoise`: neighbours across UV seams,
        never across islands that only touch in the image, each texel weighed by its error):
        ``ao`` and ``stderr`` are then the denoised map and its error (its propagated variance and the
        filter's estimated bias), ``raw_ao`` and ``raw_stderr`` the estimate before it. Needs
        ``replicates`` >= 2 (an honest error per texel). Adaptive sampling stops on the raw error.
    constant_answer : benchmarks only: no occlusion query reaches Embree (every ray unoccluded), so
        that the bake's own work is measured alone, in every worker too. The result is not AO.

    Returns
    -------
    BakeResult

    Raises
    ------
    MeshError, MeshTypeError, SettingsError, BakeMemoryError (before any heavy work), BakeCancelled.
    With ``highpoly``, also MeshError when no matching ray finds the high-poly surface (it says what
    to change), before any AO ray is traced.
    """
    return _bake_images(target, occluders, resolution, samples, (quantity,), **_options(locals()))[quantity]


#: bake_ao's keyword arguments that _bake_images takes as they are.
_OPTIONS = ("min_samples", "target_error", "max_distance", "distribution", "source", "margin", "seed", "threads",
            "ignore_backfaces", "falloff", "replicates", "progress", "cancel", "on_tile", "tile_size", "chunk_rays",
            "on_rays", "bent_normals", "bent_space", "highpoly", "extrusion", "max_ray_distance", "cage", "empty_ok",
            "workers", "ground", "constant_answer", "denoise")


def _options(arguments):
    return {k: arguments[k] for k in _OPTIONS}


def bake_maps(target, occluders=(), resolution=(1024, 1024), samples=256, *, quantities=("ao", "thickness"),
              min_samples=16, target_error=0.0, max_distance=float("inf"), distribution="cosine", source="sobol",
              margin=16, seed=0, threads=None, ignore_backfaces=False, falloff=0.0, replicates=2, progress=None,
              cancel=None, on_tile=None, tile_size=None, chunk_rays=1 << 16, on_rays=None, bent_normals=False,
              bent_space=None, highpoly=None, extrusion=None, max_ray_distance=0.0, cage=None, empty_ok=False,
              workers=1, ground=None, constant_answer=False, denoise=False):
    """Bake several quantities of ``target`` (AO and the thickness map) in one pass: one set-up, each
    quantity its own rays (:mod:`core.targets.maps`).

    Parameters
    ----------
    quantities : the quantities to bake, distinct names of 'ao' and 'thickness' (default both).
    ground, ignore_backfaces, bent_normals, bent_space : apply to the AO map only (the thickness map is
        occluded by the object alone, :mod:`core.engine.thickness`); refused without 'ao' in ``quantities``.
    on_tile : called as on_tile(quantity, rows, cols, block), as :func:`bake_ao`'s with the quantity.
    on_rays : sees the rays of every quantity.
    The others are :func:`bake_ao`'s, for every quantity.

    Returns
    -------
    {quantity: BakeResult}, in the order of ``quantities``: each bit for bit the :func:`bake_ao` of
    that quantity with the same settings; ``metadata['quantities']`` names the quantities baked
    together (comma-separated, 'ao,thickness': image files keep it), ``seconds`` is the whole
    bake's wall time, ``rays`` and the Embree seconds the quantity's own.

    Raises
    ------
    What :func:`bake_ao` raises, and SettingsError for ``quantities`` that are not a list of distinct
    quantities.
    """
    from ..targets.maps import check_quantities

    return _bake_images(target, occluders, resolution, samples, check_quantities(quantities), maps=True,
                        **_options(locals()))


def texel_bake(pro, s, quantities, bent_normals=False, guide=False):
    """The bake of ``quantities`` over ``pro`` with settings ``s`` (the base quantity's,
    :func:`core.targets.maps.base_quantity`): a :class:`TexelBake`, or for several quantities a
    :class:`core.targets.maps.MapsBake` of lanes over its layout. The same in this process and in a worker.
    ``guide``: the base quantity's tiles also return the denoiser's guide of their texels."""
    root = TexelBake(pro, s, bent_normals and s.quantity == "ao", guide=guide)
    if tuple(quantities) == (s.quantity,):
        return root
    from ..targets.maps import MapsBake, lane_settings

    return MapsBake({q: root if q == s.quantity else root.lane(lane_settings(root.s, q), bent_normals and q == "ao")
                     for q in quantities})


class _Images:
    """One quantity's images, filled tile by tile (on whichever thread finished a tile)."""

    def __init__(self, bake, w, h, bent, miss, on_tile, guide=None):
        self.bake, self.on_tile, self.guide = bake, on_tile, guide
        self.ao = np.zeros((h, w), np.float32)
        self.se = np.zeros((h, w), np.float32)
        self.count = np.zeros((h, w), np.int32)
        self.mask = np.zeros((h, w), bool)
        self.bent = np.zeros((h, w, 3), np.float32) if bent else None
        self.miss = np.zeros((h, w), bool) if miss else None
        self.overlap = 0
        self.lock = threading.Lock()

    def store(self, out):
        if not len(out.texels):
            return
        t = out.texels
        self.ao.reshape(-1)[t] = out.ao
        self.se.reshape(-1)[t] = out.stderr
        self.count.reshape(-1)[t] = out.samples
        self.mask.reshape(-1)[t] = ~out.lost
        if out.sums is not None:
            self.bake.directions(out)
        if out.bent is not None:
            self.bent.reshape(-1, 3)[t] = out.bent
        if self.miss is not None:
            self.miss.reshape(-1)[t] = out.lost
        if out.guide is not None and self.guide is not None:
            for a, v in zip(self.guide, out.guide):
                a[t] = v
        with self.lock:
            self.overlap += out.overlapping
            if self.on_tile is not None:
                r, c, _ = self.bake.rect(out.key)
                self.on_tile(r, c, self.ao[r, c].copy())


def _bake_images(target, occluders, resolution, samples, quantities, *, maps=False, min_samples=16,
                 target_error=0.0, max_distance=float("inf"), distribution="cosine", source="sobol", margin=16, seed=0,
                 threads=None, ignore_backfaces=False, falloff=0.0, replicates=2, progress=None, cancel=None,
                 on_tile=None, tile_size=None, chunk_rays=1 << 16, on_rays=None, bent_normals=False, bent_space=None,
                 highpoly=None, extrusion=None, max_ray_distance=0.0, cage=None, empty_ok=False, workers=1,
                 ground=None, constant_answer=False, denoise=False):
    """:func:`bake_ao` of every quantity of ``quantities`` over one set-up: {quantity: BakeResult}.
    ``maps``: the results say which quantities were baked together (``metadata['quantities']``)."""
    from ..targets.maps import base_quantity

    t_start = time.perf_counter()
    base = base_quantity(quantities)
    s = BakeSettings.from_arguments(resolution, samples, min_samples, target_error, max_distance, distribution,
                                    source, margin, seed, threads, ignore_backfaces, falloff, tile_size, chunk_rays,
                                    replicates, ground=ground, quantity=base)
    s = dataclasses.replace(s, constant_answer=bool(constant_answer))
    if denoise and s.replicates < 2:
        raise SettingsError("denoise needs replicates >= 2: the filter weighs each texel by its standard error, "
                            "which one replicate only bounds")
    workers = _workers.check_workers(workers)
    target_in, occluders_in, bent_space_in = target, mesh_list(occluders), bent_space
    pro = Prologue(target, occluders_in, s, cancel, uvs=True, highpoly=highpoly, extrusion=extrusion,
                   max_ray_distance=max_ray_distance, cage=cage, bent_normals=bent_normals, bent_space=bent_space)
    s2a = pro.s2a
    w, h = s.width, s.height
    processes, per_worker = _workers.processes_of(workers, threads, s, pro.triangle_counts)
    if not _workers.in_process(processes) and tile_size is None:
        # Tiles for every thread of every worker, two each at least (they are dealt as workers free up).
        total = _workers.worker_count(processes) * per_worker
        tw, th = auto_tile_shape(w, h, 2 * total, s.samples)
        s = dataclasses.replace(s, tile_size=tw, tile_height=th, threads=min(total, _workers.cpu_count()))
    pro.check_memory(s)
    pro.check_cancel()

    # The denoiser's guide per texel (triangle, surface point, normal), filled in by the base
    # quantity's tiles from their fragments (selected to active rasterises without locating: the
    # denoiser then finds the texels' triangles itself).
    guide = ((np.full(h * w, -1, np.int32), np.zeros((h * w, 3), np.float32), np.zeros((h * w, 3), np.float32))
             if denoise and s2a is None else None)
    bake = texel_bake(pro, s, quantities, bent_normals, guide=guide is not None)
    lanes = bake.lanes if len(quantities) > 1 else {base: bake}
    s, uvtris, keys = bake.s, bake.uvtris, sorted(bake.bins)
    images = {q: _Images(b, w, h, b.bent_normals, s2a is not None,
                         None if on_tile is None else on_tile if not maps else functools.partial(on_tile, q),
                         guide if q == base else None)
              for q, b in lanes.items()}
    root = lanes[base]

    if len(quantities) > 1:
        def store(out):
            for q, o in bake.outs(out).items():
                images[q].store(o)
    else:
        store = images[base].store

    def job():
        """What a worker rebuilds this bake from: the input as given, plain data (the extrusion measured here)."""
        return dict(target=_workers.mesh_data(target_in), occluders=[_workers.mesh_data(o) for o in occluders_in],
                    settings=dataclasses.asdict(root.s), bent_normals=bent_normals, bent_space=bent_space_in,
                    highpoly=None if highpoly is None else [_workers.mesh_data(m) for m in _highpoly._as_list(highpoly)],
                    extrusion=extrusion if s2a is None else s2a.world.extrusion,
                    max_ray_distance=max_ray_distance, cage=None if cage is None else _workers.mesh_data(cage),
                    quantities=list(quantities), guide=guide is not None)

    rays, trace_s, trace_cpu, counters, fallback = _workers.bake_tiles(bake, keys, processes, per_worker, job, store,
                                                                       progress, cancel, on_rays)
    if len(quantities) == 1:
        counters = {base: dict(counters, rays=rays, trace_seconds=trace_s, trace_cpu_seconds=trace_cpu)}
    else:  # the processes' memory, once for the whole bake: each map's report has it
        memory = counters.pop("worker_memory", [])
        counters = {q: dict(counters[q], worker_memory=memory) for q in quantities}
    extras = {}
    for q in quantities:
        if s2a is not None:
            extras[q] = _highpoly.finish_report(counters[q], images[q].miss, images[q].mask, s2a)
        elif not images[q].mask.any() and not empty_ok:
            raise pro.nothing_covered(s, uvtris)
    return {q: _finish(images[q], lanes[q].s, pro, s2a, extras.get(q), counters[q], fallback, denoise, t_start,
                       quantities if maps else None, uvtris, guide)
            for q in quantities}


def _finish(img, s, pro, s2a, extra, counters, fallback, denoise, t_start, quantities, uvtris, guide=None):
    """One quantity's BakeResult from its filled images: denoise, margin, bent normals, metadata, report."""
    ao, se, mask, bent = img.ao, img.se, img.mask, img.bent
    w, h = s.width, s.height
    raw_ao = raw_se = None
    if denoise:
        from ..post import denoise as _denoise

        raw_ao, raw_se = ao.copy(), se.copy()
        if s.margin > 0:
            dilate(raw_ao, mask, s.margin, threads=s.threads, out=raw_ao)
        guide = _denoise.surface_guide(pro.target, (w, h), texels=guide, tris=uvtris)
        ao, se, info = _denoise.denoise(ao, se, mask, guide, threads=s.threads)
    if s.margin > 0:
        dilate(ao, mask, s.margin, threads=s.threads, out=ao)
    if bent is not None:
        bent, _ = bent_mod.dilate_directions(bent, mask, s.margin, s.threads)
    seconds = time.perf_counter() - t_start
    rays = counters["rays"]
    metadata = dict(s.metadata(s.max_distance), version=__version__, rays=rays)
    if quantities is not None:
        metadata["quantities"] = ",".join(quantities)
    if denoise:
        metadata["denoise"] = True
    if s.ground is not None:
        metadata["ground_height"] = pro.ground_height(s)[0]
    report = {"covered_texels": int(mask.sum()), "degenerate_uv_triangles": uvtris.degenerate,
              "degenerate_triangles": uvtris.degenerate_space,
              "uv_outside_triangles": uvtris.outside, "overlapping_texels": img.overlap}
    report["worker_memory"] = counters.get("worker_memory", [])
    if s2a is not None:
        metadata.update(s2a.metadata())
        extra = dict(extra)
        warnings = extra.pop("warnings")
        report.update(extra)
        report.setdefault("warnings", []).extend(warnings)  # beside any other warning of the bake
    if fallback is not None:
        report.setdefault("warnings", []).append(
            f"baked on {s.threads} threads of this process, not in worker processes: {fallback}")
    return BakeResult(ao=ao, mask=mask, stderr=se, samples=img.count, rays=rays, seconds=seconds,
                      trace_seconds=counters["trace_seconds"], threads=s.threads, metadata=metadata, report=report,
                      trace_cpu_seconds=counters["trace_cpu_seconds"], bent=bent, miss=img.miss,
                      missed=counters["missed"] if s2a is not None else 0, raw_ao=raw_ao, raw_stderr=raw_se)


__all__ = ["bake_ao", "bake_maps", "BakeResult", "DISTRIBUTIONS", "MAX_SAMPLES", "MAX_RESOLUTION", "SAMPLE_PIECE",
           "estimate_memory", "available_memory", "interval_half_width", "auto_tile_shape"]
