"""Worker processes run only the core and its dependencies, from where the parent found them: a json.py
or a numpy.py in the working folder never runs in a worker (they used to: ``python -c`` puts the working
folder first on the path, and the boot imported json before it set the path); a worker that fails at
start shows its own message in the bake's warning (it said "see its message above"); a core imported
under another name (pip's ``mc_ao_core``) has its workers import it under that name.

Each bake runs in a process of its own, so that its pool is its own.
"""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

BAKE = """
import json, sys
sys.path.insert(0, {where!r})
import numpy as np
from {package} import Mesh, bake_ao
P = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
F = np.array([[0, 1, 2], [0, 2, 3]])
ground = Mesh(P, F, uvs=(P[F][:, :, :2] + 1) / 2)
lid = Mesh(P * [0.4, 0.4, 0] + [0, 0, 0.5], F)
r = bake_ao(ground, [lid], resolution=32, samples=16, seed=3, workers=2, threads=1)
one = bake_ao(ground, [lid], resolution=32, samples=16, seed=3, workers=1, threads=1)
print(json.dumps(dict(processes=[m["process"] for m in r.report["worker_memory"]],
                      warnings=list(r.report.get("warnings") or []), same=bool((r.ao == one.ao).all()),
                      cores=sorted(n for n in sys.modules if n == "core" or n.startswith("core."))[:1],
                      numpy=np.__file__)))
"""

SABOTAGE = textwrap.dedent("""
    import os, sys
    open(os.path.join(os.path.dirname(os.path.abspath(__file__)), __name__ + ".ran"), "w").close()
    sys.exit("{name}.py from the working folder ran")
""")


def run(tmp_path, package="core", where=ROOT, cwd=None, env=None):
    script = tmp_path / "bake.py"
    script.write_text(BAKE.format(where=str(where), package=package))
    proc = subprocess.run([sys.executable, str(script)], cwd=cwd or tmp_path, capture_output=True, text=True,
                          timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stderr


def test_a_json_and_a_numpy_in_the_working_folder_never_run_in_a_worker(tmp_path):
    folder = tmp_path / "assets"
    folder.mkdir()
    for name in ("json", "numpy", "embreex", "core"):
        (folder / f"{name}.py").write_text(SABOTAGE.format(name=name))
    out, err = run(tmp_path, cwd=folder)
    assert out["processes"] == ["parent", "worker 0", "worker 1"] and not out["warnings"], (out, err)
    assert out["same"]
    assert not list(folder.glob("*.ran")), "a module of the working folder ran"


def test_a_worker_that_fails_at_start_says_why(tmp_path):
    """Its interpreter writes a reason and exits: the bake bakes on threads and its warning has the reason."""
    fake = tmp_path / "python-that-fails"
    fake.write_text("#!/bin/sh\necho 'mc_ao test: this interpreter lacks embreex' >&2\nexit 3\n")
    fake.chmod(0o755)
    script = tmp_path / "bake.py"
    script.write_text(f"import sys; sys.executable = {str(fake)!r}\n" + BAKE.format(where=str(ROOT), package="core"))
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["processes"] == ["parent"] and out["same"]  # baked here, the same bits
    [warning] = [w for w in out["warnings"] if "worker" in w]
    assert "ended at start-up (exit code 3): mc_ao test: this interpreter lacks embreex" in warning, warning


def test_a_core_imported_as_mc_ao_core_has_its_workers_import_it_so(tmp_path):
    """The core under pip's name (here a link to core/ named mc_ao_core): workers import it under that
    name from the same folder, and no process holds a second copy named core."""
    site = tmp_path / "site"
    site.mkdir()
    os.symlink(ROOT / "core", site / "mc_ao_core")
    out, err = run(tmp_path, package="mc_ao_core", where=site)
    assert out["processes"] == ["parent", "worker 0", "worker 1"] and not out["warnings"], (out, err)
    assert out["same"] and out["cores"] == []


_CLUSTER = """
import sys
import core.pipeline.remote  # the scheduler (this process) can import the core
sys.path.insert(0, sys.argv[1])  # its worker, which takes this path, finds another core first
from distributed import LocalCluster
cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None)
print(cluster.scheduler_address, flush=True)
sys.stdin.read()
cluster.close()
"""

_DASK_BAKE = """
import sys
sys.path.insert(0, {root!r})
import numpy as np
from distributed import Client
from core import Mesh, bake_ao
P = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
F = np.array([[0, 1, 2], [0, 2, 3]])
with Client({address!r}) as client:
    try:
        bake_ao(Mesh(P, F, uvs=(P[F][:, :, :2] + 1) / 2), resolution=32, samples=8, workers=client)
    except Exception as exc:
        print(type(exc).__name__, exc)
"""


def test_a_dask_worker_that_cannot_import_the_core_fails_the_bake_with_the_reason(tmp_path):
    pytest.importorskip("distributed")
    shadow = tmp_path / "shadow"
    (shadow / "core").mkdir(parents=True)
    (shadow / "core" / "__init__.py").write_text("")  # another core, first on the worker's path
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    with open(tmp_path / "cluster.log", "wb") as log:
        cluster = subprocess.Popen([sys.executable, "-c", _CLUSTER, str(shadow)], cwd=tmp_path, env=env,
                                   stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, text=True)
    try:
        address = cluster.stdout.readline().strip()
        script = tmp_path / "bake.py"
        script.write_text(_DASK_BAKE.format(root=str(ROOT), address=address))
        proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True,
                              timeout=300)  # a guard against a hang, not a measure
    finally:
        cluster.stdin.close()
        cluster.wait(timeout=60)
    assert "cannot import the core as 'core.pipeline.remote'" in proc.stdout, proc.stdout + proc.stderr
    assert "No module named 'core.pipeline'" in proc.stdout


def test_an_explicit_worker_count_is_clamped_by_the_cores_and_the_memory_and_said():
    """workers=1000 on this machine starts at most a process a core (--processes 1000 on 2 cores started
    workers until memory ran out), and says so; the bits are one process's."""
    import numpy as np

    from core import Mesh, bake_ao
    from core.base.machine import cpu_count
    from core.execution.executor import clamp_processes

    assert clamp_processes(1000, 1, 1000, cores=2, memory=64 << 30) == (2, "2 cores at 1 thread each")
    assert clamp_processes(1000, 2, 1000, cores=16, memory=64 << 30)[0] == 8
    n, why = clamp_processes(16, 1, 2_000_000, cores=16, memory=4 << 30)
    assert n < 16 and "memory for" in why  # 2M triangles a copy: fewer copies fit
    # The number is the process model's: within 80% of the memory, the parent's share first, then a
    # copy of the scene (target, occluders, high-poly) for each worker.
    from core import cost

    for triangles in ((2_000_000, 0, 0), (300_000, 1_500_000, 0), (200_000, 100_000, 900_000)):
        for memory in (3 << 30, 4 << 30, 6 << 30):
            fit = int((0.8 * memory - cost.parent_bytes(triangles[0], sum(triangles[1:])))
                      // cost.process_bytes(*triangles))
            assert 1 < fit < 16
            assert clamp_processes(16, 1, triangles, cores=16, memory=memory) == (
                fit, f"memory for {fit} ({memory / 2 ** 30:.1f} GiB available, about "
                     f"{cost.process_bytes(*triangles) / 2 ** 20:.0f} MiB each)")
    assert clamp_processes(2, 1, 1000, cores=16, memory=64 << 30) == (2, None)
    P = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    ground = Mesh(P, F, uvs=(P[F][:, :, :2] + 1) / 2)
    r = bake_ao(ground, resolution=16, samples=8, workers=1000)
    workers = [m for m in r.report["worker_memory"] if m["process"] != "parent"]
    assert 1 <= len(workers) <= cpu_count()
    [said] = [w for w in r.report["warnings"] if w.startswith("asked for 1000 worker processes")]
    assert f"baked on {len(workers)}" in said and "cores" in said
    assert np.array_equal(r.ao, bake_ao(ground, resolution=16, samples=8, workers=1).ao)
