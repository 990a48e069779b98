"""Blender side of the occluder panel's screenshots: the checkout's add-on, a scene with occluder sets.

Run inside ../shared/tools/blender-gui.sh (a real Blender GUI on a virtual screen), from the
repository root (tests/gui/occluders.sh does it):

    blender --factory-startup --window-geometry 0 0 1600 1000 --python tests/gui/occluders_panel.py

Registers mc_ao from the checkout (no core needed to draw the panel), builds a floor under boxes in
collections Props and Floor Props, sets the new settings (Include, Exclude, Ground, Quantity) as a user
would, opens the sidebar and writes $MC_AO_GUI_OUT/ready.json with where the sidebar and its tabs are.
tab.json follows once the sidebar shows the MC AO tab.
"""

import json
import os
import sys
import traceback

import bpy

OUT = os.environ.get("MC_AO_GUI_OUT", "/tmp/out/mc_ao_occluders")
sys.path.insert(0, os.getcwd())


def write(name, data):
    with open(os.path.join(OUT, name + ".tmp"), "w") as fh:
        json.dump(data, fh, indent=1)
    os.replace(os.path.join(OUT, name + ".tmp"), os.path.join(OUT, name))


def guarded(step):
    def run(*args):
        try:
            return step(*args)
        except Exception:
            traceback.print_exc()
            write("error.json", {"step": step.__name__, "error": traceback.format_exc()})
            return None
    return run


def scene_setup():
    import mc_ao

    mc_ao.register()
    scene = bpy.context.scene
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    bpy.ops.mesh.primitive_plane_add(size=6)
    floor = bpy.context.active_object
    floor.name = "Floor"
    props = bpy.data.collections.new("Props")
    scene.collection.children.link(props)
    inner = bpy.data.collections.new("Floor Props")
    props.children.link(inner)
    for name, collection, x in (("Crate", props, -1.2), ("Rug", inner, 1.2)):
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(x, 0, 0.6))
        obj = bpy.context.active_object
        obj.name = name
        for c in list(obj.users_collection):
            c.objects.unlink(obj)
        collection.objects.link(obj)
    s = scene.mc_ao
    s.occluder_collections.add().collection = props
    s.exclude_collections.add().collection = inner
    s.ground, s.ground_height = "HEIGHT", -0.05
    s.quantity = {"AO", "THICKNESS"}
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj is floor)
    bpy.context.view_layer.objects.active = floor


@guarded
def ready():
    scene_setup()
    window = bpy.context.window_manager.windows[0]
    view = max((a for a in window.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.width * a.height)
    view.spaces.active.show_region_ui = True
    view.tag_redraw()
    bpy.app.timers.register(lambda: locate(window, view), first_interval=1.0)


@guarded
def locate(window, view):
    sidebar = next(r for r in view.regions if r.type == "UI")
    scale = bpy.context.preferences.system.ui_scale
    top = window.height - (sidebar.y + sidebar.height)
    write("ready.json", {"tabs_x": sidebar.x + sidebar.width - int(14 * scale), "tabs_top": top,
                         "sidebar": [sidebar.x, top, sidebar.width, sidebar.height], "scale": scale})
    bpy.app.timers.register(lambda: wait_for_tab(sidebar), first_interval=0.2)


@guarded
def wait_for_tab(sidebar):
    if sidebar.active_panel_category != "MC AO":
        return 0.2
    write("tab.json", {"category": sidebar.active_panel_category})
    bpy.app.timers.register(watch, first_interval=0.5)
    return None


@guarded
def watch():
    """state.json: the settings as the clicks leave them, every half second."""
    s = bpy.context.scene.mc_ao
    write("state.json", {"include": [i.collection.name if i.collection else None for i in s.occluder_collections],
                         "exclude": [i.collection.name if i.collection else None for i in s.exclude_collections],
                         "only_local": s.only_local, "ground": s.ground, "quantity": sorted(s.quantity),
                         "occlude_others": bpy.context.active_object.mc_ao.occlude_others
                         if bpy.context.active_object else None})
    return 0.5


os.makedirs(OUT, exist_ok=True)
bpy.app.timers.register(ready, first_interval=2.0)
