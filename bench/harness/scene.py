"""The benchmark scenes: the Blender scene both bakers see (plane, Suzanne, two blocks) and numpy-only ones.

The Blender scene is built in bpy (plane and blocks from numpy arrays, Suzanne from Blender's operator,
UV-unwrapped by smart_project, smooth-shaded, one subdivision level), so that Cycles and mc_ao bake the
very same evaluated geometry. :func:`scene_arrays` then reads it back through the add-on's own
extraction (mc_ao.extract), which is what the operator hands to core.bake_ao.
"""

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

#: AO distance of the benchmark scene, in world units (world.light_settings.distance / max_distance).
DISTANCE = 1.5
#: The plane (8 x 8 at z = 0), the two blocks (lo, hi corners), Suzanne's location. The blocks sink
#: 0.1 into the plane: a block resting exactly on it would put its bottom face in the plane's plane,
#: where "occluded or not" depends on rounding (see the contact check in bench/sections/agreement.py).
PLANE_HALF = 4.0
SINK = 0.1
BLOCKS = (((-3.2, -1.0, -SINK), (-2.2, 1.2, 1.6)), ((1.4, -2.6, -SINK), (3.0, -1.2, 0.9)))
SUZANNE_AT = (0.0, 0.0, 1.05)
SUZANNE_ROTATION = (math.radians(-20.0), 0.0, math.radians(25.0))

QUAD = np.array([[0, 1, 2, 3]])


def box_arrays(lo, hi):
    """Vertices (8, 3) and outward-wound quads (6, 4) of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], float)
    quads = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])
    return v, quads


def _mesh_object(bpy, name, verts, quads, uvs=None):
    """A Blender mesh object from numpy arrays (quads (F, 4); uvs per loop (F * 4, 2) or None)."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(map(float, v)) for v in verts], [], [tuple(map(int, q)) for q in quads])
    if uvs is not None:
        layer = mesh.uv_layers.new(name="UVMap")
        layer.uv.foreach_set("vector", np.asarray(uvs, np.float32).ravel())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def reset_blender(bpy):
    """An empty factory scene."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    return scene


def build_scene(bpy, subdivisions=1, distance=DISTANCE, sink=SINK):
    """Build the benchmark scene in the current (empty) Blender file; return {name: object}.

    Plane 8 x 8 (UVs 0..1), Suzanne hovering over it (smart-project UVs, smooth, ``subdivisions``
    levels of a Subdivision Surface modifier), two blocks sunk ``sink`` into the plane (0: resting
    on it, coplanar bottom faces); world AO distance ``distance``.
    """
    scene = bpy.context.scene
    h = PLANE_HALF
    plane_v = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], float)
    plane_uv = (plane_v[QUAD[0]][:, :2] + h) / (2 * h)
    objs = {"Plane": _mesh_object(bpy, "Plane", plane_v, QUAD, plane_uv)}
    for i, (lo, hi) in enumerate(BLOCKS):
        v, q = box_arrays((lo[0], lo[1], -sink), hi)
        objs[f"Block{i}"] = _mesh_object(bpy, f"Block{i}", v, q)

    bpy.ops.mesh.primitive_monkey_add(size=2.0, location=SUZANNE_AT, rotation=SUZANNE_ROTATION)
    suz = bpy.context.active_object
    suz.name = suz.data.name = "Suzanne"
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(angle_limit=math.radians(66.0), island_margin=0.01)
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.object.shade_smooth()
    if subdivisions:
        mod = suz.modifiers.new("Subdivision", "SUBSURF")
        mod.levels = mod.render_levels = subdivisions
    objs["Suzanne"] = suz

    scene.world.light_settings.distance = distance
    bpy.context.view_layer.update()
    return objs


def select_only(bpy, obj):
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.context.view_layer.objects.active = obj


def read_ao(image):
    """(H, W) float32 R channel, row 0 = v = 0 (Blender's pixel order)."""
    w, h = image.size
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, image.channels)[..., 0].copy()


def scene_arrays(bpy, target_name):
    """(target MeshArrays, [occluder MeshArrays]) of the evaluated scene, as the operator extracts them."""
    from mc_ao.extract import object_arrays

    dg = bpy.context.evaluated_depsgraph_get()
    target = None
    occ = []
    for obj in bpy.context.scene.objects:
        if obj.type != "MESH":
            continue
        ev = obj.evaluated_get(dg)
        if obj.name == target_name:
            target = object_arrays(ev, with_uvs=True, with_normals=True)
        else:
            occ.append(object_arrays(ev))
    return target, occ


def core_meshes(target, occluders):
    """core.Mesh objects of MeshArrays (what mc_ao.baking.Job.run builds)."""
    from core import Mesh

    def mesh(a):
        return Mesh(positions=a.positions, triangles=a.triangles, uvs=a.uvs, normals=a.normals, name=a.name)

    return mesh(target), [mesh(o) for o in occluders]


# -- numpy-only scenes (no Blender) -------------------------------------------------------------


def displaced_grid(n, size=4.0, amplitude=0.25, seed=0):
    """An n x n quad grid (2 n^2 triangles) over [-size/2, size/2]^2, displaced by smooth bumps.

    Returns (positions (V, 3), triangles (T, 3), uvs (T, 3, 2)): a target whose cost grows with its
    triangle count while the image and the number of rays stay fixed.
    """
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n + 1)
    U, V = np.meshgrid(t, t)
    z = np.zeros_like(U)
    for _ in range(6):
        kx, ky = rng.uniform(1.0, 4.0, 2)
        ph = rng.uniform(0, 2 * math.pi, 2)
        z += np.sin(2 * math.pi * kx * U + ph[0]) * np.sin(2 * math.pi * ky * V + ph[1])
    z *= amplitude / 6 * 2
    P = np.stack([(U - 0.5) * size, (V - 0.5) * size, z], -1).reshape(-1, 3)
    UV = np.stack([U, V], -1).reshape(-1, 2)
    i = np.arange(n)
    a = (i[None, :] + (n + 1) * i[:, None]).ravel()
    quads = np.stack([a, a + 1, a + n + 2, a + n + 1], 1)
    F = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return P, F, UV[F]


LID_HEIGHT = 0.3


def lid_scene():
    """The analytic scene: unit plane (UVs 0..1) under a hovering square [0.25, 0.75]^2 at z = 0.3.

    Exact AO = 1 - F, F Lambert's polygon form factor (with an infinite AO distance).
    Returns (plane verts, plane quads, plane uvs per loop, lid verts, lid quads).
    """
    pv = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    lid = np.array([[0.25, 0.25, LID_HEIGHT], [0.75, 0.25, LID_HEIGHT], [0.75, 0.75, LID_HEIGHT],
                    [0.25, 0.75, LID_HEIGHT]])
    return pv, QUAD, pv[QUAD[0]][:, :2], lid, QUAD


from core.montecarlo.analytic import polygon_form_factor  # noqa: E402  (Lambert's form factor, one copy)


def lid_truth(width, height, order=6, footprint=1.0):
    """Exact texel values of the lid scene: the mean of 1 - F over the central ``footprint`` x
    ``footprint`` square of each texel (1: the whole texel; 0: its centre), by Gauss-Legendre."""
    lid = lid_scene()[3]
    if footprint == 0:
        g, w = np.array([0.5]), np.array([1.0])
    else:
        g, w = np.polynomial.legendre.leggauss(order)
        g, w = 0.5 + g * footprint / 2, w / 2
    out = np.zeros((height, width))
    for gy, wy in zip(g, w):
        for gx, wx in zip(g, w):
            U, V = np.meshgrid((np.arange(width) + gx) / width, (np.arange(height) + gy) / height)
            pts = np.stack([U.ravel(), V.ravel(), np.zeros(U.size)], 1)
            out += wx * wy * (1.0 - polygon_form_factor(pts, lid)).reshape(height, width)
    return out


def terrain(n=256):
    """The dense terrain: a displaced grid of 2 n^2 triangles (131k for n = 256), its own occluder."""
    from core import Mesh

    P, F, UV = displaced_grid(n)
    return Mesh(P, F, UV, name=f"terrain{2 * n * n}"), [], 0.5
