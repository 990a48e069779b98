"""The script's --summary-json record: filled in as the run goes, written once, atomically, at its
end (whatever the exit status), and what a Ctrl-C left."""

import json
import os
import sys

from .. import corelink, filecheck
from ..terminal import escape


class Summary:
    """What --summary-json records; filled in as the run goes, written once at its end."""

    def __init__(self, path, blend):
        self.path = path
        self.blend = blend
        self.settings = {}
        self.objects = []
        self.error = None
        self.outputs = []  # (path, what): the run's other files, which the summary may not be

    def problem(self):
        """Why the summary may not be written at its path (None when it may): it is the input .blend
        file, one of the run's files, or an existing file that is not an earlier summary."""
        if self.path is None:
            return None
        if os.path.isdir(self.path):
            return "it is a folder"
        return filecheck.output_problem(self.path, "the summary",
                                        inputs=[(self.blend, "the .blend file being baked")],
                                        outputs=self.outputs, replaces=("an mc_ao summary",))

    def add(self, name, status, seconds=0.0, rays=0, samples_per_texel=0.0, files=(), error=None, **extra):
        self.objects.append({
            "object": name, "status": status, "seconds": float(seconds), "rays": int(rays),
            "samples_per_texel": float(samples_per_texel), "files": [str(f) for f in files],
            "file_stats": {os.path.basename(str(f)): stat for f in files for stat in [file_stat(f)] if stat},
            "error": None if error is None else str(error), **extra,
        })

    def write(self, exit_code):
        """Write the record atomically; False (after saying why) when it cannot be written."""
        if self.path is None:
            return True
        atomicfile = corelink.load("files.atomicfile")
        version = corelink.load("_version")

        record = {
            "mc_ao": version.__version__, "output_version": version.OUTPUT_VERSION, "blend": self.blend,
            "exit_code": exit_code,
            "error": self.error if exit_code else None,
            "settings": self.settings, "objects": self.objects,
        }
        text = json.dumps(record, indent=2) + "\n"
        problem = self.problem()
        if problem is not None:
            print(f"bake_ao: error: the summary {str(self.path)!r} was not written: {problem}", file=sys.stderr)
            return False

        try:
            atomicfile.write_text(self.path, text)
        except OSError as exc:
            print(f"bake_ao: error: the summary {str(self.path)!r} was not written: {exc}", file=sys.stderr)
            return False
        return True


def file_stat(path):
    """[size, modification time in ns] of a file the run wrote, as it left it (None where it cannot be
    read): what tells a later run that a file carrying no metadata of the bake (a channel-packed copy of
    another image keeps that image's attributes) is still the one this run wrote."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns]


def s2a_record(job, result=None):
    """A Selected to Active job's entries in the summary's object record ({} for another job): its
    high-poly objects, and the sample points and texels that missed them."""
    if not job.selected_to_active:
        return {}
    report = getattr(result, "report", None) or {}
    return {"highpoly": [h.name for h in job.highpoly], "cage": job.cage.name if job.cage is not None else None,
            "matching_rays": int(report.get("matching_rays", 0)),
            "missed_sample_points": int(getattr(result, "missed", 0) or 0),
            "missed_texels": int(report.get("missed_texels", 0))}


def parallel_record(result):
    """Where a bake's tiles ran, for the summary's object record: {"parallel": {"processes", "threads",
    "why", and where the core chose between threads and worker processes, "predicted_seconds" of
    each}} (core.pipeline.result.BakeReport.parallel); {} without it."""
    report = getattr(result, "report", None) or {}
    p = report.get("parallel")
    if not p:
        return {}
    out = {k: p[k] for k in ("processes", "threads", "why")}
    if "predicted_seconds" in p:
        out["predicted_seconds"] = {k: round(float(v), 3) for k, v in p["predicted_seconds"].items()}
    return {"parallel": out}


def cancel_note(summary, what="cancelled"):
    """What a cancel left: which objects have all their files written, and of which nothing was
    written (an object's files are written with Ctrl-C held off: all of them or none)."""
    done = [escape(o["object"]) for o in summary.objects if o["status"] == "ok"]
    kept = [escape(o["object"]) for o in summary.objects if o["status"] != "ok"]
    parts = []
    if done:
        parts.append(f"every file of {', '.join(done)} is written")
    if kept:
        parts.append(f"nothing of {', '.join(kept)} was written (any file there is as it was)")
    return f"{what}; " + ("; ".join(parts) or "nothing was written")
