"""Blender side of the GUI check of atlases: two objects into one image with one click, then one of
them again, and what the image keeps.

Run by tests/gui/atlas.sh inside ../shared/tools/blender-gui.sh: ``blender --factory-startup --python
tests/gui/check_atlas.py``. It installs the zip named by $MC_AO_ZIP, builds a scene (a floor under the
startup cube; the floor's UVs in the left half of the UV square, the cube's in the right half; both
with one material whose Image Texture node shows the image Atlas, an existing 256 x 128 8-bit sRGB
image filled with a grey), sets Images to One for All with the atlas Atlas at a Size of 512 (the
existing image keeps its own), selects both and writes $MC_AO_GUI_OUT/ready.json with where to click.
atlas.sh clicks Bake AO; done1.json says what the image is. This script then selects the floor alone
and moves it (the cube stays); atlas.sh clicks Bake AO again; done2.json says what the image is
now: its size, depth, colour space, the cube's texels (equal to the first bake's?), the floor's
texels (changed?), the texels neither object reaches (still the grey?).
"""

import base64
import hashlib
import io
import json
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # the checks' shared module
from guikit import ADDON, guarded, install, split_view, start, write  # noqa: E402

OUT = start("check_atlas", os.environ.get("MC_AO_GUI_OUT", "/tmp/out/mc_ao_atlas"))
IMAGE = "Atlas"
GREY = 0.5
BUTTON_BELOW_TOP = 52  # pixels from the sidebar's top edge to the middle of the Bake AO button
state = {"phase": "first bake"}


def into_half(obj, right):
    for loop in obj.data.uv_layers.active.data:
        u, v = loop.uv
        loop.uv = (0.5 * u + (0.5 if right else 0.0), v)


def scene_setup():
    cube = bpy.data.objects["Cube"]
    cube.location = (0.0, 0.0, 1.3)
    bpy.ops.mesh.primitive_plane_add(size=6)
    floor = bpy.context.active_object
    floor.name = "Floor"
    into_half(floor, right=False)
    into_half(cube, right=True)
    image = bpy.data.images.new(IMAGE, 256, 128)  # 8-bit, sRGB: Image > New's defaults
    image.generated_color = (GREY, GREY, GREY, 1.0)
    material = bpy.data.materials.new("Kit")
    material.use_nodes = True
    node = material.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    material.node_tree.nodes.active = node
    material.node_tree.links.new(node.outputs["Color"], material.node_tree.nodes["Principled BSDF"].inputs[0])
    for obj in (floor, cube):
        obj.data.materials.clear()
        obj.data.materials.append(material)
        obj.select_set(True)
    bpy.context.view_layer.objects.active = floor
    settings = bpy.context.scene.mc_ao
    settings.images = "ATLAS"
    settings.atlas = IMAGE
    settings.resolution = 512
    settings.samples = 64


@guarded
def arrange(window):
    views = sorted((a for a in window.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.x)
    view, right = views[0], views[-1]
    right.type = "IMAGE_EDITOR"
    right.spaces.active.image = bpy.data.images[IMAGE]
    space = view.spaces.active
    space.show_region_ui = True
    space.shading.type = "SOLID"
    space.shading.color_type = "TEXTURE"
    for area in window.screen.areas:
        area.tag_redraw()
    bpy.app.timers.register(lambda: locate(window, view), first_interval=1.0)


@guarded
def ready():
    install()
    scene_setup()
    window = split_view()
    bpy.app.timers.register(lambda: arrange(window), first_interval=1.0)
    return None


@guarded
def locate(window, view):
    sidebar = next(r for r in view.regions if r.type == "UI")
    scale = bpy.context.preferences.system.ui_scale
    top = window.height - (sidebar.y + sidebar.height)
    write("ready.json", {"x": sidebar.x + sidebar.width // 2, "y": top + int(BUTTON_BELOW_TOP * scale),
                         "tabs_x": sidebar.x + sidebar.width - int(14 * scale), "tabs_top": top})
    bpy.app.timers.register(lambda: wait_for_tab(sidebar), first_interval=0.2)
    return None


@guarded
def wait_for_tab(sidebar):
    if sidebar.active_panel_category != "MC AO":
        return 0.2
    write("tab.json", {"category": sidebar.active_panel_category})
    bpy.app.timers.register(watch, first_interval=0.5)
    return None


def running():
    operators = sys.modules.get(f"{ADDON}.mc_ao.operators")
    return operators is not None and bool(operators._RUNS or operators._SESSIONS)


def pixels(image):
    px = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(image.size[1], image.size[0], image.channels)


def record_owner(image):
    """The owner map and names of the record the bake kept on the image (numpy alone reads it)."""
    data = base64.b64decode(image["mc_ao_atlas"])
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        meta = json.loads(bytes(z["meta"]).decode())
        return z["owner"], meta["names"]


def digest(a):
    return hashlib.sha1(np.ascontiguousarray(a).tobytes()).hexdigest()[:12]


def describe(image):
    px = pixels(image)
    owner, names = record_owner(image)
    cube, floor = owner == names.index("Cube"), owner == names.index("Floor")
    untouched = np.all(np.abs(px[..., :3] - round(GREY * 255) / 255) < 1e-6, axis=2)
    return {"size": list(image.size), "float": image.is_float, "colorspace": image.colorspace_settings.name,
            "names": names, "cube_texels": int(cube.sum()), "floor_texels": int(floor.sum()),
            "cube_digest": digest(px[cube]), "floor_digest": digest(px[floor]),
            "grey_texels": int(untouched.sum())}


@guarded
def watch():
    image = bpy.data.images.get(IMAGE)
    if running():
        state["seen_running"] = True
        return 0.2
    if not state.get("seen_running") or image is None or "mc_ao_atlas" not in image.keys():
        return 0.2
    state["seen_running"] = False
    if state["phase"] == "first bake":
        write("done1.json", describe(image))
        floor = bpy.data.objects["Floor"]
        for obj in bpy.context.view_layer.objects:
            obj.select_set(obj is floor)
        bpy.context.view_layer.objects.active = floor
        floor.location.x += 0.5  # the floor alone changes: its shadow of the cube moves
        state["phase"] = "second bake"
        write("selected.json", {"selected": [o.name for o in bpy.context.selected_objects]})
        return 0.2
    write("done2.json", describe(image))
    return None


bpy.app.timers.register(ready, first_interval=2.0)
