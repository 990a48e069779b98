"""A real, small filesystem for the tests of writes onto a full disk: a tmpfs the test mounts itself.

Mounting needs root (CI runs as root); elsewhere the tests that need it skip, saying why.
"""

import contextlib
import errno
import os
import subprocess

import pytest

PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


@contextlib.contextmanager
def small_filesystem(path, size=1 << 20):
    """Mount a tmpfs of ``size`` bytes at ``path`` (a new folder) for the block; unmount it after."""
    os.makedirs(path)
    try:
        proc = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0755", "mc_ao_test", str(path)],
                              capture_output=True, text=True)
    except FileNotFoundError:
        pytest.skip("no mount command here; the full-disk tests mount a small tmpfs (CI runs as root)")
    if proc.returncode != 0:
        pytest.skip(f"mounting a small tmpfs is not permitted here ({proc.stderr.strip() or proc.returncode}); "
                    "the full-disk tests need it (CI runs as root)")
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=True)


def fill(folder, leave=0):
    """Fill the filesystem of ``folder`` with a file ``.filler`` until only ``leave`` bytes are free."""
    filler = os.path.join(folder, ".filler")
    chunk = b"\xff" * (64 * PAGE)
    with open(filler, "wb", buffering=0) as f:
        while True:
            try:
                f.write(chunk)
            except OSError as exc:
                if exc.errno != errno.ENOSPC:
                    raise
                break
        for size in (PAGE, 1):  # the last pages partly written chunks left
            while True:
                try:
                    f.write(b"\xff" * size)
                except OSError as exc:
                    if exc.errno != errno.ENOSPC:
                        raise
                    break
    if leave:
        with open(filler, "r+b") as f:
            f.truncate(max(os.path.getsize(filler) - leave, 0))
    st = os.statvfs(folder)
    return st.f_bavail * st.f_frsize


def listing(folder):
    """The folder's entries, the filler left out."""
    return sorted(n for n in os.listdir(folder) if n != ".filler")
