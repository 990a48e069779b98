"""Writes that fail change nothing, on a real full filesystem; file names, permissions, read-only files.

Every image file goes through core.files.atomicfile: a temporary file, checked (read back), fsynced, then
renamed over the target. OpenImageIO's PNG and 8-bit TIFF writers report a file cut short by a
full disk as written; these tests fill a real tmpfs to show that such a write now fails, names the
file and the reason, and leaves the previous file byte for byte.
"""

import errno
import os
import stat

import numpy as np
import pytest

pytest.importorskip("OpenImageIO")

from core.files import imageio  # noqa: E402
from core.base.errors import ImageWriteError  # noqa: E402
from tests.fullfs import PAGE, fill, listing, small_filesystem  # noqa: E402

CASES = [(".png", 8), (".png", 16), (".tif", 8), (".tif", 16), (".tif", "float"), (".exr", "half"), (".exr", "float")]


def noise(h=256, w=256, seed=0):
    """Pixels that do not compress: every file of them is far larger than the room the tests leave."""
    return np.random.default_rng(seed).random((h, w), dtype=np.float32)


@pytest.fixture
def disk(tmp_path):
    with small_filesystem(tmp_path / "disk", size=2 << 20) as path:
        yield path


@pytest.mark.parametrize("leave", [0, 4 * PAGE], ids=["full", "nearly-full"])
@pytest.mark.parametrize("ext,bits", CASES)
def test_a_write_onto_a_full_disk_fails_and_keeps_the_previous_file(disk, ext, bits, leave):
    target = disk / f"Ground_AO{ext}"
    target.write_bytes(b"the previous bake")
    free = fill(disk, leave)
    assert free <= leave
    with pytest.raises(ImageWriteError) as info:
        imageio.write_image(target, noise(), bits=bits)
    assert str(info.value) == f"could not write {str(target)!r}: no space left on the device"
    assert info.value.errno == errno.ENOSPC
    assert target.read_bytes() == b"the previous bake"
    assert listing(disk) == [target.name]  # no temporary file left


class Result:
    def __init__(self, seed=1):
        self.ao = noise(seed=seed)
        self.stderr = noise(seed=seed + 1) * 0.01
        self.metadata = {"samples": 4}


@pytest.mark.parametrize("room_for_ao", [False, True])
@pytest.mark.parametrize("ext,bits", CASES)
def test_ao_and_stderr_onto_a_full_disk_change_neither(disk, tmp_path, ext, bits, room_for_ao):
    """The AO file and its standard-error file are replaced together or not at all."""
    result = Result()
    ao, se = disk / f"Ground_AO{ext}", disk / "Ground_AO_stderr.exr"
    ao.write_bytes(b"previous ao")
    se.write_bytes(b"previous stderr")
    leave = 0
    if room_for_ao:  # the AO file fits, its standard error does not
        probe = tmp_path / f"probe{ext}"
        imageio.write_image(probe, result.ao, bits=bits)
        leave = probe.stat().st_size + 2 * PAGE
    fill(disk, leave)
    with pytest.raises(ImageWriteError) as info:
        imageio.write_ao(ao, result, bits=bits, stderr_path=se, stderr_bits="float")
    assert "no space left on the device" in str(info.value) and info.value.errno == errno.ENOSPC
    assert ao.read_bytes() == b"previous ao" and se.read_bytes() == b"previous stderr"
    assert listing(disk) == sorted([ao.name, se.name])


def test_a_truncated_png_is_caught_by_reading_it_back(tmp_path, monkeypatch):
    """Without the read-back, OpenImageIO's PNG writer reports a cut-short file as written."""
    real = imageio._write_temp

    def cut_short(oiio, temp, *args):
        real(oiio, temp, *args)
        with open(temp, "r+b") as f:
            f.truncate(os.path.getsize(temp) // 2)

    target = tmp_path / "ao.png"
    target.write_bytes(b"old")
    monkeypatch.setattr(imageio, "_write_temp", cut_short)
    with pytest.raises(ImageWriteError, match="does not read back as written"):
        imageio.write_image(target, noise(32, 32))
    assert target.read_bytes() == b"old" and listing(tmp_path) == ["ao.png"]


def test_pixels_that_differ_are_caught(tmp_path, monkeypatch):
    """A file that decodes, but not to the pixels written, does not replace anything either."""
    real = imageio._write_temp

    def other_pixels(oiio, temp, target, ext, data, *args):
        real(oiio, temp, target, ext, 1.0 - data, *args)

    monkeypatch.setattr(imageio, "_write_temp", other_pixels)
    with pytest.raises(ImageWriteError, match="its pixels differ from those written"):
        imageio.write_image(tmp_path / "ao.exr", noise(8, 8), bits="float")
    assert listing(tmp_path) == []


@pytest.mark.parametrize("length", [243, 250, 255])
@pytest.mark.parametrize("ext", [".png", ".exr"])
def test_the_longest_file_names_can_be_written(tmp_path, length, ext):
    """The temporary file's name has a fixed length: a legal target name stays legal."""
    name = "a" * (length - len(ext)) + ext
    imageio.write_ao(tmp_path / name, Result(), stderr_path=tmp_path / ("b" * (length - 4) + ".exr"))
    assert listing(tmp_path) == sorted([name, "b" * (length - 4) + ".exr"])
    y, _ = imageio.read_image(tmp_path / name)
    assert y.shape == (256, 256)


def test_a_read_only_file_is_not_replaced(tmp_path):
    target = tmp_path / "Ground_AO.png"
    target.write_bytes(b"keep me")
    target.chmod(0o444)
    with pytest.raises(ImageWriteError) as info:
        imageio.write_image(target, noise(4, 4))
    assert str(info.value) == (
        f"{str(target)!r} is read-only (its write permission is off): it was left as it is; make it "
        "writable, or choose another folder or name, to replace it"
    )
    assert info.value.errno == errno.EACCES
    assert target.read_bytes() == b"keep me" and stat.S_IMODE(target.stat().st_mode) == 0o444
    assert listing(tmp_path) == ["Ground_AO.png"]


def test_a_read_only_stderr_file_keeps_the_ao_file_too(tmp_path):
    ao, se = tmp_path / "ao.png", tmp_path / "se.exr"
    ao.write_bytes(b"old ao")
    se.write_bytes(b"old se")
    se.chmod(0o400)
    with pytest.raises(ImageWriteError, match="read-only"):
        imageio.write_ao(ao, Result(), stderr_path=se)
    assert ao.read_bytes() == b"old ao" and se.read_bytes() == b"old se"
    assert listing(tmp_path) == ["ao.png", "se.exr"]


@pytest.mark.parametrize("mode", [0o640, 0o600, 0o664, 0o604])
def test_a_replaced_file_keeps_its_permission_bits(tmp_path, mode):
    target = tmp_path / "ao.tif"
    target.write_bytes(b"old")
    target.chmod(mode)
    imageio.write_image(target, noise(4, 4))
    assert stat.S_IMODE(target.stat().st_mode) == mode
    assert target.read_bytes()[:2] in (b"II", b"MM")


def test_a_new_file_gets_the_umask_permissions(tmp_path):
    umask = os.umask(0o027)
    try:
        imageio.write_image(tmp_path / "ao.png", noise(4, 4))
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "ao.png").stat().st_mode) == 0o640


def test_a_failure_before_the_rename_leaves_no_temporary_file_for_any_writer(tmp_path):
    """core.files.atomicfile.write_file, the path of the script's JSON summary and Blender's writer."""
    from core.files import atomicfile
    from core.base.errors import FileWriteError

    target = tmp_path / "summary.json"
    target.write_text("old")

    def half_then_fail(temp):
        with open(temp, "w") as f:
            f.write("{")
        raise OSError(errno.EIO, "Input/output error")

    with pytest.raises(FileWriteError) as info:
        atomicfile.write_file(target, half_then_fail)
    assert str(info.value) == f"could not write {str(target)!r}: [Errno 5] Input/output error"
    assert target.read_text() == "old" and listing(tmp_path) == ["summary.json"]
    with pytest.raises(FileWriteError, match="empty file"):
        atomicfile.write_file(target, lambda temp: None)
    assert target.read_text() == "old" and listing(tmp_path) == ["summary.json"]


def test_temporary_names_are_short(tmp_path):
    """The temporary and backup names do not grow with the target's name."""
    from core.files import atomicfile

    seen = []
    atomicfile.write_file(tmp_path / ("x" * 250), lambda temp: (seen.append(temp.name), temp.write_bytes(b"1")))
    assert len(seen[0]) == len(".mc_ao-12345678-12345678-12345678.tmp")


def test_the_next_write_into_a_folder_removes_what_killed_writers_left(tmp_path):
    """A killed process's temporary and backup files go with the next write into that folder; a live
    process's, another host's and the user's own files stay."""
    import subprocess
    import sys
    import time

    from core.files import atomicfile

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = atomicfile._HOST
    other_host = "0" * 8 if host != "0" * 8 else "1" * 8
    names = {
        f".mc_ao-{host}-{dead.pid:08x}-0badc0de.tmp.png": False,  # killed: removed
        f".mc_ao-{host}-{dead.pid:08x}-0badc0de.bak.exr": False,
        f".mc_ao-{host}-{dead.pid:08x}-0badc0de.tmp.blend1": False,  # Blender's backup of a temporary file
        f".mc_ao-{host}-{os.getppid():08x}-0badc0de.tmp.png": True,  # a live process's (pytest's parent)
        f".mc_ao-{other_host}-{dead.pid:08x}-0badc0de.tmp.png": True,  # another machine's, on a shared disk
        ".mc_ao-0badc0de.tmp.png": True,  # the older naming, recent: maybe a live writer's
        ".mc_ao-deadbeef.tmp.png": False,  # the older naming, two days old
        ".mc_ao-notes.txt": True, "ao.tmp.png": True,
    }
    for name in names:
        (tmp_path / name).write_bytes(b"x")
    old = time.time() - 2 * 24 * 3600
    os.utime(tmp_path / ".mc_ao-deadbeef.tmp.png", (old, old))
    atomicfile.write_file(tmp_path / "summary.json", lambda temp: temp.write_text("{}"))
    assert sorted(listing(tmp_path)) == sorted([n for n, kept in names.items() if kept] + ["summary.json"])
