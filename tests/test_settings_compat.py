"""What the previous version of mc_ao recorded is still found: a manifest's tasks keep their output
version 1 fingerprints (the names of their summaries), their command lines and the settings their
files carry; a library that version made is reported and kept, and baked again when asked.

tests/data/settings_golden.json was made by the version before the settings schema (commit c36c802's
scripts and mc_ao_batch, with this file's ``records()``), whose fingerprints had no output version:
they are each task's output version 1 fingerprint now (``Task.older``). Never regenerate it: it is
how a library made before output versions is found.
"""

import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

GOLDEN = ROOT / "tests" / "data" / "settings_golden.json"

# Entries that together set every setting a manifest may set, in the forms users write them.
ENTRIES = [
    "",
    "samples = 256\nresolution = 512\nformat = ['png', 'exr']\nstderr = true\n",
    "resolution = [64, 32]\nmax_distance = 0.0\nmargin = 4\nseed = 7\nthreads = 2\n",
    "max_distance = inf\nsource = 'halton'\ndistribution = 'uniform'\noccluders = 'self'\n",
    "max_distance = 1.5\nmin_samples = 8\ntarget_error = 0.01\nuv_map = 'UVMap.001'\n",
    "image_name = '{object}_occlusion'\nignore_backfaces = true\nbits = '16'\nformat = ['tif']\n",
    "udim = true\nbent_normals = true\nbent_space = 'object'\nformat = ['exr']\nbits = 'float'\n",
    "target = 'vertex-colors'\nattribute = 'Occlusion'\ndomain = 'corner'\nattribute_type = 'byte'\n",
    "objects = ['Chair_high']\nselected_to_active = true\nactive = 'Chair_low'\nextrusion = 0.05\n"
    "max_ray_distance = 0.5\ncage = 'Chair_cage'\n",
    "match_suffix = ['_high', '_low']\nextrusion = 0.1\n",
    "objects = ['Ground', 'Block']\nsamples = 16\n",
]


def records(folder):
    """For each entry: the task's args, fingerprint and the settings record its files carry."""
    from mc_ao import filewriter
    from mc_ao_batch.manifest import bake_parser, bake_script_module, plan

    blend = Path(folder) / "asset.blend"
    blend.write_bytes(b"BLENDER-v402" + b"\0" * 100)
    os.utime(blend, ns=(1_700_000_000_000_000_000, 1_700_000_000_000_000_000))
    out = []
    for text in ENTRIES:
        manifest = Path(folder) / "m.toml"
        manifest.write_text(f"[[bake]]\nblend = 'asset.blend'\n{text}")
        (task,) = plan(manifest, Path(folder) / "out")
        namespace = bake_parser().parse_args([task.blend] + task.args)
        module = bake_script_module()
        module.default_formats(namespace)
        settings = module.settings_from(namespace)
        out.append({"entry": text, "args": task.args, "fingerprint": dict(task.older)[1],
                    "record": filewriter.settings_record(settings)})
    return out


def _plain(value):
    return json.loads(json.dumps(value))  # inf -> Infinity and back, tuples -> lists


def test_previous_fingerprints_commands_and_file_records_are_unchanged(tmp_path):
    golden = json.loads(GOLDEN.read_text())
    now = _plain(records(tmp_path))
    assert [g["entry"] for g in golden] == ENTRIES
    for old, new in zip(golden, now):
        assert new["fingerprint"] == old["fingerprint"], old["entry"]
        assert new["record"] == old["record"], old["entry"]
        # the command line may be written differently, but must mean the same
        assert sorted(new["args"]) == sorted(old["args"]) or new["args"] == old["args"], old["entry"]


def _previous_library(tmp_path):
    """tests/data/previous_library copied: a manifest, its .blend file and, in baked/, the output the
    version before output versions baked from them (its task summary and files)."""
    import shutil

    library = tmp_path / "library"
    shutil.copytree(ROOT / "tests" / "data" / "previous_library", library)
    for name, mtime_ns in json.loads((library / "mtimes.json").read_text()).items():
        os.utime(library / name, ns=(mtime_ns, mtime_ns))  # as it was when baked: part of the fingerprint
    return library


def _batch(library, *extra):
    import subprocess

    return subprocess.run([sys.executable, str(ROOT / "scripts" / "bake_batch.py"), str(library / "manifest.toml"),
                           "--output", str(library / "baked"), "--blender", "bpy", *extra],
                          capture_output=True, text=True, timeout=600)


def test_a_library_made_by_an_older_output_version_is_reported_and_kept(tmp_path):
    """The new code finds the previous version's task complete under its output version 1 fingerprint:
    it says so and keeps every file, byte for byte, and bakes nothing."""
    import pytest

    pytest.importorskip("bpy")
    from core._version import OUTPUT_VERSION
    from mc_ao_batch.manifest import plan
    from mc_ao_batch.task import made_by_older, why_not_done

    assert OUTPUT_VERSION > 1
    library = _previous_library(tmp_path)
    (task,) = plan(library / "manifest.toml", library / "baked")
    assert why_not_done(task) is not None  # not done by this output version ...
    assert made_by_older(task) == (1, task.summary_of(dict(task.older)[1]))  # ... but by version 1, complete
    files = {p: p.read_bytes() for p in (library / "baked").rglob("*") if p.is_file()}
    proc = _batch(library)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert ("0 baked, 0 already done, 1 task made by an older version (kept; --rebake-older or "
            "rebake_older = true bakes them again), 0 failed of 1") in proc.stdout, proc.stdout
    assert "kept (made by output version 1)" in proc.stdout
    summary = json.loads((library / "baked" / "mc_ao_batch.json").read_text())
    assert summary["counts"] == {"ok": 0, "skipped": 0, "older": 1, "failed": 0}
    assert summary["tasks"][0]["older"] == 1
    assert all(p.read_bytes() == data for p, data in files.items())


def test_rebake_older_bakes_an_older_library_again_and_the_next_run_finds_it_done(tmp_path):
    """--rebake-older (or rebake_older = true in the manifest) bakes the task again: its files now
    record this output version, the old summary goes, and a second run finds the task done."""
    import pytest

    pytest.importorskip("bpy")
    from core._version import OUTPUT_VERSION
    from core.files.imageio import read_image

    for how in ("option", "manifest"):
        library = _previous_library(tmp_path / how)
        extra = ("--rebake-older",) if how == "option" else ()
        if how == "manifest":
            text = (library / "manifest.toml").read_text()
            (library / "manifest.toml").write_text(text.replace("[defaults]", "[defaults]\nrebake_older = true", 1)
                                                   if "[defaults]" in text else "[defaults]\nrebake_older = true\n" + text)
        old_summaries = sorted(p.name for p in (library / "baked").rglob("mc_ao-*.json"))
        proc = _batch(library, *extra)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert "1 baked, 0 already done, 0 failed of 1" in proc.stdout, proc.stdout
        images = [p for p in (library / "baked").rglob("*") if p.suffix in (".png", ".exr")]
        assert images and all(read_image(p)[1]["output_version"] == OUTPUT_VERSION for p in images)
        summaries = sorted(p.name for p in (library / "baked").rglob("mc_ao-*.json"))
        assert len(summaries) == 1 and summaries != old_summaries
        proc = _batch(library, *extra)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert "0 baked, 1 already done, 0 failed of 1" in proc.stdout, proc.stdout


def test_rebake_older_is_the_batchs_own_key_never_a_bake_setting(tmp_path):
    """rebake_older (in [defaults] or an entry) goes on the task, not on the bake's command line nor
    into its fingerprint; anything but true or false is refused by name."""
    import pytest

    from mc_ao_batch.manifest import ManifestError, plan

    blend = tmp_path / "asset.blend"
    blend.write_bytes(b"BLENDER-v402" + b"\0" * 100)
    manifest = tmp_path / "m.toml"
    plain = "[[bake]]\nblend = 'asset.blend'\n"
    manifest.write_text(plain)
    (base,) = plan(manifest, tmp_path / "out")
    assert base.rebake_older is False and [v for v, _ in base.older] == list(range(base_version() - 1, 0, -1))
    for text in ("[defaults]\nrebake_older = true\n" + plain, plain + "rebake_older = true\n"):
        manifest.write_text(text)
        (task,) = plan(manifest, tmp_path / "out")
        assert task.rebake_older is True
        assert (task.args, task.fingerprint, task.older) == (base.args, base.fingerprint, base.older)
    manifest.write_text(plain + "rebake_older = 'yes'\n")
    with pytest.raises(ManifestError, match="rebake_older must be true or false"):
        plan(manifest, tmp_path / "out")


def base_version():
    from core._version import OUTPUT_VERSION

    return OUTPUT_VERSION


def test_every_file_records_the_output_version(tmp_path):
    """Images and PLY files (colour attributes) carry output_version: what the batch compares."""
    import numpy as np

    from core.files import imageio, plyio
    from core._version import OUTPUT_VERSION

    image = imageio.write_image(tmp_path / "a.png", np.zeros((2, 2), np.float32), metadata={"object": "A"})
    assert imageio.read_image(image)[1]["output_version"] == OUTPUT_VERSION
    ply = tmp_path / "a.ply"
    plyio.write_ply(ply, np.zeros((3, 3)), [3], [0, 1, 2], np.zeros(3), metadata={"object": "A"})
    assert plyio.read_ply(ply)[4]["output_version"] == OUTPUT_VERSION
