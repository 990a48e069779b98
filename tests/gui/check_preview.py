"""Blender side of the GUI picture docs/preview.png: UDIM tiles, bent normals and
Preview on Object in a real Blender.

Run by tests/gui/preview.sh inside ../shared/tools/blender-gui.sh: ``blender --factory-startup
--python tests/gui/check_preview.py``. It installs the zip named by $MC_AO_ZIP, builds a scene
(Suzanne with an orange material on a ground plane whose checker material's UVs span UDIM tiles
1001 and 1002), bakes both with UDIM Tiles and Bent Normals on (the Bake AO operator), clicks
Preview on Object (the operator, in the 3D Viewport's context), shows the tiled AO image in an
Image Editor, and writes $MC_AO_GUI_OUT/ready.json with where the sidebar's tabs are; preview.sh
clicks the MC AO tab and takes the screenshot. state.json says what was made (tiles, materials).
"""

import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # the checks' shared module
from guikit import guarded, install, log, split_view, start, write  # noqa: E402

OUT = start("check_preview", os.environ.get("MC_AO_GUI_OUT", "/tmp/out/mc_ao_preview"))
state = {}


def material(name, colour, checker=False):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    principled.inputs["Base Color"].default_value = colour
    if checker:
        node = tree.nodes.new("ShaderNodeTexChecker")
        node.inputs["Color1"].default_value = colour
        node.inputs["Color2"].default_value = (0.95, 0.95, 0.92, 1.0)
        node.inputs["Scale"].default_value = 8.0
        node.location = (-300, 200)
        tree.links.new(node.outputs["Color"], principled.inputs["Base Color"])
    return mat


def scene_setup():
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    bpy.ops.mesh.primitive_monkey_add(location=(-1.2, 0.1, 0.62), rotation=(-0.5, 0.0, -0.5))
    suzanne = bpy.context.active_object
    suzanne.name = "Suzanne"
    bpy.ops.object.shade_smooth()
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(island_margin=0.05)
    bpy.ops.object.mode_set(mode="OBJECT")
    suzanne.data.materials.append(material("Skin", (0.8, 0.35, 0.1, 1.0)))
    bpy.ops.mesh.primitive_plane_add(size=3)
    ground = bpy.context.active_object
    ground.name = "Ground"
    ground.scale = (2.0, 1.0, 1.0)
    bpy.ops.object.transform_apply(scale=True)
    for d in ground.data.uv_layers.active.uv:  # the plane's halves in tiles 1001 and 1002
        d.vector = (2.0 * d.vector[0], d.vector[1])
    ground.data.materials.append(material("Floor", (0.55, 0.7, 0.9, 1.0), checker=True))
    bpy.ops.mesh.primitive_cube_add(size=0.9, location=(1.4, 0.2, 0.45), rotation=(0.0, 0.0, 0.4))
    block = bpy.context.active_object
    block.name = "Block"
    block.data.materials.append(material("Block", (0.6, 0.6, 0.6, 1.0)))
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (ground, suzanne, block))
    bpy.context.view_layer.objects.active = suzanne
    settings = bpy.context.scene.mc_ao
    settings.resolution = 512
    settings.samples = 64
    settings.use_udim = True
    settings.bent_normals = True
    bpy.ops.ed.undo_push(message="scene ready")


@guarded
def ready():
    install()
    scene_setup()
    window = split_view(0.62)
    bpy.app.timers.register(lambda: bake(window), first_interval=1.0)
    return None


@guarded
def bake(window):
    views = sorted((a for a in window.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.x)
    view, right = views[0], views[-1]
    right.type = "IMAGE_EDITOR"
    region = next(r for r in view.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=view, region=region):
        result = bpy.ops.object.mc_ao_bake()
        log("bake:", result)
    view.spaces.active.shading.type = "MATERIAL"
    state.update(window=window, view=view, region=region)
    right.spaces.active.image = bpy.data.images["Ground_AO"]
    image_region = next(r for r in right.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=right, region=image_region):
        bpy.ops.image.view_all(fit_view=True)  # both tiles
    space = view.spaces.active
    space.show_region_ui = True
    space.overlay.show_extras = False  # no camera or light in the way
    space.region_3d.view_distance = 8.5
    space.region_3d.view_rotation = (0.88, 0.36, 0.12, 0.29)
    space.region_3d.view_location = (0.9, 0.1, 0.2)
    for area in window.screen.areas:
        area.tag_redraw()
    ground_ao = bpy.data.images["Ground_AO"]
    state.update({
        "bake": list(result),
        "ground_tiles": [t.number for t in ground_ao.tiles],
        "bent_tiles": [t.number for t in bpy.data.images["Ground_BentNormal"].tiles],
    })
    write("baked.json", {k: v for k, v in state.items() if k not in ("window", "view", "region")})
    bpy.app.timers.register(lambda: locate(window, view), first_interval=1.0)


@guarded
def locate(window, view):
    sidebar = next(r for r in view.regions if r.type == "UI")
    scale = bpy.context.preferences.system.ui_scale
    top = window.height - (sidebar.y + sidebar.height)
    write("ready.json", {"tabs_x": sidebar.x + sidebar.width - int(14 * scale), "tabs_top": top})
    state["sidebar"] = sidebar
    bpy.app.timers.register(watch, first_interval=0.5)


def preview():
    """Preview on Object, as the button does it, in the 3D Viewport's context."""
    with bpy.context.temp_override(window=state["window"], area=state["view"], region=state["region"]):
        result = bpy.ops.object.mc_ao_preview("EXEC_DEFAULT", True)
    write("previewed.json", {
        "preview": list(result), "shading": state["view"].spaces.active.shading.type,
        "floor_nodes": sorted(n.bl_idname for n in bpy.data.materials["Floor"].node_tree.nodes),
        "suzanne_preview": "mc_ao_preview" in bpy.data.objects["Suzanne"].keys(),
        "block_slots": [(s.link, s.material.name) for s in bpy.data.objects["Block"].material_slots],
    })


@guarded
def watch():
    if "tab" not in state and state["sidebar"].active_panel_category == "MC AO":
        write("tab.json", {"category": "MC AO"})
        state["tab"] = True
    if os.path.exists(os.path.join(OUT, "before")):
        preview()
        return None
    return 0.3


bpy.app.timers.register(ready, first_interval=1.0)
