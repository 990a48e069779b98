"""The public calls: a bake's meshes, its options (checked into one request) and its callbacks.

:func:`bake` takes a :class:`core.base.request.BakeRequest` and bakes any kind (an image, UDIM tiles,
face corners; one quantity or several); the others take the options as keywords, as they always
have (``bake_ao(target, occluders, resolution=..., samples=..., **options)``), make the request
(:meth:`core.base.request.BakeRequest.from_options`: an unknown keyword is a TypeError that names the
closest option) and run the one pipeline (:func:`core.pipeline.run.run`).
"""

from ..base.request import BakeRequest
from .result import BakeResult
from .run import run

#: What :func:`bake_maps` and the other calls of several quantities bake unless told otherwise.
DEFAULT_QUANTITIES = ("ao", "thickness")


def bake(target, occluders=(), request=None, *, highpoly=None, cage=None, bent_space=None, corners=None,
         progress=None, cancel=None, on_tile=None, on_rays=None):
    """Bake ``request`` (a :class:`core.base.request.BakeRequest`; None: its defaults) of ``target``:
    {quantity: BakeResult}, one per quantity of ``request.all_quantities``.

    ``request.kind`` says what is baked: 'image' (as :func:`bake_ao`, or :func:`bake_maps` with
    ``quantities``), 'udim' (:func:`bake_udim`, :func:`bake_udim_maps`) or 'corners'
    (:func:`bake_vertex_ao`, :func:`bake_vertex_maps`). ``highpoly``, ``cage`` and ``bent_space`` are
    :func:`bake_ao`'s (images and UDIM tiles), ``corners`` :func:`bake_vertex_ao`'s; the callbacks
    are :func:`bake_ao`'s (``on_tile`` as :func:`bake_maps`'s with several quantities, and with the
    tile first for UDIM tiles). Results are bit for bit those of the call of the same kind and options.
    """
    request = BakeRequest() if request is None else request
    if not isinstance(request, BakeRequest):
        raise TypeError(f"bake() takes a core.base.request.BakeRequest, got {type(request).__name__}")
    if corners is not None and request.kind != "corners":
        raise TypeError(f"bake() got corners for a bake of kind {request.kind!r}: corners are a 'corners' bake's")
    return run(request, target, occluders, highpoly=highpoly, cage=cage, bent_space=bent_space, corners=corners,
               progress=progress, cancel=cancel, on_tile=on_tile, on_rays=on_rays)


def _one(call, kind, options):
    """The request of a call that bakes one quantity (``quantity=``)."""
    if "quantities" in options:
        several = {"bake_ao": "bake_maps", "bake_udim": "bake_udim_maps", "bake_vertex_ao": "bake_vertex_maps"}[call]
        raise TypeError(f"{call}() got an unexpected keyword argument 'quantities': it bakes one quantity "
                        f"(quantity=...); {several}() bakes several")
    return BakeRequest.from_options(call, kind, options)


def _several(call, kind, quantities, options):
    """The request of a call that bakes several quantities (``quantities=``)."""
    if "quantity" in options:
        raise TypeError(f"{call}() got an unexpected keyword argument 'quantity': it bakes quantities=...")
    return BakeRequest.from_options(call, kind, dict(options, quantities=quantities))


def bake_ao(target, occluders=(), resolution=(1024, 1024), samples=256, *, highpoly=None, cage=None, bent_space=None,
            progress=None, cancel=None, on_tile=None, on_rays=None, **options):
    """Bake ambient occlusion of ``target`` into a (H, W) texture over its UVs.

    ``target`` may be a list of meshes (or a :class:`core.Atlas` of them): an atlas, every target
    baked into the one image over its own UVs (:mod:`core.pipeline.atlas`). Each target is baked as
    it would be alone with the others as occluders, and the texels they share go to the one covering
    more of each (equal areas: the first by name); margins grow into empty texels only. The result
    then has ``owner``, ``targets`` and ``record``; ``core.Atlas(targets, occluding=..., keep=record)``
    says which targets occlude the others and keeps, from an earlier bake's ``record``, the texels of
    every target whose fingerprint (its mesh, UVs and transform, the settings, the meshes within its
    reach) did not change: the same bits as baking them again. ``highpoly`` and ``cage`` are then
    lists with one entry per target, and so may ``bent_space`` be.

    With ``highpoly``, bake the AO of the high-poly meshes into the target's UVs instead (Blender's
    "Selected to Active"): each sample point of the target is moved to the high-poly surface by
    Cycles' rules and AO is evaluated there (:mod:`core.highpoly` says exactly how).

    Every option (the keywords after ``samples``, and ``resolution`` and ``samples`` themselves) is an
    option of :data:`core.base.request.OPTIONS`, checked once into a
    :class:`core.base.request.BakeRequest`; a keyword that names no option is a TypeError naming the
    closest one.

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
        starting beyond another part of it in concave places (:func:`core.highpoly.extrusion.auto_extrusion`).
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
        None: one), 'auto' (from the cores and the memory: :func:`core.execution.executor.auto_workers`), or a
        ``distributed.Client``: the tiles as tasks on its Dask cluster (a lost worker's tiles are
        redone). The same bits for any workers x threads x tiling on one machine, and across
        machines whose CPUs take the same instruction paths (:mod:`core.execution.pool`).
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
    request = _one("bake_ao", "image", dict(options, resolution=resolution, samples=samples))
    return run(request, target, occluders, highpoly=highpoly, cage=cage, bent_space=bent_space, progress=progress,
               cancel=cancel, on_tile=on_tile, on_rays=on_rays)[request.quantity]


def bake_maps(target, occluders=(), resolution=(1024, 1024), samples=256, *, quantities=DEFAULT_QUANTITIES,
              highpoly=None, cage=None, bent_space=None, progress=None, cancel=None, on_tile=None, on_rays=None,
              **options):
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
    request = _several("bake_maps", "image", quantities, dict(options, resolution=resolution, samples=samples))
    return run(request, target, occluders, highpoly=highpoly, cage=cage, bent_space=bent_space, progress=progress,
               cancel=cancel, on_tile=on_tile, on_rays=on_rays)


def bake_udim(target, occluders=(), resolution=(1024, 1024), samples=256, *, highpoly=None, cage=None,
              bent_space=None, progress=None, cancel=None, on_tile=None, on_rays=None, **options):
    """Bake every UDIM tile the UVs of ``target`` touch (or the given ``tiles``), one image each.

    Parameters
    ----------
    tiles : None (the tiles :func:`covered_tiles` finds) or tile numbers; a listed tile the UVs do
        not touch is baked empty (nothing covered, all zero), as Cycles clears such a tile.
    on_tile : called as on_tile(tile, rows, cols, ao_block), as :func:`core.bake_ao`'s with the tile.
    progress : fraction of the whole bake, each tile weighed by the UV area it covers.
    The other parameters are :func:`core.bake_ao`'s, for every tile (the margin is per tile).

    Returns
    -------
    BakeResult with ``tiles`` (see :class:`core.BakeResult`)
    """
    request = _one("bake_udim", "udim", dict(options, resolution=resolution, samples=samples))
    return run(request, target, occluders, highpoly=highpoly, cage=cage, bent_space=bent_space, progress=progress,
               cancel=cancel, on_tile=on_tile, on_rays=on_rays)[request.quantity]


def bake_udim_maps(target, occluders=(), resolution=(1024, 1024), samples=256, *, quantities=DEFAULT_QUANTITIES,
                   highpoly=None, cage=None, bent_space=None, progress=None, cancel=None, on_tile=None, on_rays=None,
                   **options):
    """Several quantities of every UDIM tile in one pass per tile (:func:`core.bake_maps` per tile).

    ``quantities`` as for :func:`core.bake_maps`; ``on_tile`` is called as on_tile(quantity, tile,
    rows, cols, block); the others as for :func:`bake_udim`.

    Returns
    -------
    {quantity: BakeResult with ``tiles``}: each bit for bit :func:`bake_udim` of that quantity with the
    same settings.
    """
    request = _several("bake_udim_maps", "udim", quantities, dict(options, resolution=resolution, samples=samples))
    return run(request, target, occluders, highpoly=highpoly, cage=cage, bent_space=bent_space, progress=progress,
               cancel=cancel, on_tile=on_tile, on_rays=on_rays)


def bake_vertex_ao(target, occluders=(), corners=None, samples=256, *, progress=None, cancel=None, on_rays=None,
                   **options):
    """Bake ambient occlusion at the face corners of ``target`` (Cycles' colour-attribute bake).

    Parameters
    ----------
    target : Mesh (UVs not needed). It always occludes itself.
    occluders : Meshes that also block rays, in the same world space.
    corners : (C, 2) integers, (triangle, corner 0..2) of each face corner to bake, e.g. Blender's
        face corners each mapped to the first triangle that holds it; None: every triangle corner.
    merge : corners with the same vertex and normal share one sample point (default).
    bent_normals : also estimate each corner's bent normal (world space) from the same rays
        (summed over all replicates).
    replicates : as for :func:`core.bake_ao`: with 2 or more, ``stderr`` and adaptive sampling use
        the spread between replicates, pooled over each sample point's neighbourhood on the mesh
        (its vertex and the vertices that share an edge with it: :class:`Neighbours`), as a
        texel's is pooled over the texels around it.
    ground, quantity : as for :func:`core.bake_ao` ('auto': the target's lowest point).
    denoise : filter the corners' estimates over the mesh (:func:`core.post.denoise.denoise_vertices`: the
        points up to two edges away, each weighed by its error): ``ao`` and ``stderr`` the denoised
        values and their error, ``raw_ao`` and ``raw_stderr`` the estimates before it (needs
        ``replicates`` >= 2).
    The other parameters are those of :func:`core.bake_ao`; progress is reported per chunk of
    rays and ``on_rays`` batches name the sample point (``texels``) of each ray.

    Returns
    -------
    BakeResult, its arrays per corner

    Raises
    ------
    MeshError, MeshTypeError, SettingsError, BakeCancelled.
    """
    request = _one("bake_vertex_ao", "corners", dict(options, samples=samples))
    return run(request, target, occluders, corners=corners, progress=progress, cancel=cancel,
               on_rays=on_rays)[request.quantity]


def bake_vertex_maps(target, occluders=(), corners=None, samples=256, *, quantities=DEFAULT_QUANTITIES, progress=None,
                     cancel=None, on_rays=None, **options):
    """Several quantities at the face corners of ``target`` in one pass (:mod:`core.targets.maps`): one set-up
    (sample points, neighbours, pattern, scene where shared), each quantity its own rays.

    ``quantities``, ``ground``, ``ignore_backfaces``, ``bent_normals`` as for :func:`core.bake_maps`;
    the others as for :func:`bake_vertex_ao`.

    Returns
    -------
    {quantity: BakeResult}: each bit for bit :func:`bake_vertex_ao` of that quantity with the same
    settings, ``metadata['quantities']`` the quantities baked together.
    """
    request = _several("bake_vertex_maps", "corners", quantities, dict(options, samples=samples))
    return run(request, target, occluders, corners=corners, progress=progress, cancel=cancel, on_rays=on_rays)


#: The result of :func:`bake_vertex_ao` (its arrays per corner) and of :func:`bake_udim` (the tiles'
#: stacked, with ``tiles``): :class:`core.BakeResult`.
VertexBakeResult = UdimResult = BakeResult

__all__ = ["bake", "bake_ao", "bake_maps", "bake_udim", "bake_udim_maps", "bake_vertex_ao", "bake_vertex_maps",
           "BakeResult", "VertexBakeResult", "UdimResult", "DEFAULT_QUANTITIES"]
