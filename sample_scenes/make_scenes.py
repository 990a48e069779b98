#!/usr/bin/env python3
"""Build the sample scenes with bpy and save them as small .blend files beside this script.

The shipped files are made by the oldest Blender the extension supports, 4.2 LTS: a file saved by a
newer Blender does not open in older ones (Blender 4.2 to 4.4 cannot read 5.0's files at all).

    .venv-bpy42/bin/python sample_scenes/make_scenes.py        # all scenes, with the bpy 4.2 module
    blender -b --python sample_scenes/make_scenes.py           # the same, run by Blender 4.2
    .venv/bin/python sample_scenes/make_scenes.py --output DIR suzanne   # any Blender, elsewhere

(``bash scripts/test_bpy42.sh --collect-only -q`` makes .venv-bpy42.) Another Blender than 4.2 writes
only with ``--output``, into another folder, so that it cannot replace the shipped files by
ones 4.2 cannot open.

Every mesh has a UV map inside [0, 1] (udim.blend's Bust: inside its two tiles) whose islands do not
overlap, after the modifiers too (what a bake reads), so each is a valid bake target that bakes without a warning (tests/blender/
test_sample_scenes.py checks that). Scenes:

  suzanne.blend   Suzanne (one subdivision level, applied) on a ground plane: the README's default.
  room.blend      a box interior with furniture-like blocks: contact shadows, corners, occlusion
                  between separate objects.
  analytic.blend  a plane under a hovering disk (a 64-gon) whose exact AO is known: AO = 1 - F,
                  F Lambert's form factor of the polygon (see tests/scenes.py).
  dense.blend     a grid subdivided and displaced by modifiers into 524k triangles (the file stays
                  small; the add-on bakes the evaluated mesh), for benchmarks.
  rock.blend      Selected to Active: Rock_high (an icosphere subdivided and displaced by modifiers
                  into 123k triangles) baked onto Rock_low (an 80-triangle icosphere, smooth, Smart
                  UV Project; --match-suffix _high _low pairs them), on a ground plane.
  udim.blend      UDIM tiles: Suzanne on a pedestal, one mesh (Bust) whose head is in tile 1001 and
                  pedestal in tile 1002, on a ground plane.
  props.blend     props without a floor, in collections: Crate and Barrel (Props), two bottles
                  (Clutter, inside Props), a wall (Backdrop); the crate's material reads an
                  occlusion-roughness-metallic image, Crate_ORM: the ground, occluder collections and
                  channel packing.
  atlas.blend     a texture atlas: a kit of four objects (Base, Column, Ball, Block) resting on each
                  other, sharing one material whose active Image Texture node reads the image Atlas;
                  each object's UVs fill one quarter of the one UV square, so the four bake into
                  one image (--atlas Atlas, or the materials' image).
"""

import argparse
import math
import sys
from pathlib import Path

import bpy
import bmesh  # after bpy: the bpy module puts Blender's own modules (bmesh, mathutils) on the path

HERE = Path(__file__).resolve().parent

#: The analytic scene's numbers, shared with tests and docs.
ANALYTIC = {"plane_half_size": 1.0, "disk_radius": 0.5, "disk_height": 0.4, "disk_vertices": 64}
#: The rock's numbers: its high-poly reaches displacement / 2 outside the sphere of its radius, and the
#: low-poly's flat faces lie inside that sphere, so an extrusion of 0.1 (the README's) covers the gap.
ROCK = {"radius": 0.5, "displacement": 0.12, "cell": 0.15}
#: The props scene's numbers: the size of its occlusion-roughness-metallic image (the bake into its
#: red channel is this size).
PROPS = {"orm_size": 512}
#: The atlas scene's numbers: the shared image's size, and each object's quarter of the UV square
#: (lower-left corner), its islands inset by ``inset`` of the quarter's side.
ATLAS = {"image_size": 1024, "image": "Atlas", "inset": 0.03,
         "quarters": {"Base": (0.0, 0.0), "Column": (0.5, 0.0), "Ball": (0.0, 0.5), "Block": (0.5, 0.5)}}


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


def seams_from_uv_islands(obj):
    """Mark exactly the edges where the active UV map is cut (the islands' borders) as seams.

    bmesh rather than ``bpy.ops.uv.seams_from_islands``: that operator works on the selected UVs.
    Blender 5.0 starts with UV sync selection on, so every UV of the selected faces counts; 4.2 starts
    with it off and no UV selected after Smart UV Project, so there the operator cancels, marks
    nothing, and the unwrap that follows makes one distorted island of the whole head.
    """
    bm = bmesh.from_edit_mesh(obj.data)
    uv = bm.loops.layers.uv.active
    for edge in bm.edges:
        loops = list(edge.link_loops)
        seam = False
        if len(loops) == 2:
            a, b = loops  # opposite directions: a runs v0 -> v1, b runs v1 -> v0
            seam = ((a[uv].uv - b.link_loop_next[uv].uv).length > 1e-6
                    or (a.link_loop_next[uv].uv - b[uv].uv).length > 1e-6)
        edge.seam = seam
    bmesh.update_edit_mesh(obj.data)


def unwrap_without_overlaps(obj, margin=0.01):
    """Islands cut by Smart UV Project, each flattened by the angle-based unwrap of the subdivided mesh.

    Smart UV Project alone projects each island onto a plane, and where a curved island folds back
    over itself in that projection (on Suzanne by a brow, an ear and the chin) its faces overlap: 147
    texels of a 512 x 512 bake, 163 once the subdivision modifier has smoothed the UVs. Unwrapping
    the same islands by angle-based flattening of the control mesh still folds two faces over each
    other (61 texels at 512); of the mesh the subdivision modifier makes (``use_subsurf_data``), no
    face overlaps another (measured by the baker's rasteriser on the evaluated mesh, from 64 x 64 to
    4096 x 4096; tests/blender/test_sample_scenes.py keeps it so). ``margin`` spaces the packed
    islands: at 0.01 at least 12 texels apart at 1024 x 1024.
    """
    active(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(island_margin=0.02)
    seams_from_uv_islands(obj)
    bpy.ops.uv.unwrap(method="ANGLE_BASED", margin=margin, use_subsurf_data=True)
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
    path = OUTPUT / name
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")


def suzanne():
    reset()
    ground(4.0)
    bpy.ops.mesh.primitive_monkey_add(size=1.0, location=(0, 0, 0.62), rotation=(math.radians(-35), 0, 0))
    monkey = bpy.context.active_object
    monkey.name = monkey.data.name = "Suzanne"
    subdivided_suzanne(monkey)
    save("suzanne.blend")


def subdivided_suzanne(monkey):
    """One subdivision level, unwrapped without overlaps, then applied: the file holds the mesh that
    is baked, so that every target takes it as it is (a color attribute lives on the mesh's own
    vertices: a live Subdivision modifier would refuse it)."""
    mod = monkey.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = mod.render_levels = 1
    shade(monkey, True)
    unwrap_without_overlaps(monkey)
    active(monkey)
    bpy.ops.object.modifier_apply(modifier=mod.name)


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
    # Linear UVs, as the simple subdivision's positions: with OpenSubdiv's smoothing (the default,
    # "Keep Boundaries") the UVs of the border land one float32 step above 1.0 (1.0000001), and the
    # bake reports those 1662 triangles as reaching outside the image.
    sub.uv_smooth = "NONE"
    disp = grid.modifiers.new("Displace", "DISPLACE")
    disp.texture = tex
    disp.strength = 0.6
    disp.texture_coords = "LOCAL"
    shade(grid, True)
    save("dense.blend")


def rock():
    """A high-poly rock (an icosphere subdivided and displaced by modifiers into 123k triangles) and
    its low-poly (an 80-triangle icosphere, smooth, Smart UV Project) for Selected to Active:
    Rock_high onto Rock_low (the names --match-suffix _high _low pairs), on a ground plane."""
    reset()
    ground(4.0)
    r = ROCK["radius"]
    z = r + ROCK["displacement"] / 2 + 0.01  # its lowest point just above the ground
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=r, location=(0, 0, z))
    high = bpy.context.active_object
    high.name = high.data.name = "Rock_high"
    sub = high.modifiers.new("Subdivision", "SUBSURF")  # 123k triangles, kept small in the file
    sub.levels = sub.render_levels = 4
    tex = bpy.data.textures.new("Cracks", type="VORONOI")
    tex.noise_scale = ROCK["cell"]
    tex.distance_metric = "DISTANCE"
    disp = high.modifiers.new("Displace", "DISPLACE")
    disp.texture = tex
    disp.strength = ROCK["displacement"]
    disp.texture_coords = "LOCAL"
    shade(high, True)
    smart_uv(high)  # not needed to bake from it; it makes the mesh a valid bake target too
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=r, location=(0, 0, z))
    low = bpy.context.active_object
    low.name = low.data.name = "Rock_low"
    shade(low, True)
    smart_uv(low, margin=0.03)
    save("rock.blend")


def udim():
    """Suzanne on a pedestal as one mesh, Bust, laid out over two UDIM tiles as a character's head and
    body get tiles of their own: the head in tile 1001 (u, v in [0, 1)), the pedestal in 1002 (u in
    [1, 2)); on a ground plane (tile 1001). Baked with --udim: Bust_AO.1001 and Bust_AO.1002."""
    reset()
    ground(4.0)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 0.35))
    pedestal = bpy.context.active_object
    pedestal.scale = (0.9, 0.9, 0.7)
    bpy.ops.object.transform_apply(scale=True)
    smart_uv(pedestal)
    for corner in pedestal.data.uv_layers.active.data:
        corner.uv = (corner.uv[0] + 1.0, corner.uv[1])  # tile 1002
    bpy.ops.mesh.primitive_monkey_add(size=1.0, location=(0, 0, 1.12), rotation=(math.radians(-35), 0, 0))
    monkey = bpy.context.active_object
    subdivided_suzanne(monkey)
    active(monkey)
    pedestal.select_set(True)
    bpy.ops.object.join()  # into the head's object; both UV maps are "UVMap", so they become one
    monkey.name = monkey.data.name = "Bust"
    save("udim.blend")


def cylinder(name, location, radius, depth, vertices=24):
    bpy.ops.mesh.primitive_cylinder_add(vertices=vertices, radius=radius, depth=depth, location=location)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    smart_uv(obj)
    return obj


def collection(name, parent=None):
    """A new collection ``name`` inside ``parent`` (default: the scene's)."""
    coll = bpy.data.collections.new(name)
    (parent or bpy.context.scene.collection).children.link(coll)
    return coll


def move_to(obj, coll):
    for old in list(obj.users_collection):
        old.objects.unlink(obj)
    coll.objects.link(obj)


def orm_material(obj, image_name, size=PROPS["orm_size"]):
    """A material whose Principled BSDF reads roughness and metallic from a glTF occlusion-roughness-
    metallic image (a generated one: red, the occlusion, 1; green, the roughness, 0.6; blue, the
    metallic, 0), the image a bake packs its AO into with Channel R and Into it."""
    image = bpy.data.images.new(image_name, size, size, alpha=False)
    image.generated_color = (1.0, 0.6, 0.0, 1.0)
    image.colorspace_settings.name = "Non-Color"
    mat = bpy.data.materials.new(obj.name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.location = (-600, 0)
    split = nodes.new("ShaderNodeSeparateColor")
    split.location = (-300, 0)
    links.new(tex.outputs["Color"], split.inputs["Color"])
    links.new(split.outputs["Green"], bsdf.inputs["Roughness"])
    links.new(split.outputs["Blue"], bsdf.inputs["Metallic"])
    obj.data.materials.append(mat)


def props():
    """Props as an asset library has them, without a floor: a crate and a barrel in collection Props,
    bottles beside the crate in Clutter (inside Props), a wall behind them in Backdrop; the crate's
    material reads a generated occlusion-roughness-metallic image, Crate_ORM. For the ground
    (--ground: the props' contact shadow without a floor mesh), occluder collections (--occluder-
    collections Props --exclude-collections Clutter) and channel packing (--channel r --into Crate_ORM)."""
    reset()
    props_coll = collection("Props")
    clutter = collection("Clutter", props_coll)
    backdrop = collection("Backdrop")
    crate = cube("Crate", (0.0, 0.0, 0.4), (0.8, 0.8, 0.8))
    bpy.ops.object.transform_apply(scale=True)
    smart_uv(crate)
    orm_material(crate, "Crate_ORM")
    barrel = cylinder("Barrel", (0.95, 0.05, 0.45), 0.3, 0.9)
    shade(barrel, True)
    for obj in (crate, barrel):
        move_to(obj, props_coll)
    for i, (x, y) in enumerate([(-0.55, -0.15), (-0.6, 0.12)]):
        move_to(cylinder(f"Bottle{i}", (x, y, 0.15), 0.06, 0.3, vertices=12), clutter)
    wall = cube("Wall", (0.3, 0.75, 0.75), (3.0, 0.1, 1.5))
    bpy.ops.object.transform_apply(scale=True)
    smart_uv(wall)
    move_to(wall, backdrop)
    save("props.blend")


def into_quarter(obj, corner, inset):
    """Move ``obj``'s UVs (inside [0, 1]) into the quarter of the UV square whose lower-left corner is
    ``corner``, inset by ``inset`` of its side on every border: the objects of an atlas share one UV
    square without sharing a texel."""
    scale = 0.5 * (1.0 - 2.0 * inset)
    for loop in obj.data.uv_layers.active.data:
        u, v = loop.uv
        loop.uv = (corner[0] + 0.5 * inset + scale * u, corner[1] + 0.5 * inset + scale * v)


def atlas():
    """A kit of four objects baked into one image (a texture atlas): Base, a slab; Column standing on
    it; Ball (an icosphere) resting on the column; Block leaning against the column on the base. They share one
    material, Kit, whose active Image Texture node reads the image Atlas (generated, 8-bit,
    Non-Color, black), as Cycles' bake finds its target; each object's UVs fill its quarter of the
    UV square (ATLAS), so no texel belongs to two objects."""
    reset()
    a = ATLAS
    base = cube("Base", (0.0, 0.0, 0.1), (1.6, 1.2, 0.2))
    bpy.ops.mesh.primitive_cylinder_add(vertices=24, radius=0.18, depth=1.0, location=(0.0, 0.0, 0.7))
    column = bpy.context.active_object
    column.name = column.data.name = "Column"
    shade(column, True)
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=0.3, location=(0.0, 0.0, 1.47))
    ball = bpy.context.active_object
    ball.name = ball.data.name = "Ball"
    shade(ball, True)
    block = cube("Block", (0.45, 0.1, 0.4), (0.4, 0.4, 0.4))
    block.rotation_euler = (0.0, 0.0, math.radians(20))
    objects = {"Base": base, "Column": column, "Ball": ball, "Block": block}
    image = bpy.data.images.new(a["image"], a["image_size"], a["image_size"], alpha=True)
    image.colorspace_settings.name = "Non-Color"
    mat = bpy.data.materials.new("Kit")
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.location = (-400, 0)
    nodes.active = tex
    for name, obj in objects.items():
        active(obj)
        bpy.ops.object.transform_apply(location=False, rotation=True, scale=True)
        smart_uv(obj, margin=0.03)
        into_quarter(obj, a["quarters"][name], a["inset"])
        obj.data.materials.append(mat)
    for obj in objects.values():  # nothing selected: the script bakes every mesh of the file
        obj.select_set(False)
    save("atlas.blend")


SCENES = {"suzanne": suzanne, "room": room, "analytic": analytic, "dense": dense, "rock": rock, "udim": udim,
          "props": props, "atlas": atlas}


#: Where save() writes; main() sets it.
OUTPUT = HERE
#: The Blender (major, minor) that makes the shipped files.
SHIPPED_BY = (4, 2)


def main(argv):
    global OUTPUT
    parser = argparse.ArgumentParser(prog="make_scenes.py", description="Build the sample scenes.")
    parser.add_argument("scenes", nargs="*", metavar="SCENE",
                        help=f"scenes to make (default: all): {', '.join(SCENES)}")
    parser.add_argument("--output", type=Path, help="folder to write into (default: beside this script)")
    args = parser.parse_args(argv)
    unknown = [name for name in args.scenes if name not in SCENES]
    if unknown:
        parser.error(f"no scene {', '.join(map(repr, unknown))}; the scenes: {', '.join(SCENES)}")
    version = tuple(bpy.app.version[:2])
    if args.output is None and version != SHIPPED_BY:
        parser.exit(2, (
            f"make_scenes.py: error: this is Blender {bpy.app.version_string}; the shipped scenes are made by "
            f"Blender {SHIPPED_BY[0]}.{SHIPPED_BY[1]} so that every supported Blender opens them. Run "
            f".venv-bpy42/bin/python sample_scenes/make_scenes.py (bash scripts/test_bpy42.sh makes "
            f".venv-bpy42), or pass --output to write somewhere else.\n"))
    OUTPUT = (args.output or HERE).resolve()
    OUTPUT.mkdir(parents=True, exist_ok=True)
    for name in args.scenes or list(SCENES):
        SCENES[name]()


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
