"""Blender's command line, for the few options a batch task uses, on the bpy module (Blender itself).

CI has the bpy module but no Blender executable. The batch runner's Blender command is

    blender --background FILE --python-exit-code 1 --python SCRIPT -- ARGS

and this runs it the way Blender does, in order: open FILE (in background mode a file that fails to
load ends Blender with exit status 1 before any script runs; Blender 4.3 checked by hand), then run
SCRIPT as ``__main__`` with ``sys.argv`` holding the whole command line (a script reads its own
arguments after ``--``), and exit with the status the script exits with (or 1 when it raises, per
--python-exit-code). Any other option is refused, so a command line this does not understand fails
the test instead of being half-run. Also -b, -y/--enable-autoexec (accepted, without effect on a
file without scripts) as Flamenco's default blenderArgs pass them.
"""

import runpy
import sys


def main(argv):
    background = False
    exit_code_on_error = 0
    blend = script = None
    i = 0
    while i < len(argv):
        a = argv[i]
        if a == "--":
            break
        if a in ("-b", "--background"):
            background = True
        elif a in ("-y", "--enable-autoexec"):
            pass
        elif a == "--python-exit-code":
            i += 1
            exit_code_on_error = int(argv[i])
        elif a in ("-P", "--python"):
            i += 1
            script = argv[i]
        elif not a.startswith("-") and a.endswith(".blend") and script is None and blend is None:
            blend = a
        else:
            print(f"batch_blender_cli: unsupported argument {a!r}", file=sys.stderr)
            return 64
        i += 1
    if not background or script is None:
        print("batch_blender_cli: only 'blender --background [FILE] --python SCRIPT' is supported", file=sys.stderr)
        return 64

    import bpy

    if blend is not None:
        try:
            bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
        except RuntimeError as exc:
            print(f"Error: {exc}", file=sys.stderr)
            return 1
    sys.argv = [sys.executable] + list(argv)
    try:
        runpy.run_path(script, run_name="__main__")
    except SystemExit as exc:
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    except BaseException:
        import traceback

        traceback.print_exc()
        return exit_code_on_error
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
