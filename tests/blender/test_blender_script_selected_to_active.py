"""scripts/bake_ao.py's Selected to Active options, and the batch mode passing them on from a manifest.

--selected-to-active with --active and the high-poly --objects, --extrusion, --max-ray-distance,
--cage; --match-suffix HIGH LOW for pairs matched by name. Every option is checked before baking
(exit 2, in --summary-json too), the summary records the high-poly objects and the misses.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
BATCH = str(ROOT / "scripts" / "bake_batch.py")
FAST = ("--samples", "16", "--resolution", "16", "--threads", "2", "--format", "exr", "--margin", "0")


def bumps(bpy, name, location=(0, 0, 0), size=2.2):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=16, y_subdivisions=16, size=size, location=location)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    co = np.empty(3 * len(obj.data.vertices))
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 2] = 0.05 * np.sin(4 * co[:, 0]) * np.cos(3 * co[:, 1])
    obj.data.vertices.foreach_set("co", co.ravel())
    obj.data.update()
    while obj.data.uv_layers:  # a sculpt has no UVs of its own: it is baked from, not into
        obj.data.uv_layers.remove(obj.data.uv_layers[0])
    return obj


@pytest.fixture(scope="module")
def blends(bpy, tmp_path_factory):
    """pairs.blend: Chair_low/Chair_high and Table_low/Table_high side by side, Lamp_low alone, a box
    over the chair, a cage of Chair_low, a Cage4 of another topology (both hidden and not rendered); Chair_low active,
    Chair_high selected."""
    folder = tmp_path_factory.mktemp("s2a")
    clean_scene(bpy)
    chair = add_plane(bpy, "Chair_low", size=2)
    bumps(bpy, "Chair_high")
    add_plane(bpy, "Table_low", size=2, location=(5, 0, 0))
    bumps(bpy, "Table_high", location=(5, 0, 0))
    add_plane(bpy, "Lamp_low", size=1, location=(-5, 0, 0))
    add_cube(bpy, "Box", size=0.5, location=(0.3, 0, 0.5))
    add_plane(bpy, "Chair_cage", size=2, location=(0, 0, 0.3))
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=2, y_subdivisions=2, size=2, location=(0, 0, 0.3))
    bpy.context.active_object.name = "Cage4"
    for name in ("Chair_cage", "Cage4"):  # rendered, they would occlude as any object (as in Cycles' bake)
        bpy.context.view_layer.objects[name].hide_set(True)
        bpy.context.view_layer.objects[name].hide_render = True
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj.name in ("Chair_low", "Chair_high"))
    bpy.context.view_layer.objects.active = chair
    path = folder / "pairs.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def run_script(*args):
    return subprocess.run([sys.executable, SCRIPT, *map(str, args)], capture_output=True, text=True, timeout=300)


def read(path):
    from core.files import imageio

    ao, metadata = imageio.read_image(path)
    return np.squeeze(ao), metadata


def test_bakes_the_high_poly_onto_the_active_low_poly(blends, tmp_path):
    out = tmp_path / "out"
    proc = run_script(blends, "--selected-to-active", "--active", "Chair_low", "--objects", "Chair_high",
                      "--extrusion", "0.2", "--output", out, "--summary-json", tmp_path / "s.json", *FAST)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["Chair_low_AO.exr"]
    assert "bake_ao: Chair_low: from Chair_high; no sample point missed the high-poly" in proc.stderr
    ao, metadata = read(out / "Chair_low_AO.exr")
    assert ao.shape == (16, 16) and ao.min() < 0.6 and ao.max() == 1.0  # the box shades the high-poly
    assert metadata["selected_to_active"] is True and metadata["highpoly"] == "Chair_high"
    assert metadata["cage_extrusion"] == 0.2 and metadata["extrusion"] == 0.2
    record = json.loads((tmp_path / "s.json").read_text())
    assert record["exit_code"] == 0
    assert record["settings"]["selected_to_active"] is True and record["settings"]["cage_extrusion"] == 0.2
    obj = record["objects"][0]
    assert obj["object"] == "Chair_low" and obj["status"] == "ok" and obj["highpoly"] == ["Chair_high"]
    assert obj["missed_sample_points"] == 0 and obj["matching_rays"] == 16 * 16 and obj["cage"] is None
    # The file's selection and active object are the default; a cage gives the same rays here.
    same = run_script(blends, "--selected-to-active", "--extrusion", "0.2", "--output", tmp_path / "same", *FAST)
    assert same.returncode == 0, same.stderr
    assert "bake_ao: baking the selected Chair_high onto Chair_low" in same.stderr
    cage = run_script(blends, "--selected-to-active", "--cage", "Chair_cage", "--output", tmp_path / "cage", *FAST)
    assert cage.returncode == 0, cage.stderr
    # --cage alone: the low-poly extruded along its vertex normals, which on a plane are its normal.
    generated = run_script(blends, "--selected-to-active", "--cage", "--extrusion", "0.2", "--output",
                           tmp_path / "generated", "--summary-json", tmp_path / "g.json", *FAST)
    assert generated.returncode == 0, generated.stderr
    assert json.loads((tmp_path / "g.json").read_text())["settings"]["use_cage"] is True
    for folder in ("same", "cage", "generated"):
        assert np.array_equal(read(tmp_path / folder / "Chair_low_AO.exr")[0], ao), folder


def test_pairs_matched_by_name(blends, tmp_path):
    out = tmp_path / "out"
    proc = run_script(blends, "--match-suffix", "_high", "_low", "--extrusion", "0.2", "--output", out,
                      "--summary-json", tmp_path / "s.json", *FAST)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["Chair_low_AO.exr", "Table_low_AO.exr"]
    assert "bake_ao: Lamp_low: skipped, there is no Lamp_high" in proc.stderr
    assert "bake_ao: Table_low: from Table_high; no sample point missed the high-poly" in proc.stderr
    chair, table = read(out / "Chair_low_AO.exr")[0], read(out / "Table_low_AO.exr")[0]
    assert chair.min() < 0.6 < table.min()  # the box stands over the chair only
    record = json.loads((tmp_path / "s.json").read_text())
    assert record["settings"]["match_suffix"] == ["_high", "_low"]
    assert [(o["object"], o["highpoly"]) for o in record["objects"]] == [
        ("Chair_low", ["Chair_high"]), ("Table_low", ["Table_high"])]
    only = run_script(blends, "--match-suffix", "_high", "_low", "--objects", "Table_low", "--extrusion", "0.2",
                      "--output", tmp_path / "only", *FAST)
    assert only.returncode == 0, only.stderr
    assert sorted(p.name for p in (tmp_path / "only").iterdir()) == ["Table_low_AO.exr"]


def test_misses_are_reported(blends, tmp_path):
    # Lamp_low lies over nothing of Chair_high's: every ray misses, which fails the object (exit 1)
    # with what to change; the max ray distance cuts the chair's rays short.
    proc = run_script(blends, "--selected-to-active", "--active", "Chair_low", "--objects", "Chair_high",
                      "--extrusion", "0.2", "--max-ray-distance", "0.1", "--output", tmp_path,
                      "--summary-json", tmp_path / "s.json", *FAST)
    assert proc.returncode == 1
    assert ("bake_ao: Chair_low: no matching ray from 'Chair_low' found the high-poly surface of 'Chair_high', "
            "so nothing could be baked: the nearest high-poly surface along the rays lies ") in proc.stderr
    assert "beyond the max ray distance 0.1; raise the max ray distance above" in proc.stderr
    record = json.loads((tmp_path / "s.json").read_text())
    assert record["objects"][0]["status"] == "failed" and record["objects"][0]["highpoly"] == ["Chair_high"]
    assert not list(tmp_path.glob("*.exr"))


@pytest.mark.parametrize("args, message", [
    (["--extrusion", "0.1"], "--extrusion is a setting of --selected-to-active (or --match-suffix), which is off"),
    (["--active", "Chair_low"], "--active is a setting of --selected-to-active"),
    (["--cage", "Chair_cage"], "--cage is a setting of --selected-to-active"),
    (["--selected-to-active", "--extrusion", "-1"], "--extrusion must be a finite distance >= 0, not -1.0"),
    (["--selected-to-active", "--max-ray-distance", "nan"],
     "--max-ray-distance must be a distance >= 0 (0 or inf = unlimited), not nan"),
    (["--match-suffix", "_x", "_x"], "--match-suffix needs two different, non-empty suffixes, not '_x' and '_x'"),
    (["--match-suffix", "_high", "_low", "--active", "Chair_low"],
     "--active names one low-poly; with --match-suffix, --objects names the low-poly objects"),
    (["--match-suffix", "_high", "_low", "--cage", "Chair_cage"], "--cage NAME names one cage for one low-poly"),
    (["--selected-to-active", "--active", "Chair_low", "--objects", "Chair_low"],
     "--active 'Chair_low' is also among --objects (the high-poly objects)"),
    (["--selected-to-active", "--active", "Nope"], "no object 'Nope' in the view layer; its objects: Box, "),
    (["--selected-to-active", "--objects", "Nope"], "no object 'Nope' in the view layer"),
    (["--selected-to-active", "--cage", "Nope"], "no cage object 'Nope' in the view layer"),
    (["--selected-to-active", "--active", "Chair_high", "--objects", "Table_high"],
     "Chair_high has no UV map (unwrap it first: Edit Mode, U)"),
    (["--selected-to-active", "--active", "Lamp_low", "--objects", "Box", "Chair_low"], None),
    (["--selected-to-active", "--cage", "Cage4"],
     "the cage object Cage4 does not have the topology of Chair_low after modifiers (Cage4: 9 vertices, 4 faces, "
     "16 corners; Chair_low: 4 vertices, 1 faces, 4 corners): the cage must be a copy of Chair_low with only its "
     "vertices moved"),
    (["--match-suffix", "_high", "_low", "--objects", "Lamp_low"], "Lamp_low has no high-poly 'Lamp_high' in the view layer"),
    (["--match-suffix", "_high", "_low", "--objects", "Box"], "Box does not end with the low-poly suffix '_low'"),
    (["--match-suffix", "_top", "_bottom"], "no pair of objects named <base>_top and <base>_bottom in the view layer"),
    (["--selected-to-active", "--udim"],
     "--selected-to-active bakes AO into one image texture of the low-poly: turn off --udim"),
    (["--selected-to-active", "--bent-normals"], "--selected-to-active bakes AO into one image texture of the "
                                                 "low-poly: turn off --bent-normals"),
    (["--match-suffix", "_high", "_low", "--target", "vertex-colors", "--format", "ply"],
     "--selected-to-active bakes AO into one image texture of the low-poly: set --target to image-textures"),
])
def test_bad_options_exit_2_before_baking(blends, tmp_path, args, message):
    proc = run_script(blends, "--output", tmp_path / "out", "--summary-json", tmp_path / "s.json", *FAST, *args)
    if message is None:  # a valid combination among them: the check is not a blanket refusal
        assert proc.returncode in (0, 1), proc.stderr
        return
    assert proc.returncode == 2, proc.stderr
    assert f"bake_ao: error: {message}" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "out").exists()
    record = json.loads((tmp_path / "s.json").read_text())
    assert record["exit_code"] == 2 and message in record["error"]


def batch(manifest, out):
    return subprocess.run([sys.executable, BATCH, str(manifest), "--output", str(out), "--runner", "local",
                           "--workers", "1", "--blender", "bpy"], capture_output=True, text=True, timeout=600)


def test_the_batch_passes_the_options_on_from_a_manifest(blends, tmp_path):
    from mc_ao_batch.manifest import ManifestError, plan

    manifest = tmp_path / "manifest.toml"
    defaults = "[defaults]\nresolution = 16\nsamples = 16\nformat = [\"exr\"]\nmargin = 0\n\n"
    manifest.write_text(defaults + f"[[bake]]\nblend = \"{blends.as_posix()}\"\nmatch_suffix = [\"_high\", \"_low\"]\n"
                                   "extrusion = 0.2\n")
    proc = batch(manifest, tmp_path / "out")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    data = json.loads((tmp_path / "out" / "mc_ao_batch.json").read_text())
    task = data["tasks"][0]
    assert task["status"] == "ok"
    assert [(o["object"], o["highpoly"]) for o in task["objects"]] == [
        ("Chair_low", ["Chair_high"]), ("Table_low", ["Table_high"])]
    assert sorted(p.rsplit("/", 1)[-1] for p in task["files"]) == ["Chair_low_AO.exr", "Table_low_AO.exr"]
    # The one-pair form, as the task's command line.
    manifest.write_text(defaults + f"[[bake]]\nblend = \"{blends.as_posix()}\"\nselected_to_active = true\n"
                                   "active = \"Chair_low\"\nobjects = [\"Chair_high\"]\ncage = \"Chair_cage\"\n"
                                   "max_ray_distance = 0.5\n")
    args = plan(manifest, tmp_path / "out2")[0].args
    for words in (["--selected-to-active"], ["--active", "Chair_low"], ["--objects", "Chair_high"],
                  ["--cage", "Chair_cage"], ["--max-ray-distance", "0.5"]):
        i = args.index(words[0])
        assert args[i:i + len(words)] == words, args
    # Bad values are refused by bake_ao.py's own checks, before anything runs.
    for entry, message in (("match_suffix = \"_high\"", "match_suffix takes a list of 2 values, not '_high'"),
                           ("extrusion = 0.5", "--extrusion is a setting of --selected-to-active"),
                           ("match_suffix = [\"_a\", \"_a\"]", "--match-suffix needs two different")):
        manifest.write_text(f"[[bake]]\nblend = \"{blends.as_posix()}\"\n{entry}\n")
        with pytest.raises(ManifestError, match=message):
            plan(manifest, tmp_path / "bad")


def test_a_batch_rerun_skips_the_pairs_it_baked(blends, tmp_path):
    """Bake, rerun: nothing is baked again (the summary's match_suffix is the run's choice of objects,
    which no file's metadata carries)."""
    manifest = tmp_path / "manifest.toml"
    manifest.write_text("[defaults]\nresolution = 16\nsamples = 8\nmargin = 0\n\n"
                        f"[[bake]]\nblend = \"{blends.as_posix()}\"\nmatch_suffix = [\"_high\", \"_low\"]\n")
    out = tmp_path / "out"
    first = batch(manifest, out)
    assert first.returncode == 0 and "1 baked, 0 already done" in first.stdout, first.stdout + first.stderr
    files = {p: p.read_bytes() for p in out.rglob("*_AO.png")}
    again = batch(manifest, out)
    assert again.returncode == 0 and "0 baked, 1 already done" in again.stdout, again.stdout + again.stderr
    assert {p: p.read_bytes() for p in out.rglob("*_AO.png")} == files
