#!/usr/bin/env python3
"""Build the sample scenes with bpy and save them as small .blend files beside this script.

    .venv/bin/python sample_scenes/make_scenes.py            # all scenes
    blender -b --python sample_scenes/make_scenes.py         # the same, run by Blender

Every mesh has a UV map without overlaps (Smart UV Project, or a planar map for planes), so each is
a valid bake target. Scenes:

  suzanne.blend   Suzanne on a ground plane: the README's default.
  room.blend      a box interior with furniture-like blocks: contact shadows, corners, occlusion
                  between separate objects.
  analytic.blend  a plane under a hovering disk (a 64-gon) whose exact AO is known: AO = 1 - F,
                  F Lambert's form factor of the polygon (see tests/scenes.py).
  dense.blend     a grid subdivided and displaced by modifiers into 260k triangles (the file stays
                  small; the add-on bakes the evaluated mesh), for benchmarks.
"""

import math
import sys
from pathlib import Path

import bpy

HERE = Path(__file__).resolve().parent

#: The analytic scene's numbers, shared with tests and docs.
ANALYTIC = {"plane_half_size": 1.0, "disk_radius": 0.5, "disk_height": 0.4, "disk_vertices": 64}


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    return scene


def active(obj):
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def smart_uv(obj, margin=0.02):
    active(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(island_margin=margin)
    bpy.ops.object.mode_set(mode="OBJECT")


def shade(obj, smooth):
    for p in obj.data.polygons:
        p.use_smooth = smooth


def ground(size, name="Ground", z=0.0):
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0, 0, z))
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    return obj  # the primitive's UVs map the plane onto the whole square


def cube(name, location, scale):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=location)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    obj.scale = scale
    smart_uv(obj)
    return obj


def save(name):
    path = HERE / name
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")


def suzanne():
    reset()
    ground(4.0)
    bpy.ops.mesh.primitive_monkey_add(size=1.0, location=(0, 0, 0.62), rotation=(math.radians(-35), 0, 0))
    monkey = bpy.context.active_object
    monkey.name = monkey.data.name = "Suzanne"
    mod = monkey.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = mod.render_levels = 1
    shade(monkey, True)
    smart_uv(monkey)
    save("suzanne.blend")


def room():
    reset()
    # The room: a box seen from inside (normals flipped inwards), 6 x 5 x 3.
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 1.5))
    shell = bpy.context.active_object
    shell.name = shell.data.name = "Room"
    shell.scale = (6, 5, 3)
    bpy.ops.object.transform_apply(scale=True)
    active(shell)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.flip_normals()
    bpy.ops.object.mode_set(mode="OBJECT")
    smart_uv(shell)
    cube("Table", (0.5, 0.3, 0.75), (1.6, 0.9, 0.08))
    for i, (x, y) in enumerate([(-0.2, -0.05), (1.2, -0.05), (-0.2, 0.65), (1.2, 0.65)]):
        cube(f"Leg{i}", (x, y, 0.355), (0.08, 0.08, 0.71))
    cube("Cabinet", (-2.5, 1.9, 1.0), (0.8, 0.9, 2.0))
    cube("Crate", (2.0, -1.6, 0.35), (0.7, 0.7, 0.7))
    cube("Shelf", (2.7, 1.2, 1.4), (0.5, 2.0, 0.06))
    save("room.blend")


def analytic():
    reset()
    a = ANALYTIC
    ground(2 * a["plane_half_size"], name="Plane")
    bpy.ops.mesh.primitive_circle_add(vertices=a["disk_vertices"], radius=a["disk_radius"], fill_type="NGON",
                                      location=(0, 0, a["disk_height"]))
    disk = bpy.context.active_object
    disk.name = disk.data.name = "Disk"
    smart_uv(disk)
    save("analytic.blend")


def dense():
    reset()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=64, y_subdivisions=64, size=4.0)
    grid = bpy.context.active_object
    grid.name = grid.data.name = "Terrain"
    tex = bpy.data.textures.new("Hills", type="CLOUDS")
    tex.noise_scale = 0.6
    tex.noise_depth = 3
    sub = grid.modifiers.new("Subdivision", "SUBSURF")
    sub.subdivision_type = "SIMPLE"
    sub.levels = sub.render_levels = 3  # 64 x 64 x 2 x 4^3 = 524k triangles
    disp = grid.modifiers.new("Displace", "DISPLACE")
    disp.texture = tex
    disp.strength = 0.6
    disp.texture_coords = "LOCAL"
    shade(grid, True)
    save("dense.blend")


SCENES = {"suzanne": suzanne, "room": room, "analytic": analytic, "dense": dense}


def main(argv):
    names = [a for a in argv if a in SCENES] or list(SCENES)
    for name in names:
        SCENES[name]()


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
