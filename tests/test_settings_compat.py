"""What the previous version of mc_ao recorded still counts as done: a manifest's tasks keep their
fingerprints (the names of their summaries), their command lines and the settings their files carry.

tests/data/settings_golden.json was made by the version before the settings schema (commit c36c802's
scripts and mc_ao_batch, with this file's ``records()``); regenerating it is only right when the
mc_ao version changes (a new version re-bakes everything anyway):

    python tests/test_settings_compat.py --write
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
        out.append({"entry": text, "args": task.args, "fingerprint": task.fingerprint,
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


if __name__ == "__main__":
    import tempfile

    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/test_settings_compat.py --write")
    with tempfile.TemporaryDirectory() as folder:
        GOLDEN.write_text(json.dumps(_plain(records(folder)), indent=1) + "\n")
    print(f"wrote {GOLDEN}")


def test_a_library_baked_by_the_previous_version_is_not_baked_again(tmp_path):
    """tests/data/previous_library: a manifest, its .blend file and, in baked/, the output the previous version
    baked from them (its task summary and files). The new code finds every task done."""
    import shutil
    import subprocess

    import pytest

    pytest.importorskip("bpy")
    library = tmp_path / "library"
    shutil.copytree(ROOT / "tests" / "data" / "previous_library", library)
    for name, mtime_ns in json.loads((library / "mtimes.json").read_text()).items():
        os.utime(library / name, ns=(mtime_ns, mtime_ns))  # as it was when baked: part of the fingerprint
    files = {p: p.read_bytes() for p in (library / "baked").rglob("*") if p.is_file()}
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "bake_batch.py"), str(library / "manifest.toml"),
                           "--output", str(library / "baked"), "--blender", "bpy"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "0 baked, 1 already done, 0 failed" in proc.stdout, proc.stdout
    assert all(p.read_bytes() == data for p, data in files.items())
