"""Fingerprints of the files the add-on's script writes, for a set of option sets on the sample scenes.

scripts/output_hashes.py fingerprints the core's arrays; this runs scripts/bake_ao.py (the add-on's
whole path: settings, objects, jobs, the core call, the outputs and their files) and prints one line
per file written: ``<option set>/<file> <hash of its pixels, or of a PLY's body>``; metadata (dates,
versions) left out. Run it on two checkouts and compare the lists to show that a change of the
add-on's code leaves every file's pixels as they were:

    .venv/bin/python scripts/addon_output_hashes.py > after.txt
    (cd ../before && .venv/bin/python scripts/addon_output_hashes.py) > before.txt
    diff before.txt after.txt

Small bakes (48 x 48, 8 samples, one thread, one process but where two are the point): a few
minutes on two cores.
"""

import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FAST = ["--resolution", "48", "--samples", "8", "--margin", "2", "--quiet", "--threads", "1", "--processes", "1"]
# name -> (scene, options); later options win over FAST's
SETS = {
    "plain": ("suzanne", ["--objects", "Suzanne", "Ground"]),
    "exr": ("suzanne", ["--format", "exr", "png", "--stderr", "--bent-normals", "--bent-space", "object"]),
    "maps": ("suzanne", ["--quantity", "ao", "thickness", "--max-distance", "0.5"]),
    "thick": ("room", ["--objects", "Table", "Crate", "--quantity", "thickness", "--max-distance", "0.3"]),
    "vertex": ("suzanne", ["--target", "vertex-colors", "--domain", "corner"]),
    "udim": ("udim", ["--udim", "--format", "exr", "--stderr"]),
    "umaps": ("udim", ["--udim", "--quantity", "ao", "thickness"]),
    "denoise": ("room", ["--objects", "Table", "Cabinet", "--denoise", "--target-error", "0.05", "--ground",
                         "--occluders", "selected"]),
    "s2a": ("rock", ["--selected-to-active", "--active", "Rock_low", "--objects", "Rock_high", "--format", "exr"]),
    "s2acage": ("rock", ["--selected-to-active", "--active", "Rock_low", "--objects", "Rock_high", "--cage",
                         "--extrusion", "0.05"]),
    "workers": ("analytic", ["--processes", "2", "--source", "halton", "--distribution", "uniform", "--seed", "5",
                             "--ground-height", "-0.1"]),
}


def digest(path):
    """The hash of a file's pixels (read back by the core) or of a PLY's body (after its header)."""
    if path.suffix == ".ply":
        data = path.read_bytes()
        data = data[data.index(b"end_header"):]  # the header's comments carry the metadata
    else:
        import numpy as np

        from core.files.imageio import read_image

        data = np.ascontiguousarray(read_image(str(path))[0]).tobytes()
    return hashlib.sha256(data).hexdigest()[:16]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=sorted(SETS), help="these option sets only")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    with tempfile.TemporaryDirectory(prefix="addon_hashes_") as tmp:
        for name in args.only or SETS:
            scene, options = SETS[name]
            out = Path(tmp) / name
            proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "bake_ao.py"),
                                   str(ROOT / "sample_scenes" / f"{scene}.blend"), *FAST, *options, "--output", str(out)],
                                  capture_output=True, text=True, env=dict(os.environ, PYTHONHASHSEED="0"))
            if proc.returncode != 0:
                print(f"{name} exit {proc.returncode}: {proc.stderr.strip().splitlines()[-1:]}", flush=True)
                continue
            for path in sorted(p for p in out.rglob("*") if p.is_file()):
                print(f"{name}/{path.relative_to(out)} {digest(path)}", flush=True)


if __name__ == "__main__":
    main()
