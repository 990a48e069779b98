"""Selected to Active in Blender: bake the AO of the selected objects into the active one's UVs.

The same settings as Cycles' Bake panel (``scene.mc_ao.use_selected_to_active``, ``cage_extrusion``,
``max_ray_distance``, ``use_cage``, ``cage_object``) and the same objects: the active object is the
low-poly target (a mesh with a UV map), every other selected object with a surface (meshes, curves,
text, metaballs, evaluated with their modifiers) is a high-poly source. Its image is
``<active>_AO`` (the Image setting applies as for any bake). The core's rules are in
:mod:`core.highpoly`; this module picks the objects, reads their geometry and checks them, and needs
no bpy at import.

How Blender's objects become the core's input, as Cycles does it (``object_bake_api.cc``):

- the low-poly's normals: its corner normals (Cycles extrudes along the vertex normals of the mesh
  split at sharp edges and flat faces, the same except where the mesh has custom normals); with
  Cage on and no cage object, its vertex normals (Cycles' cage: the unsplit mesh, always smooth);
- the extrusion is in the low-poly's object space in Cycles: mc_ao multiplies it by the object's
  scale (exact for a uniform scale; for a non-uniform one the report says so);
- a cage object must have the low-poly's topology after modifiers (the same faces, corners and the
  same vertices at every corner: a copy with its vertices moved); its vertices are read in world
  space through its own transform, on the low-poly's triangles;
- Occluders: All Rendered adds every other object that renders (as Cycles, which renders the view
  layer), narrowed by Include, Exclude, Only Local and each object's Occludes Other Objects
  (mc_ao.occluders); Selected and Object Alone leave the high-poly objects alone. The low-poly and
  the cage never occlude.
"""

import numpy as np

from .baking import Job, check_channel, id_name_max_bytes, kind_of, skip_reason
from .extract import GEOMETRY_TYPES, ExtractError, MeshArrays, object_arrays


def high_objects(selected, active, cage=None):
    """The selected objects with a surface other than the active one and the cage, in name order."""
    return sorted((o for o in selected if o is not active and o is not cage and o.type in GEOMETRY_TYPES),
                  key=lambda o: o.name)


def cage_of(settings):
    """The cage object the settings name (a pointer on scene.mc_ao, a name in a BakeSettings), or None."""
    if not getattr(settings, "use_cage", False):
        return None
    cage = getattr(settings, "cage_object", None)
    if isinstance(cage, str):
        if not cage:
            return None
        import bpy

        return bpy.data.objects.get(cage)
    return cage


def why_not(selected, active, cage=None):
    """None when Selected to Active can bake the selection, else why not (for the poll, panel, report)."""
    if active is None:
        return "Selected to Active needs an active object: the low-poly to bake onto (select it last)"
    if active.type != "MESH":
        return f"Selected to Active: the active object {active.name} is {kind_of(active)}, not a mesh to bake onto"
    reason = skip_reason(active)
    if reason is not None:
        return f"Selected to Active: the active object {active.name} {reason}"
    if cage is active:
        return f"Selected to Active: the cage object is {active.name} itself; choose a copy of it, moved outwards"
    if cage is not None and cage.type != "MESH":
        return f"Selected to Active: the cage object {cage.name} is {kind_of(cage)}, not a mesh"
    others = [o for o in selected if o is not active]
    if not high_objects(others, active, cage):
        if not [o for o in others if o is not cage]:
            return f"Selected to Active: select the high-poly objects to bake from, then {active.name} last"
        return f"Selected to Active: none of the objects selected besides {active.name} has a surface to bake from"
    return None


def _scale(matrix):
    """The uniform scale of an object's transform (cube root of |det|) and whether it is uniform."""
    m = np.array(matrix, dtype=np.float64).reshape(4, 4)[:3, :3]
    axes = np.linalg.norm(m, axis=0)
    s = abs(float(np.linalg.det(m))) ** (1.0 / 3.0)
    return s, bool(np.allclose(axes, s, rtol=1e-6, atol=0.0))


def _topology(mesh):
    corners = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corners)
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    return len(mesh.vertices), sizes, corners


def cage_arrays(low_eval, cage_eval, target):
    """The cage's vertices in world space on the low-poly's triangles (``target``'s), or ExtractError
    when the cage's evaluated mesh does not have the low-poly's topology."""
    low_name, cage_name = low_eval.original.name, cage_eval.original.name
    low_mesh = low_eval.to_mesh()
    try:
        low_topology = _topology(low_mesh)
    finally:
        low_eval.to_mesh_clear()
    cage_mesh = cage_eval.to_mesh()
    try:
        if cage_mesh is None:
            raise ExtractError(f"the cage object {cage_name} has no mesh")
        cage_topology = _topology(cage_mesh)
        positions = np.empty(3 * len(cage_mesh.vertices), np.float32)  # Blender's own type: one copy
        cage_mesh.vertices.foreach_get("co", positions)
        positions = positions.astype(np.float64)
    finally:
        cage_eval.to_mesh_clear()
    same = (low_topology[0] == cage_topology[0] and np.array_equal(low_topology[1], cage_topology[1])
            and np.array_equal(low_topology[2], cage_topology[2]))
    if not same:
        def describe(t):
            return f"{t[0]} vertices, {len(t[1])} faces, {len(t[2])} corners"

        raise ExtractError(
            f"the cage object {cage_name} does not have the topology of {low_name} after modifiers "
            f"({cage_name}: {describe(cage_topology)}; {low_name}: {describe(low_topology)}"
            + (", the faces use other vertices" if describe(cage_topology) == describe(low_topology) else "")
            + f"): the cage must be a copy of {low_name} with only its vertices moved"
        )
    m = np.array(cage_eval.matrix_world, dtype=np.float64).reshape(4, 4)
    positions = positions.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return MeshArrays(name=cage_name, positions=positions, triangles=target.triangles)


def plan(depsgraph, active, selected, settings, *, view_layer=None, max_bytes=None):
    """The Job of a Selected to Active bake: ``active`` (original object) from the other objects of
    ``selected``, with ``settings`` (mc_ao.settings.BakeSettings). Raises ExtractError naming the
    objects (no faces, a cage of another topology, high-poly objects without faces)."""
    from . import occluders as occluder_sets

    cage = cage_of(settings)
    reason = why_not(selected, active, cage)
    if reason is not None:
        raise ExtractError(reason)
    check_channel(settings)
    highs = high_objects(selected, active, cage)
    active_eval = active.evaluated_get(depsgraph)
    use_vertex_normals = settings.use_cage and cage is None
    target = object_arrays(active_eval, uv_map=settings.uv_map, with_uvs=True, with_normals=True,
                           vertex_normals=use_vertex_normals)
    if target is None:
        raise ExtractError(f"{active.name} has no faces to bake")
    sources = []
    for obj in highs:
        arrays = object_arrays(obj.evaluated_get(depsgraph), with_normals=True)
        if arrays is not None:
            sources.append(arrays)
    if not sources:
        names = ", ".join(o.name for o in highs)
        raise ExtractError(f"Selected to Active: {names} {'has' if len(highs) == 1 else 'have'} no faces to bake from")
    cage_mesh = None
    if cage is not None:
        cage_mesh = cage_arrays(active_eval, cage.evaluated_get(depsgraph), target)
    notes = []
    scale, uniform = _scale(active_eval.matrix_world)
    if not uniform and cage is None and settings.cage_extrusion > 0:
        notes.append(f"{active.name} has a non-uniform scale: the extrusion is applied along its world normals, "
                     f"scaled by {scale:.4g} (Cycles scales it per axis); apply the scale (Ctrl A) for the same "
                     "result as Cycles")
    occluders = []
    if settings.occluders == "VISIBLE" and settings.quantities == ("ao",):  # Selected: the high-poly objects alone, as Object Alone
        skip = {active.name, *(o.name for o in highs)} | ({cage.name} if cage is not None else set())
        occluders = [arrays for key, arrays in occluder_sets.pool(depsgraph, settings, view_layer=view_layer,
                                                                 notes=notes)
                     if key not in skip]
    elif settings.occluder_collections or settings.exclude_collections:
        occluder_sets.Chooser(depsgraph.scene, settings.occluder_collections, settings.exclude_collections)
    max_bytes = id_name_max_bytes() if max_bytes is None else max_bytes
    (quantity,) = settings.quantities  # one: mc_ao.schema refuses both with Selected to Active
    job = Job(active.name, settings.quantity_image_name_for(active.name, quantity, max_bytes), target, occluders,
              quantity=quantity)
    job.highpoly = sources
    job.cage = cage_mesh
    job.extrusion = 0.0 if cage is not None else settings.cage_extrusion * scale
    job.max_ray_distance = settings.max_ray_distance
    job.notes = notes
    return job


__all__ = ["high_objects", "cage_of", "why_not", "cage_arrays", "plan"]
