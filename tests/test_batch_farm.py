"""The batch mode on render farms: the Flamenco job type (under Node, and in goja, Flamenco's own
JavaScript engine) and its jobs, submission to a Manager, and the Open Job Description template run by
openjd. The same generated library as tests/test_batch.py (session fixtures in batch_helpers)."""

import json
import shutil
import subprocess
import sys
import threading
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path

import pytest

from batch_helpers import (  # noqa: F401 (library, local_run: fixtures)
    ROOT, batch, images, library, local_run, sub_manifest, summary,
)
from mc_ao_batch.manifest import plan
from mc_ao_batch.task import bake_command

FLAMENCO = ROOT / "farm" / "flamenco"
JOB_TYPE = FLAMENCO / "mc_ao_bake.js"
OPENJD_TEMPLATE = ROOT / "farm" / "openjd" / "mc_ao_bake.yaml"
OPENJD = Path(sys.executable).with_name("openjd")


def _node():
    node = shutil.which("node")
    if node is None:
        pytest.skip("Node.js is not installed (the Flamenco job type's tests run under it)")
    return node


def test_flamenco_job_type_passes_its_node_tests():
    proc = subprocess.run([_node(), "--test", str(FLAMENCO)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr
    assert "# fail 0" in proc.stdout and "# pass 5" in proc.stdout


def compile_with_node(job_file):
    proc = subprocess.run([_node(), str(FLAMENCO / "standin" / "compile.js"), str(JOB_TYPE), str(job_file)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


@pytest.fixture(scope="module")
def gojacheck(tmp_path_factory):
    """farm/flamenco/standin/gojacheck built: the job type run by goja at the version Flamenco pins."""
    go = shutil.which("go")
    if go is None:
        pytest.skip("Go is not installed (it builds the goja check of the Flamenco job type)")
    exe = tmp_path_factory.mktemp("goja") / "gojacheck"
    proc = subprocess.run([go, "build", "-o", str(exe), "."], cwd=FLAMENCO / "standin" / "gojacheck",
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    return exe


def flamenco_argv(command, blender_args=()):
    """The argv a Flamenco Worker runs for a blender-render command (internal/worker/command_blender.go)."""
    p = command["parameters"]
    assert command["name"] == "blender-render" and p["exeArgs"] == "{blenderArgs}"
    return [p["exe"], *blender_args, *p["argsBefore"], *([p["blendfile"]] if p["blendfile"] else []), *p["args"]]


def test_flamenco_job_compiles_to_the_local_runners_blender_commands(library, local_run, tmp_path, gojacheck):
    out = tmp_path / "out"
    job_file = tmp_path / "job.json"
    proc = batch(library, "--output", out, "--runner", "flamenco", "--job-file", job_file)
    assert proc.returncode == 0, proc.stderr
    assert "6 tasks to bake, 0 already done" in proc.stdout
    job = json.loads(job_file.read_text())
    assert job["type"] == "mc-ao-bake" and job["submitter_platform"] and job["priority"] == 50
    assert set(job["settings"]) == {"mc_ao_root", "output_root", "tasks"}

    tasks = compile_with_node(job_file)
    # Flamenco's own engine compiles it to the very same tasks
    goja = subprocess.run([str(gojacheck), str(JOB_TYPE), str(job_file)], capture_output=True, text=True,
                          timeout=120)
    assert goja.returncode == 0, goja.stderr
    assert json.loads(goja.stdout) == tasks

    planned = plan(library, out, threads=0)
    assert [t["name"] for t in tasks] == [f"bake-{p.name}" for p in planned]
    for task, planned_task in zip(tasks, planned):
        assert task["type"] == "blender" and len(task["commands"]) == 1 and task["dependencies"] == []
        assert flamenco_argv(task["commands"][0]) == bake_command(planned_task, ("blender", "{blender}"))

    # a Worker runs two of them (Flamenco's default blenderArgs: -b -y), with Blender's command line
    blender = tmp_path / "blender"
    blender.write_text(f'#!/bin/sh\nexec "{sys.executable}" "{ROOT / "tests" / "batch_blender_cli.py"}" "$@"\n')
    blender.chmod(0o755)
    local_out, _ = local_run
    for task in tasks:
        if task["name"] in ("bake-chair", "bake-torus"):
            argv = flamenco_argv(task["commands"][0], ["-b", "-y"])
            run = subprocess.run([str(blender)] + argv[1:], capture_output=True, text=True, timeout=300)
            assert run.returncode == 0, run.stdout + run.stderr
    for name in ("chair", "torus"):
        assert images(out / name) == images(local_out / name)


def test_flamenco_job_leaves_out_what_is_done(library, local_run, tmp_path):
    out, _ = local_run
    work = tmp_path / "out"
    shutil.copytree(out, work)
    job_file = tmp_path / "job.json"
    proc = batch(library, "--output", work, "--runner", "flamenco", "--job-file", job_file)
    assert proc.returncode == 0, proc.stderr
    assert "1 tasks to bake, 5 already done" in proc.stdout
    assert [t["name"] for t in compile_with_node(job_file)] == ["bake-broken"]
    proc = batch(library, "--output", work, "--runner", "flamenco", "--job-file", job_file, "--force")
    assert "6 tasks to bake, 0 already done" in proc.stdout


class _Manager(BaseHTTPRequestHandler):
    """A stand-in for a Flamenco Manager's job submission endpoint (POST /api/v3/jobs)."""

    requests = []
    answer = (200, {"id": "6a6ab0a4-7c7a-4bd0-b1bb-1dfea4f6f0d0", "status": "queued"})

    def do_POST(self):
        body = self.rfile.read(int(self.headers["Content-Length"]))
        type(self).requests.append((self.path, self.headers["Content-Type"], json.loads(body)))
        code, data = type(self).answer
        payload = json.dumps(data).encode()
        self.send_response(code)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(payload)))
        self.end_headers()
        self.wfile.write(payload)

    def log_message(self, *args):
        pass


@pytest.fixture
def manager():
    server = HTTPServer(("127.0.0.1", 0), _Manager)
    _Manager.requests = []
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server, f"http://127.0.0.1:{server.server_port}"
    server.shutdown()
    server.server_close()


def test_flamenco_submission_posts_the_job_to_the_manager(library, tmp_path, manager):
    server, url = manager
    _Manager.answer = (200, {"id": "6a6ab0a4-7c7a-4bd0-b1bb-1dfea4f6f0d0", "status": "queued"})
    proc = batch(library, "--output", tmp_path / "out", "--runner", "flamenco", "--manager", url,
                 "--job-name", "props AO")
    assert proc.returncode == 0, proc.stderr
    assert "submitted job 6a6ab0a4-7c7a-4bd0-b1bb-1dfea4f6f0d0 (props AO)" in proc.stdout
    [(path, content_type, job)] = _Manager.requests
    assert path == "/api/v3/jobs" and content_type == "application/json"
    # SubmittedJob's required fields (Flamenco's OpenAPI: name, type, priority, submitter_platform)
    assert job["name"] == "props AO" and job["type"] == "mc-ao-bake"
    assert isinstance(job["priority"], int) and job["submitter_platform"]
    assert all(isinstance(v, str) for v in job["settings"].values())
    assert all(isinstance(v, str) for v in job["metadata"].values())
    assert len(json.loads(job["settings"]["tasks"])) == 6

    _Manager.answer = (412, {"code": 412, "message": "job type etag does not match"})
    proc = batch(library, "--output", tmp_path / "out", "--runner", "flamenco", "--manager", url)
    assert proc.returncode == 1
    assert "refused the job: HTTP 412: job type etag does not match" in proc.stderr


def test_flamenco_without_a_manager_answering_fails_clearly(library, tmp_path):
    server = HTTPServer(("127.0.0.1", 0), _Manager)
    port = server.server_port
    server.server_close()  # nothing listens there now
    proc = batch(library, "--output", tmp_path, "--runner", "flamenco", "--manager", f"http://127.0.0.1:{port}")
    assert proc.returncode == 1 and f"cannot reach the Flamenco Manager at http://127.0.0.1:{port}" in proc.stderr


def _openjd():
    if not OPENJD.exists():
        pytest.skip(f"openjd-cli is not installed in this Python's environment ({OPENJD}); requirements-batch.txt")
    return OPENJD


def test_openjd_template_passes_openjd_check():
    _openjd()
    proc = subprocess.run([str(OPENJD), "check", str(OPENJD_TEMPLATE)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "passes validation checks" in proc.stdout


def test_openjd_run_bakes_one_task_per_entry(library, local_run, tmp_path):
    _openjd()
    local_out, _ = local_run
    manifest = sub_manifest(library, {"chair.blend", "torus.blend", "broken.blend"}, "openjd.toml")
    params = tmp_path / "params.json"
    out = tmp_path / "out"
    proc = batch(manifest, "--output", out, "--runner", "openjd", "--job-params", params, "--blender", "bpy")
    assert proc.returncode == 0, proc.stderr
    values = json.loads(params.read_text())
    assert values["Entries"] == 3 and values["OutputDir"] == str(out) and values["Blender"] == "bpy"

    def openjd_run(*extra):
        return subprocess.run([str(OPENJD), "run", str(OPENJD_TEMPLATE), "-p", f"file://{params}", *extra],
                              capture_output=True, text=True, timeout=600)

    # the good entries, as a farm runs them: each task on its own
    for entry in (1, 3):
        run = openjd_run("--task-param", f"Entry={entry}")
        assert run.returncode == 0, run.stdout + run.stderr
    for name in ("chair", "torus"):
        assert images(out / name) == images(local_out / name)
    # the broken one fails its task, with the reason in the task's log
    run = openjd_run("--task-param", "Entry=2")
    assert run.returncode != 0
    assert "broken: FAILED" in run.stdout and "cannot open" in run.stdout
    # the whole job in one local session: entry 1 is done already, entry 2 fails the session
    run = openjd_run()
    assert run.returncode != 0
    assert "[1/1] chair: skipped (done)" in run.stdout and "[1/1] broken: FAILED" in run.stdout
