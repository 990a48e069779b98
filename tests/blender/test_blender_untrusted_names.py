"""Object names come from whoever made the .blend file: they never choose where a file goes.

A .blend file is baked by scripts/bake_ao.py and by the operator's Save to File with objects named
like paths (relative, absolute, Windows ones), a Windows device name, names that differ only in
case or only by a separator, a 300-character name (Blender keeps 255 bytes of it) and non-ASCII
names. Every file must land inside the output folder, one per object and format, and nothing may
appear anywhere else.
"""

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_plane, clean_scene, image_ao, select_only

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
FAST = ["--samples", "2", "--resolution", "8", "--margin", "0", "--threads", "1", "--occluders", "self"]


def hostile_names(base):
    return [
        "../escaped", "../../x", str(base / "abs" / "x"), "a/b", "a_b", "..\\x", "C:x", "CON", "Cube", "cube",
        "n" * 300, "Würfel", "立方体", "ёжик 🙂", " .. ",
    ]


def make_objects(bpy, names):
    clean_scene(bpy)
    objects = []
    for k, name in enumerate(names):
        obj = add_plane(bpy, "P", size=1, location=(2 * k, 0, 0))
        obj.name = name
        obj.data.name = f"mesh{k}"
        objects.append(obj)
    return objects


def every_file(folder):
    return sorted(os.path.join(d, f) for d, _, files in os.walk(folder) for f in files)


@pytest.fixture(scope="module")
def hostile_blend(bpy, tmp_path_factory):
    base = tmp_path_factory.mktemp("names")
    objects = make_objects(bpy, hostile_names(base))
    kept = [o.name for o in objects]
    from mc_ao.baking import id_name_max_bytes

    assert kept[10] == "n" * id_name_max_bytes()  # what Blender keeps of 300 characters (5.0: 255, 4.2: 63)
    for obj in objects:
        obj.select_set(False)
    path = base / "hostile.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    clean_scene(bpy)
    return base, path, kept


def test_the_script_writes_every_file_inside_the_output_folder(hostile_blend, tmp_path):
    from core.files import imageio

    base, blend, names = hostile_blend
    work = tmp_path / "deep" / "er"
    out = work / "out"
    summary = work / "summary.json"
    before = every_file(base)
    proc = subprocess.run(
        [sys.executable, SCRIPT, str(blend), "--output", str(out), "--format", "png", "exr", "--stderr",
         "--summary-json", str(summary), *FAST],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    files = every_file(out)
    assert len(files) == 3 * len(names) == len({f.casefold() for f in files})  # distinct, also in case
    assert all(os.path.dirname(os.path.realpath(f)) == str(out) for f in files)
    # Nothing anywhere else: not beside the output folder, not above it, not at the absolute name.
    assert every_file(tmp_path) == sorted(files + [str(summary)])
    assert every_file(base) == before and not (base / "abs").exists()
    assert all(len(os.path.basename(f).encode()) <= 255 for f in files)
    record = json.loads(summary.read_text())
    assert sorted(o["object"] for o in record["objects"]) == sorted(names)
    assert sorted(f for o in record["objects"] for f in o["files"]) == files
    for obj in record["objects"]:  # each object's files carry its name, whatever the file is called
        for path in obj["files"]:
            assert imageio.read_image(path)[1]["object"] == obj["object"]
    stems = {os.path.basename(o["files"][0]).removesuffix(".png"): o["object"] for o in record["objects"]}
    assert stems["Würfel_AO"] == "Würfel" and stems["立方体_AO"] == "立方体"  # safe names are kept
    by_object = {n: s for s, n in stems.items()}
    for name in ("Cube", "cube"):  # one file on a case-insensitive disk: both get their name's hash
        assert by_object[name].startswith(f"{name}_AO-") and len(by_object[name]) == len("Cube_AO-12345678")
    assert by_object["a_b"] == "a_b_AO" and by_object["a/b"].startswith("a_b_AO-")
    assert by_object["CON"] == "CON_AO"  # only the bare device name is reserved


def test_the_operator_saves_every_file_inside_the_output_folder(bpy, scene, tmp_path):
    base = tmp_path / "blend"
    base.mkdir()
    objects = make_objects(bpy, hostile_names(base))
    out = tmp_path / "deep" / "out"
    settings = scene.mc_ao
    settings.save_to_file = True
    settings.output_dir = str(out)
    settings.resolution, settings.samples, settings.margin, settings.occluders = 8, 2, 0, "SELF"
    select_only(bpy, *objects)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    files = every_file(out)
    assert len(files) == len(objects) == len({f.casefold() for f in files})
    assert every_file(tmp_path) == files and not (base / "abs").exists()
    assert all(os.path.dirname(os.path.realpath(f)) == str(out) for f in files)


@pytest.mark.parametrize("names", [["n" * 300], ["é" * 200], ["x" * 253], ["n" * 252 + "1", "n" * 252 + "2"]],
                         ids=["300-ascii", "200-two-byte", "253-ascii", "differ-at-the-end"])
def test_an_object_name_too_long_for_its_image_name_bakes_into_its_own_image(bpy, scene, names):
    """Blender cuts a name at its limit (255 bytes in 5.0, 63 before): "<object>_AO" keeps its "_AO"
    and a hash of the object's name, so each object bakes into one image of its own, found again."""
    from mc_ao.baking import id_name_max_bytes

    limit = id_name_max_bytes()
    objects = make_objects(bpy, names)
    scene.mc_ao.resolution = 8
    select_only(bpy, *objects)
    for _ in range(2):  # the second bake finds the images of the first and reuses them
        assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
        assert len(bpy.data.images) == len(objects)
    # "<object>_AO" where it fits (Blender 4.2 cuts the second of two clashing names shorter), else the
    # start of the object's name and a hash of all of it: "<start>-<hash>_AO".
    plain = {f"{o.name}_AO" for o in objects}
    hashed = [re.fullmatch(r"(.+)-[0-9a-f]{8}_AO", i.name) for i in bpy.data.images if i.name not in plain]
    assert all(hashed) and all(len(i.name.encode()) <= limit for i in bpy.data.images)
    assert hashed, "at least one object's name is too long for <object>_AO"
    assert all(any(o.name.startswith(m.group(1)) for o in objects) for m in hashed)
    for image in bpy.data.images:
        ao, _ = image_ao(image)
        assert np.all(ao > 0.99)  # an open plane: baked white, not left blank (0)


MISSING = "Missing\x1b[31m"
TERMINAL_TRICKS = "Evil\x1b[2J\x1b]0;title\x07\rbake_ao: baked 99 of 99 objects\n\u202eelif"


def test_names_reach_the_terminal_and_the_batch_log_escaped(bpy, tmp_path):
    """A name with escape sequences, a carriage return, a newline and a bidirectional override: the
    script's and the batch's output (and the task's log) hold it escaped, never raw, and no fake line."""
    objects = make_objects(bpy, [TERMINAL_TRICKS, "Plain"])
    assert objects[0].name == TERMINAL_TRICKS  # Blender keeps every character
    for obj in objects:
        obj.select_set(False)  # nothing selected: the script bakes every mesh
    blend = tmp_path / "tricks.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    clean_scene(bpy)
    proc = subprocess.run([sys.executable, SCRIPT, str(blend), "--output", str(tmp_path / "out"), *FAST],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    manifest = tmp_path / "m.toml"
    manifest.write_text(f"[[bake]]\nblend = 'tricks.blend'\nsamples = 2\nresolution = 8\nmargin = 0\n"
                        f"objects = ['Plain', {json.dumps(TERMINAL_TRICKS)}, {json.dumps(MISSING)}]\n")
    batch = subprocess.run([sys.executable, str(ROOT / "scripts" / "bake_batch.py"), str(manifest), "--output",
                            str(tmp_path / "batch"), "--blender", "bpy"], capture_output=True, text=True, timeout=300)
    assert batch.returncode == 1  # the missing object fails the task
    logs = "".join(p.read_text() for p in (tmp_path / "batch").rglob("*.log"))
    for text in (proc.stdout, proc.stderr, batch.stdout, batch.stderr, logs):
        assert not re.search("[\x00-\x08\x0b-\x1f\x7f\u202e]", text), text
        assert not any(line.startswith("bake_ao: baked 99") for line in text.splitlines()), text
    assert "Evil\\x1b[2J" in proc.stdout and "\\u202eelif" in proc.stdout
    assert "Missing\\x1b[31m" in batch.stdout


def test_the_operators_reports_hold_names_escaped(bpy, scene, capfd):
    """Blender prints an operator's reports to the terminal in the background: escaped there too."""
    objects = make_objects(bpy, [TERMINAL_TRICKS])
    select_only(bpy, objects[0])
    scene.mc_ao.resolution, scene.mc_ao.samples = 8, 2
    capfd.readouterr()
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    out, err = capfd.readouterr()
    assert "Evil\\x1b[2J" in out + err
    assert not re.search("[\x00-\x08\x0b-\x1f\x7f\u202e]", out + err), out + err
    assert not any(line.startswith("bake_ao: baked 99") for line in (out + err).splitlines())
