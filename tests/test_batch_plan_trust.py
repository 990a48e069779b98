"""The batch's plan, without baking: how many tasks run at once and on how many processes each, where a
manifest's Into file is found, and entries compared by the file they reach.

A fake Blender (a script that records its command line) stands in for the bake where a test needs the
runner to start tasks.
"""

import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from batch_helpers import BATCH
from mc_ao_batch.cli import BYTES_PER_BAKE_PROCESS, batch_share
from mc_ao_batch.manifest import ManifestError, plan

GiB = 1 << 30


def test_tasks_at_a_time_are_at_most_the_cores_and_each_bake_gets_its_share():
    assert batch_share(100000, cores=2, memory=64 * GiB) == (2, 1, "2 cores")
    assert batch_share(100000, cores=2, memory=1.5 * GiB) == (2, 1, "2 cores")
    assert batch_share(4, cores=16, memory=64 * GiB) == (4, 4, None)  # 4 tasks x 4 processes x 1 thread
    assert batch_share(1, cores=16, memory=64 * GiB) == (1, 16, None)
    assert batch_share(3, cores=16, memory=None) == (3, 5, None)  # memory unknown: the cores alone
    for asked in (1, 2, 3, 5, 8, 16, 100):
        for cores in (1, 2, 3, 8, 16, 64):
            tasks, processes, _ = batch_share(asked, cores=cores, memory=1024 * GiB)
            assert 1 <= tasks <= min(asked, cores) and tasks * processes <= cores


def test_tasks_at_a_time_and_their_processes_fit_the_memory_by_the_process_model():
    from core import cost

    def needs(tasks, processes):  # every task's Blender and its bake's worker processes
        return tasks * (BYTES_PER_BAKE_PROCESS + (processes * cost.process_bytes(0) if processes > 1 else 0))

    for memory in (1.0 * GiB, 1.2 * GiB, 2 * GiB, 4 * GiB, 8 * GiB):  # 1 GiB: one task, room for 2 processes
        tasks, processes, why = batch_share(16, cores=16, memory=memory)
        assert needs(tasks, processes) <= 0.8 * memory < needs(tasks, processes + 1)  # the most that fit
        assert tasks * processes <= 16 and f"memory for {tasks} x {processes} processes" in why
    assert batch_share(16, cores=16, memory=1)[:2] == (1, 1)  # never fewer than one task on one process
    assert batch_share(2, cores=2, memory=64 * GiB) == (2, 1, None)


def _fake_blender(folder):
    """An executable that records its command line beside the task's summary and fails (no summary)."""
    exe = folder / "fake-blender"
    exe.write_text(f"#!{sys.executable}\n"
                   "import json, sys\n"
                   "args = sys.argv[1:]\n"
                   "summary = args[args.index('--summary-json') + 1]\n"
                   "open(summary + '.args', 'w').write(json.dumps(args))\n"
                   "sys.exit(3)\n")
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    return exe


def test_a_huge_workers_count_is_clamped_and_said(tmp_path):
    """--workers 100000 started every task at once (363 processes, 6 GB in 14 s)."""
    from core.base.machine import cpu_count

    lib = tmp_path / "lib"
    lib.mkdir()
    entries = "".join(f'[[bake]]\nblend = "a{i}.blend"\n\n' for i in range(3))
    (lib / "m.toml").write_text("[defaults]\nsamples = 8\n\n" + entries)
    for i in range(3):
        (lib / f"a{i}.blend").write_bytes(b"BLENDER")
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, str(BATCH), str(lib / "m.toml"), "--output", str(out), "--workers", "100000",
                           "--blender", str(_fake_blender(tmp_path))], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stdout + proc.stderr  # the fake bakes fail
    want, processes, _ = batch_share(100000)
    assert want <= cpu_count()
    assert f"--workers 100000: {want} tasks at a time ({cpu_count()} cores" in proc.stderr
    data = json.loads((out / "mc_ao_batch.json").read_text())
    assert data["workers"] == want and data["workers_asked"] == 100000
    for task in data["tasks"]:
        args = json.loads(Path(task["summary"] + ".args").read_text())
        assert args[args.index("--threads") + 1] == "1" and args[args.index("--processes") + 1] == str(processes)


def test_an_entry_that_sets_processes_or_threads_keeps_them(tmp_path):
    (tmp_path / "m.toml").write_text('[[bake]]\nblend = "a.blend"\nprocesses = 3\n\n'
                                     '[[bake]]\nblend = "b.blend"\nthreads = 2\n\n[[bake]]\nblend = "c.blend"\n')
    a, b, c = plan(tmp_path / "m.toml", tmp_path / "out", threads=1, processes=4)
    assert (a.processes, a.threads, a.args[a.args.index("--processes") + 1]) == (0, 1, "3")
    assert (b.processes, b.threads) == (0, 2)
    assert (c.processes, c.threads) == (4, 1)


def test_into_is_found_beside_the_manifest_not_in_the_working_folder(tmp_path, monkeypatch):
    """As blend is: a batch run from another folder holding a file of the same name packed into that one."""
    lib, elsewhere = tmp_path / "lib", tmp_path / "elsewhere"
    (lib / "tex").mkdir(parents=True)
    elsewhere.mkdir()
    (lib / "tex" / "orm.png").write_bytes(b"\x89PNG\r\n\x1a\nthe library's")
    (elsewhere / "tex").mkdir()
    (elsewhere / "tex" / "orm.png").write_bytes(b"\x89PNG\r\n\x1a\nanother file of the same name")
    manifest = lib / "m.toml"
    manifest.write_text('[defaults]\nchannel = "R"\n\n[[bake]]\nblend = "a.blend"\ninto = "tex/orm.png"\n\n'
                        '[[bake]]\nblend = "b.blend"\ninto = "ORM"\n')
    monkeypatch.chdir(elsewhere)
    a, b = plan(manifest, tmp_path / "out")
    assert a.args[a.args.index("--into") + 1] == str(lib / "tex" / "orm.png")
    assert b.args[b.args.index("--into") + 1] == "ORM"  # no such file there: a Blender image's name, as given

    # The Into file is an input: a changed one bakes again; a library moved with its manifest does not.
    moved = tmp_path / "moved"
    shutil.copytree(lib, moved, copy_function=shutil.copy2)
    [a_moved, _] = plan(moved / "m.toml", tmp_path / "out2")
    assert a_moved.fingerprint == a.fingerprint
    (lib / "tex" / "orm.png").write_bytes(b"\x89PNG\r\n\x1a\nthe library's, painted over")
    [a_changed, _] = plan(manifest, tmp_path / "out")
    assert a_changed.fingerprint != a.fingerprint


def test_two_entries_that_reach_one_blend_file_are_refused(tmp_path):
    (tmp_path / "real.blend").write_bytes(b"BLENDER")
    os.symlink(tmp_path / "real.blend", tmp_path / "link.blend")
    (tmp_path / "m.toml").write_text('[[bake]]\nblend = "real.blend"\n\n[[bake]]\nblend = "link.blend"\n')
    with pytest.raises(ManifestError, match="the same file as entry 1"):
        plan(tmp_path / "m.toml", tmp_path / "out")
