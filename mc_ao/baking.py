"""What to bake: pick the targets, gather their geometry and their occluders, run the core (core.bake).

plan() reads Blender data and must run in the main thread; Job.run() and Job.run_maps() (one core
call, Job._bake, for every kind) touch no bpy and run on a worker thread (the operator's, scripts/bake_ao.py's), so that the main thread stays free.
"""

from dataclasses import dataclass, field

from . import corelink
from .extract import GEOMETRY_TYPES, ExtractError, MeshArrays, object_arrays
from .settings import bake_kind


def can_be_target(obj, needs_uvs=True):
    """A target is a mesh object with a UV map (checked on its original data, cheaply, for poll);
    a colour-attribute bake (``needs_uvs`` False) takes any mesh object."""
    return obj.type == "MESH" and (not needs_uvs or len(obj.data.uv_layers) > 0)


def targets_of(objects, needs_uvs=True):
    """The objects among ``objects`` that bake_ao can bake, in name order (a stable bake order)."""
    return sorted((obj for obj in objects if can_be_target(obj, needs_uvs)), key=lambda obj: obj.name)


# Object.type -> what to call it in a message, where the identifier is not plain English.
_KINDS = {
    "FONT": "text", "META": "metaball", "GPENCIL": "grease pencil", "GREASEPENCIL": "grease pencil",
    "CURVES": "hair curves", "POINTCLOUD": "point cloud", "LIGHT_PROBE": "light probe",
}


def kind_of(obj):
    """``obj``'s type as a noun with its article: "a light", "an empty", "a text"."""
    noun = _KINDS.get(obj.type, obj.type.lower().replace("_", " "))
    return ("an " if noun[0] in "aeiou" else "a ") + noun


def skip_reason(obj, needs_uvs=True):
    """Why a selected object is not baked ("is a light, not a mesh", "has no UV map"), or None."""
    if obj.type != "MESH":
        return f"is {kind_of(obj)}, not a mesh"
    if not can_be_target(obj, needs_uvs):
        return "has no UV map (unwrap it first: Edit Mode, U)"
    return None


def skip_note(obj, occluders, needs_uvs=True):
    """The warning for a selected object that is not baked, e.g. "Lamp: skipped, it is a light, not a mesh".

    ``occluders`` is the Occluders setting: a skipped object with a surface still occludes the others
    unless each object is baked alone.
    """
    from .occluders import occlude_others

    note = f"{obj.name}: skipped, it {skip_reason(obj, needs_uvs)}"
    if obj.type in GEOMETRY_TYPES and occluders != "SELF" and occlude_others(obj):
        note += "; it still occludes the baked objects"
    return note


def why_not_bakeable(objects, needs_uvs=True):
    """None when something among ``objects`` (the selection) can be baked, else the reason, for the UI.

    The same text is the operator's poll message (the button's tooltip, and the error of a script
    that calls the operator anyway), the panel's hint, and the operator's report.
    """
    objects = list(objects)
    if not objects:
        return "Nothing is selected: select a mesh object with a UV map"
    if any(can_be_target(obj, needs_uvs) for obj in objects):
        return None
    if len(objects) == 1:
        return f"{objects[0].name} {skip_reason(objects[0], needs_uvs)}"
    meshes = [obj for obj in objects if obj.type == "MESH"]
    if not meshes:
        return "None of the selected objects is a mesh"
    if len(meshes) == 1:
        return f"{meshes[0].name} {skip_reason(meshes[0])}, and the others are not meshes"
    return "None of the selected meshes has a UV map"


@dataclass
class Job:
    """The bake of one object: its geometry with UVs and normals, and the geometry around it."""

    object_name: str
    image_name: str
    target: MeshArrays
    occluders: list = field(default_factory=list)
    # Selected to Active (mc_ao.selected_to_active): the high-poly sources, the cage (or None), the
    # extrusion (world units) and the max ray distance; warnings for the report.
    highpoly: list = field(default_factory=list)
    cage: MeshArrays = None
    extrusion: float = 0.0
    max_ray_distance: float = 0.0
    notes: list = field(default_factory=list)
    # What this job bakes (core.bake_ao's quantity): 'ao' or 'thickness'; an object baked for both has a
    # job for each, each with its own image.
    quantity: str = "ao"

    @property
    def selected_to_active(self):
        return bool(self.highpoly)

    def run(self, settings, threads=None, progress=None, cancel=None, on_tile=None, quantity=None):
        """The core's bake of this job; returns its result. Needs no bpy (safe in a worker thread).

        ``quantity``: bake this core quantity (core.bake_ao's ``quantity``, e.g. "thickness") instead
        of the job's own (an output that needs a second quantity), without bent normals (the core
        makes them with the job's own bake). Raises core.McAoError subclasses (core.BakeCancelled
        when ``cancel`` fires).
        """
        return self._bake(settings, threads, (quantity or self.quantity,), False, progress, cancel, on_tile)

    def shares_bake_with(self, other):
        """Whether ``other`` bakes the same object from the same geometry (another quantity of it): the
        two can be baked together (:meth:`run_maps`)."""
        return (other.object_name == self.object_name and other.target is self.target
                and len(other.highpoly) == len(self.highpoly)
                and all(a is b for a, b in zip(other.highpoly, self.highpoly)) and other.cage is self.cage
                and other.extrusion == self.extrusion and other.max_ray_distance == self.max_ray_distance)

    def run_maps(self, settings, threads=None, quantities=("ao", "thickness"), progress=None, cancel=None,
                 on_tile=None):
        """Several core quantities of this object from one bake (core.bake of a request with several
        quantities: one set-up, each quantity its own rays): {quantity: result}, each bit for bit
        what :meth:`run` returns for it from this job (its occluders for the AO, none for a thickness
        map; the ground, back faces and bent normals for the AO only, the bent normals only where the
        AO is the job's own quantity). ``on_tile(quantity, rows, cols, block)``. Needs no bpy."""
        return self._bake(settings, threads, tuple(quantities), True, progress, cancel, on_tile)

    def _bake(self, settings, threads, quantities, maps, progress, cancel, on_tile):
        """This job's core bake (:func:`core_bake`): its target, its occluders for the AO, its
        high-poly meshes and cage for Selected to Active, its corners for a colour attribute."""
        core = corelink.load()

        def mesh(arrays, uvs=True):
            return core.Mesh(positions=arrays.positions, triangles=arrays.triangles, uvs=arrays.uvs if uvs else None,
                             normals=arrays.normals, name=arrays.name)

        extra = {}
        if settings.vertex_colors:
            extra["corners"] = self.target.extra["corners"]
        else:
            extra["bent_space"] = (self.target.extra or {}).get("bent_space")
            if self.highpoly and not (settings.use_udim or settings.bent_normals):
                extra.update(highpoly=[mesh(h) for h in self.highpoly],
                             cage=None if self.cage is None else mesh(self.cage),
                             extrusion=extrusion_of(self.cage, self.extrusion), max_ray_distance=self.max_ray_distance)
        occluders = [mesh(o) for o in self.occluders] if "ao" in quantities else []  # a thickness map: none
        return core_bake(settings, threads, quantities, maps, self.quantity, mesh(self.target, uvs=not
                         settings.vertex_colors), occluders, progress=progress, cancel=cancel, on_tile=on_tile, **extra)


def extrusion_of(cage, extrusion):
    """The core's extrusion of a Selected to Active bake: 0 (the default) without a cage is "auto",
    measured from the meshes (how far the high-poly lies outside the low-poly: core.highpoly), never
    Cycles' trap of none; else the distance as given."""
    return "auto" if cage is None and extrusion == 0 else extrusion


def core_bake(settings, threads, quantities, maps, own, target, occluders, *, highpoly=None, cage=None,
              extrusion=None, max_ray_distance=0.0, bent_space=None, corners=None, resolution=None, progress=None,
              cancel=None, on_tile=None):
    """The one core call of every bake (core.bake), for a job of one object (Job) or of several into one
    image (mc_ao.atlas: ``target`` a core.Atlas): an image, UDIM tiles or a colour attribute, of one
    quantity or (``maps``) several at once; ``own`` is the job's own quantity (bent normals come with
    its bake only). The request is made of the settings' options (BakeSettings.bake_kwargs, with
    ``threads``; ``resolution`` in place of theirs), less what the bake does not take: the ground and
    back faces are the AO's (the core refuses them for a thickness map), an image's resolution and
    margin are not a colour attribute's. ``highpoly`` (with ``cage``, ``extrusion``,
    ``max_ray_distance``): Selected to Active. Returns {quantity: result} with ``maps``, else the one
    result. Needs no bpy."""
    core = corelink.load()
    kind = bake_kind(settings)
    main = "ao" if maps else quantities[0]  # the quantity whose options the bake takes: a bake of maps takes the AO's
    kw = settings.bake_kwargs(threads)
    if resolution is not None:
        kw["resolution"] = tuple(resolution)
    if "ao" not in quantities:
        kw.pop("ground", None)
        kw.pop("ignore_backfaces", None)
    if not maps and main != "ao":
        kw["quantity"] = main
    if main != own or kind == "corners":
        kw.pop("bent_normals", None)
    if maps:
        kw["quantities"] = tuple(quantities)
    options = corelink.load("base.request").BY_NAME
    kw = {name: value for name, value in kw.items() if kind in options[name].kinds}
    calls = {"progress": progress, "cancel": cancel}
    if kind == "corners":
        calls["corners"] = corners
    else:
        if kw.get("bent_normals"):
            calls["bent_space"] = bent_space
        if highpoly is not None:
            kw.update(extrusion=extrusion, max_ray_distance=max_ray_distance)
            calls.update(highpoly=highpoly, cage=cage)
        if kind == "image":
            calls["on_tile"] = on_tile
    results = core.bake(target, occluders, core.BakeRequest.from_options("bake", kind, kw), **calls)
    return results if maps else results[main]


def needs_uvs(settings):
    """Whether the bake's targets need a UV map (all but a colour-attribute bake)."""
    return not settings.vertex_colors


def extra_for(settings):
    """The ``extra`` callable for a target's extract.object_arrays, or None."""
    from . import bent, vertex_colors

    parts = []
    if settings.vertex_colors:
        parts.append(vertex_colors.corner_data)
    elif settings.bent_normals:
        parts.append(bent.frames_data(settings))
    if not parts:
        return None

    def extra(mesh, arrays):
        out = {}
        for part in parts:
            out.update(part(mesh, arrays))
        return out

    return extra


def check_plan(jobs_, settings, objects):
    """Raise ExtractError (naming the objects) for what stops a bake before it starts: two targets
    sharing one mesh for a colour-attribute bake (one attribute cannot hold both), an attribute of
    another type or domain, modifiers that change the face corners; ``objects``: name -> object."""
    from . import vertex_colors

    if settings.vertex_colors:
        owners = {}
        for job in jobs_:
            mesh = objects[job.object_name].data
            other = owners.get(mesh.name)
            if other is not None:
                raise ExtractError(
                    f"{other} and {job.object_name} share the mesh {mesh.name!r}: its color attribute can "
                    "hold the bake of only one of them; bake them one at a time, or make the mesh single-user"
                )
            owners[mesh.name] = job.object_name
            vertex_colors.check_object(objects[job.object_name], settings, job.target.extra)


# The UV coverage of a mesh, by (mesh name, its number of face corners, UV map): the panel asks on
# every redraw, and reading a large mesh's UVs costs milliseconds.
_COVERAGE = {}


def uv_coverage(obj, uv_map="", udim=False):
    """About the share of the UV square that ``obj``'s faces cover (core.execution.cost.covered_fraction of its
    UV map's triangles), cached per mesh; 0.5 where it cannot be read. ``udim``: of every UDIM tile
    together (each triangle counted in the tile of its centre, moved into the square: 2 for two tiles
    fully covered)."""
    import numpy as np

    mesh = obj.data
    layer = mesh.uv_layers.get(uv_map) if uv_map else mesh.uv_layers.active
    if layer is None or not len(mesh.loops):
        return 0.5
    key = (mesh.name_full, len(mesh.loops), layer.name, udim)
    if key not in _COVERAGE:
        uv = np.empty(2 * len(mesh.loops), np.float32)
        layer.data.foreach_get("uv", uv)
        uv = uv.reshape(-1, 2)
        mesh.calc_loop_triangles()
        tris = np.empty(3 * len(mesh.loop_triangles), np.int32)
        mesh.loop_triangles.foreach_get("loops", tris)
        corners = uv[tris.reshape(-1, 3)].astype(np.float64)
        fraction = corelink.load("execution.cost").covered_fraction
        if len(_COVERAGE) > 64:
            _COVERAGE.clear()
        if udim:
            # each tile a triangle reaches (an island across a tile's border is baked in both), the
            # triangle's part in it about the clipped corners' area (covered_fraction)
            lo, hi = np.floor(corners.min(axis=1)), np.ceil(corners.max(axis=1)) - 1
            tiles = {(u, v) for a, b in zip(lo.astype(int), hi.astype(int))
                     for u in range(a[0], max(a[0], b[0]) + 1) for v in range(a[1], max(a[1], b[1]) + 1)}
            _COVERAGE[key] = sum(fraction(corners[(lo[:, 0] <= u) & (hi[:, 0] >= u) & (lo[:, 1] <= v) & (hi[:, 1] >= v)]
                                          - (u, v)) for u, v in sorted(tiles))
        else:
            _COVERAGE[key] = fraction(corners)
    return _COVERAGE[key]


# The occluders' triangle counts of bake_cost, by what decides them besides Blender's data: the panel
# asks on every redraw, and counting walks every rendered object and instance (about 5 us each).
# forget_occluder_counts empties it whenever the data changes (operators.HANDLERS: depsgraph_update_post
# and load_post).
_OCCLUDER_COUNTS = {}


def forget_occluder_counts():
    """Blender's data changed: count the occluders and measure the UV maps' coverage again."""
    _OCCLUDER_COUNTS.clear()
    _COVERAGE.clear()


def occluder_counts(depsgraph, settings, selected=(), view_layer=None):
    """mc_ao.occluders.pool's occluders as ``[(object name or None for an instance, triangles)]``,
    without reading their geometry; kept until the data changes (forget_occluder_counts)."""
    from . import occluders as occluder_sets

    view_layer = view_layer or depsgraph.view_layer
    key = (depsgraph.scene.name_full, view_layer.name, settings.occluders, tuple(settings.occluder_collections),
           tuple(settings.exclude_collections), settings.only_local, tuple(settings.quantities),
           tuple(obj.name_full for obj in selected) if settings.occluders == "SELECTED" else ())
    if key not in _OCCLUDER_COUNTS:
        counts = occluder_sets.pool(depsgraph, settings, selected=selected, view_layer=view_layer,
                                    read=occluder_sets.triangle_count)
        if len(_OCCLUDER_COUNTS) > 64:
            _OCCLUDER_COUNTS.clear()
        _OCCLUDER_COUNTS[key] = counts
    return _OCCLUDER_COUNTS[key]


#: This machine as the bakes of this session found it: their measured time over what bake_cost
#: estimated, followed geometrically (each bake moves it half way, in log terms, to its own ratio),
#: within [1/5, 5]. The panel's estimate is bake_cost's times this (calibrated): a machine faster or
#: slower than the bench's, or busier than its load average says, is learnt from its own bakes.
_CALIBRATION = {"factor": 1.0}


def calibrated(cost):
    """``cost`` (core.execution.cost.Cost) with its time scaled by what this session's bakes measured."""
    return type(cost)(cost.seconds * _CALIBRATION["factor"], cost.bytes)


def learn_from_bake(estimated, measured):
    """A bake estimated at ``estimated`` seconds (uncalibrated) took ``measured``: follow it. Bakes
    under half a second say more of their fixed costs than of the machine, and are left out."""
    import math

    if estimated > 0.5 and measured > 0.5:
        factor = math.sqrt(_CALIBRATION["factor"] * measured / estimated)
        _CALIBRATION["factor"] = min(5.0, max(0.2, factor))


def bake_cost(settings, targets, depsgraph=None, *, selected=(), view_layer=None, threads=None, highpoly=(),
              cage=None):
    """What baking ``targets`` with ``settings`` will cost, before it runs (core.execution.cost): a
    core.execution.cost.Cost for them all, one after another.

    core.execution.cost prices a target's triangles, its occluders' and a high-poly's apart; each is counted
    here as the bake will hold it, from the evaluated meshes (``depsgraph``: the context's by default)
    without reading their geometry: the occluders :func:`plan` gives each target (mc_ao.occluders:
    the Occluders choice, Include and Exclude, instances, Only Local, Occludes Other Objects;
    ``selected`` and ``view_layer`` as :func:`plan` takes them), and for Selected to Active
    (``highpoly``: the high-poly objects, ``cage``: the cage object or None) the high-poly objects'
    and the cage's, with the occluders mc_ao.selected_to_active.plan takes. The processes and threads
    are those the bake takes (core.execution.executor.processes_of; Processes 0 picks them from the cores, the
    memory and these counts); ``threads``: the bake's (properties.resolve_threads), else the
    settings' (0: every core). Every setting that changes the work is priced: the maps baked (AO and
    thickness: twice the rays), Denoise, UDIM tiles (the texels of every tile), a colour attribute's
    corners; and the machine's load now (core.execution.cost.machine_load): on a busy machine the bake
    gets a share of the cores. Adaptive sampling takes at most Samples: the estimate is its longest.
    """
    from types import SimpleNamespace

    from . import occluders as occluder_sets

    if depsgraph is None:
        import bpy

        depsgraph = bpy.context.evaluated_depsgraph_get()
    cost = corelink.load("execution.cost")
    workers = corelink.load("execution.executor")
    w, h = settings.size
    threads = threads or settings.threads or None
    # core.execution.executor.processes_of reads the bake's thread count from its settings
    core_settings = SimpleNamespace(threads=threads or workers.cpu_count())
    skip, high = set(), 0
    if highpoly:
        skip = {obj.name for obj in (*targets, *highpoly, *((cage,) if cage is not None else ()))}
        pool = (occluder_counts(depsgraph, settings, view_layer=view_layer)
                if settings.occluders == "VISIBLE" and settings.quantities == ("ao",) else [])
        high = sum(occluder_sets.triangle_count(obj.evaluated_get(depsgraph)) or 0 for obj in highpoly)
    else:
        pool = occluder_counts(depsgraph, settings, selected, view_layer)
    seconds, peak = 0.0, 0
    # The machine's load now: the bake's threads share the cores with it (read from /proc, no more).
    load, cpus = cost.machine_load()
    for obj in targets:
        mesh = obj.evaluated_get(depsgraph).data
        triangles = len(mesh.loops) - 2 * len(mesh.polygons)  # an n-gon is n - 2 triangles
        occluders = sum(n for key, n in pool if key != obj.name and key not in skip)
        highpoly_triangles = high + (triangles if cage is not None else 0)  # the cage: the target's topology
        covered = (uv_coverage(obj, settings.uv_map, settings.use_udim) if not settings.vertex_colors else 1.0) * w * h
        if settings.vertex_colors:
            covered = len(mesh.loops)
        processes, per_worker = workers.processes_of(
            "auto" if settings.processes == 0 else settings.processes, threads, core_settings,
            (triangles, occluders, highpoly_triangles))
        c = cost.estimate(covered, settings.samples, triangles,
                          image_texels=w * h if not settings.vertex_colors else covered,
                          threads=per_worker, processes=processes, occluder_triangles=occluders,
                          highpoly_triangles=highpoly_triangles, quantities=len(settings.quantities),
                          denoise=settings.denoise, load=load, cpus=cpus,
                          starting=processes if processes > 1 and not workers.pool_ready(processes, per_worker) else 0)
        seconds += c.seconds
        peak = max(peak, c.bytes)
    return cost.Cost(seconds, peak)


def id_name_max_bytes():
    """The longest datablock name this Blender keeps, in bytes of UTF-8 (63 up to 4.4, 255 from 5.0).

    Blender cuts a longer name at its end when it creates the datablock: image names are made to
    fit first (BakeSettings.image_name_for), so that each object keeps an image of its own.
    """
    import bpy

    return bpy.types.ID.bl_rna.properties["name"].length_max - 1


def plan(depsgraph, targets, settings, *, selected=(), view_layer=None):
    """One Job per target object, with geometry evaluated by ``depsgraph`` (modifiers applied).

    Parameters
    ----------
    depsgraph : bpy.types.Depsgraph
        Evaluated dependency graph (``context.evaluated_depsgraph_get()``).
    targets : list of bpy.types.Object
        Mesh objects to bake (original, not evaluated, objects).
    settings : mc_ao.settings.BakeSettings
    selected : list of bpy.types.Object
        The occluders when ``settings.occluders == "SELECTED"`` (each target is left out of its own list).
    view_layer : bpy.types.ViewLayer, optional
        Whose rendered objects occlude for ``settings.occluders == "VISIBLE"`` (All Rendered); the
        depsgraph's by default. Include, Exclude, Only Local and each object's Occludes Other Objects
        narrow the occluders (mc_ao.occluders).

    Returns one Job per target and quantity (AO, thickness), in that order.

    Raises
    ------
    ExtractError
        A target has no faces or no such UV map, two targets would bake into one image, a bad Include
        or Exclude collection, or a Channel the Into image does not have.
    """
    from . import occluders as occluder_sets

    max_bytes = id_name_max_bytes()
    images = []
    for obj in targets:
        names = [settings.quantity_image_name_for(obj.name, q, max_bytes) for q in settings.quantities]
        if settings.error_map and not settings.vertex_colors:
            names += [settings.quantity_image_name_for(obj.name, q, max_bytes, "_stderr") for q in settings.quantities]
        if settings.bent_normals and not settings.vertex_colors:
            names.append(settings.bent_image_name_for(obj.name, max_bytes))
        images += [(obj.name, name) for name in names]
    check_image_names(images)

    check_channel(settings)
    notes = []
    pool = occluder_sets.pool(depsgraph, settings, selected=selected, view_layer=view_layer, notes=notes)

    extra = extra_for(settings)
    jobs = []
    for obj in targets:
        target = object_arrays(
            obj.evaluated_get(depsgraph), uv_map=settings.uv_map, with_uvs=needs_uvs(settings),
            with_normals=True, extra=extra,
        )
        if target is None:
            raise ExtractError(f"{obj.name} has no faces to bake")
        occluders = [arrays for key, arrays in pool if key != obj.name]
        for quantity in settings.quantities:  # a thickness map: the object alone occludes it
            jobs.append(Job(obj.name, settings.quantity_image_name_for(obj.name, quantity, max_bytes), target,
                            occluders if quantity == "ao" else [], quantity=quantity))
    if jobs:
        jobs[0].notes.extend(notes)
    check_plan(jobs, settings, {obj.name: obj for obj in targets})
    return jobs


def check_image_names(images):
    """Raise ExtractError when two objects would bake into one image; ``images``: [(object name,
    image name)] of every image a bake makes."""
    owners = {}
    for obj, name in images:
        if name in owners:
            raise ExtractError(image_name_clash(owners[name], obj, name))
        owners[name] = obj


def image_name_clash(first, second, name):
    """The refusal of two images named ``name``, of the objects ``first`` and ``second`` (one object's
    two images where they are the same): the poll's and the bake's checks say it in these words."""
    if first == second:
        return (f"{first}'s images would both be named {name!r} (its AO and its bent normals or error "
                "map): choose another Image name")
    return (f"{first} and {second} would both bake into image {name!r}: put {{object}} into the Image name, "
            "or set Images to One for All to bake them into one image together")


# Channel index of each Channel setting.
CHANNELS = {"R": 0, "G": 1, "B": 2, "A": 3}


def channel_problem(settings, images=None):
    """Why AO cannot go into ``settings.channel`` of the image ``settings.into`` (bpy.data.images, or
    ``images``: name -> image), or None (Channel off, or it can)."""
    if settings.channel == "NONE":
        return None
    if images is None:
        import bpy

        images = bpy.data.images
    image = images.get(settings.into)
    if image is None:
        import os

        if os.path.splitext(settings.into)[1].lower() not in (".png", ".exr", ".tif", ".tiff"):
            return f"Into: there is no image named {settings.into!r} to write the AO into"
        # a file (the script's --into PATH): core.files.imageio checks it, naming it and what it has
        try:
            corelink.load("files.channels").check_channel(settings.into, settings.channel, settings.size)
        except corelink.load().SettingsError as exc:
            return str(exc)
        return None
    channels = image_channels(image)
    # An image of 3 channels has no alpha; one of 1 or 2 (grey, grey and alpha) no separate green or blue.
    has = {4: "RGBA", 3: "RGB", 2: "RA", 1: "R"}.get(channels, "")
    if settings.channel not in has:
        return (f"image {settings.into!r} has no {settings.channel} channel (it has {channels}: "
                f"{', '.join(has) or 'none'}); choose one of them")
    w, h = settings.size
    if tuple(image.size) != (w, h) and all(image.size):
        return (f"image {settings.into!r} is {image.size[0]}x{image.size[1]}, not the bake's {w}x{h}: bake at its "
                f"size to write into its {settings.channel} channel")
    return None  # mc_ao.outputs.channel writes it


def image_channels(image):
    """How many channels ``image`` holds (its file's or its buffer's): Blender's Image.channels says 4
    for every loaded image, its depth (bits per pixel) tells: 8 bits a channel, 32 in a float image."""
    depth = getattr(image, "depth", 0)
    per = 32 if getattr(image, "is_float", False) else 8
    if depth and depth % per == 0 and 1 <= depth // per <= 4:
        return depth // per
    return image.channels


def check_channel(settings, images=None):
    """Raise ExtractError with :func:`channel_problem`'s reason, before any work."""
    problem = channel_problem(settings, images)
    if problem is not None:
        raise ExtractError(problem)
