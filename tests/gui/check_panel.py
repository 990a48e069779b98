"""Blender side of tests/gui/panel.sh: the panel's items in a real Blender 4.3.

Run inside ../shared/tools/blender-gui.sh by panel.sh: ``blender --factory-startup --python
tests/gui/check_panel.py``. It installs the zip named by $MC_AO_ZIP (as Install from Disk does),
opens sample_scenes/props.blend, splits the window into the 3D Viewport (sidebar on the tab MC AO)
and two Image Editors on the right: the upper one free, the lower one pinned to Crate_ORM. Then it
answers panel.sh's commands, one JSON file each ($MC_AO_GUI_OUT/cmd_N.json -> ack_N.json):

    {"do": "set", "values": {setting: value}}     scene.mc_ao's settings ("into": an image's name)
    {"do": "select", "objects": [...], "active": name}
    {"do": "state"}                                what the panel and the editors show now
    {"do": "editor_mode", "mode": "PAINT"}         the free Image Editor's mode
    {"do": "editor_image", "image": name}          the free Image Editor's image
    {"do": "wait_bake", "seconds": N}              until no bake runs (after a click), then the state

Nothing here clicks: panel.sh does, with xdotool, as a hand does.
"""

import json
import os
import sys
import time

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # the checks' shared module
from guikit import ADDON, guarded, install, start, write  # noqa: E402

OUT = start("check_panel", os.environ.get("MC_AO_GUI_OUT", "/tmp/out/mc_ao_panel"), log_writes=False,
            json_default=str)
SCENE = os.path.join(os.getcwd(), "sample_scenes", "props.blend")
# Pixels from the sidebar's top edge to the middle of the Bake AO button, at UI scale 1.
BUTTON_BELOW_TOP = 52
state = {"next": 0, "window": None, "view": None, "free": None, "pinned": None, "outcome": None}


def addon_module(name):
    """The installed extension's module mc_ao.<name> (bl_ext.<repo>.mc_ao.mc_ao.<name>)."""
    return next(module for key, module in sys.modules.items()
                if key.startswith(ADDON + ".") and key.endswith(f"mc_ao.{name}"))


@guarded
def ready():
    install()
    bpy.ops.wm.open_mainfile(filepath=SCENE, load_ui=False)
    bpy.app.timers.register(split, first_interval=1.0)


@guarded
def split():
    window = bpy.context.window_manager.windows[0]
    area = max((a for a in window.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.screen.area_split(direction="VERTICAL", factor=0.55)
    bpy.app.timers.register(lambda: split_right(window), first_interval=1.0)


@guarded
def split_right(window):
    views = sorted((a for a in window.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.x)
    right = views[-1]
    right.type = "IMAGE_EDITOR"
    region = next(r for r in right.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=right, region=region):
        bpy.ops.screen.area_split(direction="HORIZONTAL", factor=0.5)
    bpy.app.timers.register(lambda: arrange(window), first_interval=1.0)


@guarded
def arrange(window):
    editors = sorted((a for a in window.screen.areas if a.type == "IMAGE_EDITOR"), key=lambda a: -a.y)
    free, pinned = editors[0], editors[-1]
    orm = bpy.data.images["Crate_ORM"]
    free.spaces.active.image = orm
    pinned.spaces.active.image = orm
    pinned.spaces.active.use_image_pin = True
    view = min((a for a in window.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.x)
    space = view.spaces.active
    space.show_region_ui = True
    space.shading.type = "SOLID"
    space.shading.color_type = "TEXTURE"
    state.update(window=window, view=view, free=free, pinned=pinned)
    s = bpy.context.scene.mc_ao
    s.resolution, s.samples, s.processes = 512, 32, 0
    select(["Crate"], "Crate")
    for area in window.screen.areas:
        area.tag_redraw()
    bpy.app.timers.register(locate, first_interval=1.0)


@guarded
def locate():
    window, view = state["window"], state["view"]
    sidebar = next(r for r in view.regions if r.type == "UI")
    scale = bpy.context.preferences.system.ui_scale
    top = window.height - (sidebar.y + sidebar.height)
    write("ready.json", {"x": sidebar.x + sidebar.width // 2, "y": top + int(BUTTON_BELOW_TOP * scale),
                         "tabs_x": sidebar.x + sidebar.width - int(14 * scale), "tabs_top": top,
                         "sidebar": [sidebar.x, top, sidebar.width, sidebar.height], "scale": scale,
                         "window": [window.width, window.height]})
    bpy.app.timers.register(wait_for_tab, first_interval=0.2)


@guarded
def wait_for_tab():
    sidebar = next(r for r in state["view"].regions if r.type == "UI")
    if sidebar.active_panel_category != "MC AO":
        return 0.2
    write("tab.json", {"category": sidebar.active_panel_category})
    bpy.app.timers.register(serve, first_interval=0.2)
    return None


def select(names, active):
    layer = bpy.context.view_layer
    for obj in layer.objects:
        obj.select_set(obj.name in names)
    layer.objects.active = bpy.data.objects.get(active) if active else None


def set_values(values):
    s = bpy.context.scene.mc_ao
    for name, value in values.items():
        if name == "into":
            s.into = bpy.data.images.get(value) if value else None
        elif name == "quantity":
            s.quantity = set(value)
        else:
            setattr(s, name, value)


def report_state():
    operators, panel = addon_module("operators"), addon_module("panel")
    settings_mod = addon_module("settings")
    context = bpy.context
    with context.temp_override(window=state["window"], area=state["view"],
                               region=next(r for r in state["view"].regions if r.type == "UI")):
        poll = bpy.ops.object.mc_ao_bake.poll()
        reason = operators.why_not(bpy.context)
        values = settings_mod.BakeSettings.from_properties(bpy.context.scene.mc_ao)
        occluded = panel.occluded_by(values.in_effect())
        estimate = ""
        choice, _ = operators.choice_of(bpy.context)
        if choice is not None and choice.targets:
            estimate, _ = panel.cost_text(bpy.context, values.in_effect(), choice.targets)
    window = state["window"]

    def rect(area):  # [x, y from the top, width, height] in X11's screen coordinates
        return [area.x, window.height - (area.y + area.height), area.width, area.height]

    return {"poll": poll, "reason": reason, "free_rect": rect(state["free"]), "pinned_rect": rect(state["pinned"]), "occluded_by": occluded, "estimate": estimate,
            "running": operators.is_running(), "last": operators.last_outcome,
            "free_editor": getattr(state["free"].spaces.active.image, "name", None),
            "free_mode": state["free"].spaces.active.mode,
            "pinned_editor": getattr(state["pinned"].spaces.active.image, "name", None),
            "placeholder": panel.IMAGE_NAME_PLACEHOLDER,
            "images": sorted(i.name for i in bpy.data.images)}


@guarded
def serve():
    """Answer the next command file, if there is one (every 0.2 s)."""
    n = state["next"]
    path = os.path.join(OUT, f"cmd_{n}.json")
    if not os.path.exists(path):
        return 0.2
    with open(path) as fh:
        cmd = json.load(fh)
    state["next"] = n + 1
    do = cmd["do"]
    if do == "set":
        set_values(cmd["values"])
    elif do == "select":
        select(cmd["objects"], cmd.get("active"))
    elif do == "editor_mode":
        state["free"].spaces.active.mode = cmd["mode"]
    elif do == "editor_image":
        state["free"].spaces.active.image = bpy.data.images.get(cmd["image"])
    elif do == "wait_bake":
        state["wait_until"] = time.monotonic() + cmd.get("seconds", 300)
        state["seen_running"] = False
        bpy.app.timers.register(lambda: wait_bake(n), first_interval=0.2)
        return None
    for area in state["window"].screen.areas:
        area.tag_redraw()
    data = report_state()
    state["outcome"] = addon_module("operators").last_outcome  # what a click after this ack is told by
    write(f"ack_{n}.json", data)
    return 0.2


@guarded
def wait_bake(n):
    operators = addon_module("operators")
    running = operators.is_running()
    # A bake quicker than these 0.3 s steps (or than the second between the click and this command) is
    # never seen running: its outcome, set when a bake ends, is then new since the last answer.
    outcome = operators.last_outcome
    ended = outcome is not state["outcome"] and outcome is not None and outcome[0] != "ERROR"
    state["seen_running"] |= running or ended
    if running and time.monotonic() < state["wait_until"]:
        data = report_state()
        write(f"during_{n}.json", data)  # what the editors show while it fills in
        return 0.3
    for area in state["window"].screen.areas:
        area.tag_redraw()
    data = report_state()
    data["seen_running"] = state["seen_running"]
    state["outcome"] = operators.last_outcome
    write(f"ack_{n}.json", data)
    bpy.app.timers.register(serve, first_interval=0.2)
    return None


os.makedirs(OUT, exist_ok=True)
bpy.app.timers.register(ready, first_interval=2.0)
