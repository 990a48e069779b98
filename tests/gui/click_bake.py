"""Blender side of the GUI test: install the built zip, set up a scene, then report where to click.

Run by tests/gui/run.sh inside ../shared/tools/blender-gui.sh (a real Blender GUI on a virtual
screen): ``blender --factory-startup --python tests/gui/click_bake.py``. It installs the zip named
by $MC_AO_ZIP into a temporary user repository (the path of Install from Disk), enables it, adds a
plane under the startup cube with the AO image on its material, opens the sidebar tab "MC AO" and
splits the view with an Image Editor. Then it writes $MC_AO_GUI_OUT/ready.json with the window
coordinates of the Bake AO button, and watches: done.json when a bake has finished,
cancelled.json when a second bake was cancelled (with whether the image kept the first bake's
pixels). xdotool does the clicking (run.sh); nothing here presses the button.
"""

import hashlib
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # the checks' shared module
from guikit import ADDON, guarded, install, log, split_view, start, write  # noqa: E402

OUT = start("click_bake", os.environ.get("MC_AO_GUI_OUT", "/tmp/out/mc_ao_gui"), log_writes=False)
IMAGE = "Ground_AO"
# Pixels from the sidebar's top edge to the middle of the Bake AO button, at UI scale 1: the panel
# header (about 26) and half the 1.5-high button (about 15), plus the paddings.
BUTTON_BELOW_TOP = 52
state = {"phase": "first bake", "first_digest": None}


def digest(image):
    pixels = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    return hashlib.sha1(pixels.tobytes() + repr(tuple(image.size)).encode()).hexdigest()


def scene_setup():
    cube = bpy.data.objects["Cube"]
    cube.location = (0.0, 0.0, 1.3)
    bpy.ops.mesh.primitive_plane_add(size=6)
    ground = bpy.context.active_object
    ground.name = "Ground"
    # The AO image on the ground's material, so the viewport shows the bake as it lands.
    image = bpy.data.images.new(IMAGE, 64, 64, is_data=True)
    material = bpy.data.materials.new("Ground")
    material.use_nodes = True
    node = material.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    material.node_tree.nodes.active = node
    material.node_tree.links.new(node.outputs["Color"], material.node_tree.nodes["Principled BSDF"].inputs[0])
    ground.data.materials.append(material)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj is ground)
    bpy.context.view_layer.objects.active = ground
    settings = bpy.context.scene.mc_ao
    settings.resolution = 512
    settings.samples = 256


@guarded
def arrange(window):
    """Left half: the 3D Viewport, textured solid shading, sidebar on the tab MC AO; right: the image."""
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
    # Window coordinates have their origin at the bottom left, X11's at the top left. The Bake AO
    # button is the first row of the first panel: below the panel header, across the region.
    top = window.height - (sidebar.y + sidebar.height)
    x = sidebar.x + sidebar.width // 2
    y = top + int(BUTTON_BELOW_TOP * scale)
    # Region.active_panel_category is read-only in Blender 4.3, so run.sh clicks down the strip
    # of tabs at the sidebar's right edge, as a user would; tab.json says when it shows MC AO.
    write("ready.json", {"x": x, "y": y, "tabs_x": sidebar.x + sidebar.width - int(14 * scale), "tabs_top": top,
                         "sidebar": [sidebar.x, sidebar.y, sidebar.width, sidebar.height],
                         "window": [window.width, window.height], "scale": scale})
    log("ready, button at", x, y, "tab", sidebar.active_panel_category)
    bpy.app.timers.register(lambda: wait_for_tab(sidebar), first_interval=0.2)
    return None


@guarded
def wait_for_tab(sidebar):
    if sidebar.active_panel_category != "MC AO":
        return 0.2
    write("tab.json", {"category": sidebar.active_panel_category})
    log("sidebar shows the MC AO tab")
    bpy.app.timers.register(watch, first_interval=0.5)
    return None


def running():
    operators = sys.modules.get(f"{ADDON}.mc_ao.operators")
    return operators is not None and bool(operators._RUNS)


@guarded
def watch():
    image = bpy.data.images.get(IMAGE)
    if state["phase"] == "first bake":
        if running():
            state["seen_running"] = True
        elif state.get("seen_running") and image is not None and tuple(image.size) == (512, 512):
            state["first_digest"] = digest(image)
            state["phase"] = "second bake"
            write("done.json", {"size": list(image.size), "float": image.is_float,
                                "colorspace": image.colorspace_settings.name})
            log("first bake done")
            state["seen_running"] = False
    elif state["phase"] == "second bake":
        if running():
            state["seen_running"] = True
        elif state.get("seen_running"):
            kept = image is not None and digest(image) == state["first_digest"]
            write("cancelled.json", {"kept_previous_pixels": kept})
            log("second bake over; previous pixels kept:", kept)
            return None
    return 0.2


bpy.app.timers.register(ready, first_interval=2.0)
