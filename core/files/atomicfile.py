"""Replace a file only by a complete, checked new version: the one way every writer here writes.

A writer (OpenImageIO, Blender's image writer, ``json.dump``) does not always say when a write
failed: OpenImageIO's PNG and 8-bit TIFF writers, and Blender's PNG writer, report a file cut short
by a full disk as written. So no writer here ever writes its target directly:

1. :class:`PendingFile` checks the target (its folder exists, it is not a folder, it is not a file
   the user made read-only) and reserves a temporary file beside it under a short name of fixed
   length (``.mc_ao-HHHHHHHH-PPPPPPPP-XXXXXXXX.tmp<ext>``: this host's tag, this process's id and a
   random part; a name built from the target's would turn a legal 250-byte file name into one the
   filesystem refuses).
2. The writer writes the temporary file; :meth:`PendingFile.finish` checks it: the file is not
   empty, and ``verify(temp)`` (for images: the file decodes completely to the pixels written)
   passes. It then gets the permission bits of the file it replaces (new files get the umask's,
   0o666 & ~umask, as any new file), and is fsynced.
3. :meth:`PendingFile.commit` renames it over the target (``os.replace``: atomic, a reader sees
   the old file or the new one, never a mix) and fsyncs the folder.

On any failure the temporary file is removed and the target keeps its old bytes. A process that is
killed cannot remove its temporary files: the first write of a later process into the same folder
removes them (:func:`remove_stale`), those of this host whose process is gone, never a live one's.
"""

from __future__ import annotations

import errno as _errno
import hashlib
import os
import pathlib
import re
import secrets
import socket
import stat
import time

from ..base.errors import FileWriteError


__all__ = ["write_text", "PendingFile", "TEMP_PREFIX", "write_file", "io_error", "fsync_dir", "remove_stale",
           "commit_together"]

#: Every temporary (and backup) file a writer here makes starts with this.
TEMP_PREFIX = ".mc_ao-"
_O_BINARY = getattr(os, "O_BINARY", 0)


def io_error(error_class, message, err=None):
    """An ``error_class`` (an OSError) with ``message`` as its text and ``errno`` set.

    ``filename`` stays unset: setting it would make OSError.__str__ print
    "[Errno n] strerror: filename" instead of the message, which names the path itself.
    """
    exc = error_class(message)
    exc.errno = err
    return exc


def fsync_dir(directory):
    """Make a rename in ``directory`` durable (POSIX); best effort, some filesystems refuse."""
    if os.name == "nt":
        return
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _disk_full(directory):
    """True when the filesystem holding ``directory`` has no free block left (for this user)."""
    try:
        st = os.statvfs(directory)
    except (OSError, AttributeError):  # no statvfs on Windows
        return False
    return st.f_bavail == 0 or st.f_bfree == 0


def remove_quietly(path):
    try:
        os.unlink(path)
    except OSError:
        pass


def _host_tag():
    """8 hex digits naming this machine: a temporary file's process id means something only here."""
    return hashlib.sha256(socket.gethostname().encode("utf-8", "replace")).hexdigest()[:8]


_HOST = _host_tag()
_STALE = re.compile(r"^\.mc_ao-(?P<host>[0-9a-f]{8})-(?P<pid>[0-9a-f]{8})-[0-9a-f]{8}\.(?:tmp|bak)")
# The names before host and process ids were in them: removed once a day old (no way to tell a live one).
_OLD_STALE = re.compile(r"^\.mc_ao-[0-9a-f]{8}\.(?:tmp|bak)")
_OLD_AGE = 24 * 3600
_CLEANED = set()  # folders this process has cleaned already


def short_name(kind, ext=""):
    """A hidden name of fixed length for a temporary or backup file:
    ``.mc_ao-<host>-<pid>-<random>.<kind><ext>``, each part 8 hex digits."""
    return f"{TEMP_PREFIX}{_HOST}-{os.getpid() & 0xFFFFFFFF:08x}-{secrets.token_hex(4)}.{kind}{ext}"


def _pid_alive(pid):
    """Whether process ``pid`` runs on this machine (True when unsure: a live file is never removed)."""
    if pid == os.getpid():
        return True
    if os.name == "nt":  # os.kill(pid, 0) would end the process on Windows
        try:
            import ctypes

            kernel32 = ctypes.windll.kernel32
            handle = kernel32.OpenProcess(0x1000, False, pid)  # PROCESS_QUERY_LIMITED_INFORMATION
            if not handle:
                return ctypes.GetLastError() != 87  # ERROR_INVALID_PARAMETER: no such process
            try:
                code = ctypes.c_ulong()
                kernel32.GetExitCodeProcess(handle, ctypes.byref(code))
                return code.value == 259  # STILL_ACTIVE
            finally:
                kernel32.CloseHandle(handle)
        except Exception:
            return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # another user's process
    return True


def remove_stale(directory):
    """Remove the temporary and backup files that killed processes of this host left in ``directory``.

    A name carries its process's id and host (:func:`short_name`): a file is removed only when it is
    this host's and its process is gone. Files of the older naming (no process id) are removed once
    a day old. Done once per folder per process; best effort (a file that cannot be removed stays).
    Returns the names removed.
    """
    key = os.path.normcase(os.path.abspath(directory))
    if key in _CLEANED:
        return []
    _CLEANED.add(key)
    removed = []
    try:
        names = [n for n in os.listdir(directory) if n.startswith(TEMP_PREFIX)]
    except OSError:
        return removed
    now = time.time()
    for name in names:
        path = os.path.join(directory, name)
        m = _STALE.match(name)
        if m is not None:
            if m["host"] != _HOST or _pid_alive(int(m["pid"], 16)):
                continue
        elif _OLD_STALE.match(name):
            try:
                if now - os.lstat(path).st_mtime < _OLD_AGE:
                    continue
            except OSError:
                continue
        else:
            continue
        try:
            if stat.S_ISREG(os.lstat(path).st_mode):
                os.unlink(path)
                removed.append(name)
        except OSError:
            pass
    return removed


def read_only(path):
    """True when ``path`` is an existing file this process should not replace: the user took its
    write permission away. Checked on the permission bits too, since root may write anything."""
    try:
        st = os.stat(path)
    except OSError:
        return False
    if not stat.S_ISREG(st.st_mode):
        return False
    return not os.access(path, os.W_OK) or not st.st_mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH)


class PendingFile:
    """A temporary file beside ``target``, to be written, checked by :meth:`finish`, then committed.

    Parameters
    ----------
    target : str or os.PathLike
        The file to create or replace. Its folder must exist (nothing here creates folders).
    ext : str
        The temporary file's extension (writers such as OpenImageIO pick the format from it);
        the target's own by default.
    overwrite : bool
        If False and the target exists, refuse (errno EEXIST), also when it appears later: the
        commit is an atomic ``link()`` where the filesystem has hard links.
    error : type
        The exception class raised (a subclass of :class:`core.base.errors.FileWriteError`).

    Raises ``error`` when the folder is missing or not a folder, the target is a folder, exists
    with ``overwrite=False``, or is read-only, or the temporary file cannot be created.
    """

    def __init__(self, target, ext=None, overwrite=True, error=FileWriteError):
        self.target = pathlib.Path(target)
        self.error = error
        self.overwrite = overwrite
        self.temp = None
        name = os.fspath(self.target)
        directory = self.target.parent
        if not directory.is_dir():
            exists = directory.exists()
            raise io_error(
                error,
                f"cannot write {name!r}: the directory {os.fspath(directory)!r} "
                f"{'is not a directory' if exists else 'does not exist'}",
                _errno.ENOTDIR if exists else _errno.ENOENT,
            )
        if self.target.is_dir():
            raise io_error(error, f"cannot write {name!r}: it is a directory", _errno.EISDIR)
        if not overwrite and os.path.lexists(self.target):
            raise self.exists_error()
        if overwrite and read_only(self.target):
            raise io_error(
                error,
                f"{name!r} is read-only (its write permission is off): it was left as it is; make it "
                "writable, or choose another folder or name, to replace it",
                _errno.EACCES,
            )
        ext = self.target.suffix if ext is None else ext
        remove_stale(directory)
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | _O_BINARY
        try:
            for _ in range(100):
                candidate = directory / short_name("tmp", ext)
                try:
                    # 0o666: the umask decides the permissions, as for any new file.
                    fd = os.open(candidate, flags, 0o666)
                except FileExistsError:
                    continue
                os.close(fd)
                self.temp = candidate
                break
            else:
                raise OSError(_errno.EEXIST, "no free temporary file name")
        except OSError as exc:
            raise io_error(
                error,
                f"cannot write {name!r}: cannot create a file in {os.fspath(directory)!r}: "
                f"{exc.strerror or exc}",
                exc.errno,
            ) from exc

    def exists_error(self):
        return io_error(
            self.error, f"{os.fspath(self.target)!r} already exists and overwrite=False", _errno.EEXIST
        )

    def fail(self, reason, err=None):
        """The error for a failed write of the temporary file (it is removed here).

        ``reason`` is an exception or text; the temporary file's name in it becomes the target's,
        and when the filesystem is full the error says just that (errno ENOSPC): the writers that
        notice a full disk at all say only that something could not be written or read back.
        """
        text = str(reason).removeprefix(f"could not write {os.fspath(self.target)!r}: ")
        if self.temp is not None:
            text = text.replace(os.fspath(self.temp), os.fspath(self.target))
        lines = [line.strip() for line in text.splitlines() if line.strip()] or ["unknown error"]
        if isinstance(reason, OSError) and err is None:
            err = reason.errno
        if err != _errno.ENOSPC and _disk_full(self.target.parent):
            err = _errno.ENOSPC
            text = "no space left on the device"
        else:
            text = "; ".join(lines)
        self.discard()
        return io_error(self.error, f"could not write {os.fspath(self.target)!r}: {text}", err)

    def finish(self, verify=None):
        """Check the written temporary file, give it the old file's permissions, fsync it.

        ``verify(temp_path)`` raises (any exception; its text goes into the error) when the file
        is not what was meant to be written. Raises ``error`` (and removes the temporary file) on
        any failure.
        """
        try:
            size = os.stat(self.temp).st_size
            if size == 0:
                raise self.fail("the writer left an empty file")
            if verify is not None:
                try:
                    verify(self.temp)
                except Exception as exc:
                    raise self.fail(f"the file written does not read back as written ({exc})") from exc
            self._copy_permissions()
            fd = os.open(self.temp, os.O_RDWR | _O_BINARY)  # Windows fsync needs write access
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        except BaseException as exc:  # KeyboardInterrupt included: never leave a temp file behind
            if isinstance(exc, self.error) or not isinstance(exc, Exception):
                self.discard()
                raise
            raise self.fail(getattr(exc, "strerror", None) or exc, getattr(exc, "errno", None)) from exc

    def _copy_permissions(self):
        try:
            st = os.stat(self.target)
        except OSError:
            return  # a new file: the umask's permissions
        if not stat.S_ISREG(st.st_mode):
            return
        os.chmod(self.temp, stat.S_IMODE(st.st_mode))
        mine = os.stat(self.temp)
        if (mine.st_uid, mine.st_gid) != (st.st_uid, st.st_gid) and hasattr(os, "chown"):
            try:
                os.chown(self.temp, st.st_uid, st.st_gid)  # root replacing another user's file
            except OSError:
                pass  # not permitted: the file is this user's, as any file they write
            else:
                os.chmod(self.temp, stat.S_IMODE(st.st_mode))  # chown may clear setuid/setgid

    def discard(self):
        if self.temp is not None:
            remove_quietly(self.temp)

    def commit(self):
        """Move the temporary file onto the target: the target is old or new, never partial."""
        try:
            if self.overwrite:
                os.replace(self.temp, self.target)
            else:
                self._commit_no_clobber()
        except self.error:
            self.discard()
            raise
        except BaseException as exc:
            self.discard()
            if not isinstance(exc, OSError):
                raise
            raise io_error(
                self.error,
                f"could not move the finished file onto {os.fspath(self.target)!r}: {exc}",
                exc.errno,
            ) from exc
        fsync_dir(self.target.parent)

    def _commit_no_clobber(self):
        # link() fails if the target exists, atomically: no window between a check and the rename.
        try:
            os.link(self.temp, self.target)
        except FileExistsError:
            raise self.exists_error() from None
        except OSError:
            # No hard links here (FAT, some network shares): check, then rename.
            if os.path.lexists(self.target):
                raise self.exists_error() from None
            os.replace(self.temp, self.target)
        else:
            os.unlink(self.temp)


def commit_together(pendings, error=FileWriteError):
    """Commit finished :class:`PendingFile` s all together or not at all.

    Each target that exists is first hard-linked to a backup beside it; then the temporary files
    are renamed over their targets one after another. When a rename fails, the targets already
    replaced get their old files back (or are removed, where there was none), every temporary file
    is removed, and ``error`` is raised naming the target that failed. Where the filesystem has no
    hard links the old file cannot be kept aside: nothing is committed and ``error`` says so. A
    KeyboardInterrupt during the renames is handled like a failure (everything put back) and then
    re-raised.
    """
    pendings = list(pendings)
    backups = []
    try:
        for p in pendings:
            backups.append(backup_of(p.target))
    except OSError as exc:
        for p in pendings:
            p.discard()
        for b in backups:
            if b:
                remove_quietly(b)
        raise io_error(error, f"cannot keep the old file {os.fspath(p.target)!r} aside while the new ones "
                              f"are moved in ({exc.strerror or exc}); nothing was replaced", exc.errno) from exc
    done = 0
    try:
        for p in pendings:
            p.commit()
            done += 1
    except BaseException:
        for p in pendings[done:]:
            p.discard()
        for p, b in zip(pendings[:done], backups[:done]):
            roll_back(p.target, b)
        for b in backups[done:]:
            if b:
                remove_quietly(b)
        raise
    for b in backups:
        if b:
            remove_quietly(b)


def backup_of(target):
    """Hard-link an existing ``target`` to a hidden name beside it; None when there is no target.
    Raises OSError where no link can be made (a filesystem without hard links)."""
    target = pathlib.Path(target)
    if not os.path.lexists(target):
        return None
    for _ in range(100):
        candidate = target.parent / short_name("bak", target.suffix)
        try:
            os.link(target, candidate)
        except FileExistsError:
            continue
        return candidate
    raise OSError(_errno.EEXIST, "no free backup file name")


def roll_back(target, backup):
    """Undo a committed rename of ``target``: its :func:`backup_of` put back over it, or, where there
    was no old file (``backup`` None), the new one removed. True when the target is as it was."""
    target = pathlib.Path(target)
    try:
        if backup is None:
            os.unlink(target)
        else:
            os.replace(backup, target)
    except OSError:
        return False
    fsync_dir(target.parent)
    return True


def write_file(target, write, verify=None, overwrite=True, error=FileWriteError, ext=None):
    """Write ``target`` through ``write(temp_path)``, check it, and only then replace the target.

    ``write`` raising (anything) leaves the target as it was and no temporary file; an OSError or
    other Exception from it becomes ``error`` naming the target. Returns the target as a Path.
    """
    pending = PendingFile(target, ext=ext, overwrite=overwrite, error=error)
    try:
        write(pending.temp)
    except BaseException as exc:
        if not isinstance(exc, Exception):
            pending.discard()
            raise
        raise pending.fail(exc) from exc
    pending.finish(verify)
    pending.commit()
    return pending.target


def write_text(target, text, error=FileWriteError):
    """Write ``text`` (UTF-8) to ``target`` through :func:`write_file`, read back whole before it
    replaces the old file; the folder is made if missing. Summaries, logs, job files."""

    def write(temp):
        with open(temp, "w", encoding="utf-8") as f:
            f.write(text)

    def verify(temp):
        with open(temp, encoding="utf-8") as f:
            if f.read() != text:
                raise ValueError("it reads back different")

    os.makedirs(os.path.dirname(os.path.abspath(target)), exist_ok=True)
    return write_file(target, write, verify=verify, error=error)
