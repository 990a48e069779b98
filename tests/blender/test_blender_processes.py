"""Processes and Denoise, as a user sets them: the operator, the script and the batch bake the same
bytes in worker processes as in one process; a denoised bake says so in its files; the batch does not
bake again because the process count changed; disabling the add-on ends its worker processes."""

import json
import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene, image_ao, select_only

pytestmark = pytest.mark.blender
SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
COMMON = ["--objects", "Ground", "--resolution", "32", "--samples", "8", "--seed", "2", "--format", "png", "exr",
          "--quiet"]


@pytest.fixture
def scene_file(bpy, addon, tmp_path):
    clean_scene(bpy)
    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    select_only(bpy, ground)
    path = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path, ground


def run(path, out, *extra):
    proc = subprocess.run([sys.executable, SCRIPT, str(path), *COMMON, *extra, "--output", str(out),
                           "--summary-json", str(out) + ".json"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads((out.parent / (out.name + ".json")).read_text())


def test_the_script_writes_the_same_bytes_in_any_number_of_processes(scene_file, tmp_path):
    path, _ = scene_file
    run(path, tmp_path / "one", "--processes", "1")
    run(path, tmp_path / "two", "--processes", "2")
    run(path, tmp_path / "auto")
    for name in ("Ground_AO.png", "Ground_AO.exr"):
        one = (tmp_path / "one" / name).read_bytes()
        assert (tmp_path / "two" / name).read_bytes() == one and (tmp_path / "auto" / name).read_bytes() == one


def test_a_denoised_bake_differs_from_the_raw_one_and_says_so(scene_file, tmp_path):
    path, _ = scene_file
    raw = run(path, tmp_path / "raw")
    den = run(path, tmp_path / "den", "--denoise")
    assert (tmp_path / "raw" / "Ground_AO.exr").read_bytes() != (tmp_path / "den" / "Ground_AO.exr").read_bytes()
    assert "denoise" not in json.dumps(raw["settings"]) and den["settings"]["denoise"] is True


def test_the_operator_bakes_the_same_image_in_processes(bpy, scene_file):
    path, ground = scene_file
    settings = bpy.context.scene.mc_ao
    settings.resolution, settings.samples, settings.seed = 32, 8, 2
    images = {}
    for processes in (1, 2):
        settings.processes = processes
        assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
        images[processes], _ = image_ao(bpy.data.images["Ground_AO"])
    assert np.array_equal(images[1], images[2])
    import core.execution.pool as W  # the checkout's core, which the add-on uses here

    assert W._POOL is not None and len(W._POOL.workers) == 2


def test_the_batch_fingerprint_does_not_depend_on_the_processes(tmp_path):
    from mc_ao_batch.manifest import plan

    blend = tmp_path / "a.blend"
    blend.write_bytes(b"BLENDER")
    fingerprints = []
    for extra in ("", "processes = 2\n", "processes = 0\n"):
        manifest = tmp_path / "m.toml"
        manifest.write_text(f"[[bake]]\nblend = 'a.blend'\nsamples = 8\n{extra}")
        (task,) = plan(manifest, tmp_path / "out")
        fingerprints.append(task.fingerprint)
    manifest.write_text("[[bake]]\nblend = 'a.blend'\nsamples = 8\ndenoise = true\n")
    (denoised,) = plan(manifest, tmp_path / "out")
    assert len(set(fingerprints)) == 1 and denoised.fingerprint != fingerprints[0]


def test_disabling_the_add_on_ends_its_worker_processes(bpy, scene_file):
    import core.execution.pool as W

    settings = bpy.context.scene.mc_ao
    settings.resolution, settings.samples, settings.processes = 16, 4, 2
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    procs = [w.process for w in W._POOL.workers]
    import mc_ao

    mc_ao.unregister()
    try:
        assert W._POOL is None and all(p.poll() is not None for p in procs)
    finally:
        mc_ao.register()
