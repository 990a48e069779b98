"""A small generated asset library and its manifest, for the batch mode's tests and benchmark.

    python tests/batch_assets.py FOLDER [--copies N] [--resolution R] [--samples S]

needs the bpy module (it builds the .blend files with it) and writes, under FOLDER:

- chair.blend (Ground, Block), props/lamp.blend (Ground, Shade), more/lamp.blend (a second "lamp":
  the same file stem in another folder), "crate v2?.blend" (a name that is not a safe file name),
  torus.blend (Ground, Ring; baked at 24x16), and broken.blend: the first half of chair.blend, as an
  interrupted copy leaves it;
- manifest.toml listing all six, with per-entry overrides.

With ``--copies N`` (the benchmark) it writes N good assets asset000.blend ... and a manifest of
those instead. Nothing is selected in the saved files, so an entry without ``objects`` bakes every
mesh with a UV map.
"""

import argparse
import shutil
import sys
from pathlib import Path


def _bpy():
    import bpy

    return bpy


def _new_scene(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)


def _add(bpy, kind, name, **kwargs):
    getattr(bpy.ops.mesh, f"primitive_{kind}_add")(**kwargs)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    return obj


def _save(bpy, path):
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    bpy.context.view_layer.objects.active = None
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=False)


def make_library(folder, resolution=16, samples=8):
    """The six-asset library and its manifest; returns the manifest's path."""
    bpy = _bpy()
    folder = Path(folder)

    _new_scene(bpy)
    _add(bpy, "plane", "Ground", size=4)
    _add(bpy, "cube", "Block", size=1, location=(0, 0, 0.8))
    _save(bpy, folder / "chair.blend")

    _new_scene(bpy)
    _add(bpy, "plane", "Ground", size=3)
    _add(bpy, "cylinder", "Shade", vertices=12, radius=0.5, depth=1, location=(0, 0, 0.7))
    _save(bpy, folder / "props" / "lamp.blend")

    _new_scene(bpy)
    _add(bpy, "plane", "Ground", size=3)
    _add(bpy, "ico_sphere", "Bulb", subdivisions=2, radius=0.6, location=(0, 0, 0.5))
    _save(bpy, folder / "more" / "lamp.blend")

    _new_scene(bpy)
    _add(bpy, "cube", "Crate", size=1)
    _add(bpy, "cube", "Lid", size=1, location=(0, 0, 1.05), scale=(0.6, 0.6, 0.05))
    _save(bpy, folder / "crate v2?.blend")

    _new_scene(bpy)
    _add(bpy, "plane", "Ground", size=3)
    _add(bpy, "torus", "Ring", major_radius=0.8, minor_radius=0.2, major_segments=24, minor_segments=8,
         location=(0, 0, 0.25))
    _save(bpy, folder / "torus.blend")

    data = (folder / "chair.blend").read_bytes()
    (folder / "broken.blend").write_bytes(data[: len(data) // 2])

    manifest = folder / "manifest.toml"
    manifest.write_text(f"""\
# The batch tests' library: five good assets and a broken one.
[defaults]
resolution = {resolution}
samples = {samples}
format = ["png", "exr"]
margin = 2

[[bake]]
blend = "chair.blend"
objects = ["Ground", "Block"]

[[bake]]
blend = "props/lamp.blend"

[[bake]]
blend = "more/lamp.blend"
samples = {2 * samples}
seed = 3

[[bake]]
blend = "broken.blend"

[[bake]]
blend = "crate v2?.blend"
format = ["png"]
occluders = "selected"

[[bake]]
blend = "torus.blend"
resolution = "{int(resolution * 1.5)}x{resolution}"
""")
    return manifest


def make_copies(folder, copies, resolution=64, samples=32):
    """``copies`` good assets (a chair each, under a few names), for the benchmark; the manifest's path."""
    bpy = _bpy()
    folder = Path(folder)
    _new_scene(bpy)
    _add(bpy, "plane", "Ground", size=4)
    _add(bpy, "cube", "Block", size=1, location=(0, 0, 0.8))
    _save(bpy, folder / "asset000.blend")
    for i in range(1, copies):
        shutil.copyfile(folder / "asset000.blend", folder / f"asset{i:03d}.blend")
    entries = "".join(f'\n[[bake]]\nblend = "asset{i:03d}.blend"\n' for i in range(copies))
    manifest = folder / "manifest.toml"
    manifest.write_text(f"[defaults]\nresolution = {resolution}\nsamples = {samples}\nformat = [\"exr\"]\n{entries}")
    return manifest


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folder", type=Path)
    p.add_argument("--copies", type=int, default=0)
    p.add_argument("--resolution", type=int)
    p.add_argument("--samples", type=int)
    args = p.parse_args(argv)
    kwargs = {k: v for k, v in (("resolution", args.resolution), ("samples", args.samples)) if v}
    if args.copies:
        print(make_copies(args.folder, args.copies, **kwargs))
    else:
        print(make_library(args.folder, **kwargs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
