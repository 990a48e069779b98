"""The batch never destroys what the user owns, and keeps what it did: a manifest's values are never
options, the batch summary's path is checked before the first bake and never replaces the manifest or
a .blend file, the summary is not private to root (0600), a full disk while writing a task's log is the
task's failure (not an internal error), and an interrupted batch records the tasks that finished.
"""

import json
import os
import signal
import stat
import subprocess
import sys
import threading

import pytest

from mc_ao_batch import cli
from mc_ao_batch.manifest import ManifestError, plan
from mc_ao_batch.task import run_task

from batch_helpers import BATCH, STARTED, library, sub_manifest  # noqa: F401 (library: a fixture)
from tests.fullfs import fill, small_filesystem

pytestmark = pytest.mark.blender


def write_manifest(folder, text):
    manifest = folder / "m.toml"
    manifest.write_text(text)
    return manifest


@pytest.mark.parametrize("key, value", [
    ("objects", '["Ground", "--save", "X.blend", "--overwrite-input"]'),
    ("format", '["png", "--stderr"]'),
    ("match_suffix", '["--overwrite-input", "_low"]'),
])
def test_a_list_value_that_looks_like_an_option_is_refused(tmp_path, capsys, key, value):
    blend = tmp_path / "a.blend"
    blend.write_bytes(b"BLENDER-v402 the user's file")
    manifest = write_manifest(tmp_path, f"[[bake]]\nblend = 'a.blend'\n{key} = {value}\n")
    out = tmp_path / "out"
    assert cli.main([str(manifest), "--output", str(out), "--blender", "bpy"]) == 2
    err = capsys.readouterr().err
    assert "starts with '-'" in err and "never an option" in err, err
    assert not out.exists() and blend.read_bytes() == b"BLENDER-v402 the user's file"


@pytest.mark.parametrize("key, value", [("uv_map", "--overwrite-input"), ("image_name", "-{object}")])
def test_a_single_value_that_starts_with_a_dash_stays_a_value(tmp_path, key, value):
    manifest = write_manifest(tmp_path, f"[[bake]]\nblend = 'a.blend'\n{key} = '{value}'\n")
    (task,) = plan(manifest, tmp_path / "out")
    from mc_ao_batch.manifest import bake_parser

    namespace = bake_parser().parse_args([task.blend] + task.args)
    assert getattr(namespace, key) == value and namespace.overwrite_input is False


def test_the_manifest_is_refused_as_its_own_summary_before_anything_runs(tmp_path, capsys):
    manifest = write_manifest(tmp_path, "[[bake]]\nblend = 'a.blend'\n")
    before = manifest.read_bytes()
    out = tmp_path / "out"
    assert cli.main([str(manifest), "--output", str(out), "--blender", "bpy", "--summary", str(manifest)]) == 2
    err = capsys.readouterr().err
    assert "the manifest" in err and "nothing was baked" in err and "Traceback" not in err, err
    assert manifest.read_bytes() == before and not out.exists()


def test_a_blend_file_is_refused_as_the_summary(tmp_path, capsys):
    blend = tmp_path / "a.blend"
    blend.write_bytes(b"BLENDER-v402 the user's file")
    other = tmp_path / "other.blend"  # not in the manifest: refused for what it is
    other.write_bytes(b"BLENDER-v402 another file")
    manifest = write_manifest(tmp_path, "[[bake]]\nblend = 'a.blend'\n")
    for path in (blend, other):
        assert cli.main([str(manifest), "--output", str(tmp_path / "out"), "--blender", "bpy",
                         "--summary", str(path)]) == 2
        assert "nothing was baked" in capsys.readouterr().err
    assert blend.read_bytes() == b"BLENDER-v402 the user's file"
    assert other.read_bytes() == b"BLENDER-v402 another file"


@pytest.mark.parametrize("case", ["folder", "read-only", "under-a-file"])
def test_an_unwritable_summary_stops_the_batch_before_the_first_bake(tmp_path, capsys, case):
    manifest = write_manifest(tmp_path, "[[bake]]\nblend = 'a.blend'\n")
    if case == "folder":
        summary = tmp_path / "taken"
        summary.mkdir()
    elif case == "read-only":
        summary = tmp_path / "summary.json"
        summary.write_text(json.dumps({"mc_ao": "0", "tasks": []}))
        summary.chmod(0o444)
    else:
        (tmp_path / "file").write_text("x")
        summary = tmp_path / "file" / "summary.json"
    out = tmp_path / "out"
    assert cli.main([str(manifest), "--output", str(out), "--blender", "bpy", "--summary", str(summary)]) == 2
    err = capsys.readouterr().err
    assert "cannot write the batch summary" in err and "Traceback" not in err, err
    assert not out.exists()


def test_the_batch_summary_gets_the_umask_permissions(tmp_path):
    pytest.importorskip("bpy")  # the task runs (and fails fast) in the bpy module of this Python
    """A task that fails fast (its .blend file is missing) still gives a summary, readable as any new file."""
    manifest = write_manifest(tmp_path, "[[bake]]\nblend = 'missing.blend'\n")
    out = tmp_path / "out"
    umask = os.umask(0o022)
    try:
        code = cli.main([str(manifest), "--output", str(out), "--blender", "bpy", "--quiet"])
    finally:
        os.umask(umask)
    assert code == 1
    assert stat.S_IMODE((out / "mc_ao_batch.json").stat().st_mode) == 0o644
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary file left


def test_a_full_disk_while_writing_a_tasks_log_fails_that_task_with_the_reason(tmp_path):
    pytest.importorskip("bpy")  # the task would run in the bpy module of this Python
    manifest = write_manifest(tmp_path, "[[bake]]\nblend = 'a.blend'\n")
    with small_filesystem(tmp_path / "disk", size=1 << 20) as disk:
        (task,) = plan(manifest, disk)
        os.makedirs(task.output)
        fill(disk)
        record = run_task(task, blender="bpy")
    assert record["status"] == "failed"
    assert "no space left" in record["error"].lower() and "internal error" not in record["error"], record["error"]


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_an_interrupted_batch_records_the_tasks_that_finished(library, tmp_path):
    """Two tasks one at a time; Ctrl-C when the second starts: the summary has the first as baked."""
    manifest = sub_manifest(library, ["chair.blend", "torus.blend"], "two.toml")
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, str(BATCH), str(manifest), "--output", str(out), "--workers", "1", "--blender", "bpy",
         "--verbose"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)
    watchdog = threading.Timer(300, proc.kill)
    watchdog.start()
    started = 0
    try:
        for line in proc.stdout:
            if STARTED.match(line.rstrip("\n")):
                started += 1
                if started == 2:
                    proc.send_signal(signal.SIGINT)
                    break
        stdout, stderr = proc.communicate()
    finally:
        watchdog.cancel()
    assert proc.returncode == 130, stdout + stderr
    data = json.loads((out / "mc_ao_batch.json").read_text())
    assert data["exit_code"] == 130
    tasks = {t["blend"]: t for t in data["tasks"]}
    assert tasks["chair.blend"]["status"] == "ok" and tasks["chair.blend"]["files"]
    assert tasks["torus.blend"]["status"] == "failed" and "interrupted" in tasks["torus.blend"]["error"]
    assert data["counts"] == {"ok": 1, "skipped": 0, "older": 0, "failed": 1}


def test_a_bad_manifest_value_is_a_manifest_error_naming_the_entry(tmp_path):
    manifest = write_manifest(tmp_path, "[[bake]]\nblend = 'a.blend'\nobjects = ['-x']\n")
    with pytest.raises(ManifestError, match=r"entry 1 \(a.blend\): objects: '-x' starts with '-'"):
        plan(manifest, tmp_path / "out")



def test_the_batch_takes_the_scripts_parser_from_the_package():
    """The batch imports mc_ao.cli for the script's options and checks; it loads no script by its path."""
    import ast

    from pathlib import Path

    from mc_ao import cli as script
    from mc_ao_batch import manifest

    assert manifest.bake_script_module() is script
    parser = manifest.bake_parser()
    assert {a.dest for a in parser._actions} >= {a.dest for a in script.make_parser(with_blend=True)._actions}
    for path in sorted((Path(__file__).resolve().parents[1] / "mc_ao_batch").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            name = node.attr if isinstance(node, ast.Attribute) else node.id if isinstance(node, ast.Name) else None
            assert name not in {"spec_from_file_location", "SourceFileLoader", "run_path", "exec_module"}, \
                f"{path.name} loads a module by its path ({name})"
