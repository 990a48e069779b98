"""One batch task: skip it when its output is complete, else bake the .blend file in a process of its own.

The bake is ``scripts/bake_ao.py`` with ``--summary-json``, under Blender (``blender -b FILE --python
scripts/bake_ao.py -- ...``) when an executable is given or found, else under a Python with the bpy
module. Its summary, at a path that carries the task's fingerprint (:attr:`Task.summary`), is what a
later run reads back to decide whether the task is done:

- the summary's run ended with exit status 0 and every object in it has status "ok";
- it was made by this output version (:data:`core._version.OUTPUT_VERSION`);
- every file it lists exists and is the very file the bake wrote (its size and modification time as
  the summary records them), or else carries, in its metadata, the settings the summary records (all
  but the choice of objects, such as match_suffix, which no file carries) and the same output version
  (an output folder copied elsewhere); a channel-packed copy of another image, which keeps that
  image's attributes, counts as done only as the file the bake wrote.

The fingerprint covers the .blend file (path, size, modification time), every setting that changes
the output and the output version, so a changed asset or setting bakes again and everything else is
skipped; ``force`` bakes regardless. A task whose output an older output version made, complete by
the same rules under that version's fingerprint, is *kept* (reported as made by an older version,
its files untouched) unless ``rebake_older`` (``--rebake-older``, or ``rebake_older = true`` in the
manifest) asks for it to be baked again.

:func:`run_task` returns a plain dict (the batch summary's record of the task) and raises nothing for
a failed bake: a crash or a broken file fails its own task only.
"""

import glob
import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from importlib.util import find_spec

from core._version import OUTPUT_VERSION
from mc_ao.terminal import escape

from . import BAKE_SCRIPT
from .manifest import Task

# Entries of a summary's "settings" that choose which objects a run bakes: no file's metadata
# carries them (each file records its own object and high-poly objects), so they are not compared.
_RUN_ONLY_SETTINGS = {"match_suffix", "match_collections"}
GUARD = os.path.join(os.path.dirname(os.path.abspath(__file__)), "guard.py")
_TAIL_LINES = 12


class NoBakerError(RuntimeError):
    """Neither a Blender executable nor the bpy module is available."""


def find_baker(blender=None):
    """What runs the bakes here: ``("blender", path)`` or ``("bpy", python)``.

    ``blender``: an executable path given by the user (used as is), "bpy" to use the bpy module, or
    None to look for one: $BLENDER, then ``blender`` on the PATH, else the bpy module of this Python.
    """
    if blender and blender != "bpy":
        found = shutil.which(blender)
        if found is None:
            raise NoBakerError(f"no Blender executable at {blender!r}")
        return "blender", found
    if blender is None:
        for candidate in (os.environ.get("BLENDER"), "blender"):
            found = candidate and shutil.which(candidate)
            if found:
                return "blender", found
    if find_spec("bpy") is None:
        raise NoBakerError(
            "no Blender executable (give --blender PATH, set $BLENDER or put blender on the PATH) "
            f"and no bpy module in this Python ({sys.executable}; pip install bpy)"
        )
    return "bpy", sys.executable


def bake_command(task, baker):
    """The command line that bakes ``task`` (a :class:`Task`) with ``baker`` (see :func:`find_baker`)."""
    kind, exe = baker
    tail = list(task.args) + [
        "--output", task.output, "--summary-json", task.summary, "--threads", str(task.threads), "--quiet",
    ] + (["--processes", str(task.processes)] if task.processes else [])
    if kind == "blender":
        # no --factory-startup: it would leave the user's preferences unread, and with them the mc_ao
        # extension whose bundled embreex the bake needs
        return [exe, "--background", task.blend, "--python-exit-code", "1",
                "--python", str(BAKE_SCRIPT), "--"] + tail
    return [exe, str(BAKE_SCRIPT), task.blend] + tail


def read_summary(path):
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _same(a, b):
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def output_version_of(record):
    """The output version a summary or a file's metadata records (1: made before output versions)."""
    try:
        return int(record.get("output_version", 1))
    except (TypeError, ValueError):
        return None


def why_not_done(task):
    """None when the task's output is complete and current; else why it must be baked (a short text)."""
    return _why_not_complete(task, task.summary, OUTPUT_VERSION)


def made_by_older(task):
    """(output version, summary path) of the newest older output version whose bake of ``task`` is
    complete (its summary, every file it lists, their settings and output version), or None."""
    for version, fingerprint in task.older:
        path = task.summary_of(fingerprint)
        if os.path.isfile(path) and _why_not_complete(task, path, version) is None:
            return version, path
    return None


def keeps_older(task, rebake_older=False):
    """(output version, summary path) when ``task`` is not done but an older output version's complete
    bake of it is kept (neither ``rebake_older`` nor the task's own ``rebake_older`` asks for a new
    one); else None."""
    if rebake_older or task.rebake_older:
        return None
    return made_by_older(task)


def _why_not_complete(task, summary_path, version):
    summary = read_summary(summary_path)
    if summary is None:
        return "not baked with these settings yet"
    if summary.get("exit_code") != 0 or summary.get("error"):
        return "the last bake failed"
    objects = summary.get("objects") or []
    if not objects or any(o.get("status") != "ok" for o in objects):
        return "the last bake did not finish every object"
    if output_version_of(summary) != version:
        return f"made by output version {summary.get('output_version', 1)}, this is {version}"
    settings = summary.get("settings") or {}
    from core.files.imageio import ImageReadError, read_image

    for obj in objects:
        files = obj.get("files") or []
        if not files:
            return f"{obj.get('object')}: no files recorded"
        for recorded in files:
            # bake_ao.py writes flat into the task's folder: look there, so that an output folder
            # that was moved or mounted elsewhere still counts as done
            path = os.path.join(task.output, os.path.basename(recorded))
            if not os.path.isfile(path):
                return f"{path} is missing"
            if _as_written(path, (obj.get("file_stats") or {}).get(os.path.basename(recorded))):
                # The very file the bake wrote (its size and time as the summary recorded them): also a
                # copy of another image with the map in one of its channels (Channel and Into), which keeps
                # that image's attributes and carries no record of the bake to check.
                continue
            try:
                if path.lower().endswith(".ply"):  # --target vertex-colors
                    from core.files.plyio import read_ply

                    metadata = read_ply(path)[4]
                else:
                    _, metadata = read_image(path)
            except (ImageReadError, OSError, ValueError) as exc:
                return f"{path} cannot be read: {exc}"
            if not metadata:
                return f"{path} has no mc_ao metadata to check"
            if metadata.get("object", obj.get("object")) != obj.get("object"):
                return f"{path} holds the bake of {metadata['object']!r}, not of {obj.get('object')!r}"
            if output_version_of(metadata) != version:
                return f"{path} was made by output version {metadata.get('output_version', 1)}, not {version}"
            for key, value in settings.items():
                if key in _RUN_ONLY_SETTINGS:
                    continue
                if key not in metadata or not _same(metadata[key], value):
                    return f"{path}: {key} is {metadata.get(key)!r}, the bake recorded {value!r}"
    return None


def _as_written(path, recorded_stat):
    """Whether the file at ``path`` has the [size, modification time in ns] the bake's summary recorded."""
    if not recorded_stat:
        return False
    try:
        st = os.stat(path)
    except OSError:
        return False
    return [st.st_size, st.st_mtime_ns] == list(recorded_stat)


def _record(task, status, **fields):
    record = {
        "task": task.name, "index": task.index, "blend": task.blend_given, "output": task.output,
        "status": status, "seconds": 0.0, "bake_seconds": 0.0, "rays": 0, "objects": [], "files": [],
        "error": None, "exit_code": None, "attempts": 1, "summary": task.summary, "log": task.log,
        "host": socket.gethostname(), "pid": os.getpid(),
    }
    record.update(fields)
    return record


def _from_summary(record, summary, task):
    objects = summary.get("objects") or []
    for o in objects:
        o["files"] = [os.path.join(task.output, os.path.basename(f)) for f in (o.get("files") or [])]
    record["objects"] = objects
    record["files"] = [f for o in objects for f in o["files"]]
    record["rays"] = int(sum(o.get("rays") or 0 for o in objects))
    record["bake_seconds"] = float(sum(o.get("seconds") or 0.0 for o in objects))
    return record


def _log_tail(path):
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            lines = [line.rstrip() for line in f if line.strip()]
    except OSError:
        return ""
    return "\n".join(lines[-_TAIL_LINES:])


def _signal_name(code):
    if code > 128:
        try:
            return f" ({signal.Signals(code - 128).name})"
        except ValueError:
            pass
    return ""


def _failure_text(code, summary, log):
    if summary is not None:
        # escaped: the errors carry object names, which may hold newlines and escape sequences
        errors = []
        if summary.get("error"):
            errors.append(escape(str(summary["error"]).strip(), keep="\n"))
        for o in summary.get("objects") or []:
            if o.get("status") != "ok":
                errors.append(f"{escape(o.get('object'))}: {escape(str(o.get('error') or 'failed').strip())}")
        if errors:
            return "; ".join(errors)
        if code != 0:
            return f"the bake exited with status {code}"
        return "the bake finished without baking any object"
    # No summary: the process died, or Blender stopped before the script ran (a file it cannot
    # read). Lead with the last line that says what went wrong; the log's end follows.
    tail = _log_tail(log)
    lines = [line for line in tail.splitlines() if not line.startswith("$ ")]
    reason = next((line.strip() for line in reversed(lines) if re.search(r"error|exception|fatal", line, re.I)), "")
    text = f"the bake process exited with status {code}{_signal_name(code)} before writing its summary"
    if reason:
        text += f": {reason}"
    return text + (f"\nits last output:\n" + "\n".join(lines) if lines else f"; see {log}")


def _remove_stale(task):
    """Summaries and logs of earlier fingerprints: they describe files this bake replaces."""
    keep = {os.path.abspath(task.summary), os.path.abspath(task.log)}
    for path in glob.glob(os.path.join(glob.escape(task.output), "mc_ao-" + "[0-9a-f]" * 16 + ".*")):
        if os.path.abspath(path) not in keep and path.endswith((".json", ".log")):
            try:
                os.remove(path)
            except OSError:
                pass


def run_task(task, *, force=False, rebake_older=False, blender=None, on_start=None, on_process=None, env=None):
    """Bake one task unless it is done; return its record (a dict). Never raises for a failed bake.

    A task whose output an older output version made is kept (a "skipped" record with ``older``: that
    version) unless ``rebake_older`` or the task's own ``rebake_older``; ``force`` bakes every task.

    ``task``: a :class:`Task` or its dict. ``blender``: see :func:`find_baker`. ``on_start(info)``
    is called once the bake process runs, with the task's name, this process's pid and the bake's
    process group; ``on_process(proc)`` gets the :class:`subprocess.Popen` of the guard (close its
    stdin to stop the bake). ``env``: the bake's environment (default: this process's).
    """
    if isinstance(task, dict):
        task = Task.from_dict(task)
    t0 = time.perf_counter()
    if not force:
        reason = why_not_done(task)
        if reason is None:
            record = _record(task, "skipped", exit_code=0, attempts=0)
            _from_summary(record, read_summary(task.summary), task)
            record["seconds"] = time.perf_counter() - t0
            return record
        kept = keeps_older(task, rebake_older)
        if kept is not None:
            record = _record(task, "skipped", exit_code=0, attempts=0, older=kept[0], summary=kept[1])
            _from_summary(record, read_summary(kept[1]), task)
            record["seconds"] = time.perf_counter() - t0
            return record
    try:
        baker = find_baker(blender)
    except NoBakerError as exc:
        return _record(task, "failed", error=str(exc), seconds=time.perf_counter() - t0)
    try:
        os.makedirs(task.output, exist_ok=True)
        if os.path.lexists(task.summary):
            os.remove(task.summary)  # a crash must not leave the previous run's summary in its place
        log = open(task.log, "wb", buffering=0)  # a failed write raises here, not again at close
    except OSError as exc:
        return _record(task, "failed", error=f"cannot write to {task.output}: {exc.strerror or exc}",
                       seconds=time.perf_counter() - t0)
    command = bake_command(task, baker)
    with log:
        try:
            log.write(("$ " + escape(subprocess.list2cmdline(command)) + "\n").encode())
            log.flush()
        except OSError as exc:  # a full disk: the task's failure, with the reason
            return _record(task, "failed", error=f"cannot write the task's log {task.log}: "
                                                 f"{os.strerror(exc.errno) if exc.errno else exc}",
                           seconds=time.perf_counter() - t0)
        try:
            proc = subprocess.Popen([sys.executable, GUARD, "--"] + command, stdin=subprocess.PIPE,
                                    stdout=log, stderr=subprocess.STDOUT, start_new_session=True, env=env)
        except OSError as exc:
            return _record(task, "failed", error=f"cannot start the bake: {exc.strerror or exc}",
                           seconds=time.perf_counter() - t0)
        try:
            if on_process is not None:
                on_process(proc)
            if on_start is not None:
                on_start({"event": "started", "task": task.name, "index": task.index,
                          "host": socket.gethostname(), "pid": os.getpid(), "bake_pid": proc.pid})
            code = proc.wait()
        finally:
            if proc.poll() is None:
                proc.kill()
            try:
                proc.stdin.close()
            except OSError:
                pass
            proc.wait()
    summary = read_summary(task.summary)
    ok = code == 0 and summary is not None and summary.get("exit_code") == 0 \
        and bool(summary.get("objects")) and all(o.get("status") == "ok" for o in summary["objects"])
    record = _record(task, "ok" if ok else "failed", exit_code=code)
    if summary is not None:
        _from_summary(record, summary, task)
    if not ok:
        record["error"] = _failure_text(code, summary, task.log)
    else:
        _remove_stale(task)
    record["seconds"] = time.perf_counter() - t0
    return record
