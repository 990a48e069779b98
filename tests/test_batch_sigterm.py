"""SIGTERM (a farm cancelling the job, ``kill``) stops the batch as Ctrl-C does: the running bakes end,
the summary records the tasks that finished, the exit status says it was SIGTERM (143)."""

import json
import signal
import subprocess
import sys
import threading

import pytest

from batch_helpers import BATCH, STARTED, library, sub_manifest  # noqa: F401 (library: a fixture)

pytestmark = pytest.mark.blender


def _default_signals():
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def test_sigterm_ends_the_batch_with_its_summary(library, tmp_path):
    """Two tasks one at a time; SIGTERM when the second starts: the first is baked, the second not."""
    manifest = sub_manifest(library, ["chair.blend", "torus.blend"], "two.toml")
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, str(BATCH), str(manifest), "--output", str(out), "--workers", "1", "--blender", "bpy",
         "--verbose"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_signals)
    watchdog = threading.Timer(300, proc.kill)
    watchdog.start()
    started = 0
    try:
        for line in proc.stdout:
            if STARTED.match(line.rstrip("\n")):
                started += 1
                if started == 2:
                    proc.send_signal(signal.SIGTERM)
                    break
        stdout, stderr = proc.communicate()
    finally:
        watchdog.cancel()
    assert proc.returncode == 143, stdout + stderr
    assert "terminated (SIGTERM)" in stdout
    data = json.loads((out / "mc_ao_batch.json").read_text())
    assert data["exit_code"] == 143
    tasks = {t["blend"]: t for t in data["tasks"]}
    assert tasks["chair.blend"]["status"] == "ok" and tasks["chair.blend"]["files"]
    assert tasks["torus.blend"]["status"] == "failed" and "interrupted" in tasks["torus.blend"]["error"]
