#!/usr/bin/env python3
"""Build the installable extension zips: one per platform under dist/, with that platform's wheels.

    python scripts/build_extension.py                       # every platform in the manifest
    python scripts/build_extension.py --platform current    # only this machine's platform
    python scripts/build_extension.py --platform linux-x64 --output-dir /tmp/dist

The wheels listed in blender_manifest.toml are downloaded with pip into wheels/ (ignored by git,
never committed) when missing. The zips are made by Blender's own extension builder
(``blender --command extension build --split-platforms``): with ``--blender PATH`` through that
executable, else through the builder script that the ``bpy`` module carries
(``bpy/<version>/scripts/addons_core/bl_pkg/cli/blender_ext.py``, plain Python). Only when neither
is available does this script write the zips itself, the same way: the manifest at the zip root
with a ``[build.generated]`` table naming the platform and its wheels, the staged files, and the
platform's wheels.

What a zip holds is an allow-list, SHIP: the manifest, the add-on's entry (``__init__.py``), its two
packages (``core/``, ``mc_ao/``), the licence and the README, plus the platform's wheels. Nothing
else in the checkout (the batch, the farm, tests, bench, scripts, sample scenes) is ever staged.
The build runs on a staged copy holding only those, whose manifest lists only the chosen platforms
and their wheels (so that building a subset does not need every platform's wheels) and whose
``[build]`` table only keeps caches and dot-files out (NEVER). The allow-list is applied by staging,
not by the manifest's ``[build] paths``: Blender's builder (4.2 to 5.0) takes ``paths`` as single
files, not folders, and with ``paths`` set and ``--split-platforms`` it filters the wrong entries
as wheels and stops.
"""

import argparse
import fnmatch
import importlib.util
import os
import platform as _platform
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = "blender_manifest.toml"
# Everything a zip ships besides the wheels, relative to the extension root: a file, or a folder
# shipped whole. An allow-list, so that nothing added to the checkout ships by default.
SHIP = (MANIFEST, "__init__.py", "core/", "mc_ao/", "LICENSE", "README.md")
# Never shipped from inside those folders (gitignore-style patterns): caches, dot-files, backups.
NEVER = ("__pycache__/", "*.pyc", ".*", "*.blend[1-9]")


class BuildError(Exception):
    pass


# -- platforms and wheels ----------------------------------------------------------------------

def current_platform():
    """This machine's platform in Blender's spelling (linux-x64, windows-x64, macos-arm64, ...)."""
    system = {"linux": "linux", "darwin": "macos", "windows": "windows"}.get(
        _platform.system().lower(), _platform.system().lower())
    machine = _platform.machine().lower()
    machine = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64"}.get(machine, machine)
    return f"{system}-{machine}"


def parse_wheel(filename):
    """(distribution, version, python tag, abi tag, platform tag) of a wheel file name."""
    parts = Path(filename).name[: -len(".whl")].split("-")
    if len(parts) not in (5, 6):
        raise BuildError(f"not a wheel file name: {filename}")
    return parts[0], parts[1], parts[-3], parts[-2], parts[-1]


def wheel_platforms(filename):
    """Blender platforms a wheel runs on, from its platform tag (which may join several with '.')."""
    found = set()
    for tag in parse_wheel(filename)[4].split("."):
        if tag == "any":
            return {"any"}
        if tag == "win_amd64":
            found.add("windows-x64")
        elif tag == "win_arm64":
            found.add("windows-arm64")
        elif tag.startswith(("manylinux", "musllinux", "linux")):
            found.add("linux-x64" if tag.endswith("x86_64") else "linux-arm64")
        elif tag.startswith("macosx"):
            if tag.endswith("universal2"):
                found.update({"macos-x64", "macos-arm64"})
            else:
                found.add("macos-arm64" if tag.endswith("arm64") else "macos-x64")
    return found


def wheels_for(wheels, platforms):
    return [w for w in wheels if wheel_platforms(w) & (set(platforms) | {"any"})]


def download_wheels(wheels, wheel_dir):
    """pip-download every listed wheel missing from ``wheel_dir``, exactly that file (no dependencies)."""
    wheel_dir.mkdir(parents=True, exist_ok=True)
    for wheel in wheels:
        name = Path(wheel).name
        if (wheel_dir / name).is_file():
            continue
        dist, version, py, abi, plat = parse_wheel(name)
        cmd = [
            sys.executable, "-m", "pip", "download", f"{dist}=={version}", "--no-deps",
            "--only-binary=:all:", "--dest", str(wheel_dir), "--python-version", py[2:].lstrip("p"),
            "--implementation", py[:2], "--abi", abi,
        ]
        for tag in plat.split("."):
            cmd += ["--platform", tag]
        print(f"downloading {name}", flush=True)
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0 or not (wheel_dir / name).is_file():
            raise BuildError(f"pip could not download {name}:\n{proc.stdout}{proc.stderr}")


# -- staging -----------------------------------------------------------------------------------

def manifest_for(text, platforms, wheels):
    """The manifest text with its platforms and wheels lists cut down to ``platforms`` and ``wheels``."""
    def toml_list(items, multiline):
        if not multiline:
            return "[" + ", ".join(f'"{i}"' for i in items) + "]"
        return "[\n" + "".join(f'  "{i}",\n' for i in items) + "]"

    text, n = re.subn(r"(?m)^platforms\s*=\s*\[[^\]]*\]", lambda m: "platforms = " + toml_list(platforms, False), text)
    if n != 1:
        raise BuildError("the manifest has no one-line platforms = [...] list")
    text, n = re.subn(r"(?ms)^wheels\s*=\s*\[.*?\]", lambda m: "wheels = " + toml_list(wheels, True), text)
    if n != 1:
        raise BuildError("the manifest has no wheels = [...] list")
    return with_build_table(text)


def with_build_table(text):
    """The manifest text with its ``[build]`` table (if any) replaced by one excluding NEVER."""
    text = re.sub(r"(?ms)^\[build\][ \t]*\n.*?(?=^\[[A-Za-z]|\Z)", "", text)
    return (text.rstrip("\n") + "\n\n[build]\n# Staged by scripts/build_extension.py: only what its allow-list SHIP names.\n"
            "paths_exclude_pattern = [" + ", ".join(f'"{p}"' for p in NEVER) + "]\n")


def stage(source, stage_dir, platforms, wheels, wheel_dir):
    """Copy what SHIP names to ``stage_dir``, with a manifest for ``platforms`` and their wheels."""
    text = (source / MANIFEST).read_text(encoding="utf-8")
    missing = [p for p in SHIP if not (source / p).exists()]
    if missing:
        raise BuildError("the extension has no " + ", ".join(missing))

    def ignore(directory, names):
        rel_dir = os.path.relpath(directory, source).replace(os.sep, "/") + "/"
        return [n for n in names if _excluded(rel_dir + n, os.path.isdir(os.path.join(directory, n)), NEVER)]

    stage_dir.mkdir(parents=True)
    for path in SHIP:
        if path.endswith("/"):
            shutil.copytree(source / path, stage_dir / path, ignore=ignore)
        elif path != MANIFEST:
            shutil.copy2(source / path, stage_dir / path)
    (stage_dir / MANIFEST).write_text(manifest_for(text, platforms, wheels), encoding="utf-8")
    for wheel in wheels:
        target = stage_dir / wheel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(wheel_dir / Path(wheel).name, target)


# -- building ----------------------------------------------------------------------------------

def bpy_extension_builder():
    """Path of Blender's extension builder script inside the installed bpy module, or None."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        return None
    for location in spec.submodule_search_locations:
        found = sorted(Path(location).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
        if found:
            return found[-1]
    return None


def build_with_blender(stage_dir, output_dir, blender=None):
    """Run Blender's ``extension build --split-platforms`` on the staged copy; False if unavailable."""
    args = ["build", "--source-dir", str(stage_dir), "--output-dir", str(output_dir), "--split-platforms"]
    if blender:
        cmd = [blender, "--factory-startup", "--command", "extension", *args]
    else:
        builder = bpy_extension_builder()
        if builder is None:
            return False
        cmd = [sys.executable, str(builder), *args]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    sys.stdout.write(proc.stdout)
    if proc.returncode != 0:
        raise BuildError(f"Blender's extension build failed ({' '.join(cmd)}):\n{proc.stdout}{proc.stderr}")
    return True


def _excluded(rel, is_dir, patterns):
    """Whether gitignore-style ``patterns`` (as NEVER, or a manifest's ``paths_exclude_pattern``)
    exclude a path.

    Covers the forms used here: "/name" anchored at the root, "name/" for directories
    only, and globs without a slash matched against every path component.
    """
    parts = rel.split("/")
    for pattern in patterns:
        dir_only = pattern.endswith("/")
        body = pattern.strip("/")
        if pattern.startswith("/"):
            candidates = ["/".join(parts[: i + 1]) for i in range(len(parts))]
            kinds = [i < len(parts) - 1 or is_dir for i in range(len(parts))]
        else:
            candidates = parts
            kinds = [i < len(parts) - 1 or is_dir for i in range(len(parts))]
        for candidate, candidate_is_dir in zip(candidates, kinds):
            if (candidate_is_dir or not dir_only) and fnmatch.fnmatchcase(candidate, body):
                return True
    return False


def build_zips_here(stage_dir, output_dir):
    """Write one zip per platform the way Blender's builder does (used when it is not available)."""
    with open(stage_dir / MANIFEST, "rb") as fh:
        manifest = tomllib.load(fh)
    patterns = manifest["build"]["paths_exclude_pattern"]
    wheels = manifest.get("wheels", [])
    listed = {os.path.normpath(w).replace(os.sep, "/") for w in wheels} | {MANIFEST}
    files = []
    for directory, dirnames, filenames in os.walk(stage_dir):
        rel_dir = os.path.relpath(directory, stage_dir).replace(os.sep, "/")
        rel_dir = "" if rel_dir == "." else rel_dir + "/"
        dirnames[:] = sorted(d for d in dirnames if not _excluded(rel_dir + d, True, patterns))
        for name in sorted(filenames):
            rel = rel_dir + name
            if rel not in listed and not _excluded(rel, False, patterns):
                files.append(rel)
    manifest_text = (stage_dir / MANIFEST).read_text(encoding="utf-8")
    for plat in manifest["platforms"]:
        plat_wheels = wheels_for(wheels, [plat])
        generated = (
            "\n\n# BEGIN GENERATED CONTENT.\n# This must not be included in source manifests.\n"
            "[build.generated]\n"
            f'platforms = ["{plat}"]\n'
            "wheels = [" + ", ".join(f'"{w}"' for w in plat_wheels) + "]\n"
            "# END GENERATED CONTENT.\n"
        )
        out = output_dir / f"{manifest['id']}-{manifest['version']}-{plat.replace('-', '_')}.zip"
        temp = out.with_name("." + out.name)
        with zipfile.ZipFile(temp, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zf:
            zf.writestr(MANIFEST, manifest_text + generated)
            for wheel in plat_wheels:
                zf.write(stage_dir / wheel, os.path.normpath(wheel).replace(os.sep, "/"), zipfile.ZIP_STORED)
            for rel in files:
                zf.write(stage_dir / rel, rel)
        os.replace(temp, out)
        print(f'created: "{out}", {out.stat().st_size}')


def build(platforms=None, output_dir=ROOT / "dist", wheel_dir=ROOT / "wheels", blender=None,
          download=True, builder="auto"):
    """Build the zips; return their paths (one per platform, in the manifest's platform order).

    builder: "auto" (Blender's builder if available, else this script's), "blender" or "self".
    """
    with open(ROOT / MANIFEST, "rb") as fh:
        manifest = tomllib.load(fh)
    known = manifest["platforms"]
    platforms = [current_platform() if p == "current" else p for p in (platforms or known)]
    unknown = [p for p in platforms if p not in known]
    if unknown:
        raise BuildError(f"platform {', '.join(unknown)} is not in the manifest (it has {', '.join(known)})")
    platforms = [p for p in known if p in platforms]
    wheels = wheels_for(manifest.get("wheels", []), platforms)
    if download:
        download_wheels(wheels, wheel_dir)
    missing = [w for w in wheels if not (wheel_dir / Path(w).name).is_file()]
    if missing:
        raise BuildError("missing wheels (run without --no-download): " + ", ".join(missing))

    output_dir = Path(output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="mc_ao_build_") as tmp:
        stage_dir = Path(tmp) / "mc_ao"
        stage(ROOT, stage_dir, platforms, wheels, wheel_dir)
        done = False
        if builder in ("auto", "blender"):
            done = build_with_blender(stage_dir, output_dir, blender)
            if not done and builder == "blender":
                raise BuildError("no Blender extension builder: pass --blender PATH or install the bpy module")
        if not done:
            build_zips_here(stage_dir, output_dir)
    name = f"{manifest['id']}-{manifest['version']}"
    return [output_dir / f"{name}-{p.replace('-', '_')}.zip" for p in platforms]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--platform", action="append", dest="platforms", metavar="PLATFORM",
                        help="build for this platform only (repeatable; 'current' = this machine)")
    parser.add_argument("--output-dir", type=Path, default=ROOT / "dist")
    parser.add_argument("--wheel-dir", type=Path, default=ROOT / "wheels")
    parser.add_argument("--blender", help="Blender executable whose 'extension build' makes the zips")
    parser.add_argument("--builder", choices=("auto", "blender", "self"), default="auto",
                        help="'self' writes the zips without Blender's builder (default: Blender's if found)")
    parser.add_argument("--no-download", dest="download", action="store_false",
                        help="use the wheels already in --wheel-dir, download nothing")
    args = parser.parse_args(argv)
    try:
        zips = build(args.platforms, args.output_dir, args.wheel_dir, args.blender, args.download, args.builder)
    except BuildError as exc:
        print(f"build_extension: {exc}", file=sys.stderr)
        return 1
    for path in zips:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
