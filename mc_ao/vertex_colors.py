"""Colour attributes as a bake target (scene.mc_ao.target = 'VERTEX_COLORS'), Cycles' way.

Cycles' AO bake into a colour attribute (``bake_targets_init_vertex_colors`` and
``bake_targets_output_vertex_colors`` in Blender's object_bake_api.cc) estimates one value
per face corner at the corner's vertex (a hair inside the first triangle holding it), with the
corner's shading normal, and stores in the point domain the plain mean of a vertex's corners, in
the corner domain each corner's own; float colours hold the linear value, byte colours its sRGB
encoding (``linearrgb_to_srgb_uchar4``). The core does the estimating
(:func:`core.bake_vertex_ao`); this module maps Blender's face corners to it and writes
the attribute:

- the face corners come from the evaluated mesh (modifiers applied); they must be the original
  mesh's (Cycles maps a changed topology back through original indices, which Python cannot
  reach): a modifier that adds or removes vertices or faces is refused with the object's name;
- the attribute is the one named by the settings ("AO"), created when missing, as a float colour
  with 32-bit Float on, else a byte colour, on the chosen domain; an attribute of that name with
  another type or domain (or any attribute that is not a colour) is refused before baking, naming
  the object and the attribute (Cycles silently follows the existing attribute instead);
- nothing changes until the bake of the object finishes: Esc and failures leave the mesh as it was,
  and the write is one undo step with the operator's.

Everything here but :func:`corner_data` and :func:`ply_data` (which read a temporary mesh) runs in
the main thread.
"""

import numpy as np

from .extract import ExtractError

DOMAIN_NAMES = {"POINT": "Vertex", "CORNER": "Face Corner"}
TYPE_NAMES = {"FLOAT_COLOR": "float color", "BYTE_COLOR": "byte color"}


def attribute_type(settings):
    """The colour attribute type a bake creates: FLOAT_COLOR with 32-bit Float on, else BYTE_COLOR."""
    return "FLOAT_COLOR" if settings.float_buffer else "BYTE_COLOR"


def corner_data(mesh, arrays):
    """From the evaluated (temporary) mesh: each face corner's (triangle, corner) for the core, its
    vertex, the counts, and the object-space faces for a PLY file."""
    loops = arrays.loops.reshape(-1)
    n_loops = len(mesh.loops)
    _, first = np.unique(loops, return_index=True)
    if len(first) != n_loops:  # every face corner is in some triangle of the tessellation
        raise ExtractError(f"{arrays.name}: {n_loops - len(first)} face corners are in no triangle")
    corners = np.stack([first // 3, first % 3], axis=1).astype(np.int64)
    corner_vertex = np.empty(n_loops, np.int32)
    mesh.loops.foreach_get("vertex_index", corner_vertex)
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    starts = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_start", starts)
    # Corners of each face in order (loop_start .. + loop_total), as PLY faces list them.
    face_loops = np.concatenate([np.arange(s, s + k) for s, k in zip(starts, sizes)]) if len(sizes) else \
        np.zeros(0, np.int64)
    return {"corners": corners, "corner_vertex": corner_vertex, "vertex_count": len(mesh.vertices),
            "loop_count": n_loops, "object_positions": co.reshape(-1, 3), "face_sizes": sizes,
            "face_loops": face_loops}


def check_object(obj, settings, data=None):
    """Raise ExtractError (naming the object and the attribute) when ``obj`` cannot take the bake:
    Edit Mode, an attribute of that name with another type or domain, or (``data`` from
    :func:`corner_data`) modifiers that change its vertices or face corners."""
    mesh = obj.data
    name = settings.attribute_name
    if not name.strip():
        raise ExtractError(f"{obj.name}: no color attribute name is set; name one (Attribute)")
    if obj.mode == "EDIT":
        raise ExtractError(f"{obj.name} is in Edit Mode; switch to Object Mode to bake into its color attribute")
    want_type, want_domain = attribute_type(settings), settings.attribute_domain
    existing = mesh.attributes.get(name)
    if existing is not None:
        if existing.data_type not in TYPE_NAMES:
            raise ExtractError(
                f"{obj.name}: its mesh {mesh.name!r} has an attribute {name!r} of type {existing.data_type} "
                f"on the {DOMAIN_NAMES.get(existing.domain, existing.domain)} domain, not a color attribute; "
                "choose another attribute name or remove it"
            )
        if (existing.data_type, existing.domain) != (want_type, want_domain):
            fix = []
            if existing.data_type != want_type:
                fix.append(f"turn 32-bit Float {'on' if existing.data_type == 'FLOAT_COLOR' else 'off'}")
            if existing.domain != want_domain:
                fix.append(f"set Domain to {DOMAIN_NAMES.get(existing.domain, existing.domain)}")
            raise ExtractError(
                f"{obj.name}: color attribute {name!r} is a {TYPE_NAMES[existing.data_type]} on the "
                f"{DOMAIN_NAMES.get(existing.domain, existing.domain)} domain, the bake would write a "
                f"{TYPE_NAMES[want_type]} on the {DOMAIN_NAMES[want_domain]} domain; "
                f"{' and '.join(fix)}, or choose another attribute name"
            )
    if data is not None and (data["vertex_count"], data["loop_count"]) != (len(mesh.vertices), len(mesh.loops)):
        raise ExtractError(
            f"{obj.name}: its modifiers change the mesh ({data['vertex_count']} vertices and {data['loop_count']} "
            f"face corners evaluated, {len(mesh.vertices)} and {len(mesh.loops)} in the mesh), so the bake "
            "cannot be stored in its color attribute; apply the modifiers or bake into image textures"
        )


def modifier_problem(obj, depsgraph):
    """Why ``obj``'s color attribute cannot take a bake because its modifiers change its vertices or
    face corners (the evaluated mesh against its own, as the bake's check finds it), or None. Cheap
    enough for a button's poll: the depsgraph has the evaluated mesh already."""
    if obj.type != "MESH" or depsgraph is None:
        return None
    evaluated = obj.evaluated_get(depsgraph).data
    mesh = obj.data
    if (len(evaluated.vertices), len(evaluated.loops)) == (len(mesh.vertices), len(mesh.loops)):
        return None
    return (f"{obj.name}: its modifiers change the mesh ({len(evaluated.vertices)} vertices and "
            f"{len(evaluated.loops)} face corners evaluated, {len(mesh.vertices)} and {len(mesh.loops)} in the "
            "mesh), so the bake cannot be stored in its color attribute; apply the modifiers or bake into "
            "image textures")


def values(result, data, domain):
    """The attribute's values (N,) float: per face corner, or per vertex the mean of its corners'."""
    core_vertices = _core_vertices()
    if domain == "CORNER":
        return result.ao.astype(np.float64)
    return core_vertices.vertex_means(result.ao, data["corner_vertex"], data["vertex_count"])


def _core_vertices():
    from . import corelink

    return corelink.load("geometry.corners")


def write_attribute(obj, settings, result, data):
    """Store the finished bake in ``obj``'s colour attribute (created if missing); return its name.

    Linear values through ``.color`` (a byte attribute encodes them to sRGB as Cycles does), RGB =
    AO, alpha 1. Raises ExtractError if the attribute changed since the check before the bake.
    """
    check_object(obj, settings)
    mesh = obj.data
    name = settings.attribute_name
    ao = values(result, data, settings.attribute_domain)
    created = False
    attr = mesh.color_attributes.get(name)
    if attr is None:
        attr = mesh.color_attributes.new(name, attribute_type(settings), settings.attribute_domain)
        created = True
    try:
        if len(attr.data) != len(ao):
            raise ExtractError(f"{obj.name}: color attribute {name!r} has {len(attr.data)} values, the bake {len(ao)}")
        rgba = np.ones((len(ao), 4), np.float32)
        rgba[:, :3] = np.clip(ao, 0.0, 1.0)[:, None]
        attr.data.foreach_set("color", rgba.ravel())
    except BaseException:
        if created:
            mesh.color_attributes.remove(attr)
        raise
    mesh.update()
    return name


def ply_data(result, data, domain):
    """(positions, face sizes, face vertices, ao) of the PLY file of a finished bake (object space):
    per vertex, or with every face corner a vertex of its own for the corner domain."""
    ao = values(result, data, domain)
    sizes = data["face_sizes"]
    if domain == "CORNER":
        positions = data["object_positions"][data["corner_vertex"]]
        return positions, sizes, data["face_loops"], ao
    return data["object_positions"], sizes, data["corner_vertex"][data["face_loops"]], ao
