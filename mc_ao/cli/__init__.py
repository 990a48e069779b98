"""The background bake, ``scripts/bake_ao.py`` (its entry point): bake ambient occlusion of objects
in a .blend file into image files, without the UI. No bpy at import.

Run by Blender (its arguments for this script follow "--"):

    blender -b -q scene.blend --python scripts/bake_ao.py -- --objects A B --samples 128 --resolution 1024 --output out/

or by a Python that has the bpy module (then the .blend file is the first argument):

    python scripts/bake_ao.py scene.blend --objects A B --samples 128 --resolution 1024 --output out/

Writes <image>_AO.png (and/or .exr, .tif, per --format) for each object into the output folder
and prints a summary.

Selected to Active (as Cycles' bake, see core.highpoly for the exact rules): the AO of high-poly
objects baked into a low-poly's UVs, into <low>_AO:

    ... --selected-to-active --active Chair_low --objects Chair_high Bolts --extrusion 0.05
    ... --match-suffix _high _low [--objects Chair_low Table_low]

--active is the low-poly (default: the file's active object) and --objects the high-poly objects
(default: the file's other selected objects); --extrusion, --max-ray-distance (0 = no limit) and
--cage [NAME] (Cycles' Cage: alone, the low-poly extruded along its vertex normals; with NAME, an
object of the low-poly's topology) are Cycles' settings. --match-suffix HIGH LOW
bakes every object named <base>LOW that has a <base>HIGH onto it, one image each (--objects names
the low-poly objects to bake, default all of them; a <base>LOW without its <base>HIGH is skipped
with a note, or is an error when named). Every setting is checked before anything is baked. File names come from
the image names ("<object>_AO"), made safe: a name never chooses where a file goes (no folders,
no "..", no names Windows refuses; a name that had to change gets a short hash of the original,
and two objects never share a file, also on filesystems that ignore case). Every file lands in
the output folder; it (and the --summary-json file's folder) are the only folders the script
creates. A file is written to a temporary file, checked (read back) and only then moved over any
file already at its path: a write that fails (a full disk) leaves that file as it was, a read-only
file is not replaced, and a replaced file keeps its permission bits. Progress goes to stderr: a
bar on a terminal, else a line per tenth of each object ("bake_ao: [1/2] Ground: 30%"), the first
once the bake has traced its first rays; --quiet turns it off.

Exit status: 0 when every object baked and every file was written; 1 when a bake or a file
failed (the other objects are still baked); 2 for bad arguments or input found before baking (a
setting out of its range, an unknown object, a named object that is not a mesh or has no UV map,
an output folder that cannot be written, an unreadable .blend file, ...), once, with nothing
baked; 130 on Ctrl-C.

--summary-json PATH writes, at the end of every run (also one that exits with 1, 2 or 130), and
atomically, a JSON record of it:

    {"mc_ao": version, "output_version": the version of what the bake writes (each file records it too),
     "blend": the .blend path as given, "exit_code": int, "error": str or null,
     "settings": {the bake's settings, as written into each file's metadata; {} when the
                  arguments were refused},
     "objects": [{"object": name, "status": "ok" or "failed", "seconds": the bake's wall time,
                  "rays": int, "samples_per_texel": mean over covered texels, "files": [absolute
                  paths written], "error": str or null}, ...]}

The summary's path may not be the .blend file, one of the run's files or an existing file that is
not an earlier summary (exit 2, nothing baked, that file untouched); --save's may not be the input
(unless --overwrite-input) or an existing file that is not a .blend file, and the saved file is
read back to its end marker before it replaces anything.

"error" is null after a run in which everything succeeded. Unlimited max_distance is written as
Infinity, as Python's json module writes and reads it (and as the files' metadata records it).

The bake is the add-on's: the same geometry gathering (modifiers applied, world space, corner
normals, the chosen UV map), the same worker thread, file names and writers (mc_ao.filewriter), the
same core.
"""

import os
import sys
import traceback

from .. import baking, corelink, filecheck, filewriter, interrupts, service
from ..choose import Pick, choose
from ..extract import ExtractError
from ..terminal import EscapingStream, escape
from .blenderlog import blender_output
from .blendsave import check_save
from ..schema import BITS, FORMATS
from .options import (UsageError, default_formats, early_summary_args, make_parser, run_by_blender, script_argv,
                      settings_from)
from .scriptrun import bake
from .summary import Summary, cancel_note


def check_paths(args, summary):
    """The output folder and the summary's file can be written (before anything is baked)."""
    atomicfile = corelink.load("files.atomicfile")

    problem = filecheck.folder_problem(args.output)
    if problem is not None:
        raise UsageError(f"cannot write to the output folder '{args.output}': {problem}; nothing was baked")
    if args.summary_json is not None:
        path = args.summary_json
        problem = summary.problem() or filecheck.folder_problem(path.parent)
        if problem is None and atomicfile.read_only(path):
            problem = "it is read-only"
        if problem is not None:
            summary.path = None  # nowhere to write it
            raise UsageError(f"cannot write the summary '{path}': {problem}; nothing was baked")


def main(argv=None):
    """Run the script (see the module's docstring); the exit status. Everything it prints goes through
    mc_ao.terminal.EscapingStream: a name cannot write escape sequences to the terminal or a log."""
    out, err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = EscapingStream(out), EscapingStream(err)
    try:
        return _main(argv)
    finally:
        sys.stdout, sys.stderr = out, err


def _main(argv=None):
    in_blender = run_by_blender()
    argv = script_argv(argv)
    summary = Summary(*early_summary_args(argv, in_blender))
    code = 1
    try:
        with interrupts.sigterm_interrupts():
            code = run(argv, in_blender, summary)
    except UsageError as exc:
        for line in str(exc).splitlines():
            print(f"bake_ao: error: {line}", file=sys.stderr)
        print(exc.usage, file=sys.stderr, end="")
        summary.error = str(exc)
        summary.settings, summary.objects = {}, []
        code = 2
    except KeyboardInterrupt as exc:
        terminated = isinstance(exc, interrupts.Terminated)
        print(f"\nbake_ao: {cancel_note(summary, 'terminated (SIGTERM)' if terminated else 'cancelled')}",
              file=sys.stderr)
        summary.error = "terminated (SIGTERM)" if terminated else "cancelled (Ctrl-C)"
        code = 143 if terminated else 130
    except Exception as exc:
        # Under Blender an escaping exception would end the script with exit status 0.
        traceback.print_exc()
        print("bake_ao: error: unexpected failure, see the traceback above", file=sys.stderr)
        summary.error = f"unexpected failure: {type(exc).__name__}: {exc}"
        code = 1
    if not summary.write(code) and code == 0:
        code = 1
    return code


def run(argv, in_blender, summary):
    args = make_parser(with_blend=not in_blender).parse_args(argv)
    args.format = list(dict.fromkeys(default_formats(args)))
    settings = settings_from(args)
    check_paths(args, summary)
    try:
        import bpy
    except ImportError:
        raise UsageError(
            "this Python has no bpy module: install it (pip install bpy==5.0.1) or run the script "
            "with Blender: blender -b -q scene.blend --python scripts/bake_ao.py -- [options]"
        ) from None
    if not in_blender:
        if not os.path.isfile(args.blend):
            raise UsageError(f"no such .blend file: {args.blend}")
        try:
            with blender_output():  # without Blender's "Read blend: ..." line
                bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend), load_ui=False)
        except RuntimeError as exc:
            raise UsageError(f"cannot open {args.blend}: {exc}") from None

    missing = corelink.missing_dependency()
    if missing is not None:
        raise UsageError(missing)
    core = corelink.load()
    if not filewriter.oiio_available():
        print("bake_ao: no OpenImageIO in this Python; writing files with Blender's image writer", file=sys.stderr)

    check_save(args, bpy.data.filepath)
    try:
        jobs = choose_jobs(bpy, args, settings)
        formats = [(FORMATS[f], BITS[args.bits] if args.bits else None) for f in args.format]
        plan = service.plan(settings, jobs, str(args.output), formats)
    except (ExtractError, core.McAoError) as exc:
        raise UsageError(str(exc)) from None
    summary.outputs = [(f, "one of this run's files") for f in plan.paths()]
    if getattr(args, "save", None) is not None:
        summary.outputs.append((args.save, "the --save file"))
    check_paths(args, summary)  # again, now that the run's own files are known
    summary.settings = record = filewriter.settings_record(settings)
    if args.match_suffix:  # the summary's record only: file metadata holds plain values
        summary.settings = dict(record, match_suffix=list(args.match_suffix))
    if getattr(args, "match_collections", False):
        summary.settings = dict(summary.settings, match_collections=True)
    return bake(plan, args, summary)


def choose_jobs(bpy, args, settings):
    """The jobs of the objects the options name (or the file's selection, or every mesh: mc_ao.choose),
    after printing what was left out; UsageError for objects that cannot bake."""
    view_layer = bpy.context.view_layer
    layer = view_layer.objects
    pick = Pick(selected=[o for o in layer if o.select_get()], active=layer.active, names=tuple(args.objects or ()),
                active_name=args.active, match_suffix=tuple(args.match_suffix or ()) or None,
                match_collections=bool(getattr(args, "match_collections", False)), script=True)
    try:
        choice = choose(settings, pick, view_layer)
        needs_uvs = baking.needs_uvs(settings)
        for obj in choice.skipped:
            print(f"bake_ao: {escape(obj.name)}: skipped, it {baking.skip_reason(obj, needs_uvs)}", file=sys.stderr)
        for note in choice.notes:
            print(f"bake_ao: {escape(note)}", file=sys.stderr)
        jobs = choice.jobs(bpy.context.evaluated_depsgraph_get())
    except ExtractError as exc:  # a ChoiceError too
        # Said to the operator's user as "Selected to Active: the active object X ...": here X is --active's.
        raise UsageError(str(exc).replace("Selected to Active: ", "").replace("the active object ", "")) from None
    for job in jobs:
        for note in job.notes:
            print(f"bake_ao: {escape(job.object_name)}: warning: {escape(note)}", file=sys.stderr)
    return jobs
