"""Bent normals on the Blender side (scene.mc_ao.bent_normals): the frames, the image, its files.

The core estimates each texel's bent normal from the AO bake's own rays and expresses it in the
space asked for (:mod:`core.post.bent`). Here:

- tangent space: the frames Blender's normal bake and the Normal Map node use: MikkTSpace tangents
  and bitangent signs per face corner from ``Mesh.calc_tangents`` on the evaluated mesh, for the
  bake's UV map (Blender's own bake takes the active UV map; the bake's map is the one the texture
  is read with), the corner normals, all in object space, and the transpose of the object's 3x3
  matrix taking world vectors there (``RE_bake_normal_world_to_tangent``); the frame normalises the
  interpolated normal from Blender 5.1 on, as its Normal Map node does (:func:`normal_map_unit_normal`). ``calc_tangents`` works
  on triangles and quads only: a mesh with faces of more corners is refused, naming the object
  (a Triangulate modifier, or Object space, bakes it);
- object space: the inverse of the object's 3x3 matrix (``RE_bake_normal_world_to_object``);
- the image "<object>_BentNormal" (Non-Color; float or 8-bit as the AO image), RGB = n / 2 + 1/2,
  the flat (0.5, 0.5, 1) in tangent space (black in object space) outside the islands and margin;
  it is created, filled and kept like the AO image, when the object's bake finishes.
"""

import numpy as np

from . import corelink
from .extract import ExtractError, default_uv_map


#: The first Blender whose Normal Map node normalises the interpolated normal (core.post.bent.TangentFrames).
UNIT_NORMAL_SINCE = (5, 1, 0)


def normal_map_unit_normal(version=None):
    """Whether this Blender's (or ``version``'s) Normal Map node decodes with a unit normal: 5.1 and
    later; 4.2 to 5.0 with the normal as interpolated (measured through Cycles: 4.2.23, 5.0.1, 5.1.2,
    5.2.3)."""
    if version is None:
        import bpy

        version = bpy.app.version
    return tuple(version[:3]) >= UNIT_NORMAL_SINCE


def frames_data(settings):
    """An ``extra`` callable for extract.object_arrays: the bent-normal space of the object, as the
    dict {"bent_space": ...} (core.post.bent's argument)."""
    def extra(mesh, arrays):
        bent = corelink.load("post.bent")
        matrix = np.asarray(arrays.matrix, dtype=np.float64)[:3, :3]
        if settings.bent_space == "OBJECT":
            try:
                return {"bent_space": np.linalg.inv(matrix)}
            except np.linalg.LinAlgError:
                raise ExtractError(f"{arrays.name} has a zero scale, its surface has no normal") from None
        sizes = np.empty(len(mesh.polygons), np.int32)
        mesh.polygons.foreach_get("loop_total", sizes)
        big = int(np.count_nonzero(sizes > 4))
        if big:
            raise ExtractError(
                f"{arrays.name}: {big} face{'s have' if big > 1 else ' has'} more than 4 corners; Blender computes "
                "tangents for triangles and quads only: add a Triangulate modifier, or bake the bent normals "
                "in Object space"
            )
        uv_name = settings.uv_map or default_uv_map(mesh)
        try:
            mesh.calc_tangents(uvmap=uv_name)
        except RuntimeError as exc:
            raise ExtractError(f"{arrays.name}: Blender computes no tangents for it: {exc}") from None
        try:
            n = len(mesh.loops)
            tangents = np.empty(n * 3, np.float32)
            mesh.loops.foreach_get("tangent", tangents)
            signs = np.empty(n, np.float32)
            mesh.loops.foreach_get("bitangent_sign", signs)
            normals = np.empty(n * 3, np.float32)
            mesh.corner_normals.foreach_get("vector", normals)
        finally:
            mesh.free_tangents()
        loops = arrays.loops
        frames = bent.TangentFrames(tangents.reshape(-1, 3).astype(np.float64)[loops],
                                    signs.astype(np.float64)[loops], normals.reshape(-1, 3).astype(np.float64)[loops],
                                    matrix.T, unit_normal=normal_map_unit_normal())
        return {"bent_space": frames}

    return extra


def encoded(result, settings):
    """The (H, W, 3) RGB of a bake result's bent normals (the margin filled, the rest Blender's fill)."""
    bent = corelink.load("post.bent")
    filled = np.any(result.bent != 0, axis=-1)
    return bent.encode(result.bent, filled, tangent=settings.bent_space == "TANGENT")
