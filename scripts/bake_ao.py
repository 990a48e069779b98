#!/usr/bin/env python3
"""Bake ambient occlusion of objects in a .blend file into image files, without the UI.

Run by Blender (its arguments for this script follow "--"):

    blender -b scene.blend --python scripts/bake_ao.py -- --objects A B --samples 128 --resolution 1024 --output out/

or by a Python that has the bpy module (then the .blend file is the first argument):

    python scripts/bake_ao.py scene.blend --objects A B --samples 128 --resolution 1024 --output out/

Writes <image>_AO.png (and/or .exr, .tif, per --format) for each object into the output folder
and prints a summary. Every setting is checked before anything is baked. File names come from
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

    {"mc_ao": version, "blend": the .blend path as given, "exit_code": int, "error": str or null,
     "settings": {the bake's settings, as written into each file's metadata; {} when the
                  arguments were refused},
     "objects": [{"object": name, "status": "ok" or "failed", "seconds": the bake's wall time,
                  "rays": int, "samples_per_texel": mean over covered texels, "files": [absolute
                  paths written], "error": str or null}, ...]}

"error" is null after a run in which everything succeeded. Unlimited max_distance is written as
Infinity, as Python's json module writes and reads it (and as the files' metadata records it).

The bake is the add-on's: the same geometry gathering (modifiers applied, world space, corner
normals, the chosen UV map), the same worker thread, file names and writers (mc_ao.jobs), the
same core.
"""

import argparse
import json
import os
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# --format choice -> Blender's file format name (mc_ao.settings.FILE_FORMATS)
FORMATS = {"png": "PNG", "exr": "OPEN_EXR", "tif": "TIFF"}
BITS = {"8": 8, "16": 16, "half": "half", "float": "float"}
# BakeSettings field -> the option that sets it, for messages
OPTIONS = {
    "samples": "--samples", "min_samples": "--min-samples", "target_error": "--target-error",
    "max_distance": "--max-distance",
    "source": "--source", "distribution": "--distribution", "occluders": "--occluders",
    "uv_map": "--uv-map", "margin": "--margin", "image_name": "--image-name", "seed": "--seed",
    "threads": "--threads",
}


class UsageError(Exception):
    """Bad arguments or input: exit status 2. ``usage``: the usage text to show after the message."""

    def __init__(self, message, usage=""):
        super().__init__(message)
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


def make_parser(with_blend):
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
    parser.add_argument("--format", nargs="+", choices=sorted(FORMATS), default=["png"],
                        help="file formats to write, one file each (default: png)")
    parser.add_argument("--bits", choices=sorted(BITS),
                        help="sample type of the files: png 8|16, exr half|float, tif 8|16|float "
                             "(default: 8-bit PNG and TIFF, half EXR)")
    parser.add_argument("--stderr", action="store_true",
                        help="also write each texel's standard error to <image>_stderr.exr (the error the "
                             "bake makes, for every sample source: texels draw two independent randomisations, "
                             "about 1.2 times the noise of one at equal rays)")
    parser.add_argument("--samples", type=int, default=128,
                        help="rays per texel, 1 to 1048576 (default: 128)")
    parser.add_argument("--min-samples", type=int, default=16,
                        help="rays per texel before adaptive sampling may stop (default: 16)")
    parser.add_argument("--target-error", type=float, default=0.0,
                        help="95%% CI half-width at which a texel stops; 0 = adaptive off (default)")
    parser.add_argument("--resolution", type=parse_resolution, default=(1024, 1024), metavar="N|WxH",
                        help="image size, at most 65536 a side (default: 1024)")
    parser.add_argument("--max-distance", type=float, default=0.0,
                        help="occlusion distance; 0 or inf = unlimited (default)")
    parser.add_argument("--source", choices=("sobol", "halton", "stratified", "independent"), default="sobol")
    parser.add_argument("--distribution", choices=("cosine", "uniform"), default="cosine")
    parser.add_argument("--occluders", choices=("visible", "selected", "self"), default="visible",
                        help="what occludes: every visible object (default), the baked objects "
                             "(selected), or each object alone (self)")
    parser.add_argument("--uv-map", default="", help="UV map name (default: each mesh's active render UV map)")
    parser.add_argument("--margin", type=int, default=16, help="margin in pixels (default: 16)")
    parser.add_argument("--image-name", default="",
                        help='image and file name, "{object}" replaced by the object name (default: '
                             '{object}_AO); made a safe file name')
    parser.add_argument("--seed", type=int, default=0, help="0 or more (default: 0)")
    parser.add_argument("--threads", type=int, default=0, help="worker threads; 0 = all cores")
    parser.add_argument("--ignore-backfaces", action="store_true")
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

    def add(self, name, status, seconds=0.0, rays=0, samples_per_texel=0.0, files=(), error=None):
        self.objects.append({
            "object": name, "status": status, "seconds": float(seconds), "rays": int(rays),
            "samples_per_texel": float(samples_per_texel), "files": [str(f) for f in files],
            "error": None if error is None else str(error),
        })

    def write(self, exit_code):
        """Write the record atomically; False (after saying why) when it cannot be written."""
        if self.path is None:
            return True
        from core import atomicfile
        from core._version import __version__

        record = {
            "mc_ao": __version__, "blend": self.blend, "exit_code": exit_code,
            "error": self.error if exit_code else None,
            "settings": self.settings, "objects": self.objects,
        }
        text = json.dumps(record, indent=2) + "\n"

        def write(temp):
            with open(temp, "w", encoding="utf-8") as f:
                f.write(text)

        try:
            folder = os.path.dirname(os.path.abspath(self.path))
            os.makedirs(folder, exist_ok=True)
            atomicfile.write_file(self.path, write)
        except OSError as exc:
            print(f"bake_ao: error: the summary {str(self.path)!r} was not written: {exc}", file=sys.stderr)
            return False
        return True


def pick_objects(bpy, names, baking):
    """The objects to bake: the named ones, else the selected bakeable ones, else every bakeable one.

    Named objects that cannot be baked are an error (exit 2); selected ones are skipped with a note.
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
            if not baking.can_be_target(obj):
                raise UsageError(f"{obj.name} {baking.skip_reason(obj)}")
        return objects
    selected = [o for o in layer_objects if o.select_get()]
    objects = baking.targets_of(selected)
    if objects:
        for obj in selected:
            if obj not in objects:
                print(f"bake_ao: {obj.name}: skipped, it {baking.skip_reason(obj)}", file=sys.stderr)
        return objects
    objects = baking.targets_of(layer_objects)
    if not objects:
        raise UsageError("the file has no mesh with a UV map to bake")
    print(
        f"bake_ao: {'no mesh with a UV map is selected' if selected else 'nothing is selected'}; "
        f"baking every mesh with a UV map: {', '.join(o.name for o in objects)}",
        file=sys.stderr,
    )
    return objects


def settings_from(args):
    """The BakeSettings of the arguments, after checking every value (UsageError lists what is wrong)."""
    from core import imageio
    from mc_ao import corelink, jobs
    from mc_ao.settings import BakeSettings

    width, height = args.resolution
    settings = BakeSettings(
        samples=args.samples, min_samples=args.min_samples, target_error=args.target_error,
        resolution=width, height=height, max_distance=args.max_distance,
        source=args.source.upper(), distribution=args.distribution.upper(),
        occluders=args.occluders.upper(), uv_map=args.uv_map, margin=args.margin,
        image_name=args.image_name, seed=args.seed, threads=args.threads,
        ignore_backfaces=args.ignore_backfaces, error_map=args.stderr,
    )
    problems = []
    for field, message in jobs.check_settings(settings):
        if field in ("resolution", "height"):  # both from --resolution, each at least 1 already
            message = f"--resolution must be at most {corelink.load('bake').MAX_RESOLUTION} a side, not {width}x{height}"
            if message not in problems:
                problems.append(message)
            continue
        problems.append(f"{OPTIONS.get(field, field)} {message}")
    if args.bits is not None:
        bits = BITS[args.bits]
        for fmt in args.format:
            allowed = imageio.FORMATS["." + fmt][0]
            if bits not in allowed:
                problems.append(
                    f"--bits {args.bits} cannot be written as {fmt}: {fmt} files take --bits "
                    + " or ".join(str(b) for b in allowed)
                )
    if any(sep in args.image_name for sep in "/\\") or args.image_name in (".", ".."):
        problems.append(f"--image-name {args.image_name!r} is a path: give a name; files go into --output")
    if problems:
        raise UsageError("\n".join(problems))
    return settings


def check_paths(args, summary):
    """The output folder and the summary's file can be written (before anything is baked)."""
    from core import atomicfile
    from mc_ao import jobs

    problem = jobs.folder_problem(args.output)
    if problem is not None:
        raise UsageError(f"cannot write to the output folder '{args.output}': {problem}; nothing was baked")
    if args.summary_json is not None:
        path = args.summary_json
        problem = "it is a folder" if path.is_dir() else jobs.folder_problem(path.parent)
        if problem is None and atomicfile.read_only(path):
            problem = "it is read-only"
        if problem is not None:
            summary.path = None  # nowhere to write it
            raise UsageError(f"cannot write the summary '{path}': {problem}; nothing was baked")


def main(argv=None):
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
        print("\nbake_ao: cancelled; the files of finished objects are written, nothing of the "
              "cancelled one was", file=sys.stderr)
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
    args.format = list(dict.fromkeys(args.format))
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

    from mc_ao import baking, corelink, jobs
    from mc_ao.extract import ExtractError

    missing = corelink.missing_dependency()
    if missing is not None:
        raise UsageError(missing)
    core = corelink.load()
    if not jobs.oiio_available():
        print("bake_ao: no OpenImageIO in this Python; writing files with Blender's image writer", file=sys.stderr)

    objects = pick_objects(bpy, args.objects, baking)
    try:
        plan = baking.plan(
            bpy.context.evaluated_depsgraph_get(), objects, settings,
            selected=objects, view_layer=bpy.context.view_layer,
        )
        formats = [(FORMATS[f], BITS[args.bits] if args.bits else None) for f in args.format]
        files = jobs.output_files(str(args.output), [j.image_name for j in plan], formats, stderr=args.stderr)
    except (ExtractError, core.McAoError) as exc:
        raise UsageError(str(exc)) from None
    summary.settings = record = jobs.settings_record(settings)
    return bake(plan, files, settings, record, args, summary)


def bake(plan, files, settings, record, args, summary):
    """Bake the jobs on a worker thread, write each finished one's files here; the exit status."""
    from mc_ao import baking, jobs

    progress = Progress(enabled=not args.quiet)
    run = jobs.BakeRun(plan, settings, args.threads or None, live=False)
    rows, failures, done = [], 0, set()
    width, height = settings.size

    def begin(i):
        print(f"bake_ao: [{i + 1}/{len(plan)}] baking {plan[i].object_name}", flush=True)
        progress.begin(f"[{i + 1}/{len(plan)}] {plan[i].object_name}")

    def failed(i, errors, seconds=None, files=(), rays=0, per_texel=0.0):
        nonlocal failures
        progress.end()
        failures += 1
        done.add(i)
        for error in errors:
            print(f"bake_ao: {plan[i].object_name}: {error}", file=sys.stderr)
        if seconds is None:
            seconds = time.monotonic() - run.started.get(i, time.monotonic())
        summary.add(plan[i].object_name, "failed", seconds, rays, per_texel, files, "; ".join(map(str, errors)))

    begin(0)
    run.start()
    try:
        while True:
            kind, *rest = run.next_message()
            if kind == "end":
                break
            i = rest[0]
            if kind == "progress":
                progress.update(rest[1])
            elif kind == "done":
                result = rest[1]
                progress.end()
                job = plan[i]
                written, errors = jobs.write_outputs(result, files[job.image_name],
                                                     dict(record, object=job.object_name))
                for note in baking.input_notes(result):
                    print(f"bake_ao: {job.object_name}: warning: {note}", file=sys.stderr)
                per_texel, rate = baking.throughput(result)
                if errors:
                    failed(i, [exc for _, exc in errors], result.seconds, written, result.rays, per_texel)
                else:
                    done.add(i)
                    summary.add(job.object_name, "ok", result.seconds, result.rays, per_texel, written)
                    rows.append((job.object_name, f"{width}x{height}", f"{result.seconds:.2f}",
                                 f"{per_texel:.0f}", f"{rate:.2f}", ", ".join(written)))
            elif kind == "error":
                failed(i, [rest[1]])
            elif kind == "crash":
                exc, trace = rest[1], rest[2]
                print(trace, file=sys.stderr, end="")
                failed(i, [f"bake failed ({type(exc).__name__}: {exc}); the traceback is above"])
            if kind in ("done", "error", "crash") and i + 1 < len(plan):
                begin(i + 1)
    except BaseException as exc:
        run.stop()  # a "cancelled" message comes only from here: the cancel is this Ctrl-C's
        progress.end()
        why = "cancelled (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else "the run stopped"
        for i, job in enumerate(plan):
            if i not in done:
                summary.add(job.object_name, "failed", error=f"not baked: {why}")
        raise
    run.stop()

    header = ("object", "size", "seconds", "samples/texel", "Mrays/s", "files")
    if rows:
        widths = [max(len(r[i]) for r in rows + [header]) for i in range(len(header))]
        for row in [header] + rows:
            print("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip())
    print(f"bake_ao: baked {len(rows)} of {len(plan)} objects" + (f", {failures} failed" if failures else ""))
    if failures:
        summary.error = f"{failures} of {len(plan)} objects failed"
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
