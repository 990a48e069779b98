"""Handing a manifest to a render farm: a Flamenco job (job type farm/flamenco/mc_ao_bake.js) and the
parameters of the Open Job Description template farm/openjd/mc_ao_bake.yaml.

Flamenco: the job carries the planned tasks as JSON in its ``tasks`` setting; the job type's
``compileJob`` (JavaScript, run by the Flamenco Manager) turns each into one ``blender-render`` task
that runs ``scripts/bake_ao.py`` on its .blend file, the same entry point and arguments as the local
runner's Blender command. Tasks that are already done are left out of the job (unless forced), so a
resubmitted job bakes only what changed. The job is written to a file, or submitted to a Manager's
REST API (``POST /api/v3/jobs``, Flamenco 3).

Open Job Description: the template has one task per manifest entry; each runs ``bake_batch.py
--entry N``, so skipping, summaries and logs are the local runner's.
"""

import json
import os
import platform
import urllib.error
import urllib.request

from core._version import __version__

from . import ROOT
from .task import keeps_older, why_not_done

JOB_TYPE = "mc-ao-bake"  # Flamenco names a job type after its script: mc_ao_bake.js
OPENJD_TEMPLATE = ROOT / "farm" / "openjd" / "mc_ao_bake.yaml"


def flamenco_job(tasks, *, output, name, mc_ao_root=None, force=False, priority=50):
    """A Flamenco ``SubmittedJob`` (a dict) for the tasks not done yet; ``(job, skipped tasks)``: those
    done and those an older output version made and that are kept (see :func:`mc_ao_batch.task.keeps_older`)."""
    todo, skipped = [], []
    for task in tasks:
        # an older output version's complete bake is kept unless the task asks to bake it again
        (todo if force or (why_not_done(task) is not None and keeps_older(task) is None) else skipped).append(task)
    plan = [{"name": t.name, "blend": t.blend, "args": t.args, "summary": os.path.basename(t.summary),
             "threads": t.threads} for t in todo]
    job = {
        "name": name,
        "type": JOB_TYPE,
        "priority": priority,
        "submitter_platform": platform.system().lower(),
        "settings": {
            "mc_ao_root": str(mc_ao_root or ROOT),
            "output_root": str(output),
            "tasks": json.dumps(plan),
        },
        "metadata": {"mc_ao.version": __version__, "mc_ao.tasks": str(len(todo))},
    }
    return job, skipped


def submit_flamenco(job, manager, timeout=60):
    """POST the job to a Flamenco Manager; return the Manager's answer (the stored job, with its id)."""
    url = manager.rstrip("/") + "/api/v3/jobs"
    request = urllib.request.Request(url, data=json.dumps(job).encode(), method="POST",
                                     headers={"Content-Type": "application/json", "Accept": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=timeout) as response:
            return json.loads(response.read() or b"{}")
    except urllib.error.HTTPError as exc:
        body = exc.read().decode(errors="replace")
        try:
            body = json.loads(body).get("message", body)
        except (ValueError, AttributeError):
            pass
        raise RuntimeError(f"the Flamenco Manager at {manager} refused the job: HTTP {exc.code}: {body}") from None
    except (urllib.error.URLError, OSError) as exc:
        raise RuntimeError(f"cannot reach the Flamenco Manager at {manager}: {getattr(exc, 'reason', exc)}") from None


def openjd_parameters(manifest, output, count, *, python=None, blender="auto", mc_ao_root=None):
    """Job parameter values for farm/openjd/mc_ao_bake.yaml (for ``openjd run -p file://...``)."""
    import sys

    return {
        "Manifest": os.path.abspath(manifest),
        "OutputDir": os.path.abspath(output),
        "Entries": count,
        "McAoRoot": str(mc_ao_root or ROOT),
        "Python": python or sys.executable,
        "Blender": blender or "auto",
    }
