"""Evaluated Blender geometry -> numpy arrays in world space, the input of core.Mesh.

Everything here runs in the main thread (it reads bpy data); the arrays it returns are plain numpy
and may then go to worker threads.
"""

from dataclasses import dataclass

import numpy as np

# Object types that evaluate to a mesh (and can occlude); only meshes carry UV maps for a target.
GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}


class ExtractError(ValueError):
    """The geometry of an object cannot be baked (no UV map, a degenerate transform, ...)."""


@dataclass
class MeshArrays:
    """Triangles of one object in world space.

    positions (V, 3) float64, triangles (T, 3) int32, uvs (T, 3, 2) float32 per corner or None,
    normals (T, 3, 3) float32 per corner (unit length) or None.
    """

    name: str
    positions: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray | None = None
    normals: np.ndarray | None = None
    loops: np.ndarray | None = None  # (T, 3) int32: the mesh's face corner (loop) of each triangle corner
    extra: dict | None = None  # what object_arrays(extra=...) added (colour-attribute corners, tangents)
    matrix: np.ndarray | None = None  # (4, 4) the object-to-world matrix the positions went through


def default_uv_map(mesh):
    """Name of the UV map a bake uses when none is named: the active render one, else the active one."""
    layers = mesh.uv_layers
    for layer in layers:
        if layer.active_render:
            return layer.name
    if layers.active is not None:
        return layers.active.name
    return layers[0].name if len(layers) else None


def _foreach(collection, attr, count, width, dtype, as_type=None):
    """``collection.foreach_get(attr)`` as a (count, width) array. ``dtype`` must be the property's own
    type (float32 for coordinates and normals, uint32 for a loop triangle's indices): Blender copies a
    matching buffer at once and converts any other type element by element (dense.blend's 524k
    triangles: 0.45 s against 0.02 s); ``as_type`` converts afterwards, exactly."""
    out = np.empty(count * width, dtype=dtype)
    collection.foreach_get(attr, out)
    if as_type is not None:
        out = out.astype(as_type)
    return out.reshape(count, width) if width > 1 else out


def _rows(a, index):
    """a[index] for an integer index array (np.take: numpy's fancy indexing is several times slower)."""
    return np.take(a, index.reshape(-1), axis=0).reshape(index.shape + a.shape[1:])


def mesh_arrays(name, mesh, matrix, *, uv_map=None, with_uvs=False, with_normals=False, vertex_normals=False):
    """Triangles of a (usually evaluated) Blender mesh, transformed by ``matrix`` into world space.

    Parameters
    ----------
    name : str
        Object name, for messages.
    mesh : bpy.types.Mesh
    matrix : mathutils.Matrix or array_like (4, 4)
        Object-to-world transform (``object.matrix_world`` or an instance's matrix).
    uv_map : str, optional
        UV map to read when ``with_uvs``; "" or None picks :func:`default_uv_map`.
    with_uvs, with_normals : bool
        Read the per-corner UVs and the corner normals (Blender's custom, smooth or flat normals,
        whatever the mesh shades with). Occluders need neither.
    vertex_normals : bool
        With ``with_normals``, the vertex normals instead (from the geometry alone: what Cycles'
        Selected to Active extrudes a cage along).

    Returns
    -------
    MeshArrays

    Raises
    ------
    ExtractError
        The mesh has no UV map (or not the named one), or the transform is singular while normals
        are wanted.
    """
    uv_layer = None
    if with_uvs:
        uv_name = uv_map or default_uv_map(mesh)
        uv_layer = mesh.uv_layers.get(uv_name) if uv_name else None
        if uv_layer is None:
            if uv_map:
                have = ", ".join(repr(layer.name) for layer in mesh.uv_layers) or "none"
                raise ExtractError(f"{name} has no UV map {uv_map!r} (UV maps: {have})")
            raise ExtractError(f"{name} has no UV map; unwrap it first (Edit Mode, U)")

    mesh.calc_loop_triangles()
    tris = mesh.loop_triangles
    n_tris = len(tris)
    m = np.array(matrix, dtype=np.float64).reshape(4, 4)
    linear = m[:3, :3]

    positions = _foreach(mesh.vertices, "co", len(mesh.vertices), 3, np.float32, np.float64)
    positions = positions @ linear.T + m[:3, 3]
    triangles = _foreach(tris, "vertices", n_tris, 3, np.uint32, np.int32)
    corners = _foreach(tris, "loops", n_tris, 3, np.uint32, np.int32)

    uvs = None
    if uv_layer is not None:
        uvs = _rows(_foreach(uv_layer.uv, "vector", len(mesh.loops), 2, np.float32), corners)

    normals = None
    if with_normals:
        try:
            # Normals transform with the inverse transpose; as row vectors that is n @ inv(M).
            to_world = np.linalg.inv(linear)
        except np.linalg.LinAlgError:
            raise ExtractError(f"{name} has a zero scale, its surface has no normal") from None
        if vertex_normals:
            verts = _foreach(mesh.loops, "vertex_index", len(mesh.loops), 1, np.int32)
            normals = _rows(_foreach(mesh.vertex_normals, "vector", len(mesh.vertices), 3, np.float32, np.float64), verts)
        else:
            normals = _foreach(mesh.corner_normals, "vector", len(mesh.loops), 3, np.float32, np.float64)
        normals = normals @ to_world
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
        normals = _rows(normals.astype(np.float32), corners)

    if np.linalg.det(linear) < 0:
        # A mirroring transform reverses the winding; swap two corners so that the triangles' own
        # (right-hand) normals still point out of the surface, as the corner normals do.
        order = [0, 2, 1]
        triangles = triangles[:, order]
        uvs = None if uvs is None else uvs[:, order]
        normals = None if normals is None else normals[:, order]
        corners = corners[:, order]

    return MeshArrays(name=name, positions=positions, triangles=triangles, uvs=uvs, normals=normals, loops=corners,
                      matrix=m)


def object_arrays(obj_eval, matrix=None, extra=None, **kwargs):
    """:func:`mesh_arrays` of an evaluated object (modifiers applied), via a temporary mesh.

    ``extra``: None, or a callable ``extra(mesh, arrays)`` returning a dict, called with the temporary
    mesh before it is freed; its dict becomes ``arrays.extra`` (mc_ao.vertex_colors and mc_ao.bent
    read face corners and tangents there).

    Returns None for an object without faces (an empty curve, a text with no characters, ...).
    """
    mesh = obj_eval.to_mesh()
    try:
        if mesh is None or len(mesh.polygons) == 0:
            return None
        name = obj_eval.original.name if obj_eval.original is not None else obj_eval.name
        arrays = mesh_arrays(name, mesh, obj_eval.matrix_world if matrix is None else matrix, **kwargs)
        if extra is not None:
            arrays.extra = extra(mesh, arrays)
        return arrays
    finally:
        obj_eval.to_mesh_clear()
