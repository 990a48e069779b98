"""What the GUI checks share inside Blender (each tests/gui/*.sh starts Blender with one of them): the
folder they write to, their log lines, timer steps that report a failure instead of hanging, the
extension's zip installed as a user installs it, and the 3D Viewport split in two.

A check puts this folder on its path, imports what it uses and calls :func:`start` before anything else.
"""

import json
import os
import tempfile
import traceback

import bpy

#: The extension repository the zip is installed into, and the add-on's module name there.
REPO = "mc_ao_gui"
ADDON = f"bl_ext.{REPO}.mc_ao"

_check = {"name": "gui", "out": "/tmp/out/mc_ao_gui", "log_writes": True, "json_default": None}


def start(name, out, log_writes=True, json_default=None):
    """This check's ``name`` (its log lines begin with it in brackets) and the folder ``out`` its files go
    to (returned); ``log_writes``: each file written is also logged; ``json_default``: json.dump's."""
    _check.update(name=name, out=out, log_writes=log_writes, json_default=json_default)
    return out


def log(*args):
    print(f"[{_check['name']}]", *args, flush=True)


def write(name, data):
    """``data`` as JSON in the check's folder, whole or not at all (the shell script polls for it)."""
    path = os.path.join(_check["out"], name)
    with open(path + ".tmp", "w") as fh:
        json.dump(data, fh, indent=1, default=_check["json_default"])
    os.replace(path + ".tmp", path)
    if _check["log_writes"]:
        log(name, data)


def guarded(step):
    """A timer step that, if it fails, writes error.json (the shell script stops on it) instead of hanging."""
    def run(*args):
        try:
            return step(*args)
        except Exception:
            traceback.print_exc()
            write("error.json", {"step": step.__name__, "error": traceback.format_exc()})
            return None
    return run


def install():
    """Install and enable $MC_AO_ZIP from a repository of its own, as Install from Disk does."""
    repos = bpy.context.preferences.extensions.repos
    directory = tempfile.mkdtemp(prefix="mc_ao_gui_repo_")
    repos.new(name="MC AO GUI", module=REPO, custom_directory=directory, source="USER")
    result = bpy.ops.extensions.package_install_files(filepath=os.environ["MC_AO_ZIP"], repo=REPO,
                                                      enable_on_install=True)
    log("install:", result, "enabled:", ADDON in bpy.context.preferences.addons)


def split_view(factor=0.5):
    """Split the largest 3D Viewport in two (the left part ``factor`` of it); the halves get their jobs
    once they have been drawn. Returns the window."""
    window = bpy.context.window_manager.windows[0]
    area = max((a for a in window.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.screen.area_split(direction="VERTICAL", factor=factor)
    return window
