"""Several objects into one image (a texture atlas): which objects share an image, and their bake.

An image is shared in one of three ways, each chosen explicitly (the Images setting):

- One Image for All (``ATLAS``): every object of the bake into the image the Atlas setting names
  (the script's ``--atlas NAME``, the manifest's ``atlas``);
- Node Image (``NODE``): each object into the image of its materials' active Image Texture node,
  as Cycles' bake finds its target; objects whose materials name the same image bake into it
  together. Never the default: it writes into whatever image the node holds;
- an Image name without ``{object}`` (``OWN``): one object into a named image, which may already hold
  other objects' texels.

Each shared image is one :class:`AtlasJob`: the objects are baked by the core as one atlas
(:func:`core.bake_ao` of a list: each object as it would be baked alone with the others as
occluders, each texel from the object covering more of it, margins into empty texels only). An
image that an earlier bake filled carries that bake's record (its objects, their fingerprints and
texels): an object whose fingerprint did not change keeps its texels, and the objects it holds that
this bake does not name keep theirs (:func:`record_of`).

plan() reads Blender data (main thread); AtlasJob.run() touches no bpy.
"""

from dataclasses import dataclass, field

from . import baking, corelink
from .extract import ExtractError, object_arrays


@dataclass
class AtlasJob:
    """The bake of several objects into one image.

    object_name : what messages call the bake (the image's name: "Atlas"); image_name : the image the
    quantity goes into; names, targets : the objects and their geometry; occluding : whether each
    occludes the others (mc_ao.occluders: the Occluders choice, Include, Exclude, Occludes Other
    Objects); occluders : the other objects that occlude; sources, cages : per object (Selected to
    Active), or None; size : (width, height) of the bake (an existing shared image keeps its size);
    keep : {quantity: core AtlasRecord} of an earlier bake of the image.
    """

    object_name: str
    image_name: str
    names: list
    targets: list
    occluding: list
    occluders: list = field(default_factory=list)
    sources: list = None  # Selected to Active: each object's high-poly meshes
    cages: list = None  # and its cage (or None)
    extrusion: float = 0.0
    max_ray_distance: float = 0.0
    quantity: str = "ao"
    size: tuple = None
    keep: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    atlas = True

    @property
    def selected_to_active(self):
        return bool(self.sources)

    @property
    def highpoly(self):
        """Every object's high-poly meshes together (what a summary and the files' metadata list)."""
        return [h for hs in self.sources or () for h in hs]

    @property
    def cage(self):
        """The first cage (the files' metadata names one), or None."""
        return next((c for c in self.cages or () if c is not None), None)

    @property
    def target(self):  # what a Job's outputs read of its target (a colour attribute's, not an atlas's)
        return self.targets[0]

    def label(self):
        """The objects, for a summary: "Base, Column, Ball"."""
        return ", ".join(self.names)

    def shares_bake_with(self, other):
        """Whether ``other`` bakes the same objects into images of the same name root (another quantity)."""
        return (getattr(other, "atlas", False) and other.object_name == self.object_name
                and other.names == self.names and all(a is b for a, b in zip(other.targets, self.targets)))

    def run(self, settings, threads=None, progress=None, cancel=None, on_tile=None, quantity=None):
        """The core's atlas bake of this job (its own quantity, or ``quantity``); no bpy."""
        return self._bake(settings, threads, (quantity or self.quantity,), False, progress, cancel, on_tile)

    def run_maps(self, settings, threads=None, quantities=("ao", "thickness"), progress=None, cancel=None,
                 on_tile=None):
        """Several quantities of the atlas in one bake (core.bake_maps of the list); no bpy."""
        return self._bake(settings, threads, tuple(quantities), True, progress, cancel, on_tile)

    def _bake(self, settings, threads, quantities, maps, progress, cancel, on_tile):
        """The atlas's core bake: mc_ao.baking.core_bake (the add-on's one core call) of a core.Atlas of
        its targets, at the atlas's size, with each target's bent-normal space and, for Selected to
        Active, each one's high-poly meshes and cage."""
        core = corelink.load()

        def mesh(arrays, uvs=True):
            return core.Mesh(positions=arrays.positions, triangles=arrays.triangles, uvs=arrays.uvs if uvs else None,
                             normals=arrays.normals, name=arrays.name)

        extra = {"bent_space": [(t.extra or {}).get("bent_space") for t in self.targets]}
        if self.sources:
            extra.update(highpoly=[[mesh(h) for h in hs] if hs else None for hs in self.sources],
                         cage=None if self.cage is None else [None if c is None else mesh(c) for c in self.cages],
                         extrusion=baking.extrusion_of(self.cage, self.extrusion),
                         max_ray_distance=self.max_ray_distance)
        main = "ao" if maps else quantities[0]
        keep = {q: r for q, r in (self.keep or {}).items() if q in quantities and r is not None}
        atlas = core.Atlas([mesh(t) for t in self.targets], occluding=list(self.occluding),
                           keep=(keep if maps else keep.get(main)) or None)
        occluders = [mesh(o) for o in self.occluders] if "ao" in quantities else []
        return baking.core_bake(settings, threads, quantities, maps, self.quantity, atlas, occluders,
                                resolution=self.size, progress=progress, cancel=cancel, on_tile=on_tile, **extra)


# -- which objects share an image ---------------------------------------------------------------------

def shared(settings):
    """Whether the bake's objects bake into shared images (as atlases): One for All or the materials'
    images. (An image named without ``{object}`` is shared where it holds other objects' texels:
    :func:`prepare` finds out.)"""
    return not settings.vertex_colors and settings.images != "OWN"


def node_image(obj):
    """The image of ``obj``'s materials' active Image Texture node, as Cycles' bake finds it: each
    material slot's material, its node tree's active node if that is an Image Texture node with an
    image. Raises ExtractError naming the object when none has one, or when its materials name
    several (one object bakes into one image here)."""
    found = []
    for slot in obj.material_slots:
        mat = slot.material
        tree = getattr(mat, "node_tree", None) if mat is not None else None
        node = tree.nodes.active if tree is not None else None
        image = getattr(node, "image", None) if node is not None and node.type == "TEX_IMAGE" else None
        if image is not None and image.name not in found:
            found.append(image.name)
    if not found:
        raise ExtractError(f"{obj.name} has no material whose active node is an Image Texture with an image: with "
                           "Images set to Node Image, select the Image Texture node to bake into in each of "
                           "its materials (as for Cycles' bake), or choose another Images setting")
    if len(found) > 1:
        raise ExtractError(f"{obj.name}'s materials' active Image Texture nodes hold {len(found)} images "
                           f"({', '.join(map(repr, found))}): bake it into one, with one image active in every "
                           "material")
    return found[0]


def groups(settings, targets, max_bytes=None):
    """The shared images of a bake and their objects: ``[(image name, [objects])]`` in the order of
    their first object (objects in name order within each)."""
    if settings.images == "ATLAS":
        return [(settings.atlas_image_name(max_bytes), list(targets))]
    out = {}
    for obj in targets:
        name = node_image(obj) if settings.images == "NODE" else settings.image_name_for(obj.name, max_bytes)
        out.setdefault(name, []).append(obj)
    return list(out.items())


def image_size(name, settings):
    """The size an atlas bakes at: an existing image keeps its own (its other objects' texels, and
    whatever else it holds, stay where they are); else the settings'."""
    import bpy

    image = bpy.data.images.get(name)
    if image is not None and image.source in {"GENERATED", "FILE"} and all(image.size):
        return tuple(image.size)
    return tuple(settings.size)


def record_of(image_name, quantity, folder=None, stem=None):
    """The record of the atlas an earlier bake left for ``image_name`` (core AtlasRecord), or None:
    with ``folder`` and ``stem``, the one beside its file (``<stem>.atlas.npz``, the script's), else
    the Blender image's own (a custom property, the operator's). A record that cannot be read is an
    ExtractError naming where it is; one of another quantity is not this image's."""
    core = corelink.load()
    rec = corelink.load("files.atlasrecord")
    try:
        if folder is not None and stem is not None:
            import os

            record = rec.AtlasRecord.read(os.path.join(folder, stem + rec.SIDECAR_SUFFIX))
        else:
            import bpy

            from .images import record_bytes

            image = bpy.data.images.get(image_name)
            data = record_bytes(image) if image is not None else None
            record = None if data is None else rec.AtlasRecord.from_bytes(
                bytes(data), f"the atlas record of image {image_name!r}")
    except core.SettingsError as exc:
        raise ExtractError(str(exc)) from None
    if record is not None and record.quantity != quantity:
        return None
    return record


def plan(depsgraph, targets, settings, *, selected=(), view_layer=None):
    """One AtlasJob per shared image and quantity, the objects' geometry evaluated by ``depsgraph``.
    Raises ExtractError naming the object (no faces, no such UV map, no image node, ...)."""
    from . import baking
    from . import occluders as occluder_sets

    max_bytes = baking.id_name_max_bytes()
    baking.check_channel(settings)
    notes = []
    pool = occluder_sets.pool(depsgraph, settings, selected=selected, view_layer=view_layer, notes=notes)
    keys = {key for key, _ in pool}
    extra = baking.extra_for(settings)
    jobs = []
    for image, objects in groups(settings, targets, max_bytes):
        arrays = []
        for obj in objects:
            a = object_arrays(obj.evaluated_get(depsgraph), uv_map=settings.uv_map, with_uvs=True, with_normals=True,
                              extra=extra)
            if a is None:
                raise ExtractError(f"{obj.name} has no faces to bake")
            arrays.append(a)
        names = [o.name for o in objects]
        occluding = [n in keys for n in names]
        occluders = [a for key, a in pool if key not in names]
        for quantity in settings.quantities:
            name = image if quantity == "ao" else settings.quantity_image_name_for(image, quantity, max_bytes,
                                                                                   root=True)
            job = AtlasJob(image, name, names, arrays, occluding if quantity == "ao" else [False] * len(names),
                           occluders if quantity == "ao" else [], quantity=quantity)
            jobs.append(job)
    if jobs:
        jobs[0].notes.extend(notes)
    return jobs


def from_selected_to_active(jobs, settings, lows):
    """Selected to Active into one image: the low-poly jobs (mc_ao.selected_to_active.plan, each with
    its high-poly objects) as one AtlasJob per shared image (``lows``: name -> low-poly object)."""
    from .baking import id_name_max_bytes

    max_bytes = id_name_max_bytes()
    out = {}
    for job in jobs:
        if settings.images == "ATLAS":
            image = settings.atlas_image_name(max_bytes)
        elif settings.images == "NODE":
            image = node_image(lows[job.object_name])
        else:
            image = job.image_name
        out.setdefault(image, []).append(job)
    atlases = []
    for image, members in out.items():
        names = [j.object_name for j in members]
        skip = set(names) | {h.name for j in members for h in j.highpoly}
        occluders, seen = [], set()
        for j in members:
            for o in j.occluders:
                if o.name not in skip and o.name not in seen:
                    seen.add(o.name)
                    occluders.append(o)
        job = AtlasJob(image, image, names, [j.target for j in members], [True] * len(members), occluders,
                       sources=[j.highpoly for j in members], cages=[j.cage for j in members],
                       extrusion=members[0].extrusion, max_ray_distance=members[0].max_ray_distance,
                       quantity=members[0].quantity)
        job.notes = [n for j in members for n in j.notes]
        atlases.append(job)
    return atlases


def summary(job, result):
    """What an atlas's summary line adds: which objects were baked and which kept, and why."""
    report = (getattr(result, "report", None) or {}).get("atlas") or {}
    baked, held = report.get("baked", []), report.get("held", [])
    unchanged = [n for n in report.get("kept", []) if n not in held]
    parts = [f"{len(job.names)} object{'s' if len(job.names) != 1 else ''} ({job.label()})"]
    if unchanged or held:
        kept = [f"kept {', '.join(unchanged)} (unchanged)"] if unchanged else []
        kept += [f"kept {', '.join(held)} (not in this bake)"] if held else []
        parts.append(f"baked {', '.join(baked) or 'none'}; " + "; ".join(kept))
    return "; ".join(parts)


def notes(result):
    """The atlas's warnings: overlapping UVs between its objects; objects baked again only because an
    unlimited distance makes every object reach every other."""
    report = getattr(result, "report", None) or {}
    out = []
    for o in report.get("atlas_overlaps") or []:
        tile = f" in UDIM tile {o['tile']}" if "tile" in o else ""
        out.append(f"the UVs of {o['a']} and {o['b']} overlap on {o['texels']} texel{'s' if o['texels'] != 1 else ''}"
                   f"{tile}; each such texel goes to the object covering more of it")
    atlas = report.get("atlas") or {}
    why = atlas.get("why") or {}
    if atlas.get("unlimited_reach") and any("within its reach changed" in w for w in why.values()):
        out.append("the distance is unlimited, so every object reaches every other: a change to one bakes them all "
                   "again (a finite Distance bakes again only the objects near a change)")
    return out


def prepare(jobs, settings, folder=None, formats=None, in_blender=False):
    """Before a bake: the jobs, each AtlasJob with its size (in Blender, an existing image keeps its
    own; files: the settings') and the records of the earlier bakes it starts from (the image's own in
    Blender, else the one beside its first file in ``folder``), checked against the bake; and an
    object's own job whose image holds other objects' texels (an Image name without ``{object}``)
    turned into an AtlasJob of that one object, which keeps them. Raises ExtractError naming the
    image where objects it holds would be lost."""
    import os

    if settings.vertex_colors or settings.use_udim:
        return jobs
    try:
        from .baking import id_name_max_bytes

        max_bytes = id_name_max_bytes()
    except ImportError:
        max_bytes = None
    stems = {}
    if folder is not None and not in_blender:
        from . import filewriter

        names = [n for job in jobs for q in settings.quantities
                 for n in [_quantity_image(job, settings, q, max_bytes)]]
        for name, entries in filewriter.output_files(folder, names, formats or [("PNG", None)]).items():
            stems[name] = os.path.splitext(os.path.basename(os.fspath(entries[0].path)))[0]

    def record(name, q):
        if in_blender:
            return record_of(name, q)
        stem = stems.get(name)
        return None if stem is None else record_of(name, q, folder, stem)

    out = []
    for job in jobs:
        if not getattr(job, "atlas", False):
            held = record(job.image_name, job.quantity) if "{object}" not in (settings.image_name or "{object}") else None
            if held is None or not [n for n in held.names if n != job.object_name]:
                out.append(job)
                continue
            job = AtlasJob(job.image_name, job.image_name, [job.object_name], [job.target], [True], job.occluders,
                           sources=[job.highpoly] if job.highpoly else None,
                           cages=[job.cage] if job.highpoly else None, extrusion=job.extrusion,
                           max_ray_distance=job.max_ray_distance, quantity=job.quantity, notes=job.notes)
        if in_blender:
            job.size = image_size(job.image_name, settings)
        size = tuple(job.size or settings.size)
        job.keep = {}
        for q in settings.quantities:
            name = _quantity_image(job, settings, q, max_bytes)
            rec = record(name, q)
            if rec is not None and (rec.width, rec.height) != size:
                others = [n for n in rec.names if n not in job.names]
                if others:
                    raise ExtractError(f"image {name!r} holds the texels of {', '.join(others)} at "
                                       f"{rec.width}x{rec.height}, and this bake is {size[0]}x{size[1]}: bake "
                                       "at its size, or bake those objects too")
                rec = None
            job.keep[q] = rec
        out.append(job)
    return out


def _quantity_image(job, settings, quantity, max_bytes):
    """The image of ``quantity`` of the bake that makes ``job``'s image (a shared image's root name)."""
    if quantity == job.quantity:
        return job.image_name
    return settings.quantity_image_name_for(job.object_name, quantity, max_bytes, root=getattr(job, "atlas", False))
