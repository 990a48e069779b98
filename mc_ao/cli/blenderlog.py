"""Blender's own log lines kept out of the script's output. Opening a .blend file, Blender's C code
writes `Read blend: "PATH"` (5.0: with a time and "blend |" before it), and saving a copy `Info: Saved
copy as "NAME"` (4.2: `Info: Saved "NAME"`, the atomic save's temporary name), to the process's
standard output: file descriptor 1, below Python's sys.stdout, so no print filter sees them. :func:`blender_output` points
descriptor 1 at a temporary file while Blender works and passes on every line but those."""

import contextlib
import ctypes
import os
import re
import sys
import tempfile

#: Blender's lines that say only what the script says itself: the file it opened, the copy it saved
#: (4.2: 'Saved "NAME"', after the count of external files whose paths it remapped, when none failed).
ROUTINE = re.compile(r"^(?:[\d:.]+\s+\w+\s+\|\s+)?(?:Info: )?"
                     r"(?:Read blend: |Saved copy as |Saved \"|Total files \d+ \| Changed \d+ \| Failed 0$)")


def _flush_c_streams():
    """Flush the C library's buffered streams, so that what Blender wrote reaches the descriptor now."""
    try:
        libc = ctypes.CDLL("ucrtbase") if sys.platform == "win32" else ctypes.CDLL(None)
        libc.fflush(None)
    except (OSError, AttributeError):
        pass


@contextlib.contextmanager
def blender_output(routine=ROUTINE):
    """Inside, what is written to file descriptor 1 goes to a temporary file; at the end, each of its
    lines that ``routine`` does not match is written to sys.stdout. Where descriptor 1 cannot be
    moved (no such descriptor), nothing is caught."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):
        yield
        return
    with tempfile.TemporaryFile() as caught:
        os.dup2(caught.fileno(), 1)
        try:
            yield
        finally:
            _flush_c_streams()
            os.dup2(saved, 1)
            os.close(saved)
            caught.seek(0)
            text = caught.read().decode("utf-8", "replace")
            kept = [line for line in text.splitlines() if line.strip() and not routine.match(line)]
            if kept:
                print("\n".join(kept), flush=True)
