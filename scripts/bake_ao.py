#!/usr/bin/env python3
"""Bake ambient occlusion of objects in a .blend file into image files, without the UI.

Run by Blender (its arguments for this script follow "--"):

    blender -b scene.blend --python scripts/bake_ao.py -- --objects A B --samples 128 --resolution 1024 --output out/

or by a Python that has the bpy module (then the .blend file is the first argument):

    python scripts/bake_ao.py scene.blend --objects A B --samples 128 --resolution 1024 --output out/

Writes <object>_AO.png (and/or .exr, .tif, per --format) for each object into the output folder,
prints a summary, and exits with 0 on success, 1 when a bake or a file failed (the other objects are
still baked), 2 for bad arguments or input found before baking (an unknown object, a named object
that is not a mesh or has no UV map, an output folder that cannot be written, an unreadable .blend
file, ...), 130 on Ctrl-C. A file that fails to write leaves any file already at its path as it was.
The bake is the add-on's: the same geometry gathering (modifiers applied, world space, corner
normals, the chosen UV map) and the same core.
"""

import argparse
import os
import sys
import threading
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# --format choice -> Blender's file format name (for mc_ao.settings and Blender's own writer)
FORMATS = {"png": "PNG", "exr": "OPEN_EXR", "tif": "TIFF"}
BITS = {"8": 8, "16": 16, "half": "half", "float": "float"}


class UsageError(Exception):
    """Bad arguments or input: exit status 2."""


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
    parser = argparse.ArgumentParser(
        prog="bake_ao.py",
        description="Bake ambient occlusion of objects in a .blend file into image files.",
        epilog="Under Blender: blender -b scene.blend --python scripts/bake_ao.py -- [options]",
    )
    if with_blend:
        parser.add_argument("blend", help=".blend file to open")
    parser.add_argument("--objects", nargs="+", metavar="NAME",
                        help="mesh objects to bake (default: the selected ones with a UV map, "
                             "else every mesh with a UV map in the view layer)")
    parser.add_argument("--output", "-o", type=Path, default=Path("out"), help="output folder (default: out)")
    parser.add_argument("--format", nargs="+", choices=sorted(FORMATS), default=["png"],
                        help="file formats to write, one file each (default: png)")
    parser.add_argument("--bits", choices=sorted(BITS),
                        help="sample type of the files (default: 8-bit PNG and TIFF, half EXR)")
    parser.add_argument("--stderr", action="store_true",
                        help="also write each texel's standard error to <image>_stderr.exr")
    parser.add_argument("--samples", type=int, default=128, help="rays per texel (default: 128)")
    parser.add_argument("--min-samples", type=int, default=16,
                        help="rays per texel before adaptive sampling may stop (default: 16)")
    parser.add_argument("--target-error", type=float, default=0.0,
                        help="95%% CI half-width at which a texel stops; 0 = adaptive off (default)")
    parser.add_argument("--resolution", type=parse_resolution, default=(1024, 1024), metavar="N|WxH",
                        help="image size (default: 1024)")
    parser.add_argument("--max-distance", type=float, default=0.0, help="occlusion distance; 0 = unlimited")
    parser.add_argument("--source", choices=("sobol", "halton", "stratified", "independent"), default="sobol")
    parser.add_argument("--distribution", choices=("cosine", "uniform"), default="cosine")
    parser.add_argument("--occluders", choices=("visible", "selected", "self"), default="visible",
                        help="what occludes: every visible object (default), the baked objects "
                             "(selected), or each object alone (self)")
    parser.add_argument("--uv-map", default="", help="UV map name (default: each mesh's active render UV map)")
    parser.add_argument("--margin", type=int, default=16, help="margin in pixels (default: 16)")
    parser.add_argument("--image-name", default="",
                        help='file name stem, "{object}" replaced by the object name (default: <object>_AO)')
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=0, help="worker threads; 0 = all cores")
    parser.add_argument("--ignore-backfaces", action="store_true")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    return parser


class ProgressBar:
    """A one-line progress bar on a terminal (nothing when the stream is not one)."""

    def __init__(self, stream=sys.stderr, enabled=True, width=30):
        self.stream = stream
        self.enabled = enabled and stream.isatty()
        self.width = width
        self.label = ""
        self.shown = 0.0
        self.start = time.monotonic()

    def begin(self, label):
        self.label = label
        self.start = time.monotonic()
        self.update(0.0, force=True)

    def update(self, fraction, force=False):
        # Called from the core's worker threads (one at a time).
        now = time.monotonic()
        if not self.enabled or (not force and fraction < 1.0 and now - self.shown < 0.1):
            return
        self.shown = now
        filled = int(round(self.width * min(max(fraction, 0.0), 1.0)))
        bar = "#" * filled + "-" * (self.width - filled)
        self.stream.write(f"\r{self.label} [{bar}] {fraction:4.0%} {now - self.start:6.1f} s")
        self.stream.flush()

    def end(self):
        if self.enabled:
            self.stream.write("\r" + " " * (len(self.label) + self.width + 20) + "\r")
            self.stream.flush()


def run_job(job, settings, threads, bar):
    """job.run() on a worker thread, so that Ctrl-C in the main thread can cancel the bake."""
    cancel = threading.Event()
    box = {}

    def work():
        try:
            box["result"] = job.run(settings, threads, progress=bar.update, cancel=cancel)
        except BaseException as exc:  # handed to the main thread
            box["error"] = exc

    thread = threading.Thread(target=work, name="mc_ao bake", daemon=True)
    thread.start()
    try:
        while thread.is_alive():
            thread.join(0.2)
    except KeyboardInterrupt:
        cancel.set()
        thread.join()
        raise
    if "error" in box:
        raise box["error"]
    return box["result"]


def pick_objects(bpy, names, baking):
    """The objects to bake: the named ones, else the selected bakeable ones, else every bakeable one.

    Named objects that cannot be baked are an error (exit 2); selected ones are skipped with a note.
    """
    layer_objects = bpy.context.view_layer.objects
    if names:
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


def write_files(job, result, args, images, imageio):
    """Write one file per format; return their paths."""
    bits = BITS[args.bits] if args.bits else None
    stem = args.output / job.image_name
    written = []
    for fmt in args.format:
        path = stem.with_name(stem.name + "." + fmt)
        stderr_path = stem.with_name(stem.name + "_stderr.exr") if args.stderr and fmt == args.format[0] else None
        metadata = {"object": job.object_name}
        if imageio is not None:
            imageio.write_ao(path, result, bits=bits, stderr_path=stderr_path, metadata=metadata, make_dirs=True)
            written += [path] + ([stderr_path] if stderr_path else [])
        else:
            # No OpenImageIO in this Python (Debian's Blender): Blender's writer, RGBA, no metadata.
            float_file = bits in ("half", "float", 16) or (bits is None and fmt == "exr")
            images.save_pixels_with_blender(images.rgba(result.ao), str(path), FORMATS[fmt], float_file)
            written.append(path)
    return written


def main(argv=None):
    in_blender = run_by_blender()
    parser = make_parser(with_blend=not in_blender)
    args = parser.parse_args(script_argv(argv))
    try:
        return bake(args, in_blender)
    except UsageError as exc:
        print(f"bake_ao: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\nbake_ao: cancelled; the files of finished objects are written, nothing of the "
              "cancelled one was", file=sys.stderr)
        return 130
    except Exception:
        # Under Blender an escaping exception would end the script with exit status 0.
        traceback.print_exc()
        print("bake_ao: error: unexpected failure, see the traceback above", file=sys.stderr)
        return 1


def bake(args, in_blender):
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

    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from mc_ao import baking, corelink, images
    from mc_ao.extract import ExtractError
    from mc_ao.settings import BakeSettings

    missing = corelink.missing_dependency()
    if missing is not None:
        raise UsageError(missing)
    core = corelink.load()
    imageio = corelink.load("imageio") if images.oiio_available() else None
    if imageio is None:
        print("bake_ao: no OpenImageIO in this Python; writing files with Blender's image writer", file=sys.stderr)

    width, height = args.resolution
    settings = BakeSettings(
        samples=args.samples, min_samples=args.min_samples, target_error=args.target_error,
        resolution=width, height=height, max_distance=args.max_distance,
        source=args.source.upper(), distribution=args.distribution.upper(),
        occluders=args.occluders.upper(), uv_map=args.uv_map, margin=args.margin,
        image_name=args.image_name, seed=args.seed, threads=args.threads,
        ignore_backfaces=args.ignore_backfaces,
    )
    problem = images.output_dir_problem(args.output)
    if problem is not None:
        raise UsageError(f"cannot write to the output folder '{args.output}': {problem}; nothing was baked")
    objects = pick_objects(bpy, args.objects, baking)
    try:
        jobs = baking.plan(
            bpy.context.evaluated_depsgraph_get(), objects, settings,
            selected=objects, view_layer=bpy.context.view_layer,
        )
    except ExtractError as exc:
        raise UsageError(str(exc)) from None

    bar = ProgressBar(enabled=not args.quiet)
    rows, failures = [], 0
    for n, job in enumerate(jobs, 1):
        print(f"bake_ao: [{n}/{len(jobs)}] baking {job.object_name}", flush=True)
        bar.begin(f"[{n}/{len(jobs)}] {job.object_name}")
        try:
            result = run_job(job, settings, args.threads or None, bar)
            files = write_files(job, result, args, images, imageio)
        except (core.McAoError, OSError, RuntimeError) as exc:
            bar.end()
            failures += 1
            print(f"bake_ao: {job.object_name}: {exc}", file=sys.stderr)
            continue
        bar.end()
        for note in baking.input_notes(result):
            print(f"bake_ao: {job.object_name}: warning: {note}", file=sys.stderr)
        per_texel, rate = baking.throughput(result)
        rows.append((job.object_name, f"{width}x{height}", f"{result.seconds:.2f}", f"{per_texel:.0f}",
                     f"{rate:.2f}", ", ".join(str(f) for f in files)))

    header = ("object", "size", "seconds", "samples/texel", "Mrays/s", "files")
    if rows:
        widths = [max(len(r[i]) for r in rows + [header]) for i in range(len(header))]
        for row in [header] + rows:
            print("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip())
    print(f"bake_ao: baked {len(rows)} of {len(jobs)} objects" + (f", {failures} failed" if failures else ""))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
