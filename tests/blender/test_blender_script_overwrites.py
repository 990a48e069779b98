"""scripts/bake_ao.py never writes over what the user owns: the input .blend file, the run's own
images, or a file of another kind, through --summary-json or --save; a .blend saved onto a full disk
is read back to its end marker before it replaces anything."""

import shutil
import subprocess
import sys

import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene
from tests.fullfs import PAGE, fill, listing, small_filesystem

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
FAST = ("--samples", "4", "--resolution", "16", "--threads", "1", "--quiet")


@pytest.fixture(scope="module")
def blend_file(bpy, tmp_path_factory):
    clean_scene(bpy)
    add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    path = tmp_path_factory.mktemp("scene") / "scene.blend"
    # compressed: Blender's zstd writer reports a save cut short by a full disk as done
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True, compress=True)
    clean_scene(bpy)
    return path


@pytest.fixture
def scene_copy(blend_file, tmp_path):
    copy = tmp_path / "scene.blend"
    shutil.copy(blend_file, copy)
    return copy


def run_script(*args):
    return subprocess.run([sys.executable, SCRIPT, *map(str, args)], capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("extra", [[], ["--bogus-option"]], ids=["good-arguments", "refused-arguments"])
def test_a_summary_path_that_is_the_input_blend_is_refused(scene_copy, tmp_path, extra):
    before = scene_copy.read_bytes()
    proc = run_script(scene_copy, "--summary-json", scene_copy, "--objects", "Ground", "--output",
                      tmp_path / "out", *FAST, *extra)
    assert proc.returncode == 2, proc.stderr
    assert "the summary" in proc.stderr and "Traceback" not in proc.stderr
    assert scene_copy.read_bytes() == before
    assert not (tmp_path / "out").exists()


def test_a_summary_path_that_is_an_existing_image_is_refused(scene_copy, tmp_path):
    out = tmp_path / "out"
    assert run_script(scene_copy, "--objects", "Ground", "--output", out, *FAST).returncode == 0
    image = out / "Ground_AO.png"
    before = image.read_bytes()
    proc = run_script(scene_copy, "--objects", "Ground", "--output", out, "--summary-json", image, *FAST)
    assert proc.returncode == 2, proc.stderr
    assert "a PNG image already there" in proc.stderr
    assert image.read_bytes() == before


def test_a_summary_path_that_is_one_of_the_runs_images_is_refused_before_baking(scene_copy, tmp_path):
    out = tmp_path / "out"
    proc = run_script(scene_copy, "--objects", "Ground", "--output", out, "--summary-json",
                      out / "Ground_AO.png", *FAST)
    assert proc.returncode == 2, proc.stderr
    assert "it is also" in proc.stderr and "Ground_AO.png" in proc.stderr
    assert not out.exists() or listing(out) == []


def test_a_summary_path_that_is_any_other_file_is_refused(scene_copy, tmp_path):
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    proc = run_script(scene_copy, "--objects", "Ground", "--output", tmp_path / "out", "--summary-json", notes,
                      *FAST)
    assert proc.returncode == 2 and notes.read_text() == "my notes\n", proc.stderr


def test_a_previous_summary_is_replaced(scene_copy, tmp_path):
    summary = tmp_path / "summary.json"
    for _ in range(2):
        proc = run_script(scene_copy, "--objects", "Ground", "--output", tmp_path / "out", "--summary-json",
                          summary, *FAST)
        assert proc.returncode == 0, proc.stderr


def test_save_onto_an_existing_file_of_another_kind_is_refused(scene_copy, tmp_path):
    image = tmp_path / "picture.blend"
    image.write_bytes(b"\x89PNG\r\n\x1a\nnot really a blend")
    proc = run_script(scene_copy, "--objects", "Ground", "--target", "vertex-colors", "--output", tmp_path / "out",
                      "--save", image, *FAST)
    assert proc.returncode == 2 and "a PNG image already there" in proc.stderr, proc.stderr
    assert image.read_bytes() == b"\x89PNG\r\n\x1a\nnot really a blend"


def test_save_onto_a_full_disk_exits_1_and_keeps_the_previous_file(scene_copy, tmp_path):
    previous = b"BLENDER-v402 the previous save, kept byte for byte"
    with small_filesystem(tmp_path / "disk", size=2 << 20) as disk:
        saved = disk / "baked.blend"
        saved.write_bytes(previous)
        fill(disk, 16 * PAGE)  # far less than the saved file needs
        proc = run_script(scene_copy, "--objects", "Ground", "--target", "vertex-colors", "--output",
                          tmp_path / "out", "--save", saved, *FAST)
        assert proc.returncode == 1, proc.stdout + proc.stderr
        assert f"{saved} was not saved" in proc.stderr and "Traceback" not in proc.stderr
        assert saved.read_bytes() == previous
        assert listing(disk) == ["baked.blend"]  # no temporary file left


@pytest.mark.parametrize("name, extra", [("Ground_AO.png", []), ("Ground_AO_stderr.exr", ["--stderr"]),
                                         ("Ground_AO.ply", ["--target", "vertex-colors"])])
def test_an_output_path_holding_a_file_of_another_kind_is_refused_before_baking(scene_copy, tmp_path, name, extra):
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_bytes(scene_copy.read_bytes())  # the user's .blend file, saved under that name
    proc = run_script(scene_copy, "--objects", "Ground", "--output", out, *extra, *FAST)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert f"'{out / name}' is a .blend file, not" in proc.stderr and "nothing was baked" in proc.stderr
    assert "baking" not in proc.stdout
    assert (out / name).read_bytes() == scene_copy.read_bytes() and listing(out) == [name]


def test_the_operator_refuses_to_save_over_a_file_of_another_kind(bpy, addon, tmp_path):
    from blender_helpers import select_only

    clean_scene(bpy)
    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, ground)
    settings = bpy.context.scene.mc_ao
    settings.resolution, settings.samples, settings.threads = 16, 4, 1
    settings.save_to_file = True
    settings.output_dir = str(tmp_path)
    notes = tmp_path / "Ground_AO.png"
    notes.write_text("my notes, not an image\n")
    with pytest.raises(RuntimeError, match="is a file, not a PNG image: it was left as it is.*nothing was baked"):
        bpy.ops.object.mc_ao_bake()
    assert notes.read_text() == "my notes, not an image\n" and "Ground_AO" not in bpy.data.images
    clean_scene(bpy)
