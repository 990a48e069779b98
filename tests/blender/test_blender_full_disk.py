"""Writes that fail change nothing, through scripts/bake_ao.py and the operator's Save to File.

The output folder lies on a small tmpfs the test mounts (CI runs as root; elsewhere these skip with
the reason) and fills: every format, the AO file alone and with its standard-error file, through
OpenImageIO and through Blender's own writer. Also: a read-only file is not replaced, a replaced
file keeps its permission bits, and files from Blender's writer get the umask's permissions.
"""

import json
import os
import stat
import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene, old_file, select_only
from tests.fullfs import PAGE, fill, listing, small_filesystem

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
# One uniform sample per texel: every texel is noise, so each file is far larger (40 to 100 KiB at
# 256 x 256) than the room the tests leave on the disk.
NOISY = ["--resolution", "256", "--samples", "1", "--source", "independent", "--distribution", "uniform",
         "--margin", "0", "--threads", "1", "--quiet"]
FILES = ["Ground_AO.png", "Ground_AO.exr", "Ground_AO.tif", "Ground_AO_stderr.exr"]


@pytest.fixture(scope="module")
def blend(bpy, tmp_path_factory):
    clean_scene(bpy)
    add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    path = tmp_path_factory.mktemp("scene") / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    clean_scene(bpy)
    return path


@pytest.fixture
def disk(tmp_path):
    with small_filesystem(tmp_path / "disk", size=1 << 20) as path:
        yield path


def previous_files(folder, names=FILES):
    for name in names:
        (folder / name).write_bytes(old_file(name, f"the previous {name}"))
        (folder / name).chmod(0o640)


def assert_unchanged(folder, names=FILES):
    for name in names:
        assert (folder / name).read_bytes() == old_file(name, f"the previous {name}"), name
        assert stat.S_IMODE((folder / name).stat().st_mode) == 0o640


def run_script(*args):
    return subprocess.run([sys.executable, SCRIPT, *map(str, args)], capture_output=True, text=True, timeout=300)


# -- the script ------------------------------------------------------------------------------------

@pytest.mark.parametrize("leave", [0, 2 * PAGE], ids=["full", "nearly-full"])
def test_the_script_on_a_full_disk_exits_1_and_keeps_every_previous_file(blend, disk, tmp_path, leave):
    previous_files(disk)
    fill(disk, leave)
    summary = tmp_path / "summary.json"
    proc = run_script(blend, "--objects", "Ground", "--output", disk, "--format", "png", "exr", "tif",
                      "--stderr", "--summary-json", summary, *NOISY)
    assert proc.returncode == 1, proc.stderr
    # The first file that cannot be written ends the object's save: none of its files is written.
    errors = ["bake_ao: Ground: none of its files was written (any file already there is unchanged): "
              f"could not write '{disk / 'Ground_AO.png'}': no space left on the device"]
    assert [line for line in proc.stderr.splitlines() if line.startswith("bake_ao: Ground:")] == errors
    assert "bake_ao: baked 0 of 1 objects, 1 failed" in proc.stdout
    assert "Traceback" not in proc.stderr
    assert_unchanged(disk)
    assert listing(disk) == sorted(FILES)  # no temporary file left
    record = json.loads(summary.read_text())
    assert record["exit_code"] == 1 and record["error"] == "1 of 1 objects failed"
    (obj,) = record["objects"]
    assert obj["status"] == "failed" and obj["files"] == [] and obj["rays"] == 256 * 256
    assert obj["error"] == "; ".join(e.removeprefix("bake_ao: Ground: ") for e in errors)


def test_the_script_does_not_replace_a_read_only_file(blend, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "Ground_AO.png").write_bytes(old_file("x.png", "keep me"))
    (out / "Ground_AO.png").chmod(0o444)
    proc = run_script(blend, "--objects", "Ground", "--output", out, "--format", "png", "exr", *NOISY)
    assert proc.returncode == 1
    assert (
        "bake_ao: Ground: none of its files was written (any file already there is unchanged): "
        f"'{out / 'Ground_AO.png'}' is read-only (its write permission is off): it was left "
        "as it is; make it writable, or choose another folder or name, to replace it\n"
    ) in proc.stderr
    assert (out / "Ground_AO.png").read_bytes() == old_file("x.png", "keep me")
    assert listing(out) == ["Ground_AO.png"]  # nor its other format: an object's files are all or none


def test_the_script_keeps_permission_bits(blend, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    previous_files(out, ["Ground_AO.png"])
    proc = run_script(blend, "--objects", "Ground", "--output", out, *NOISY)
    assert proc.returncode == 0, proc.stderr
    assert (out / "Ground_AO.png").read_bytes()[:4] == b"\x89PNG"
    assert stat.S_IMODE((out / "Ground_AO.png").stat().st_mode) == 0o640


# -- the operator ----------------------------------------------------------------------------------

def noisy_scene(bpy, scene, folder, file_format):
    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    settings = scene.mc_ao
    settings.resolution, settings.samples, settings.margin = 256, 1, 0
    settings.source, settings.distribution = "INDEPENDENT", "UNIFORM"
    settings.save_to_file = True
    settings.output_dir = str(folder)
    settings.file_format = file_format
    select_only(bpy, ground)
    return ground


def bake_and_report(bpy, capfd):
    capfd.readouterr()
    try:
        result = bpy.ops.object.mc_ao_bake()
    except RuntimeError as exc:  # an ERROR report makes a script's operator call raise
        result, error = {"CANCELLED"}, str(exc)
    else:
        error = ""
    return result, error, capfd.readouterr().out


@pytest.mark.parametrize("writer", ["OpenImageIO", "Blender"])
@pytest.mark.parametrize("file_format, name", [("PNG", "Ground_AO.png"), ("OPEN_EXR", "Ground_AO.exr"),
                                               ("TIFF", "Ground_AO.tif")])
def test_the_operator_on_a_full_disk_reports_the_error_not_saved(bpy, scene, disk, capfd, monkeypatch,
                                                                 file_format, name, writer):
    from mc_ao import filewriter

    if writer == "Blender":
        monkeypatch.setattr(filewriter, "oiio_available", lambda: False)
    noisy_scene(bpy, scene, disk, file_format)
    previous_files(disk, [name])
    fill(disk, 2 * PAGE)
    result, error, out = bake_and_report(bpy, capfd)
    assert error == (
        "Error: Ground: the bake is in image 'Ground_AO', but none of its files was written (any file already "
        f"there is unchanged): could not write '{disk / name}': no space left on the device\n"
    )
    # No line says the file was saved. Blender 4.2's own writer reports its failure too ("Image
    # '.mc_ao_save' could not be saved to '<the temporary file>'"), a negative that stays allowed.
    said = out.replace("could not be saved", "").replace("not saved", "")
    assert "saved" not in said, out
    assert_unchanged(disk, [name])
    assert listing(disk) == [name]
    assert "Ground_AO" in bpy.data.images and ".mc_ao_save" not in bpy.data.images


@pytest.mark.parametrize("writer", ["OpenImageIO", "Blender"])
def test_the_operator_does_not_replace_a_read_only_file(bpy, scene, tmp_path, capfd, monkeypatch, writer):
    from mc_ao import filewriter

    if writer == "Blender":
        monkeypatch.setattr(filewriter, "oiio_available", lambda: False)
    noisy_scene(bpy, scene, tmp_path, "PNG")
    path = tmp_path / "Ground_AO.png"
    path.write_bytes(old_file("x.png", "keep me"))
    path.chmod(0o444)
    result, error, _ = bake_and_report(bpy, capfd)
    assert error == (
        "Error: Ground: the bake is in image 'Ground_AO', but none of its files was written (any file already "
        f"there is unchanged): '{path}' is read-only (its write permission is off): it was left as it is; "
        "make it writable, or choose another folder or name, to replace it\n"
    )
    assert path.read_bytes() == old_file("x.png", "keep me") and listing(tmp_path) == ["Ground_AO.png"]


@pytest.mark.parametrize("writer", ["OpenImageIO", "Blender"])
def test_saved_files_get_the_umask_or_keep_their_permissions(bpy, scene, tmp_path, capfd, monkeypatch, writer):
    """New files: 0o666 & ~umask (Blender's writer through a mkstemp file made them 0o600); replaced
    files: their own bits."""
    from mc_ao import filewriter

    if writer == "Blender":
        monkeypatch.setattr(filewriter, "oiio_available", lambda: False)
    noisy_scene(bpy, scene, tmp_path, "PNG")
    umask = os.umask(0o022)
    try:
        result, error, out = bake_and_report(bpy, capfd)
        assert result == {"FINISHED"} and not error
        path = tmp_path / "Ground_AO.png"
        assert f"Ground: saved {path} ({writer})" in out
        assert stat.S_IMODE(path.stat().st_mode) == 0o644
        path.chmod(0o640)
        result, error, _ = bake_and_report(bpy, capfd)
        assert result == {"FINISHED"} and not error
        assert stat.S_IMODE(path.stat().st_mode) == 0o640
    finally:
        os.umask(umask)
    assert listing(tmp_path) == ["Ground_AO.png"]


def test_blenders_writer_reads_every_format_back(bpy, scene, tmp_path):
    """The fallback writer's check passes for what it writes (a check that refused good files would
    make every save fail), and its files hold the pixels."""
    from core.files import imageio
    from mc_ao import images

    pixels = np.random.default_rng(3).random((16, 24, 4), dtype=np.float32)
    pixels[..., 3] = 1.0
    for file_format, ext, bits, tolerance in [("PNG", ".png", 8, 0.5 / 255), ("PNG", ".png", 16, 0.5 / 65535),
                                              ("TIFF", ".tif", 8, 0.5 / 255), ("OPEN_EXR", ".exr", "half", 1e-3),
                                              ("OPEN_EXR", ".exr", "float", 0.0)]:
        path = tmp_path / f"p{bits}{ext}"
        images.save_pixels_with_blender(pixels, str(path), file_format, bits)
        got, _ = imageio.read_image(path)
        assert got.shape == pixels.shape
        assert np.abs(got[..., :3] - pixels[..., :3]).max() <= tolerance + 1e-6, (file_format, bits)
    assert len(listing(tmp_path)) == 5 and ".mc_ao_save" not in bpy.data.images
