"""Channel packing in a batch: the Into file is found beside the manifest (not in the working folder), and
a task that packed its map into a copy of it counts as done on the next run (it was baked again every
run: the copy keeps the Into file's attributes, and carries no metadata of the bake to check)."""

import json
import subprocess
import sys

import numpy as np
import pytest

from batch_helpers import BATCH, library  # noqa: F401 (library: a fixture)

pytestmark = pytest.mark.blender


def orm(path, size, value):
    from core.files import imageio

    imageio.write_image(str(path), np.full((size, size, 3), value, np.float32), bits=8)


def run(manifest, out, cwd):
    return subprocess.run([sys.executable, str(BATCH), str(manifest), "--output", str(out), "--workers", "1",
                           "--blender", "bpy"], capture_output=True, text=True, timeout=600, cwd=cwd)


def test_a_channel_packing_task_is_done_on_the_next_run_and_its_into_file_is_the_manifests(library, tmp_path):
    manifest = library.parent / "packing.toml"
    manifest.write_text('[defaults]\nresolution = 16\nsamples = 8\n\n[[bake]]\nblend = "chair.blend"\n'
                        'objects = ["Block"]\nchannel = "R"\ninto = "textures/orm.png"\n')
    (library.parent / "textures").mkdir(exist_ok=True)
    orm(library.parent / "textures" / "orm.png", 16, 0.5)
    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "textures").mkdir(parents=True)
    orm(elsewhere / "textures" / "orm.png", 8, 0.9)  # of another size: packing into it would be refused
    out = tmp_path / "out"
    first = run(manifest, out, elsewhere)
    assert first.returncode == 0, first.stdout + first.stderr
    [task] = json.loads((out / "mc_ao_batch.json").read_text())["tasks"]
    assert task["status"] == "ok" and sorted(f.split("/")[-1] for f in task["files"]) == ["Block_AO.png", "orm.png"]

    from core.files import imageio

    packed, _ = imageio.read_image(str(out / "chair" / "orm.png"))
    assert packed.shape == (16, 16, 3) and np.all(np.abs(packed[:, :, 1:] - 0.5) < 1 / 255)  # the manifest's file
    second = run(manifest, out, elsewhere)
    assert second.returncode == 0, second.stdout + second.stderr
    [task] = json.loads((out / "mc_ao_batch.json").read_text())["tasks"]
    assert task["status"] == "skipped", task  # done: not baked again
    # A copy changed since (another tool wrote it): baked again.
    orm(out / "chair" / "orm.png", 16, 0.1)
    third = run(manifest, out, elsewhere)
    [task] = json.loads((out / "mc_ao_batch.json").read_text())["tasks"]
    assert task["status"] == "ok", task
