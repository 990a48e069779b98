"""Dask workers and the name of the clone: a worker that cannot import the batch's code fails its task
with the reason (it used to hang the batch), and the tests pass in a clone whose folder is named ``mc_ao``.

The repository root is a package (the extension's ``__init__.py``): a process that has the root's
parent folder first on its path finds the root as ``mc_ao``, not the add-on's ``mc_ao/`` package.
"""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from batch_helpers import BATCH, ROOT

distributed = pytest.importorskip("distributed")  # requirements-batch.txt; absent from the numpy 2 run

_CLUSTER = """
import os, sys
import mc_ao_batch.runners  # the scheduler (this process) can import the batch's code
if sys.argv[1] == "nothing":  # its workers, which take this path, cannot: no repository on it
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != os.path.abspath(sys.argv[2])]
else:  # another mc_ao first
    sys.path.insert(0, sys.argv[1])
from distributed import LocalCluster
cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None)
print(cluster.scheduler_address, flush=True)
sys.stdin.read()  # until the test closes it
cluster.close()
"""


def _start_cluster(cwd, shadow):
    """A local cluster in a process of its own whose scheduler imports the batch's code and whose worker
    has ``shadow`` first on its path ("nothing": no repository on its path)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    with open(Path(cwd) / "cluster.log", "wb") as log:  # its workers' complaints, kept out of the test's output
        proc = subprocess.Popen([sys.executable, "-c", _CLUSTER, str(shadow), str(ROOT)], cwd=cwd, env=env,
                                stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=log, text=True)
    address = proc.stdout.readline().strip()
    assert address.startswith("tcp://"), address
    return proc, address


def _batch_on(tmp_path, shadow):
    manifest = tmp_path / "manifest.toml"
    manifest.write_text('[defaults]\nsamples = 8\n\n[[bake]]\nblend = "scene.blend"\n')
    cluster, address = _start_cluster(tmp_path, shadow)
    try:
        proc = subprocess.run([sys.executable, str(BATCH), str(manifest), "--output", str(tmp_path / "out"),
                               "--runner", "dask", "--scheduler", address, "--blender", "bpy"],
                              capture_output=True, text=True, timeout=300)  # a guard against a hang, not a measure
    finally:
        cluster.stdin.close()
        cluster.wait(timeout=60)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    [task] = json.loads((tmp_path / "out" / "mc_ao_batch.json").read_text())["tasks"]
    assert task["status"] == "failed" and task["attempts"] == 1
    return task["error"]


def test_a_dask_worker_without_the_batchs_code_fails_its_task_with_the_reason(tmp_path):
    """No repository on the worker's path: it cannot import mc_ao_batch itself."""
    error = _batch_on(tmp_path, "nothing")
    assert "cannot import the batch's code" in error and "No module named 'mc_ao_batch'" in error, error


def test_a_dask_worker_that_cannot_import_the_batch_fails_its_task_with_the_reason(tmp_path):
    """The clone named mc_ao, as a worker sees it: the repository root's parent first on its path, so
    ``mc_ao`` is the root's ``__init__.py`` and ``mc_ao.terminal`` does not import; the scheduler can
    import it (in the test that hung, the scheduler was pytest's process). The task fails at once with
    that reason; the batch does not wait for it."""
    shadow = tmp_path / "parent"
    (shadow / "mc_ao").mkdir(parents=True)
    shutil.copy(ROOT / "__init__.py", shadow / "mc_ao" / "__init__.py")  # what the root is, seen as mc_ao
    manifest = tmp_path / "manifest.toml"
    manifest.write_text('[defaults]\nsamples = 8\n\n[[bake]]\nblend = "scene.blend"\n')
    cluster, address = _start_cluster(tmp_path, shadow)
    try:
        t0 = time.monotonic()
        proc = subprocess.run([sys.executable, str(BATCH), str(manifest), "--output", str(tmp_path / "out"),
                               "--runner", "dask", "--scheduler", address, "--blender", "bpy"],
                              capture_output=True, text=True, timeout=300)  # a guard against a hang, not a measure
        seconds = time.monotonic() - t0
    finally:
        cluster.stdin.close()
        cluster.wait(timeout=60)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    data = json.loads((tmp_path / "out" / "mc_ao_batch.json").read_text())
    [task] = data["tasks"]
    assert task["status"] == "failed" and task["attempts"] == 1
    error = task["error"]
    assert "cannot import the batch's code" in error and "No module named 'mc_ao.terminal'" in error, error
    assert str(shadow / "mc_ao" / "__init__.py") in error  # which mc_ao it found
    assert "cannot import the batch's code" in proc.stdout
    print(f"failed in {seconds:.1f} s")


_PROBE = '''
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def where_mc_ao_is():
    import mc_ao.terminal

    return mc_ao.terminal.__file__


def test_processes_started_from_the_tests_import_the_add_on_as_mc_ao():
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster, Client(cluster) as client:
        found = client.submit(where_mc_ao_is, pure=False).result(timeout=120)
    assert found == os.path.join(ROOT, "mc_ao", "terminal.py")
    assert os.path.dirname(ROOT) not in [os.path.abspath(p or ".") for p in sys.path]
'''


@pytest.mark.parametrize("name", ["mc_ao", "any-other-name"])
def test_the_tests_pass_in_a_clone_named_mc_ao(tmp_path, name):
    """pytest in a copy of the repository named ``name``: a Dask cluster started by a test imports the
    add-on's ``mc_ao`` package, not the repository root."""
    clone = tmp_path / name
    clone.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for item in ("__init__.py", "pytest.ini"):
        shutil.copy(ROOT / item, clone / item)
    for folder in ("core", "mc_ao", "mc_ao_batch"):
        shutil.copytree(ROOT / folder, clone / folder, ignore=ignore)
    (clone / "tests").mkdir()
    shutil.copy(ROOT / "tests" / "conftest.py", clone / "tests" / "conftest.py")
    (clone / "tests" / "test_probe.py").write_text(_PROBE)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/test_probe.py"],
                          cwd=clone, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
