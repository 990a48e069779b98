"""File names made from untrusted names (Blender object and image names) that stay inside their folder.

A .blend file from anywhere names its objects; a bake writes ``<folder>/<object>_AO.<ext>``. Joined
naively, an object called ``../x``, ``/etc/x``, ``a/b`` or ``C:x`` would choose where the file goes.
Everything that turns a name into a path goes through here, once, for the operator, the background
script and the batch runner alike:

- :func:`safe_file_stem` maps any string to one file name component that is valid and harmless on
  Linux, macOS and Windows: no separators of either OS, no ``..``, no control characters or NUL, none
  of the characters Windows refuses (``<>:"/\\|?*``), no trailing dots or spaces (Windows drops them),
  no reserved device name (CON, PRN, AUX, NUL, COM0-9, LPT0-9, with any extension), and at most
  :data:`MAX_STEM_BYTES` bytes of UTF-8 so that suffixes (``_AO``, ``_stderr``, ``.1001``, ``.exr``)
  still fit the 255-byte limit of common filesystems. A name that had to be changed gets a short
  hash of the original appended, so two different names never map to the same stem by sanitising
  (``a/b`` and ``a_b`` stay apart).
- :func:`unique_file_stems` also keeps names apart that differ only in letter case (one file on the
  case-insensitive filesystems of Windows and macOS).
- :func:`path_inside` joins a folder and a file name and checks that the resolved path lies inside
  the resolved folder, the last line of defence.
- :func:`same_file` compares two paths by the file they reach, never by how they are spelt.
"""

import hashlib
import os
import unicodedata

from ..base.errors import SettingsError

__all__ = ["MAX_STEM_BYTES", "safe_file_stem", "unique_file_stems", "path_inside", "same_file", "UnsafePathError"]

#: Longest stem in UTF-8 bytes. 255 (ext4, APFS, NTFS in UTF-16 units) minus room for the longest
#: suffix a bake appends (``_BentNormal_stderr.1001.tiff`` is 28 bytes) and a margin.
MAX_STEM_BYTES = 200

# Windows refuses these in a file name; '/' and '\\' are the two separators.
_FORBIDDEN = set('<>:"/\\|?*')
_RESERVED = {"CON", "PRN", "AUX", "NUL", "CONIN$", "CONOUT$"} | {
    f"{dev}{i}" for dev in ("COM", "LPT") for i in list("0123456789") + ["\u00b9", "\u00b2", "\u00b3"]
}
_HASH_CHARS = 8


class UnsafePathError(SettingsError):
    """A path built for a file would leave its output folder."""


def _digest(name):
    return hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()[:_HASH_CHARS]


def _truncate_utf8(text, limit):
    """The longest prefix of ``text`` that is at most ``limit`` bytes of UTF-8 (whole characters)."""
    data = text.encode("utf-8", "surrogatepass")
    if len(data) <= limit:
        return text
    return data[:limit].decode("utf-8", "ignore")


def _clean(name):
    out = []
    for ch in unicodedata.normalize("NFC", name):
        cat = unicodedata.category(ch)
        if ch in _FORBIDDEN or cat in ("Cc", "Cf", "Cs", "Co", "Cn") or cat.startswith("Z") and ch != " ":
            out.append("_")  # controls, NUL, format characters, line/paragraph separators, odd spaces
        else:
            out.append(ch)
    text = "".join(out).strip(" ")
    text = text.rstrip(". ")  # Windows drops trailing dots and spaces: "a." would become "a"
    text = text.lstrip(".")   # no hidden files, no "." or ".." (nor "...")
    return text


def _reserved(stem):
    base = stem.split(".", 1)[0].rstrip(" ").upper()
    return base in _RESERVED


def safe_file_stem(name, max_bytes=MAX_STEM_BYTES):
    """One safe file name component (no extension added) for any string ``name``.

    Parameters
    ----------
    name : str
        Untrusted text, typically an object or image name.
    max_bytes : int
        Longest result, in bytes of UTF-8.

    Returns
    -------
    str
        ``name`` itself when it is already safe and short enough; otherwise a cleaned, shortened
        version followed by ``-`` and 8 hex digits of the SHA-256 of ``name``, so that distinct
        names stay distinct. Never empty, never ``.`` or ``..``, never a Windows device name.
    """
    name = str(name)
    cleaned = _clean(name)
    if cleaned == name and cleaned and not _reserved(cleaned) \
            and len(cleaned.encode("utf-8", "surrogatepass")) <= max_bytes:
        return cleaned
    tag = "-" + _digest(name)
    body = _truncate_utf8(cleaned, max_bytes - len(tag)).rstrip(". ")
    if not body or _reserved(body):
        body = ("_" + body) if body else "_"
    return body + tag


def unique_file_stems(names, max_bytes=MAX_STEM_BYTES):
    """:func:`safe_file_stem` of each name, made distinct also where stems differ only in case.

    Returns a dict ``name -> stem``. The result for a name does not depend on the order of
    ``names``: of stems that collide case-insensitively, each one that is not the original name
    spelled exactly gets its name's hash appended; when several are spelled exactly (``Cube`` and
    ``cube``), all of them do, so that no object's file depends on which name came first.
    """
    names = list(dict.fromkeys(str(n) for n in names))
    stems = {n: safe_file_stem(n, max_bytes) for n in names}
    groups = {}
    for n, s in stems.items():
        groups.setdefault(s.casefold(), []).append(n)
    for members in groups.values():
        if len(members) < 2:
            continue
        own = [m for m in members if stems[m] == m]
        for n in members:
            if own == [n]:
                continue  # the one name that is its own stem keeps it
            tag = "-" + _digest(n)
            if not stems[n].endswith(tag):
                stems[n] = _truncate_utf8(stems[n], max_bytes - len(tag)).rstrip(". ") + tag
    # A hash collision of 8 hex digits between names that also clash in case is beyond concern, but
    # never write two objects into one file: say so instead.
    seen = {}
    for n, s in stems.items():
        other = seen.setdefault(s.casefold(), n)
        if other != n:
            raise SettingsError(f"the names {other!r} and {n!r} map to the same file name {s!r}")
    return stems


def path_inside(folder, file_name):
    """``folder / file_name``, refusing a result that would resolve outside ``folder``.

    ``file_name`` must be a single component (as :func:`safe_file_stem` plus a suffix gives). Both
    paths are resolved (symbolic links followed, ``..`` removed) before they are compared, so a
    link planted in the folder cannot lead a write elsewhere either.

    Raises
    ------
    UnsafePathError
        The name holds a separator or is ``.``/``..``, or the resolved path leaves the folder.
    """
    file_name = os.fspath(file_name)
    if (not file_name or file_name in (".", "..") or "/" in file_name or "\\" in file_name
            or "\x00" in file_name or os.path.isabs(file_name) or os.path.splitdrive(file_name)[0]):
        raise UnsafePathError(f"{file_name!r} is not a plain file name; refusing to write it")
    root = os.path.realpath(os.fspath(folder))
    path = os.path.realpath(os.path.join(root, file_name))
    if os.path.dirname(path) != root:
        raise UnsafePathError(
            f"{file_name!r} would be written to {path!r}, outside the output folder {root!r}; refusing"
        )
    return os.path.join(os.path.abspath(os.fspath(folder)), file_name)


def same_file(a, b):
    """True when the paths ``a`` and ``b`` reach one file: two existing files by their device and
    inode (a symlink, a hard link, ``..``, a folder reached through a link, another case on a
    case-insensitive disk are seen through); otherwise each path's folder's real path joined with its
    name, compared without case (two names that differ only in case are one file on Windows' and
    macOS's disks, so they are one everywhere). The add-on's mc_ao.filecheck.same_file is the same
    rule for its inputs and outputs."""
    def key(path):
        try:
            st = os.stat(path)
            return ("file", st.st_dev, st.st_ino)
        except (OSError, ValueError):
            folder, name = os.path.split(os.path.abspath(os.fspath(path)))
            return ("path", os.path.normcase(os.path.join(os.path.realpath(folder), name)).casefold())

    return key(a) == key(b)
