"""Blender side of the GUI check that nothing baked is lost (nothing baked is lost; the status bar; the panel's hints).

Run by tests/gui/trust.sh inside ../shared/tools/blender-gui.sh: ``blender --factory-startup
--python tests/gui/check_trust.py``. It installs the zip named by $MC_AO_ZIP, builds a scene (a
ground plane whose AO image is an existing *file* image of another size than the bake, painted
over after loading; a mesh without UVs), splits the view with an Image Editor and writes
$MC_AO_GUI_OUT/ready.json with where to click. trust.sh does the clicking and the keys (Bake AO,
Esc, Shift-D, Ctrl-Z) and touches a file after each step; each step's check here writes a JSON
file saying what the image is (size, and whether its pixels are those it should have).
"""

import hashlib
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # the checks' shared module
from guikit import ADDON, guarded, install, split_view, start, write  # noqa: E402

OUT = start("check_trust", os.environ.get("MC_AO_GUI_OUT", "/tmp/out/mc_ao_trust"))
IMAGE = "Ground_AO"
BUTTON_BELOW_TOP = 52  # pixels from the sidebar's top edge to the middle of the Bake AO button
state = {"step": 0}


def digest(image):
    pixels = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    return hashlib.sha1(pixels.tobytes() + repr(tuple(image.size)).encode()).hexdigest()[:12]


def describe(image):
    return {"size": list(image.size), "digest": digest(image), "source": image.source,
            "packed": image.packed_file is not None, "dirty": image.is_dirty}


def running():
    operators = sys.modules.get(f"{ADDON}.mc_ao.operators")
    return operators is not None and bool(operators._RUNS)


def hold_first_bake():
    """The first bake stops after its first finished tile until Esc cancels it (the add-on's core,
    wrapped as tests/blender's hold_bake does): Esc always lands mid-bake, however fast the machine."""
    import importlib

    core = importlib.import_module(ADDON + ".core")
    real = core.bake  # the add-on's one core call
    state["held"] = False

    def bake(target, *args, on_tile=None, cancel=None, **kwargs):
        first = not state.get("hold_used")
        state["hold_used"] = True

        def tile(*tile_args):
            if on_tile is not None:
                on_tile(*tile_args)
            if first and cancel is not None:
                state["held"] = True
                cancel.wait(120)

        return real(target, *args, on_tile=tile, cancel=cancel, **kwargs)

    core.bake = bake


def scene_setup():
    cube = bpy.data.objects["Cube"]
    cube.location = (0.0, 0.0, 1.3)
    bpy.ops.mesh.primitive_monkey_add(location=(4.0, 0.0, 1.0))
    no_uv = bpy.context.active_object
    no_uv.name = "Suzanne without UVs"
    while no_uv.data.uv_layers:
        no_uv.data.uv_layers.remove(no_uv.data.uv_layers[0])
    bpy.ops.mesh.primitive_plane_add(size=6)
    ground = bpy.context.active_object
    ground.name = "Ground"
    # The user's AO image: a 64 x 64 file on disk, loaded, then painted on (here: a stripe).
    path = os.path.join(OUT, "ground_ao_on_disk.png")
    made = bpy.data.images.new("made", 64, 64)
    made.pixels.foreach_set(np.tile(np.linspace(0, 1, 64 * 64 * 4, dtype=np.float32), 1))
    made.filepath_raw = path
    made.file_format = "PNG"
    made.save()
    bpy.data.images.remove(made)
    image = bpy.data.images.load(path)
    image.name = IMAGE
    pixels = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    pixels.reshape(64, 64, 4)[20:30, :, :3] = 0.25
    image.pixels.foreach_set(pixels)
    state["before"] = describe(image)
    material = bpy.data.materials.new("Ground")
    material.use_nodes = True
    node = material.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    material.node_tree.nodes.active = node
    material.node_tree.links.new(node.outputs["Color"], material.node_tree.nodes["Principled BSDF"].inputs[0])
    ground.data.materials.append(material)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (ground, no_uv))  # the UV-less one is skipped with a warning
    bpy.context.view_layer.objects.active = ground
    settings = bpy.context.scene.mc_ao
    settings.resolution = 256
    settings.samples = 128
    bpy.ops.ed.undo_push(message="scene ready")


@guarded
def ready():
    install()
    hold_first_bake()
    scene_setup()
    window = split_view()
    bpy.app.timers.register(lambda: arrange(window), first_interval=1.0)
    return None


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
def locate(window, view):
    sidebar = next(r for r in view.regions if r.type == "UI")
    main = next(r for r in view.regions if r.type == "WINDOW")
    scale = bpy.context.preferences.system.ui_scale
    top = window.height - (sidebar.y + sidebar.height)
    write("ready.json", {
        "x": sidebar.x + sidebar.width // 2, "y": top + int(BUTTON_BELOW_TOP * scale),
        "tabs_x": sidebar.x + sidebar.width - int(14 * scale), "tabs_top": top,
        "view_x": main.x + main.width // 3, "view_y": window.height - (main.y + main.height // 2),
        "sidebar_width": sidebar.width, "scale": scale,
    })
    state["sidebar"] = sidebar
    bpy.app.timers.register(watch, first_interval=0.5)
    return None


def image_state():
    return describe(bpy.data.images[IMAGE])


def touched(name):
    return os.path.exists(os.path.join(OUT, name))


@guarded
def watch():
    """One step after another, each waiting for trust.sh's file saying that its keys are pressed."""
    for n in (1, 2):  # trust.sh touches dupN between its Shift-D and its Ctrl-Z: is the duplicate there?
        if touched(f"dup{n}") and not touched(f"dup{n}.json"):
            write(f"dup{n}.json", {"objects": sorted(o.name for o in bpy.data.objects)})
    step = state["step"]
    if step == 0 and state["sidebar"].active_panel_category == "MC AO":
        write("tab.json", {"category": "MC AO"})
        state["step"] = 1
    elif step == 1 and running() and state.get("held"):  # the first bake, held mid-way: trust.sh presses Esc
        write("held.json", {"held": True})
        state["step"] = 2
    elif step == 2 and not running():
        now = image_state()
        write("cancelled.json", {"before": state["before"], "now": now,
                                 "as_before": now["digest"] == state["before"]["digest"]})
        state["step"] = 3
    elif step == 3 and touched("undone1"):  # Shift-D (a duplicate), then Ctrl-Z
        now = image_state()
        write("undo_after_cancel.json", {"now": now, "as_before": now["digest"] == state["before"]["digest"],
                                         "objects": sorted(o.name for o in bpy.data.objects)})
        state["step"] = 4
    elif step == 4 and running():  # the second bake, to its end
        state["step"] = 5
    elif step == 5 and not running():
        state["baked"] = image_state()
        # The timeline becomes an Info editor: done.png shows every report of the bake, in order.
        timeline = next(a for a in bpy.context.window_manager.windows[0].screen.areas
                        if a.type == "DOPESHEET_EDITOR")
        timeline.type = "INFO"
        write("done.json", {"now": state["baked"]})
        state["step"] = 6
    elif step == 6 and touched("undone2"):
        now = image_state()
        write("undo_after_bake.json", {"now": now, "as_baked": now["digest"] == state["baked"]["digest"],
                                       "objects": sorted(o.name for o in bpy.data.objects)})
        state["step"] = 7
    elif step == 7 and touched("select_no_uv"):
        for obj in bpy.context.view_layer.objects:
            obj.select_set(obj.name == "Suzanne without UVs")
        bpy.context.view_layer.objects.active = bpy.data.objects["Suzanne without UVs"]
        for area in bpy.context.window_manager.windows[0].screen.areas:
            area.tag_redraw()
        write("no_uv.json", {"selected": "Suzanne without UVs"})
        return None
    return 0.2


bpy.app.timers.register(ready, first_interval=2.0)
