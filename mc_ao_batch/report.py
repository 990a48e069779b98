"""What a batch shows and keeps: a progress bar (or a line per task in a log), the table, the JSON summary.

Names and errors (which carry object names and manifest paths) are escaped before they are shown
(mc_ao.terminal): nothing a .blend file or a manifest holds can write escape sequences or fake lines.
"""

import json
import os
import sys
import time

from mc_ao.terminal import escape

STATUS_WORDS = {"ok": "ok", "skipped": "skipped (done)", "failed": "FAILED"}


def status_word(record):
    """How a task's record reads: a kept task made by an older output version says so."""
    if record["status"] == "skipped" and record.get("older"):
        return f"kept (made by output version {record['older']})"
    return STATUS_WORDS[record["status"]]


def older_text(n):
    """The batch's line about tasks an older output version made: kept, and how to bake them again."""
    return (f"{n} task{'s' if n != 1 else ''} made by an older version (kept; --rebake-older or "
            "rebake_older = true bakes them again)")


class Progress:
    """Redrawn on the runner's events (a task started or ended), never on a clock.

    On a terminal: one bar line on stderr, with finished lines printed above it. Elsewhere (a log,
    a farm's task output): a line per finished task on stdout, which is the progress there.
    """

    def __init__(self, total, stream=None, out=None, verbose=False, quiet=False):
        self.total = total
        self.stream = stream or sys.stderr
        self.out = out or sys.stdout
        self.tty = self.stream.isatty() and not quiet
        self.verbose = verbose
        self.quiet = quiet
        self.done = self.failed = self.skipped = self.running = 0
        self.start = time.monotonic()
        self._drawn = False

    def _clear(self):
        if self._drawn:
            self.stream.write("\r\x1b[2K")
            self._drawn = False

    def _draw(self):
        if not self.tty:
            return
        width = 30
        filled = int(width * self.done / max(self.total, 1))
        text = (f"[{'#' * filled}{'-' * (width - filled)}] {self.done}/{self.total} tasks"
                f", {self.running} running")
        if self.skipped:
            text += f", {self.skipped} skipped"
        if self.failed:
            text += f", {self.failed} failed"
        text += f"  {time.monotonic() - self.start:.0f} s"
        self.stream.write("\r\x1b[2K" + text)
        self.stream.flush()
        self._drawn = True

    def line(self, text):
        self._clear()
        print(text, file=self.out, flush=True)
        self._draw()

    def started(self, info):
        self.running += 1
        if self.verbose:
            self.line(f"bake_batch: started {info['task']} on {info.get('host')} "
                      f"(worker pid {info.get('pid')}, bake pid {info.get('bake_pid')})")
        else:
            self._draw()

    def finished(self, record):
        self.done += 1
        if record["status"] != "skipped":
            self.running = max(0, self.running - 1)
        self.failed += record["status"] == "failed"
        self.skipped += record["status"] == "skipped"
        if not self.quiet or record["status"] == "failed":
            text = f"[{self.done}/{self.total}] {escape(record['task'])}: {status_word(record)}"
            if record["status"] != "skipped":
                text += f", {object_count(record)} objects, {record['seconds']:.1f} s"
            if record["error"]:
                text += ": " + escape(record["error"].splitlines()[0])
            self.line(text)
        else:
            self._draw()

    def close(self):
        self._clear()
        self.stream.flush()


def object_count(record):
    """The objects a task baked: an object baked for AO and thickness is one object of two entries."""
    return len({o.get("object", i) for i, o in enumerate(record["objects"])})


def _mrays(record):
    return record["rays"] / record["bake_seconds"] / 1e6 if record["bake_seconds"] > 0 else 0.0


def table(records):
    """The end-of-run table: one row per task, then the errors in full."""
    header = ("#", "asset", "status", "objects", "seconds", "Mrays/s", "files")
    rows = []
    for r in sorted(records, key=lambda r: r["index"]):
        rows.append((str(r["index"]), escape(r["task"]), status_word(r), str(object_count(r)),
                     f"{r['seconds']:.1f}", f"{_mrays(r):.2f}" if r["status"] == "ok" else "-",
                     str(len(r["files"]))))
    widths = [max(len(row[i]) for row in rows + [header]) for i in range(len(header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip() for row in [header] + rows]
    failed = [r for r in sorted(records, key=lambda r: r["index"]) if r["status"] == "failed"]
    if failed:
        lines.append("")
        for r in failed:
            error = "\n".join(escape(line) for line in str(r["error"]).splitlines())
            lines.append(f"{escape(r['task'])} ({escape(r['blend'])}) failed: {error}")
            lines.append(f"  log: {escape(r['log'])}")
    return "\n".join(lines)


def counts(records):
    """Tasks baked, done already, made by an older output version and kept, failed."""
    out = {"ok": 0, "skipped": 0, "older": 0, "failed": 0}
    for r in records:
        out["older" if r["status"] == "skipped" and r.get("older") else r["status"]] += 1
    return out


def write_json_atomic(path, data, inputs=(), replaces=None):
    """Write JSON to ``path`` through core.files.atomicfile (a temporary file read back, then a rename): a new
    file gets the umask's permissions, a replaced one keeps its own.

    ``inputs``: ``(path, what)`` pairs the file may never be; ``replaces``: the mc_ao.filecheck kinds of
    an existing file it may replace (None: any but a .blend file or an image). Raises OSError (a
    core.FileWriteError naming the path) when it may not or cannot be written; the old file is then as
    it was.
    """
    from core.files import atomicfile
    from core.base.errors import FileWriteError

    problem = output_problem(path, inputs, replaces)
    if problem is not None:
        raise FileWriteError(f"{os.fspath(path)!r}: {problem}")
    text = json.dumps(data, indent=1, sort_keys=False) + "\n"
    atomicfile.write_text(path, text)


def output_problem(path, inputs=(), replaces=None):
    """Why a JSON file of the batch may not be written at ``path`` (None when it may): a folder, an input,
    an unwritable folder, a read-only file, or an existing file of another kind."""
    from core.files import atomicfile
    from mc_ao import filecheck

    path = os.path.abspath(path)
    if os.path.isdir(path):
        return "it is a folder"
    problem = filecheck.folder_problem(os.path.dirname(path))
    if problem is not None:
        return f"its folder: {problem}"
    if atomicfile.read_only(path):
        return "it is read-only"
    if replaces is None:
        kind = filecheck.file_kind(path)
        replaces = () if kind is None or kind == "a .blend file" or "image" in kind or "mesh" in kind else (kind,)
    return filecheck.output_problem(path, "", inputs=inputs, replaces=replaces)
