"""Which objects occlude a bake: the Occluders choice, narrowed to collections, less the objects that
occlude only themselves. Reads Blender data (main thread); imports no bpy at module level.

What counts as rendered follows Cycles' bake (which renders the view layer): an object counts when it
renders, whatever the viewport shows.

- Hidden in the viewport (the eye, H) counts; its geometry is the depsgraph's, modifiers applied.
- Disabled in Viewports (the monitor icon, on the object or a collection) counts too, read from its
  data without modifiers (Blender evaluates none for it); the bake's notes say so where it has some.
- Disabled in Renders (the camera icon, on the object or a collection) and an excluded collection
  (the view layer's checkbox) do not count.
- Instances (collection instances, geometry-nodes instances, vertex and face instancing) count as
  their instancer does, and belong to the instancer's collections for Include and Exclude; each is
  flattened into its own triangles (memory: core.execution.cost's bytes per triangle, in every worker process).
  An instancer that is hidden or disabled in the viewport has its collection instances counted;
  geometry-nodes instances exist only where the viewport evaluates the object.
- ``object.mc_ao.occlude_others`` off: the object occludes only itself (when it is baked).

Include and Exclude (collection names; nested collections count as Blender nests them): with Include,
only objects in an included collection occlude; an object in an excluded collection does not. Where
an object lies in both, the named collection nearer to it decides (its own collection is 0 steps
away, that collection's parent 1, ...): excluding a collection inside an included one carves it out,
including one inside an excluded one carves it back in. At equal steps the choice is ambiguous and
refused, naming the object and both collections.
"""

from .extract import GEOMETRY_TYPES, ExtractError, object_arrays

__all__ = ["occlude_others", "rendered_names", "Chooser", "pool", "triangle_count"]

# Collection instances inside collection instances are followed this deep (Blender's own limit is 8).
MAX_INSTANCE_DEPTH = 8


def occlude_others(obj):
    """``obj.mc_ao.occlude_others``; also where the add-on is not registered (a background script),
    from the value stored with the object. True when never set."""
    props = getattr(obj, "mc_ao", None)
    if props is not None and hasattr(props, "occlude_others"):
        return bool(props.occlude_others)
    # Blender 5.0 keeps the values of registered properties apart from an object's custom
    # properties (bl_system_properties_get); earlier versions keep them among them.
    system = getattr(obj, "bl_system_properties_get", None)
    stored = system() if system is not None else obj
    try:
        group = stored.get("mc_ao") if stored is not None else None
    except (TypeError, AttributeError):
        group = None
    if group is not None and hasattr(group, "get"):
        return bool(group.get("occlude_others", True))
    return True


def rendered_names(view_layer):
    """Names of the objects that render in ``view_layer``: in a collection the view layer does not
    exclude, with no collection on the way disabled in renders, and not disabled in renders themselves."""
    names = set()

    def walk(layer_collection):
        if layer_collection.exclude or layer_collection.collection.hide_render:
            return
        for obj in layer_collection.collection.objects:
            if not obj.hide_render:
                names.add(obj.name)
        for child in layer_collection.children:
            walk(child)

    root = view_layer.layer_collection  # the scene's own collection, never excluded
    for obj in root.collection.objects:
        if not obj.hide_render:
            names.add(obj.name)
    for child in root.children:
        walk(child)
    return names


class Chooser:
    """Include and Exclude of one scene, checked: ``chosen(obj)`` says whether ``obj`` may occlude.

    Raises ExtractError, before any geometry is read, for a collection that does not exist, is not in
    the scene or is empty, a collection named in both lists, and (from ``chosen``) an object that an
    included and an excluded collection claim at the same distance.
    """

    def __init__(self, scene, include=(), exclude=()):
        import bpy

        self.include, self.exclude = tuple(include), tuple(exclude)
        both = sorted(set(self.include) & set(self.exclude))
        if both:
            raise ExtractError(f"collection {both[0]!r} is both an occluder collection and an excluded one: "
                               "remove it from one list")
        self.parents = {}  # collection name -> names of the collections it is a child of
        in_scene = set()

        def walk(collection):
            for child in collection.children:
                self.parents.setdefault(child.name, set()).add(collection.name)
                if child.name not in in_scene:
                    in_scene.add(child.name)
                    walk(child)

        walk(scene.collection)
        for what, names in (("occluder collection", self.include), ("excluded collection", self.exclude)):
            for name in names:
                collection = bpy.data.collections.get(name)
                if collection is None:
                    known = ", ".join(repr(n) for n in sorted(in_scene)[:8]) or "none"
                    raise ExtractError(f"{what} {name!r} does not exist (collections of scene {scene.name!r}: "
                                       f"{known})")
                if name not in in_scene:
                    raise ExtractError(f"{what} {name!r} is not in scene {scene.name!r}: link it into the scene")
                if not len(collection.all_objects):
                    raise ExtractError(f"{what} {name!r} is empty: it holds no objects, so it would "
                                       f"{'let nothing occlude' if what.startswith('occluder') else 'exclude nothing'}")

    @property
    def active(self):
        return bool(self.include or self.exclude)

    def steps(self, obj):
        """``{collection name: steps}`` from ``obj`` to every collection that holds it, directly (0) or
        through the collections inside it."""
        steps, frontier, step = {}, [c.name for c in obj.users_collection], 0
        while frontier:
            following = []
            for name in frontier:
                if name not in steps:
                    steps[name] = step
                    following.extend(self.parents.get(name, ()))
            frontier, step = following, step + 1
        return steps

    def chosen(self, obj):
        """Whether ``obj`` (an original object; for an instance, its instancer) may occlude."""
        if not self.active:
            return True
        steps = self.steps(obj)
        near_in = min(((steps[n], n) for n in self.include if n in steps), default=None)
        near_out = min(((steps[n], n) for n in self.exclude if n in steps), default=None)
        if near_out is None:
            return near_in is not None or not self.include
        if near_in is None or near_out[0] < near_in[0]:
            return False
        if near_in[0] < near_out[0]:
            return True
        raise ExtractError(
            f"{obj.name} is in the occluder collection {near_in[1]!r} and the excluded collection {near_out[1]!r} "
            f"alike ({near_in[0]} step{'s' if near_in[0] != 1 else ''} from each): move it out of one, or "
            "name a collection nearer to it")


def _instancer_counts(obj):
    """Whether an instancer's own geometry renders beside its instances (vertex and face instancing
    hide it unless Show Instancer for Render is on)."""
    return not (obj.instance_type in ("VERTS", "FACES") and not obj.show_instancer_for_render)


def triangle_count(obj_eval, matrix=None):
    """How many triangles :func:`object_arrays` reads from an evaluated object, None where it reads
    none (no faces): a mesh's from its counts of faces and face corners (an n-gon is n - 2 triangles),
    without reading them; another type's (a curve, a text) through a temporary mesh."""
    if obj_eval.type == "MESH" and obj_eval.data is not None:
        mesh = obj_eval.data
        return len(mesh.loops) - 2 * len(mesh.polygons) if len(mesh.polygons) else None
    mesh = obj_eval.to_mesh()
    try:
        return len(mesh.loops) - 2 * len(mesh.polygons) if mesh is not None and len(mesh.polygons) else None
    finally:
        obj_eval.to_mesh_clear()


def _collection_instances(instancer, matrix, depsgraph, depth=0, read=object_arrays):
    """``read(evaluated object, matrix=...)`` (MeshArrays) of the objects a collection instance
    places, at ``matrix`` (the instancer's world matrix), following collection instances inside it."""
    from mathutils import Matrix

    collection = instancer.instance_collection
    if collection is None or depth >= MAX_INSTANCE_DEPTH:
        return
    place = matrix @ Matrix.Translation(-collection.instance_offset)
    for obj in collection.all_objects:
        if obj.hide_render:
            continue
        m = place @ obj.matrix_world
        if obj.type in GEOMETRY_TYPES:
            arrays = read(obj.evaluated_get(depsgraph), matrix=m)
            if arrays is not None:
                yield arrays
        if obj.instance_type == "COLLECTION":
            yield from _collection_instances(obj, m, depsgraph, depth + 1, read)


def _rendered_geometry(depsgraph, view_layer, chooser, notes, read=object_arrays):
    """(original object name, or None for an instance; ``read``'s MeshArrays) of every rendered, chosen object."""
    import bpy

    rendered = rendered_names(view_layer)
    chosen = {}  # name -> whether it may occlude others, decided once per object
    # bpy.data.objects.get(name) searches the list: once per object, that is quadratic in the objects
    objects = {}
    for obj in bpy.data.objects:
        objects.setdefault(obj.name, obj)

    def decide(obj):
        if obj.name not in chosen:
            chosen[obj.name] = occlude_others(obj) and chooser.chosen(obj)
        return chosen[obj.name]

    for name in sorted(rendered):  # every refusal before any geometry is read
        obj = objects.get(name)
        if obj is not None:
            decide(obj)
    seen = set()
    for inst in depsgraph.object_instances:
        obj = inst.object
        owner = (inst.parent if inst.is_instance else obj).original
        if not inst.is_instance:
            seen.add(owner.name)
        if owner.name not in rendered or obj.type not in GEOMETRY_TYPES:
            continue
        if not inst.is_instance and owner.is_instancer and not _instancer_counts(owner):
            continue
        if not decide(owner):
            continue
        arrays = read(obj, matrix=inst.matrix_world.copy())
        if arrays is not None:
            yield (None if inst.is_instance else owner.name), arrays
    # Objects that render but that the viewport does not draw: hidden (evaluated all the same) or
    # disabled in viewports (not evaluated: their data without modifiers).
    for name in sorted(rendered - seen):
        obj = objects.get(name)
        if obj is None or not decide(obj):
            continue
        evaluated = obj.evaluated_get(depsgraph)
        if obj.type in GEOMETRY_TYPES and _instancer_counts(obj):
            if not evaluated.is_evaluated and len(obj.modifiers):
                notes.append(f"{name} is disabled in viewports: it occludes as its data without its modifiers "
                             "(enable it in viewports for its modifiers)")
            arrays = read(evaluated)
            if arrays is not None:
                yield name, arrays
        if obj.instance_type == "COLLECTION":
            for arrays in _collection_instances(obj, obj.matrix_world, depsgraph, read=read):
                yield None, arrays


def _selected_geometry(depsgraph, objects, chooser, read=object_arrays):
    objects = [obj for obj in objects if obj.type in GEOMETRY_TYPES and occlude_others(obj)]
    objects = [obj for obj in objects if chooser.chosen(obj)]  # every refusal before any geometry is read
    for obj in objects:
        arrays = read(obj.evaluated_get(depsgraph))
        if arrays is not None:
            yield obj.name, arrays


def pool(depsgraph, settings, *, selected=(), view_layer=None, notes=None, read=object_arrays):
    """Every occluder of a bake: ``[(original object name or None for an instance, MeshArrays)]``;
    with ``read=triangle_count``, the same objects' triangle counts in place of their MeshArrays (what
    the estimate of a bake counts, without reading any geometry).

    A target leaves itself out (its own name); it always occludes itself in the core. Empty for Only
    Local and Object Alone. ``notes`` (a list) receives what the bake should say about the occluders.

    Raises ExtractError for a bad Include or Exclude (see :class:`Chooser`) before reading any geometry.
    """
    view_layer = view_layer or depsgraph.view_layer
    chooser = Chooser(depsgraph.scene, settings.occluder_collections, settings.exclude_collections)
    notes = [] if notes is None else notes
    if settings.only_local or settings.occluders == "SELF" or "ao" not in settings.quantities:
        return []  # (a thickness map: only the object itself occludes it)
    if settings.occluders == "SELECTED":
        return list(_selected_geometry(depsgraph, selected, chooser, read))
    return list(_rendered_geometry(depsgraph, view_layer, chooser, notes, read))
