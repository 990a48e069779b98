"""What a file on disk is, and whether a run may write a file at a path: no bpy, standard library only.

Every path a user gives for something to write (a summary, a saved .blend file, a batch summary)
is untrusted: a forgotten argument makes the next word the path (``--summary-json scene.blend``).
:func:`output_problem` refuses a path that is one of the run's inputs, another output of the same
run, or an existing file of another kind than the one about to be written; the kind is read from
the file's first bytes (:func:`file_kind`), never guessed from its name.

:func:`replace_problem` refuses to replace an existing file whose contents are not of the kind its
extension says (what the bake writes there would destroy something else). :func:`check_blend_complete` reads a .blend file to its end marker (``ENDB``): Blender can report a
save onto a full disk as done and leave a file cut short, whose header is intact.
"""

import gzip
import json
import os
import struct

__all__ = ["file_kind", "folder_problem", "output_problem", "replace_problem", "check_blend_complete", "same_file",
           "file_key", "BlendFileError",
           "KIND_OF_EXTENSION"]

_ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
_GZIP_MAGIC = b"\x1f\x8b"
_SEEK_TABLE_MAGIC = 0x8F92EAB1  # the footer of zstd's seekable format, which Blender writes
_SKIPPABLE_MAGIC = 0x184D2A5E
_IMAGE_MAGICS = (
    (b"\x89PNG\r\n\x1a\n", "a PNG image"), (b"\x76\x2f\x31\x01", "an EXR image"),
    (b"II*\x00", "a TIFF image"), (b"MM\x00*", "a TIFF image"), (b"\xff\xd8\xff", "a JPEG image"),
    (b"ply\n", "a PLY mesh"), (b"ply\r\n", "a PLY mesh"), (b"PK\x03\x04", "a zip archive"),
)


class BlendFileError(ValueError):
    """A .blend file that is not complete (cut short, or not a .blend file at all)."""


def same_file(a, b):
    """True when the paths reach one file, compared by the file they reach, never by how they are spelt.

    Two existing files: the same device and inode (a symlink, a hard link, ``..``, a folder reached
    through a link, another case on a case-insensitive disk are all seen through). A path where
    nothing is yet (an output about to be written): its folder's real path plus its name, compared
    without case (Windows' and macOS's disks ignore it; two outputs that differ only in case are one
    file there, so they are refused everywhere). An existing file and a path where nothing is are two
    files.
    """
    return file_key(a) == file_key(b)


def file_key(path):
    """What identifies the file ``path`` reaches (see :func:`same_file`): ``("file", device, inode)``
    where a file is, else ``("path", its folder's real path joined with its name, case-folded)``
    (links resolved as far as they exist)."""
    try:
        st = os.stat(path)
        return ("file", st.st_dev, st.st_ino)
    except (OSError, ValueError):
        pass
    folder, name = os.path.split(os.path.abspath(os.fspath(path)))
    return ("path", os.path.normcase(os.path.join(os.path.realpath(folder), name)).casefold())


def file_kind(path):
    """What the existing file at ``path`` holds, in words: "a .blend file", "an mc_ao summary",
    "an mc_ao batch summary", "a PNG image", ..., "a folder", "a file" (anything else); None when
    nothing is there."""
    if not os.path.lexists(path):
        return None
    if os.path.isdir(path):
        return "a folder"
    try:
        with open(path, "rb") as f:
            head = f.read(64)
    except OSError:
        return "a file"
    if head.startswith(b"BLENDER") or head.startswith(_ZSTD_MAGIC) or head.startswith(_GZIP_MAGIC):
        return "a .blend file"  # Blender's own compressions; a summary or image never starts so
    for magic, kind in _IMAGE_MAGICS:
        if head.startswith(magic):
            return kind
    if head.lstrip()[:1] == b"{":
        try:
            with open(path, encoding="utf-8") as f:
                data = json.load(f)
        except (OSError, ValueError):
            return "a file"
        if isinstance(data, dict) and "mc_ao" in data:
            return "an mc_ao batch summary" if "tasks" in data else "an mc_ao summary"
    return "a file"


def output_problem(path, kind, inputs=(), outputs=(), replaces=()):
    """Why the run may not write ``path``, or None when it may.

    Parameters
    ----------
    path : str or os.PathLike
        The file about to be written.
    kind : str
        What is written there, in words ("the summary", "--save"), for the message.
    inputs : iterable of (path, what)
        The run's inputs (the .blend file, the manifest): never written over.
    outputs : iterable of (path, what)
        The run's other outputs: two outputs are never one file.
    replaces : iterable of str
        The :func:`file_kind` words of existing files this output may replace (its own kind).
    """
    for other, what in inputs:
        if other and same_file(path, other):
            return f"it is {what}, an input of this run"
    for other, what in outputs:
        if other and same_file(path, other):
            return f"it is also {what}"
    found = file_kind(path)
    if found is not None and found not in replaces and not _empty_file(path):  # (mktemp's file: nothing to lose)
        return f"it is {found} already there, not {' or '.join(replaces) or 'a file this run writes'}"
    return None


def _empty_file(path):
    try:
        return os.path.isfile(path) and os.path.getsize(path) == 0
    except OSError:
        return False


#: What a file of each extension the bake writes holds (file_kind's words).
KIND_OF_EXTENSION = {".png": "a PNG image", ".exr": "an EXR image", ".tif": "a TIFF image",
                     ".tiff": "a TIFF image", ".ply": "a PLY mesh", ".blend": "a .blend file",
                     ".npz": "a zip archive"}  # an atlas's record (core.files.atlasrecord)


def replace_problem(path):
    """Why the bake's file at ``path`` may not replace what is there (None when it may): an existing
    file of another kind than the extension says (a .blend or notes saved as ``Ground_AO.png``). An
    empty file, and a path of an extension not listed in :data:`KIND_OF_EXTENSION`, are not checked."""
    expected = KIND_OF_EXTENSION.get(os.path.splitext(os.fspath(path))[1].lower())
    if expected is None:
        return None
    if _empty_file(path):
        return None
    found = file_kind(path)
    if found is None or found == expected:
        return None
    return (f"{os.fspath(path)!r} is {found}, not {expected}: it was left as it is; move it away, or choose "
            "another folder or name")


def folder_problem(folder):
    """Why files cannot be written into ``folder``, or None when they can.

    A folder that does not exist yet is fine where it can be created (it is created before the
    first file is written): what counts is its nearest existing ancestor, which must be a folder
    that this process may write; a link on the way that leads nowhere (a dangling symlink) is refused. Checked before a bake, so that a typo in the folder does not
    cost the bake; a write can still fail later (a full disk), and then the existing file is
    left as it was.
    """
    path = os.path.abspath(folder)
    existing = path
    while not os.path.exists(existing):
        if os.path.islink(existing):  # a link to nothing: no folder can be made there
            what = "it is" if existing == path else f"{existing!r} is"
            return f"{what} a link to {os.readlink(existing)!r}, which does not exist"
        parent = os.path.dirname(existing)
        if parent == existing:
            break
        existing = parent
    if not os.path.isdir(existing):
        return "it is a file, not a folder" if existing == path else f"{existing!r} is a file, not a folder"
    if not os.access(existing, os.W_OK | os.X_OK):
        return "it is not writable" if existing == path else f"{existing!r} is not writable"
    return None


# -- .blend files -------------------------------------------------------------------------------------

def check_blend_complete(path):
    """Raise :class:`BlendFileError` unless ``path`` is a whole .blend file: its blocks walked from the
    header to the end marker ``ENDB``.

    Plain, gzip (Blender before 3.0) and zstd (3.0 and later) files; a zstd file is decompressed
    where the ``zstandard`` module is (Blender ships it), else its seek table (which Blender writes
    last) must account for every byte of the file; either way the seek table must be whole.
    """
    with open(path, "rb") as f:
        data = f.read()
    if data.startswith(_GZIP_MAGIC):
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError) as exc:
            raise BlendFileError(f"its gzip stream is cut short or damaged ({exc})") from None
    elif data.startswith(_ZSTD_MAGIC):
        data = _zstd_payload(data)
        if data is None:
            return  # complete by its seek table; nothing to decompress it with
    _walk_blocks(data)


def _walk_blocks(data):
    if not data.startswith(b"BLENDER"):
        raise BlendFileError("it is not a .blend file (no BLENDER header)")
    if data[7:9].isdigit():
        # Blender 5.0 and later: "BLENDER" + header size (2 digits) + "-" + format (2 digits) + "v" +
        # version; blocks with 64-bit lengths: code, SDNA index (int32), old pointer, length, count (int64).
        header = int(data[7:9])
        if data[9:10] != b"-" or data[12:13] not in (b"v", b"V"):
            raise BlendFileError(f"unknown .blend header {data[:header]!r}")
        order = "<" if data[12:13] == b"v" else ">"
        head_size, length_at, length_fmt = 32, 16, order + "q"
    else:
        # Before 5.0: "BLENDER" + pointer size ('_' 4, '-' 8) + endianness + version (3 digits);
        # blocks: code, length (int32), old pointer, SDNA index, count (int32).
        header = 12
        pointer = {b"_": 4, b"-": 8}.get(data[7:8])
        if pointer is None or data[8:9] not in (b"v", b"V"):
            raise BlendFileError(f"unknown .blend header {data[:12]!r}")
        order = "<" if data[8:9] == b"v" else ">"
        head_size, length_at, length_fmt = 16 + pointer, 4, order + "i"
    pos, end = header, len(data)
    while True:
        if pos + 4 > end:
            raise BlendFileError(f"it is cut short: no end marker (ENDB) after {end} bytes")
        if pos + head_size > end:
            raise BlendFileError(f"it is cut short in a block header at byte {pos} of {end}")
        if data[pos:pos + 4] == b"ENDB":
            return
        (length,) = struct.unpack_from(length_fmt, data, pos + length_at)
        if length < 0:
            raise BlendFileError(f"a block at byte {pos} has a negative length")
        pos += head_size + length
        if pos > end:
            raise BlendFileError(f"it is cut short: a block runs to byte {pos} of {end}")


def _zstd_payload(data):
    """The decompressed .blend of a zstd file, or None when it is complete by its seek table alone."""
    _check_seek_table(data)
    try:
        import zstandard
    except ImportError:
        zstandard = None
    if zstandard is not None:
        try:
            out = bytearray()
            rest = data
            while rest:  # every frame: Blender writes several, then a skippable seek-table frame
                reader = zstandard.ZstdDecompressor().decompressobj()
                out += reader.decompress(rest)
                if not reader.eof:
                    raise BlendFileError("its compressed data is cut short")
                rest = reader.unused_data
                while rest[:4] and int.from_bytes(rest[:4], "little") & 0xFFFFFFF0 == 0x184D2A50:
                    size = 8 + int.from_bytes(rest[4:8], "little")
                    if len(rest) < size:
                        raise BlendFileError("its compressed data is cut short")
                    rest = rest[size:]
            return bytes(out)
        except zstandard.ZstdError as exc:
            raise BlendFileError(f"its compressed data is damaged ({exc})") from None
    return None


def _check_seek_table(data):
    if len(data) < 17 or int.from_bytes(data[-4:], "little") != _SEEK_TABLE_MAGIC:
        raise BlendFileError("it is cut short: its zstd seek table (written last) is missing")
    frames = int.from_bytes(data[-9:-5], "little")
    checksums = data[-5] & 0x80
    entry = 12 if checksums else 8
    table = 8 + frames * entry + 9
    if table > len(data) or int.from_bytes(data[-table:-table + 4], "little") != _SKIPPABLE_MAGIC:
        raise BlendFileError("its zstd seek table is damaged")
    compressed = sum(int.from_bytes(data[-table + 8 + i * entry:][:4], "little") for i in range(frames))
    if compressed + table != len(data):
        raise BlendFileError(f"its zstd frames hold {compressed} bytes, the file {len(data) - table}")
