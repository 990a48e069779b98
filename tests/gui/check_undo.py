"""Blender side of the GUI check of undo after two bakes (tests/gui/undo.sh clicks and presses the keys).

Run inside ../shared/tools/blender-gui.sh: ``blender --factory-startup --python tests/gui/check_undo.py``
with $MC_AO_ZIP (the extension), $MC_AO_GUI_OUT (where the JSON files go) and $MC_AO_UNDO_MODE:

- ``packed``: the Ground's AO image exists before the first bake, a generated image painted over and
  packed into the .blend file;
- ``file``: the same, and Save to File with Link to File is on: after each bake the image loads from
  its file in the output folder, which the second bake overwrites.

Steps, each waiting for undo.sh's file saying that its click or keys are done: the first bake (samples
128) -> done1.json; a setting changed (samples 16, from here: no undo step of its own) -> changed.json;
the second bake -> done2.json; Ctrl-Z -> undo.json; Ctrl-Shift-Z -> redo.json. Each JSON holds the
image's state (a digest of ``image.pixels``, the pixels the Image Editor draws) and whether it is the
one it should be: after Ctrl-Z the first bake's pixels, after Ctrl-Shift-Z the second's.
"""

import hashlib
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # the checks' shared module
from guikit import ADDON, guarded, install, split_view, start, write  # noqa: E402

OUT = start("check_undo", os.environ.get("MC_AO_GUI_OUT", "/tmp/out/mc_ao_undo"))
MODE = os.environ.get("MC_AO_UNDO_MODE", "packed")
IMAGE = "Ground_AO"
BUTTON_BELOW_TOP = 52  # pixels from the sidebar's top edge to the middle of the Bake AO button
state = {"step": 0}


def describe():
    image = bpy.data.images.get(IMAGE)
    if image is None:
        return {"exists": False}
    pixels = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    return {"exists": True, "size": list(image.size), "source": image.source,
            "packed": image.packed_file is not None, "dirty": image.is_dirty, "filepath": image.filepath,
            "digest": hashlib.sha1(pixels.tobytes() + repr(tuple(image.size)).encode()).hexdigest()[:12],
            "mean": float(pixels.reshape(-1, 4)[:, 0].mean()) if pixels.size else None,
            "samples_property": image.get("mc_ao_samples")}


def running():
    operators = sys.modules.get(f"{ADDON}.mc_ao.operators")
    return operators is not None and bool(operators._RUNS)


def started(reference):
    """Whether a bake has begun since the image was ``reference``: the operator runs, or a bake quicker
    than the watch's 0.2 s steps has already changed the image."""
    return running() or describe().get("digest") != reference["digest"]


def scene_setup():
    cube = bpy.data.objects["Cube"]
    cube.location = (0.0, 0.0, 1.3)
    bpy.ops.mesh.primitive_plane_add(size=6)
    ground = bpy.context.active_object
    ground.name = "Ground"
    # The user's AO image, there before the first bake: generated, painted over (a stripe), packed.
    image = bpy.data.images.new(IMAGE, 64, 64)
    pixels = np.full(64 * 64 * 4, 0.5, dtype=np.float32)
    pixels.reshape(64, 64, 4)[20:30, :, :3] = 0.25
    image.pixels.foreach_set(pixels)
    image.pack()
    image.use_fake_user = True
    state["before"] = describe()
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
    settings.resolution = 64
    settings.samples = 128
    settings.processes = 1
    if MODE == "file":
        settings.save_to_file = True
        settings.link_to_file = True
        settings.output_dir = os.path.join(OUT, "files")
    bpy.ops.ed.undo_push(message="scene ready")


@guarded
def ready():
    install()
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
        "mode": MODE,
    })
    state["sidebar"] = sidebar
    bpy.app.timers.register(watch, first_interval=0.5)
    return None


def touched(name):
    return os.path.exists(os.path.join(OUT, name))


@guarded
def watch():
    step = state["step"]
    if step == 0 and state["sidebar"].active_panel_category == "MC AO":
        write("tab.json", {"category": "MC AO", "before": state["before"]})
        state["step"] = 1
    elif step == 1 and started(state["before"]):  # the first bake
        state["step"] = 2
    elif step == 2 and not running():
        state["first"] = describe()
        write("done1.json", {"now": state["first"], "changed": state["first"]["digest"] != state["before"]["digest"]})
        bpy.context.scene.mc_ao.samples = 16  # another setting for the second bake
        write("changed.json", {"samples": 16})
        state["step"] = 3
    elif step == 3 and started(state["first"]):  # the second bake
        state["step"] = 4
    elif step == 4 and not running():
        state["second"] = describe()
        write("done2.json", {"now": state["second"],
                             "differs": state["second"]["digest"] != state["first"]["digest"]})
        state["step"] = 5
    elif step == 5 and touched("undone"):  # Ctrl-Z over the 3D Viewport
        now = describe()
        write("undo.json", {"now": now, "as_first_bake": now.get("digest") == state["first"]["digest"],
                            "as_second_bake": now.get("digest") == state["second"]["digest"]})
        state["step"] = 6
    elif step == 6 and touched("redone"):  # Ctrl-Shift-Z
        now = describe()
        write("redo.json", {"now": now, "as_first_bake": now.get("digest") == state["first"]["digest"],
                            "as_second_bake": now.get("digest") == state["second"]["digest"]})
        return None
    return 0.2


bpy.app.timers.register(ready, first_interval=2.0)
