"""The batch mode end to end: a generated library of six assets (one broken), baked by the local runner,
by Dask (2 worker processes, one of them killed mid-run), and by Blender's command line.

Everything runs on this machine (Dask on 127.0.0.1), with tiny assets (16 x 16 texels, 8 samples).
Nothing here waits on a clock: a worker is killed when its task says it started.
"""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from core.files import imageio
from core._version import OUTPUT_VERSION
from mc_ao_batch import cli
from mc_ao_batch.manifest import plan
from mc_ao_batch.task import why_not_done

from batch_helpers import (  # noqa: F401 (library, local_run: fixtures)
    BATCH, IMAGE_SUFFIXES, ROOT, STARTED, batch, images, library, local_run, sub_manifest, summary,
)

pytestmark = pytest.mark.blender


def test_local_runner_bakes_every_asset_and_the_broken_one_fails_alone(local_run):
    out, proc = local_run
    assert proc.returncode == 1, proc.stderr
    data, tasks = summary(out)
    assert data["exit_code"] == 1 and data["counts"] == {"ok": 5, "skipped": 0, "older": 0, "failed": 1}
    broken = tasks["broken.blend"]
    assert broken["status"] == "failed" and broken["objects"] == [] and broken["files"] == []
    assert "cannot open" in broken["error"] and "broken.blend" in broken["error"]
    # the message reaches the user in the progress line and under the table, with the log's path
    assert re.search(r"broken: FAILED.*cannot open .*broken\.blend", proc.stdout)
    assert "broken (broken.blend) failed: cannot open" in proc.stdout and broken["log"] in proc.stdout
    assert re.search(r"^4 +broken +FAILED", proc.stdout, re.M)
    assert "5 baked, 0 already done, 1 failed of 6" in proc.stdout

    for blend, t in tasks.items():
        if t is broken:
            continue
        assert t["status"] == "ok" and t["error"] is None and t["exit_code"] == 0, t
        assert t["rays"] > 0 and t["seconds"] > 0 and t["attempts"] == 1
        assert [o["status"] for o in t["objects"]] == ["ok", "ok"]
        for f in t["files"]:
            assert os.path.isabs(f) and Path(f).parent == Path(t["output"]) and Path(f).is_file()

    # the layout: OUTPUT/<safe blend stem>/<object>_AO.<ext>; the two lamp.blend files stay apart
    folders = sorted(p.name for p in out.iterdir() if p.is_dir())
    lamps = [f for f in folders if f.startswith("lamp-")]
    assert len(lamps) == 2 and re.fullmatch(r"lamp-[0-9a-f]{8}", lamps[0])
    assert "chair" in folders and "torus" in folders and "broken" in folders
    crate = next(f for f in folders if f.startswith("crate v2_-"))  # '?' is not a safe file name
    assert sorted(images(out / "chair")) == ["Block_AO.exr", "Block_AO.png", "Ground_AO.exr", "Ground_AO.png"]
    assert sorted(images(out / crate)) == ["Crate_AO.png", "Lid_AO.png"]  # its entry: png only
    assert sorted(images(out / tasks["props/lamp.blend"]["task"])) == [
        "Ground_AO.exr", "Ground_AO.png", "Shade_AO.exr", "Shade_AO.png"]  # no objects: every mesh

    # per-entry overrides reach the bake
    ring, meta = imageio.read_image(out / "torus" / "Ring_AO.exr")
    assert np.squeeze(ring).shape == (16, 24) and meta["resolution"] == "24x16"
    _, meta = imageio.read_image(out / tasks["more/lamp.blend"]["task"] / "Bulb_AO.exr")
    assert meta["samples"] == 16 and meta["seed"] == 3
    _, meta = imageio.read_image(out / "chair" / "Block_AO.exr")
    assert meta["samples"] == 8 and meta["seed"] == 0 and meta["margin"] == 2


def test_dask_runner_gives_byte_identical_files(library, local_run, tmp_path):
    out, _ = local_run
    proc = batch(library, "--output", tmp_path, "--runner", "dask", "--workers", 2, "--blender", "bpy")
    assert proc.returncode == 1, proc.stderr
    data, tasks = summary(tmp_path)
    assert data["runner"] == "dask" and data["counts"] == {"ok": 5, "skipped": 0, "older": 0, "failed": 1}
    assert "cannot open" in tasks["broken.blend"]["error"]
    assert len({t["pid"] for t in data["tasks"]}) == 2  # two worker processes did the work
    local, dask = images(out), images(tmp_path)
    assert len(local) == 18 and sorted(dask) == sorted(local)
    assert [k for k in local if local[k] != dask[k]] == []


def test_second_run_skips_every_finished_task(library, local_run, tmp_path):
    out, _ = local_run
    copy = tmp_path / "moved"  # a moved output folder still counts as done
    shutil.copytree(out, copy)
    before = {p: p.stat().st_mtime_ns for p in copy.rglob("*") if p.suffix in IMAGE_SUFFIXES}
    proc = batch(library, "--output", copy, "--workers", 2, "--blender", "bpy", "--verbose")
    assert proc.returncode == 1, proc.stderr
    data, tasks = summary(copy)
    assert data["counts"] == {"ok": 0, "skipped": 5, "older": 0, "failed": 1}
    # only the broken asset was started again; nothing was rewritten
    started = [m.group("task") for m in map(STARTED.match, proc.stdout.splitlines()) if m]
    assert started == ["broken"]
    assert {p: p.stat().st_mtime_ns for p in before} == before
    for t in data["tasks"]:
        if t["status"] == "skipped":
            assert t["attempts"] == 0 and t["files"] and all(Path(f).parent.parent == copy for f in t["files"])
    assert "0 baked, 5 already done, 1 failed of 6" in proc.stdout
    first, _ = summary(out)
    print(f"first run {first['seconds']:.1f} s, second run {data['seconds']:.1f} s")


def test_a_task_bakes_again_when_its_asset_settings_or_files_change(library, local_run, tmp_path):
    out, _ = local_run
    work = tmp_path / "out"
    shutil.copytree(out, work)
    lib = tmp_path / "lib"
    shutil.copytree(library.parent, lib)
    manifest = lib / "manifest.toml"

    def reasons():
        return {t.blend_given: why_not_done(t) for t in plan(manifest, work, threads=1)}

    r = reasons()
    assert [b for b, why in r.items() if why is not None] == ["broken.blend"]
    assert r["broken.blend"] == "the last bake failed"

    # a changed setting: a new fingerprint, nothing baked with it yet
    manifest.write_text(manifest.read_text().replace('blend = "torus.blend"\n', 'blend = "torus.blend"\nseed = 9\n'))
    assert reasons()["torus.blend"] == "not baked with these settings yet"
    # a changed asset (saved again: new modification time)
    chair = lib / "chair.blend"
    os.utime(chair, ns=(chair.stat().st_atime_ns, chair.stat().st_mtime_ns + 10**9))
    assert reasons()["chair.blend"] == "not baked with these settings yet"
    # a deleted file
    lamp = next(p for p in work.iterdir() if p.name.startswith("lamp-") and (p / "Shade_AO.png").exists())
    (lamp / "Shade_AO.png").unlink()
    assert reasons()["props/lamp.blend"].endswith("Shade_AO.png is missing")
    # a file swapped for another object's bake
    crate = next(p for p in work.iterdir() if p.name.startswith("crate"))
    shutil.copyfile(crate / "Lid_AO.png", crate / "Crate_AO.png")
    assert reasons()["crate v2?.blend"] == f"{crate / 'Crate_AO.png'} holds the bake of 'Lid', not of 'Crate'"
    # a file replaced by the same object's bake with other settings (torus.blend's Ground: 24x16, 8 samples)
    bulb = next(p for p in work.iterdir() if (p / "Bulb_AO.png").exists())
    shutil.copyfile(work / "torus" / "Ground_AO.exr", bulb / "Ground_AO.exr")
    why = reasons()["more/lamp.blend"]
    assert why.startswith(f"{bulb / 'Ground_AO.exr'}: ") and why.endswith(", the bake recorded 16")
    # the output version that made it (its summary says another): not this version's bake
    record = next(bulb.glob("mc_ao-*.json"))
    data = json.loads(record.read_text())
    data["output_version"] = 1
    record.write_text(json.dumps(data))
    assert reasons()["more/lamp.blend"] == f"made by output version 1, this is {OUTPUT_VERSION}"
    # the mc_ao version alone decides nothing: a release that writes the same values finds it done
    data["output_version"] = OUTPUT_VERSION
    data["mc_ao"] = "0.0.1"
    record.write_text(json.dumps(data))
    assert reasons()["more/lamp.blend"].startswith(f"{bulb / 'Ground_AO.exr'}: ")


def test_force_bakes_again_and_gives_the_same_bytes(library, local_run, tmp_path):
    out, _ = local_run
    work = tmp_path / "out"
    shutil.copytree(out, work)
    proc = batch(library, "--output", work, "--blender", "bpy", "--force", "--entry", 1, "--verbose")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert [m.group("task") for m in map(STARTED.match, proc.stdout.splitlines()) if m] == ["chair"]
    assert summary(work)[0] == summary(out)[0]  # --entry writes no batch summary (farm tasks run at once)
    assert images(work / "chair") == images(out / "chair")
    assert min(p.stat().st_mtime_ns for p in (work / "chair").glob("*_AO.*")) > \
        max(p.stat().st_mtime_ns for p in (out / "chair").glob("*_AO.*"))


def _state(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return None


def _freeze(group):
    """SIGSTOP a task's process group; True once its leader (the guard) is stopped, False when the
    task had ended already. Signals arrive asynchronously: wait for the state to show it."""
    try:
        os.killpg(group, signal.SIGSTOP)
    except ProcessLookupError:
        return False
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        state = _state(group)
        if state in (None, "Z", "X"):
            return False
        if state in ("T", "t"):
            return True
        time.sleep(0.001)
    raise AssertionError(f"process group {group} did not stop")


def _group_alive(pgid):
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # zombies of a dead group still answer; count live members
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == pgid and fields[0] != "Z":
                return True
    return False


def test_killing_a_dask_worker_mid_run_still_completes_the_batch(library, local_run, tmp_path):
    """A task says it started; its bake is frozen (so it cannot finish first) and its worker killed.

    Dask runs the task again on the other (or the restarted) worker; the frozen bake, whose
    runner is gone, is ended by its guard as soon as it runs again.
    """
    out, _ = local_run
    proc = subprocess.Popen(
        [sys.executable, str(BATCH), str(library), "--output", str(tmp_path), "--runner", "dask",
         "--workers", "2", "--blender", "bpy", "--verbose"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    watchdog = threading.Timer(600, proc.kill)
    watchdog.start()
    killed = None
    lines = []
    try:
        for line in proc.stdout:
            lines.append(line)
            m = STARTED.match(line.rstrip("\n"))
            if killed is None and m and m.group("task") != "broken":
                group, worker = int(m.group("bake")), int(m.group("pid"))
                if not _freeze(group):
                    continue  # it finished already: wait for the next task
                os.kill(worker, signal.SIGKILL)
                os.killpg(group, signal.SIGCONT)
                killed = (m.group("task"), worker, group)
        proc.wait()
        stderr = proc.stderr.read()
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
    assert killed is not None, "".join(lines)
    assert proc.returncode == 1, "".join(lines) + stderr
    data, tasks = summary(tmp_path)
    assert data["counts"] == {"ok": 5, "skipped": 0, "older": 0, "failed": 1}
    record = next(t for t in data["tasks"] if t["task"] == killed[0])
    assert record["status"] == "ok" and record["attempts"] == 2 and record["pid"] != killed[1]
    # the retried task's bake ran twice; only the second one counts
    starts = [m.group("task") for m in map(STARTED.match, map(str.rstrip, lines)) if m]
    assert starts.count(killed[0]) == 2
    assert images(tmp_path) == images(out)
    # the first bake of that task did not outlive its worker
    deadline = time.monotonic() + 60
    while _group_alive(killed[2]) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _group_alive(killed[2])


def test_blender_command_line_bakes_the_same_files(library, local_run, tmp_path):
    """The runner's Blender command (also every Flamenco task's), run on the bpy module's Blender."""
    out, _ = local_run
    blender = tmp_path / "blender"
    blender.write_text(f'#!/bin/sh\nexec "{sys.executable}" "{ROOT / "tests" / "batch_blender_cli.py"}" "$@"\n')
    blender.chmod(0o755)
    manifest = sub_manifest(library, {"chair.blend", "torus.blend", "broken.blend"}, "three.toml")
    proc = batch(manifest, "--output", tmp_path / "out", "--workers", 2, "--blender", blender)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert f"baked by Blender {blender}" in proc.stdout
    data, tasks = summary(tmp_path / "out")
    assert tasks["broken.blend"]["status"] == "failed"
    error = tasks["broken.blend"]["error"].splitlines()[0]  # what the progress line shows
    assert error.startswith("the bake process exited with status 1 before writing its summary: Error:")
    assert "broken.blend" in error and "Missing DNA block" in error
    for name in ("chair", "torus"):
        assert images(tmp_path / "out" / name) == images(out / name)
    log = Path(tasks["chair.blend"]["log"]).read_text()
    assert f"{blender} --background {library.parent / 'chair.blend'} --python-exit-code 1 --python" in log


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_interrupt_stops_the_running_bakes(library, tmp_path):
    """Ctrl-C while a bake runs: the batch exits 130 and that bake never finishes.

    The bake is frozen when its task says it started, so it cannot finish before the runner has
    been interrupted; once thawed, its guard sees the runner's pipe closed and ends it.
    """
    proc = subprocess.Popen(
        [sys.executable, str(BATCH), str(library), "--output", str(tmp_path), "--workers", "1",
         "--blender", "bpy", "--verbose"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        # SIGINT at its default in the batch: a process started in the background by a non-interactive
        # shell (`pytest &`, some CI runners) inherits it *ignored*, and keeps it so across exec.
        preexec_fn=_default_sigint)
    watchdog = threading.Timer(300, proc.kill)
    watchdog.start()
    try:
        for line in proc.stdout:
            m = STARTED.match(line.rstrip("\n"))
            if m:
                task, group = m.group("task"), int(m.group("bake"))
                assert _freeze(group)
                proc.send_signal(signal.SIGINT)
                os.killpg(group, signal.SIGCONT)
                break
        out, err = proc.communicate()
    finally:
        watchdog.cancel()
    assert proc.returncode == 130, out + err
    assert "interrupted" in out
    data, _ = summary(tmp_path)
    assert data["exit_code"] == 130  # no task finished: each is recorded as interrupted
    assert data["tasks"] and all(t["status"] == "failed" and t["error"].startswith("interrupted")
                                 for t in data["tasks"])
    deadline = time.monotonic() + 60
    while _group_alive(group) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _group_alive(group)
    assert not list((tmp_path / task).glob("mc_ao-*.json")), "the interrupted bake ran to its end"


@pytest.mark.parametrize("text, message", [
    ("[[bake]]\nblend = 'a.blend'\nsample = 4\n", "unknown setting 'sample'"),
    ("[[bake]]\nblend = 'a.blend'\nmax-distance = 1.0\n", "write it 'max_distance'"),
    ("[[bake]]\nblend = 'a.blend'\noutput = 'x'\n", "the batch sets it for each task"),
    ("[[bake]]\nblend = 'a.blend'\nsource = 'owen'\n", "argument --source: invalid choice: 'owen'"),
    ("[[bake]]\nblend = 'a.blend'\nsamples = 'many'\n", "argument --samples: invalid int value: 'many'"),
    ("[[bake]]\nblend = 'a.blend'\nresolution = '0'\n", "is not a size"),
    ("[[bake]]\nblend = 'a.blend'\nstderr = 'yes'\n", "stderr must be true or false"),
    ("[[bake]]\nblend = 'a.blend'\n[[bake]]\nblend = './a.blend'\n", "entry 2 (./a.blend): the same file as entry 1"),
    ("[defaults]\nobjects = ['A']\n[[bake]]\nblend = 'a.blend'\n", "objects belong to a [[bake]] entry"),
    ("[[bake]]\nobjects = ['A']\n", "entry 1: blend = \"path/to/file.blend\" is required"),
    ("[defaults]\nsamples = 4\n", "no [[bake]] entries"),
    ("[bake]\nblend = 'a.blend'\n", "bake must be an array of tables"),
    ("[jobs]\n", "unknown table jobs"),
    ("[[bake]\n", "not valid TOML"),
])
def test_a_bad_manifest_exits_2_before_anything_runs(tmp_path, capsys, text, message):
    manifest = tmp_path / "m.toml"
    manifest.write_text(text)
    out = tmp_path / "out"
    assert cli.main([str(manifest), "--output", str(out), "--blender", "bpy"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bake_batch: error: ") and message in err, err
    assert "Traceback" not in err and not out.exists()


def test_folder_names_do_not_depend_on_order_and_avoid_the_summary(tmp_path):
    entries = ["a/Chair.blend", "b/chair.blend", "c/table.blend", "mc_ao_batch.json.blend"]
    (tmp_path / "m.toml").write_text("".join(f"[[bake]]\nblend = '{e}'\n" for e in entries))
    (tmp_path / "r.toml").write_text("".join(f"[[bake]]\nblend = '{e}'\n" for e in reversed(entries)))
    names = {t.blend_given: t.name for t in plan(tmp_path / "m.toml", tmp_path / "out")}
    again = {t.blend_given: t.name for t in plan(tmp_path / "r.toml", tmp_path / "out")}
    assert names == again
    assert names["c/table.blend"] == "table"
    assert names["a/Chair.blend"].startswith("Chair-") and names["b/chair.blend"].startswith("chair-")
    assert names["a/Chair.blend"].casefold() != names["b/chair.blend"].casefold()
    assert names["mc_ao_batch.json.blend"].startswith("mc_ao_batch.json-")


def test_dask_runner_uses_a_running_scheduler(library, local_run, tmp_path):
    """--scheduler: the tasks go to a cluster someone else started (here one on 127.0.0.1)."""
    from distributed import Client, LocalCluster

    out, _ = local_run
    manifest = sub_manifest(library, {"chair.blend", "broken.blend"}, "scheduler.toml")
    with LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None) as cluster:
        proc = batch(manifest, "--output", tmp_path, "--runner", "dask", "--scheduler", cluster.scheduler_address,
                     "--blender", "bpy")
        with Client(cluster) as client:
            worker_pids = set(client.run(os.getpid).values())
    assert proc.returncode == 1, proc.stdout + proc.stderr
    data, tasks = summary(tmp_path)
    assert data["runner"] == "dask" and data["counts"] == {"ok": 1, "skipped": 0, "older": 0, "failed": 1}
    assert "cannot open" in tasks["broken.blend"]["error"]
    assert {t["pid"] for t in data["tasks"]} <= worker_pids  # run by that cluster's worker
    assert images(tmp_path / "chair") == images(out / "chair")


class _Terminal:
    """A stream that says it is a terminal, keeping what is written."""

    def __init__(self):
        self.text = ""

    def isatty(self):
        return True

    def write(self, s):
        self.text += s

    def flush(self):
        pass


def test_progress_bar_on_a_terminal_follows_the_tasks_events():
    from mc_ao_batch.report import Progress

    bar, out = _Terminal(), _Terminal()
    progress = Progress(4, stream=bar, out=out)
    progress.started({"task": "a", "host": "h", "pid": 1, "bake_pid": 2})
    assert bar.text.endswith("[------------------------------] 0/4 tasks, 1 running" + bar.text[bar.text.rindex("  "):])
    record = {"task": "a", "status": "ok", "objects": [{}, {}], "seconds": 1.25, "error": None}
    progress.finished(record)
    assert "[1/4] a: ok, 2 objects, 1.2 s\n" in out.text
    assert "[#######-----------------------] 1/4 tasks, 0 running" in bar.text
    progress.finished(dict(record, task="b", status="failed", error="cannot open b.blend\nmore"))
    assert "[2/4] b: FAILED, 2 objects, 1.2 s: cannot open b.blend\n" in out.text
    assert "2/4 tasks, 0 running, 1 failed" in bar.text
    progress.finished(dict(record, task="c", status="skipped"))
    assert "[3/4] c: skipped (done)\n" in out.text and "3/4 tasks, 0 running, 1 skipped, 1 failed" in bar.text
    progress.close()
    assert bar.text.endswith("\r\x1b[2K")


def test_bakes_under_dask_do_not_inherit_the_nannys_worker_settings(monkeypatch):
    """MALLOC_TRIM_THRESHOLD_=65536, which Dask's nanny gives its workers, halves a bake's speed."""
    pytest.importorskip("distributed")  # requirements-batch.txt; absent from the numpy 2 run of the core
    from mc_ao_batch.runners import bake_environment

    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")  # as the nanny sets it
    monkeypatch.setenv("OMP_NUM_THREADS", "3")  # set by the user: not the nanny's value
    monkeypatch.setenv("MC_AO_SOMETHING", "kept")
    env = bake_environment()
    assert "MALLOC_TRIM_THRESHOLD_" not in env
    assert env["OMP_NUM_THREADS"] == "3" and env["MC_AO_SOMETHING"] == "kept"


@pytest.mark.parametrize("text, message", [
    ("[defaults]\nsamples = 0\n[[bake]]\nblend = 'a.blend'\n", "entry 1 (a.blend): --samples must be from 1 to"),
    ("[[bake]]\nblend = 'a.blend'\n[[bake]]\nblend = 'b.blend'\nformat = ['exr']\nbits = '8'\nmargin = -1\n",
     "entry 2 (b.blend): --margin must be from 0 to 65536, not -1; --bits 8 cannot be written as exr"),
])
def test_values_out_of_range_stop_the_batch_before_anything_runs(tmp_path, capsys, text, message):
    """bake_ao.py's own checks of every value run for every entry at planning (not once per task)."""
    from mc_ao_batch.manifest import bake_script_module

    if not hasattr(bake_script_module(), "settings_from"):
        pytest.skip("this scripts/bake_ao.py has no settings_from (an older script without value checks)")
    manifest = tmp_path / "m.toml"
    manifest.write_text(text)
    assert cli.main([str(manifest), "--output", str(tmp_path / "out"), "--blender", "bpy"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and not (tmp_path / "out").exists()
