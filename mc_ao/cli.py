"""The background bake, ``scripts/bake_ao.py`` (its entry point): bake ambient occlusion of objects
in a .blend file into image files, without the UI. No bpy at import.

Run by Blender (its arguments for this script follow "--"):

    blender -b scene.blend --python scripts/bake_ao.py -- --objects A B --samples 128 --resolution 1024 --output out/

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

import argparse
import json
import os
import sys
import time
import traceback
from pathlib import Path

from . import corelink, filecheck, schema
from .terminal import EscapingStream, escape

# --format choice -> Blender's file format name (mc_ao.settings.FILE_FORMATS)
FORMATS = {"png": "PNG", "exr": "OPEN_EXR", "tif": "TIFF", "ply": "PLY"}
BITS = {"8": 8, "16": 16, "half": "half", "float": "float"}


class UsageError(Exception):
    """Bad arguments or input: exit status 2. ``usage``: the usage text to show after the message.

    ``message``: one problem (text), or a list of them, one line each; names in them are escaped
    (mc_ao.terminal.escape), so a name's newline cannot start a line of its own.
    """

    def __init__(self, message, usage=""):
        problems = message if isinstance(message, list) else [message]
        super().__init__("\n".join(escape(str(p)) for p in problems))
        self.usage = usage


class Parser(argparse.ArgumentParser):
    """argparse, but a bad argument raises UsageError (exit 2 with the summary written) instead of exiting."""

    def error(self, message):
        raise UsageError(message, self.format_usage())


def run_by_blender():
    """True when the Blender executable runs this script: it has imported bpy before running it."""
    return "bpy" in sys.modules


def script_argv(argv=None):
    if argv is not None:
        return list(argv)
    if run_by_blender():
        return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    return sys.argv[1:]


def parse_resolution(text):
    try:
        parts = [int(p) for p in text.lower().split("x")]
    except ValueError:
        parts = []
    if len(parts) not in (1, 2) or min(parts) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a size: use N or WxH, e.g. 1024 or 2048x1024")
    return parts[0], parts[-1]


def _add_setting(parser, setting):
    """The option of one schema setting (mc_ao.schema): its type, choices, default and help."""
    option, dest = setting.option, setting.option_key
    default = setting.default
    help_text = setting.help.replace("%", "%%")  # argparse formats help with %
    if setting.kind == "bool" or setting.flag is not None:
        parser.add_argument(option, dest=dest, action="store_true", help=help_text)
        return
    kwargs = {"dest": dest, "help": f"{help_text} (default: {default!r})"}
    if setting.sets:  # not given: None, so that giving it can set another setting
        kwargs["default"] = None
    if setting.kind in ("enum", "flags"):
        # any case: --channel R
        kwargs.update(choices=[schema.cli_value(i) for i in setting.identifiers], type=str.lower)
        if setting.kind == "enum":
            kwargs["default"] = schema.cli_value(default)
            kwargs["help"] = f"{help_text} (default: {schema.cli_value(default)})"
        else:
            kwargs.update(nargs="+", default=[schema.cli_value(d) for d in default])
            kwargs["help"] = f"{help_text} (default: {' '.join(schema.cli_value(d) for d in default)})"
    elif setting.kind == "collections":
        kwargs.update(nargs="+", default=[], metavar="COLLECTION", help=f"{help_text} (default: none)")
    elif setting.kind == "int":
        kwargs.update(type=int, default=default, metavar="N")
    elif setting.kind in ("float", "distance"):
        kwargs.setdefault("default", default)
        kwargs.update(type=float, metavar="D" if setting.kind == "distance" else "X")
    else:
        kwargs.update(default=default, metavar="NAME")
    parser.add_argument(option, **kwargs)


def make_parser(with_blend):
    """The script's options: every mc_ao.schema setting that has an option (its manifest key is the
    option's name with '_' for '-'), and the script's own (what to bake, where files go)."""
    parser = Parser(
        prog="bake_ao.py",
        description="Bake ambient occlusion of objects in a .blend file into image files.",
        epilog="Under Blender: blender -b scene.blend --python scripts/bake_ao.py -- [options]. "
               "Exit status: 0 all baked and written, 1 a bake or file failed, 2 bad arguments or "
               "input (nothing baked), 130 Ctrl-C.",
    )
    if with_blend:
        parser.add_argument("blend", help=".blend file to open")
    parser.add_argument("--objects", nargs="+", metavar="NAME",
                        help="mesh objects to bake (default: the selected ones with a UV map, "
                             "else every mesh with a UV map in the view layer)")
    parser.add_argument("--output", "-o", type=Path, default=Path("out"),
                        help="output folder, created if missing (default: out)")
    parser.add_argument("--format", nargs="+", choices=sorted(FORMATS), default=None,
                        help="file formats to write, one file each (default: png; ply for --target "
                             "vertex-colors)")
    parser.add_argument("--bits", choices=sorted(BITS),
                        help="sample type of the files: png 8|16, exr half|float, tif 8|16|float "
                             "(default: 8-bit PNG and TIFF, half EXR)")
    parser.add_argument("--resolution", type=parse_resolution, default=(1024, 1024), metavar="N|WxH",
                        help="image size, N or WxH (default: 1024)")
    parser.add_argument("--attribute-type", choices=("float", "byte"), default="float",
                        help="type of a new color attribute: float (linear) or byte (sRGB-encoded, as "
                             "Blender stores byte colors) (default: float)")
    parser.add_argument("--save", type=Path, metavar="PATH.blend",
                        help="with --target vertex-colors: save the .blend file with the baked color "
                             "attributes to PATH (atomically; never the input file unless "
                             "--overwrite-input is given)")
    parser.add_argument("--overwrite-input", action="store_true",
                        help="allow --save to replace the .blend file the bake read")
    for setting in schema.SETTINGS:
        if setting.option_key is not None and "selected_to_active" not in setting.targets:
            _add_setting(parser, setting)
    s2a = parser.add_argument_group(
        "selected to active", "bake the AO of high-poly objects into a low-poly's UVs (Cycles' Selected to Active)")
    for setting in schema.SETTINGS:
        if setting.option_key is not None and "selected_to_active" in setting.targets:
            _add_setting(s2a, setting)
    s2a.add_argument("--active", metavar="NAME",
                     help="the low-poly to bake onto (default: the file's active object)")
    s2a.add_argument("--cage", metavar="NAME", nargs="?", const="",
                     help="cast the rays from a cage (Cycles' Cage): alone, the low-poly extruded along its "
                          "smooth vertex normals; with NAME, that object, a copy of the low-poly with its "
                          "vertices moved outwards (the extrusion is then not used)")
    s2a.add_argument("--match-suffix", nargs=2, metavar=("HIGH", "LOW"),
                     help="bake each object named <base>HIGH onto <base>LOW (e.g. _high _low: Chair_high "
                          "onto Chair_low), one image per low-poly; implies --selected-to-active")
    parser.add_argument("--summary-json", type=Path, metavar="PATH",
                        help="write a JSON record of the run (settings, each object's status, time, "
                             "rays and files) to PATH at the end, whatever the exit status")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress")
    return parser


class Progress:
    """Progress of the bake on stderr: a bar on a terminal, else a line at each tenth ("Ground: 30%").

    The first line of each object comes with its first traced rays: a log shows when the tracing
    began, and a test can wait for it. Called on the main thread, from the bake's messages.
    """

    def __init__(self, stream=sys.stderr, enabled=True, width=30):
        self.stream = stream
        self.enabled = enabled
        self.tty = enabled and stream.isatty()
        self.width = width
        self.label = ""
        self.shown = 0.0
        self.tenth = None
        self.start = time.monotonic()

    def begin(self, label):
        self.label = label
        self.tenth = None
        self.start = time.monotonic()
        if self.tty:
            self._draw(0.0)

    def update(self, fraction):
        if not self.enabled:
            return
        fraction = min(max(fraction, 0.0), 1.0)
        if self.tty:
            now = time.monotonic()
            if fraction >= 1.0 or now - self.shown >= 0.1:  # drawing only: the bake does not wait
                self._draw(fraction)
            return
        tenth = int(fraction * 10)
        if self.tenth is None or tenth > self.tenth:
            self.tenth = tenth
            print(f"bake_ao: {self.label}: {tenth * 10}%", file=self.stream, flush=True)

    def _draw(self, fraction):
        now = time.monotonic()
        self.shown = now
        filled = int(round(self.width * fraction))
        bar = "#" * filled + "-" * (self.width - filled)
        self.stream.write(f"\r{self.label} [{bar}] {fraction:4.0%} {now - self.start:6.1f} s")
        self.stream.flush()

    def end(self):
        if self.tty:
            self.stream.write("\r" + " " * (len(self.label) + self.width + 20) + "\r")
            self.stream.flush()


class Summary:
    """What --summary-json records; filled in as the run goes, written once at its end."""

    def __init__(self, path, blend):
        self.path = path
        self.blend = blend
        self.settings = {}
        self.objects = []
        self.error = None
        self.outputs = []  # (path, what): the run's other files, which the summary may not be

    def problem(self):
        """Why the summary may not be written at its path (None when it may): it is the input .blend
        file, one of the run's files, or an existing file that is not an earlier summary."""
        from . import filecheck

        if self.path is None:
            return None
        if os.path.isdir(self.path):
            return "it is a folder"
        return filecheck.output_problem(self.path, "the summary",
                                        inputs=[(self.blend, "the .blend file being baked")],
                                        outputs=self.outputs, replaces=("an mc_ao summary",))

    def add(self, name, status, seconds=0.0, rays=0, samples_per_texel=0.0, files=(), error=None, **extra):
        self.objects.append({
            "object": name, "status": status, "seconds": float(seconds), "rays": int(rays),
            "samples_per_texel": float(samples_per_texel), "files": [str(f) for f in files],
            "error": None if error is None else str(error), **extra,
        })

    def write(self, exit_code):
        """Write the record atomically; False (after saying why) when it cannot be written."""
        if self.path is None:
            return True
        atomicfile = corelink.load("atomicfile")
        version = corelink.load("_version")

        record = {
            "mc_ao": version.__version__, "output_version": version.OUTPUT_VERSION, "blend": self.blend,
            "exit_code": exit_code,
            "error": self.error if exit_code else None,
            "settings": self.settings, "objects": self.objects,
        }
        text = json.dumps(record, indent=2) + "\n"
        problem = self.problem()
        if problem is not None:
            print(f"bake_ao: error: the summary {str(self.path)!r} was not written: {problem}", file=sys.stderr)
            return False

        try:
            atomicfile.write_text(self.path, text)
        except OSError as exc:
            print(f"bake_ao: error: the summary {str(self.path)!r} was not written: {exc}", file=sys.stderr)
            return False
        return True


def pick_objects(bpy, names, baking, needs_uvs=True):
    """The objects to bake: the named ones, else the selected bakeable ones, else every bakeable one.

    Named objects that cannot be baked are an error (exit 2); selected ones are skipped with a note.
    ``needs_uvs``: False for --target vertex-colors (any mesh can be baked).
    """
    layer_objects = bpy.context.view_layer.objects
    if names:
        names = list(dict.fromkeys(names))
        missing = [n for n in names if n not in layer_objects]
        if missing:
            meshes = sorted(o.name for o in layer_objects if o.type == "MESH")
            raise UsageError(
                f"no object {', '.join(map(repr, missing))} in the view layer; "
                f"its meshes: {', '.join(meshes) or 'none'}"
            )
        objects = [layer_objects[n] for n in names]
        for obj in objects:
            if not baking.can_be_target(obj, needs_uvs):
                raise UsageError(f"{obj.name} {baking.skip_reason(obj, needs_uvs)}")
        return objects
    selected = [o for o in layer_objects if o.select_get()]
    objects = baking.targets_of(selected, needs_uvs)
    if objects:
        for obj in selected:
            if obj not in objects:
                print(f"bake_ao: {escape(obj.name)}: skipped, it {baking.skip_reason(obj, needs_uvs)}", file=sys.stderr)
        return objects
    objects = baking.targets_of(layer_objects, needs_uvs)
    what = "mesh with a UV map" if needs_uvs else "mesh"
    if not objects:
        raise UsageError(f"the file has no {what} to bake")
    print(
        f"bake_ao: {f'no {what} is selected' if selected else 'nothing is selected'}; "
        f"baking every {what}: {', '.join(escape(o.name) for o in objects)}",
        file=sys.stderr,
    )
    return objects


def _objects_named(bpy, names, what):
    """The view layer's objects of these names (UsageError naming the missing ones)."""
    layer = bpy.context.view_layer.objects
    missing = [n for n in names if n not in layer]
    if missing:
        raise UsageError(f"no {what} {', '.join(map(repr, missing))} in the view layer; its objects: "
                         f"{', '.join(sorted(o.name for o in layer)) or 'none'}")
    return [layer[n] for n in names]


def selected_to_active_pairs(bpy, args):
    """[(low-poly object, [high-poly objects])] of the Selected to Active options; UsageError when the
    objects are not there or not usable (before baking)."""
    from . import baking

    layer = bpy.context.view_layer.objects
    if args.match_suffix:
        high_suffix, low_suffix = args.match_suffix
        if args.objects:
            lows = _objects_named(bpy, list(dict.fromkeys(args.objects)), "object")
            for obj in lows:
                if not obj.name.endswith(low_suffix):
                    raise UsageError(f"{obj.name} does not end with the low-poly suffix {low_suffix!r}")
        else:
            lows = sorted((o for o in layer if o.name.endswith(low_suffix) and len(o.name) > len(low_suffix)),
                          key=lambda o: o.name)
        pairs = []
        for low in lows:
            name = low.name[:-len(low_suffix)] + high_suffix
            high = layer.get(name)
            if high is None:
                if args.objects:
                    raise UsageError(f"{low.name} has no high-poly {name!r} in the view layer")
                print(f"bake_ao: {escape(low.name)}: skipped, there is no {escape(name)}", file=sys.stderr)
                continue
            pairs.append((low, [high]))
        if not pairs:
            raise UsageError(f"no pair of objects named <base>{high_suffix} and <base>{low_suffix} in the view layer")
        return pairs
    if args.active is not None:
        low = _objects_named(bpy, [args.active], "object")[0]
    else:
        low = layer.active
        if low is None:
            raise UsageError("--selected-to-active needs --active NAME: the file has no active object")
    cage = _objects_named(bpy, [args.cage], "cage object")[0] if args.cage else None
    if args.objects:
        highs = _objects_named(bpy, list(dict.fromkeys(args.objects)), "object")
    else:
        highs = [o for o in layer if o.select_get() and o is not low and o is not cage]
        if highs:
            print(f"bake_ao: baking the selected {', '.join(escape(o.name) for o in highs)} onto {escape(low.name)}",
                  file=sys.stderr)
    if not highs:
        raise UsageError(f"no high-poly objects to bake onto {low.name}: name them with --objects, or select "
                         "them in the file")
    for obj in highs:
        if obj.type not in baking.GEOMETRY_TYPES:
            raise UsageError(f"{obj.name} is {baking.kind_of(obj)}, not an object with a surface to bake from")
    return [(low, highs)]


def plan_selected_to_active(bpy, args, settings):
    """The Jobs of a Selected to Active run, one per low-poly (UsageError for unusable objects)."""
    from . import selected_to_active
    from .extract import ExtractError

    depsgraph = bpy.context.evaluated_depsgraph_get()
    plan = []
    for low, highs in selected_to_active_pairs(bpy, args):
        reason = selected_to_active.why_not([low, *highs], low, selected_to_active.cage_of(settings))
        if reason is not None:
            raise UsageError(reason.replace("Selected to Active: ", "").replace("the active object ", ""))
        try:
            plan.append(selected_to_active.plan(depsgraph, low, [low, *highs], settings,
                                                view_layer=bpy.context.view_layer))
        except ExtractError as exc:
            raise UsageError(str(exc)) from None
    names = [job.image_name for job in plan]
    for name in set(names):
        if names.count(name) > 1:
            raise UsageError(f"several low-poly objects would bake into image {name!r}; put {{object}} into --image-name")
    for job in plan:
        for note in job.notes:
            print(f"bake_ao: {escape(job.object_name)}: warning: {escape(note)}", file=sys.stderr)
    return plan


def settings_from(args):
    """The BakeSettings of the arguments, after checking every value (UsageError lists what is wrong)."""
    imageio = corelink.load("imageio")
    from . import schema
    from .settings import BakeSettings

    width, height = args.resolution
    values, problems = schema.from_options(args)
    values.update(
        resolution=width, height=height, float_buffer=args.attribute_type == "float",
        use_selected_to_active=bool(args.selected_to_active or args.match_suffix),
        use_cage=args.cage is not None, cage_object=args.cage or "",
    )
    settings = BakeSettings(**values)
    problems += selected_to_active_problems(args)
    for field, message in schema.problems(settings):
        if field in ("resolution", "height"):  # both from --resolution, each at least 1 already
            message = f"--resolution must be at most {corelink.load('settings').MAX_RESOLUTION} a side, not {width}x{height}"
            if message not in problems:
                problems.append(message)
            continue
        problems.append(f"{schema.BY_NAME[field].option or field} {message}")
    problems += target_problems(args, settings)
    if args.bits is not None:
        bits = BITS[args.bits]
        for fmt in args.format:
            if fmt == "ply":
                continue
            allowed = imageio.FORMATS["." + fmt][0]
            if bits not in allowed:
                problems.append(
                    f"--bits {args.bits} cannot be written as {fmt}: {fmt} files take --bits "
                    + " or ".join(str(b) for b in allowed)
                )
    if any(sep in args.image_name for sep in "/\\") or args.image_name in (".", ".."):
        problems.append(f"--image-name {args.image_name!r} is a path: give a name; files go into --output")
    if problems:
        raise UsageError(problems)
    return settings


def default_formats(args):
    """--format's default: png for images, ply for --target vertex-colors."""
    if getattr(args, "format", None) is None:
        args.format = ["ply"] if getattr(args, "target", "") == "vertex-colors" else ["png"]
    return args.format


def target_problems(args, settings):
    """What is wrong with the issue-14 options together (--target, --format, --save, ...)."""
    problems = []
    formats = default_formats(args)
    vertex = settings.target == "VERTEX_COLORS"
    if vertex:
        wrong = [f for f in formats if f != "ply"]
        if wrong:
            problems.append(f"--format {' '.join(wrong)}: --target vertex-colors writes .ply files (--format ply)")
        for flag, on in (("--udim", settings.use_udim), ("--bent-normals", settings.bent_normals)):
            if on:
                problems.append(f"{flag} bakes images; --target vertex-colors bakes a color attribute")
    elif "ply" in formats:
        problems.append("--format ply is for --target vertex-colors; images are written as png, exr or tif")
    save = getattr(args, "save", None)
    if save is not None:
        if not vertex:
            problems.append("--save writes color attributes into a .blend file: it needs --target vertex-colors")
        elif save.suffix.lower() != ".blend":
            problems.append(f"--save {str(save)!r} must name a .blend file")
    return problems


def check_save(args, input_blend):
    """--save may not replace the input .blend file unless --overwrite-input, and its folder must be writable."""

    save = getattr(args, "save", None)
    if save is None:
        return
    from . import filecheck

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
    atomicfile = corelink.load("atomicfile")

    def write(temp):
        try:
            # An absolute path: Blender 4.2 resolves a relative one against $PWD, not the working directory,
            # and the two differ when a program starts the script in another folder.
            result = bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(os.fspath(temp)), copy=True,
                                                 check_existing=False)
        finally:
            # The temporary file existed (empty) when Blender saved over it: Blender kept it as a
            # backup version, "<temp>1".
            atomicfile.remove_quietly(os.fspath(temp) + "1")
        if result != {"FINISHED"}:
            raise RuntimeError(f"Blender did not save it ({result})")

    from . import filecheck

    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    # Blender reports a compressed save cut short by a full disk as done: read it to its end marker.
    atomicfile.write_file(path, write, verify=filecheck.check_blend_complete, ext=".blend")


def selected_to_active_problems(args):
    """What is wrong with the Selected to Active options together (their values: schema.problems)."""
    problems = []
    on = args.selected_to_active or args.match_suffix
    if not on:
        for option, given in (("--active", args.active is not None), ("--cage", args.cage is not None),
                              ("--extrusion", args.extrusion != 0.0),
                              ("--max-ray-distance", args.max_ray_distance != 0.0)):
            if given:
                problems.append(f"{option} is a setting of --selected-to-active (or --match-suffix), which is off")
        return problems
    for option, given in (("--target vertex-colors", getattr(args, "target", "") == "vertex-colors"),
                          ("--udim", getattr(args, "udim", False)),
                          ("--bent-normals", getattr(args, "bent_normals", False))):
        if given:
            problems.append(f"{option}: --selected-to-active bakes AO into one image texture of the low-poly")
    if args.match_suffix:
        high, low = args.match_suffix
        if not high or not low or high == low:
            problems.append(f"--match-suffix needs two different, non-empty suffixes, not {high!r} and {low!r}")
        if args.active is not None:
            problems.append("--active names one low-poly; with --match-suffix, --objects names the low-poly objects")
        if args.cage:
            problems.append("--cage NAME names one cage for one low-poly; bake a pair with a cage object with "
                            "--active (--cage alone extrudes each low-poly along its vertex normals)")
    elif args.cage and (args.cage == args.active or args.cage in (args.objects or [])):
        problems.append(f"--cage {args.cage!r} is also the low-poly or one of the high-poly objects")
    if args.active is not None and args.active in (args.objects or []):
        problems.append(f"--active {args.active!r} is also among --objects (the high-poly objects)")
    return problems


def check_paths(args, summary):
    """The output folder and the summary's file can be written (before anything is baked)."""
    atomicfile = corelink.load("atomicfile")

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
        code = run(argv, in_blender, summary)
    except UsageError as exc:
        for line in str(exc).splitlines():
            print(f"bake_ao: error: {line}", file=sys.stderr)
        print(exc.usage, file=sys.stderr, end="")
        summary.error = str(exc)
        summary.settings, summary.objects = {}, []
        code = 2
    except KeyboardInterrupt:
        print(f"\nbake_ao: {cancel_note(summary)}", file=sys.stderr)
        summary.error = "cancelled (Ctrl-C)"
        code = 130
    except Exception as exc:
        # Under Blender an escaping exception would end the script with exit status 0.
        traceback.print_exc()
        print("bake_ao: error: unexpected failure, see the traceback above", file=sys.stderr)
        summary.error = f"unexpected failure: {type(exc).__name__}: {exc}"
        code = 1
    if not summary.write(code) and code == 0:
        code = 1
    return code


def cancel_note(summary):
    """What a cancel left: which objects have all their files written, and of which nothing was
    written (an object's files are written with Ctrl-C held off: all of them or none)."""
    done = [escape(o["object"]) for o in summary.objects if o["status"] == "ok"]
    kept = [escape(o["object"]) for o in summary.objects if o["status"] != "ok"]
    parts = []
    if done:
        parts.append(f"every file of {', '.join(done)} is written")
    if kept:
        parts.append(f"nothing of {', '.join(kept)} was written (any file there is as it was)")
    return "cancelled; " + ("; ".join(parts) or "nothing was written")


def early_summary_args(argv, in_blender):
    """(summary path, .blend path) from the raw arguments, so that the summary is written even
    when the arguments are refused."""
    pre = Parser(add_help=False)
    pre.add_argument("--summary-json", type=Path)
    if not in_blender:
        pre.add_argument("blend", nargs="?")
    try:
        known, _ = pre.parse_known_args(argv)
    except UsageError:  # a --summary-json without its path: the full parse says so
        return None, None
    if in_blender:
        import bpy

        return known.summary_json, bpy.data.filepath or None
    return known.summary_json, known.blend


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
            "with Blender: blender -b scene.blend --python scripts/bake_ao.py -- [options]"
        ) from None
    if not in_blender:
        if not os.path.isfile(args.blend):
            raise UsageError(f"no such .blend file: {args.blend}")
        try:
            bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend), load_ui=False)
        except RuntimeError as exc:
            raise UsageError(f"cannot open {args.blend}: {exc}") from None

    from . import baking, filewriter
    from .extract import ExtractError

    missing = corelink.missing_dependency()
    if missing is not None:
        raise UsageError(missing)
    core = corelink.load()
    if not filewriter.oiio_available():
        print("bake_ao: no OpenImageIO in this Python; writing files with Blender's image writer", file=sys.stderr)

    from . import service

    check_save(args, bpy.data.filepath)
    try:
        if settings.use_selected_to_active:
            jobs = plan_selected_to_active(bpy, args, settings)
        else:
            objects = pick_objects(bpy, args.objects, baking, needs_uvs=baking.needs_uvs(settings))
            jobs = baking.plan(
                bpy.context.evaluated_depsgraph_get(), objects, settings,
                selected=objects, view_layer=bpy.context.view_layer,
            )
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
    return bake(plan, args, summary)


def s2a_record(job, result=None):
    """A Selected to Active job's entries in the summary's object record ({} for another job): its
    high-poly objects, and the sample points and texels that missed them."""
    if not job.selected_to_active:
        return {}
    report = getattr(result, "report", None) or {}
    return {"highpoly": [h.name for h in job.highpoly], "cage": job.cage.name if job.cage is not None else None,
            "matching_rays": int(report.get("matching_rays", 0)),
            "missed_sample_points": int(getattr(result, "missed", 0) or 0),
            "missed_texels": int(report.get("missed_texels", 0))}


class ScriptRun:
    """The script's side of one bake (mc_ao.service.Bake): progress on stderr, each object's outcome
    (its files written by the service, Ctrl-C held off meanwhile) into the summary and the table."""

    def __init__(self, plan, args, summary):
        import bpy

        from . import service
        from .outputs.store import Store

        self.plan, self.settings, self.args, self.summary = plan, plan.settings, args, summary
        store = None
        if plan.settings.vertex_colors and getattr(args, "save", None) is not None:
            # --save: the colour attributes go into the .blend file the run saves at its end
            store = Store(plan.settings, plan.folder, plan.files,
                          lambda kind, text: print(f"bake_ao: {escape(text)}", file=sys.stderr))
        self.run = service.Bake(plan, args.threads or None, live=False, store=store,
                                store_kinds={"color_attribute"}, blend=bpy.data.filepath, hold_interrupts=True,
                                store_after_save=True)
        self.progress = Progress(enabled=not args.quiet)
        self.rows, self.failures = [], 0

    def begin(self, i):
        jobs = self.plan.jobs
        if i < len(jobs):
            name = escape(jobs[i].object_name)
            print(f"bake_ao: [{i + 1}/{len(jobs)}] baking {name}", flush=True)
            self.progress.begin(f"[{i + 1}/{len(jobs)}] {name}")

    def on_progress(self, i, fraction):
        self.progress.update(fraction)

    def on_outcome(self, outcome):
        from . import baking

        self.progress.end()
        job, settings = outcome.job, self.settings
        name = escape(job.object_name)
        if outcome.trace:
            print(outcome.trace, file=sys.stderr, end="")
        result = outcome.result
        for note in outcome.notes:
            print(f"bake_ao: {name}: warning: {escape(note)}", file=sys.stderr)
        if result is not None and job.selected_to_active:
            print(f"bake_ao: {name}: from {', '.join(escape(h.name) for h in job.highpoly)}"
                  f"{baking.miss_summary(result)}", file=sys.stderr)
        if not outcome.baked or outcome.file_error:
            error = outcome.error if not outcome.baked else (
                f"none of its files was written (any file already there is unchanged): {outcome.file_error}")
            if outcome.trace:
                error += "; the traceback is above"
            print(f"bake_ao: {name}: {escape(error)}", file=sys.stderr)
            self.failures += 1
            if result is None:
                seconds = time.monotonic() - self.run.started.get(outcome.index, time.monotonic())
                self.summary.add(job.object_name, "failed", seconds, error=error, **s2a_record(job))
            else:
                per_texel, _ = baking.throughput(result)
                self.summary.add(job.object_name, "failed", result.seconds, result.rays, per_texel, outcome.files,
                                 error, **s2a_record(job, result))
        else:
            per_texel, rate = baking.throughput(result)
            self.summary.add(job.object_name, "ok", result.seconds, result.rays, per_texel, outcome.files,
                             **s2a_record(job, result))
            self.rows.append((name, size_text(result, settings), f"{result.seconds:.2f}",
                              f"{per_texel:.0f}", f"{rate:.2f}", escape(", ".join(outcome.files))))
        self.begin(outcome.index + 1)


def bake(plan, args, summary):
    """Bake the plan's jobs on a worker thread, each finished one's files written here; the exit status."""
    handler = ScriptRun(plan, args, summary)
    run, settings = handler.run, plan.settings
    handler.begin(0)
    run.start()
    try:
        while not run.handle(run.next_message(), handler):
            pass
    except BaseException as exc:
        run.stop()  # a "cancelled" message comes only from here: the cancel is this Ctrl-C's
        handler.progress.end()
        why = "cancelled (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else "the run stopped"
        for outcome in run.cancel_rest():
            summary.add(outcome.object_name, "failed", error=f"not baked: {why}")
        raise
    run.stop()
    rows, failures = handler.rows, handler.failures
    if getattr(args, "save", None) is not None and rows:
        import bpy

        try:
            save_blend(bpy, args.save)
            print(f"bake_ao: saved {args.save} with the color attribute {settings.attribute_name!r} of "
                  f"{', '.join(r[0] for r in rows)}")
        except (OSError, RuntimeError, ValueError) as exc:
            failures += 1
            print(f"bake_ao: error: {args.save} was not saved (any file there is unchanged): {exc}", file=sys.stderr)
            summary.error = f"--save {args.save}: {exc}"

    header = ("object", "size", "seconds", "samples/texel", "Mrays/s", "files")
    if rows:
        widths = [max(len(r[i]) for r in rows + [header]) for i in range(len(header))]
        for row in [header] + rows:
            print("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip())
    print(f"bake_ao: baked {len(rows)} of {len(plan.jobs)} objects" + (f", {failures} failed" if failures else ""))
    if failures and summary.error is None:
        summary.error = f"{failures} of {len(plan.jobs)} objects failed"
    return 1 if failures else 0


def size_text(result, settings):
    """The summary's size column: WxH, WxH x N tiles (UDIM), or the face corners (colour attributes)."""
    w, h = settings.size
    if settings.vertex_colors:
        return f"{len(result.ao)} corners"
    if settings.use_udim:
        return f"{w}x{h} x{len(result.tiles)} tiles"
    return f"{w}x{h}"
