"""--save: the .blend file with the baked color attributes, written atomically and read back to its
end marker before it replaces anything; never the input file unless --overwrite-input."""

import os
import sys

from .. import corelink, filecheck
from .blenderlog import blender_output
from .options import UsageError


def check_save(args, input_blend):
    """--save may not replace the input .blend file unless --overwrite-input, and its folder must be writable."""

    save = getattr(args, "save", None)
    if save is None:
        return
    if input_blend and filecheck.same_file(save, input_blend) and not args.overwrite_input:
        raise UsageError(f"--save {str(save)!r} is the .blend file being baked; give another path, or "
                         "--overwrite-input to replace it")
    if save.is_dir():
        raise UsageError(f"--save {str(save)!r} is a folder; give a .blend file path")
    inputs = [] if args.overwrite_input else [(input_blend, "the .blend file being baked")]
    problem = filecheck.output_problem(save, "--save", inputs=inputs,
                                       outputs=[(args.summary_json, "the --summary-json file")],
                                       replaces=("a .blend file",))
    if problem is not None:
        raise UsageError(f"--save {str(save)!r}: {problem}; nothing was baked")
    problem = filecheck.folder_problem(save.parent if str(save.parent) else ".")
    if problem is not None:
        raise UsageError(f"cannot save {str(save)!r}: {problem}; nothing was baked")


def save_blend(bpy, path):
    """Save the open file (with its baked color attributes) to ``path`` atomically, as a copy."""
    atomicfile = corelink.load("files.atomicfile")

    def write(temp):
        try:
            # An absolute path: Blender 4.2 resolves a relative one against $PWD, not the working directory,
            # and the two differ when a program starts the script in another folder.
            with blender_output():  # without Blender's "Saved copy as" line, which names the temporary file
                result = bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(os.fspath(temp)), copy=True,
                                                     check_existing=False)
        finally:
            # The temporary file existed (empty) when Blender saved over it: Blender kept it as a
            # backup version, "<temp>1".
            atomicfile.remove_quietly(os.fspath(temp) + "1")
        if result != {"FINISHED"}:
            raise RuntimeError(f"Blender did not save it ({result})")

    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    # Blender reports a compressed save cut short by a full disk as done: read it to its end marker.
    atomicfile.write_file(path, write, verify=filecheck.check_blend_complete, ext=".blend")


def save_baked(path, settings, names, summary):
    """--save at the end of a run that baked ``names`` (escaped): save the file, say so; False
    (after saying why, and recording it in the summary) when it was not saved."""
    import bpy

    try:
        save_blend(bpy, path)
    except (OSError, RuntimeError, ValueError) as exc:
        print(f"bake_ao: error: {path} was not saved (any file there is unchanged): {exc}", file=sys.stderr)
        summary.error = f"--save {path}: {exc}"
        return False
    print(f"bake_ao: saved {path} with the color attribute {settings.attribute_name!r} of {', '.join(names)}")
    return True
