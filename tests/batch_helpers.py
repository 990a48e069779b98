"""Shared by the batch mode's tests: the generated library, one local run of it, and small readers."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BATCH = ROOT / "scripts" / "bake_batch.py"
IMAGE_SUFFIXES = (".png", ".exr", ".tif")
STARTED = re.compile(r"^bake_batch: started (?P<task>.+) on \S+ \(worker pid (?P<pid>\d+), bake pid (?P<bake>\d+)\)$")


def batch(*args, timeout=600):
    return subprocess.run([sys.executable, str(BATCH), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


def images(folder):
    """Every image file under ``folder``: relative path -> bytes."""
    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.suffix in IMAGE_SUFFIXES}


def summary(folder):
    data = json.loads((Path(folder) / "mc_ao_batch.json").read_text())
    return data, {t["blend"]: t for t in data["tasks"]}


def sub_manifest(manifest, blends, name):
    """A manifest beside ``manifest`` with its [defaults] and only the entries of ``blends``."""
    head, *entries = manifest.read_text().split("[[bake]]")
    keep = [e for e in entries if re.search(r'^blend = "(.*)"$', e, re.M).group(1) in blends]
    path = manifest.parent / name
    path.write_text(head + "".join("[[bake]]" + e for e in keep))
    return path


@pytest.fixture(scope="session")
def library(tmp_path_factory):
    """tests/batch_assets.py's six assets (one broken) and their manifest."""
    pytest.importorskip("bpy")
    folder = tmp_path_factory.mktemp("library")
    subprocess.run([sys.executable, str(ROOT / "tests" / "batch_assets.py"), str(folder)], check=True,
                   capture_output=True, timeout=300)
    return folder / "manifest.toml"


@pytest.fixture(scope="session")
def local_run(library, tmp_path_factory):
    """The library baked by the local runner, 2 at a time: (output folder, finished process)."""
    out = tmp_path_factory.mktemp("local") / "out"
    proc = batch(library, "--output", out, "--runner", "local", "--workers", 2, "--blender", "bpy")
    return out, proc


