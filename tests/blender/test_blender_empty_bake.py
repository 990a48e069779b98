"""A bake that covers no texel (UVs outside the image, faces or UVs without area) is an error naming
the object and why: through the script (exit 1, no file), the operator (an error report, no image
saved) and the batch (the task failed, so a rerun bakes it again instead of skipping it for ever)."""

import json
import subprocess
import sys

import pytest

from blender_helpers import ROOT, add_plane, clean_scene, select_only

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
FAST = ("--samples", "4", "--resolution", "16", "--threads", "1", "--quiet")


def move_uvs(obj, du=5.0, scale=1.0):
    for d in obj.data.uv_layers.active.uv:
        d.vector = (d.vector[0] * scale + du, d.vector[1] * scale)


@pytest.fixture(scope="module")
def blend_file(bpy, tmp_path_factory):
    clean_scene(bpy)
    add_plane(bpy, "Ground", size=4)
    move_uvs(add_plane(bpy, "Outside", size=1, location=(5, 0, 0)))
    move_uvs(add_plane(bpy, "Squashed", size=1, location=(-5, 0, 0)), du=0.5, scale=0.0)
    path = tmp_path_factory.mktemp("scene") / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    clean_scene(bpy)
    return path


@pytest.mark.parametrize("name, why", [
    ("Outside", "2 of its UV triangles lie outside the image's UV square [0, 1]"),
    ("Squashed", "2 of its UV triangles have no area in the UV map"),
])
def test_the_script_fails_the_object_that_covered_no_texel(blend_file, tmp_path, name, why):
    out = tmp_path / "out"
    summary = tmp_path / "summary.json"
    proc = subprocess.run([sys.executable, SCRIPT, blend_file, "--objects", "Ground", name, "--output", out,
                           "--summary-json", summary, *FAST], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    # One line names the object, says the bake covered nothing, why, and that nothing was written
    # (the core's MeshError or the add-on's own check of a result, whichever finds it first).
    line = next(x for x in proc.stderr.splitlines() if x.startswith(f"bake_ao: {name}: "))
    assert "the bake covered no texel" in line and why in line and line.endswith("nothing was written"), line
    assert sorted(p.name for p in out.iterdir()) == ["Ground_AO.png"]
    record = {o["object"]: o for o in json.loads(summary.read_text())["objects"]}
    assert record["Ground"]["status"] == "ok" and record[name]["status"] == "failed"


def test_the_batch_fails_the_task_and_bakes_it_again_on_a_rerun(blend_file, tmp_path):
    manifest = tmp_path / "m.toml"
    manifest.write_text(f"[[bake]]\nblend = '{blend_file.as_posix()}'\nobjects = ['Outside']\nsamples = 4\n"
                        "resolution = 16\n")
    for _ in range(2):
        proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "bake_batch.py"), str(manifest), "--output",
                               str(tmp_path / "out"), "--blender", "bpy"], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 1 and "0 baked, 0 already done, 1 failed" in proc.stdout, proc.stdout
        assert "Outside: " in proc.stdout and "the bake covered no texel" in proc.stdout


def test_the_operator_reports_the_object_and_saves_nothing(bpy, scene, tmp_path):
    from blender_helpers import new_session, tick_until

    outside = add_plane(bpy, "Outside", size=1)
    move_uvs(outside)
    select_only(bpy, outside)
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = str(tmp_path)
    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    tick_until(bpy, session, lambda: False)
    errors = [m for kind, m in reports if kind == "ERROR"]
    assert any(m.startswith("Outside: ") and "the bake covered no texel" in m for m in errors), reports
    assert list(tmp_path.iterdir()) == []
