"""pyproject.toml: `pip install .` installs core/ as the package mc_ao_core, with the dependencies it
imports declared, and an installed core bakes from any folder the same bits as core/ in this
checkout (where `from core import ...` keeps working)."""

import ast
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
#: Import names of the core's third-party dependencies -> their distribution names.
DISTRIBUTIONS = {"numpy": "numpy", "embreex": "embreex", "OpenImageIO": "OpenImageIO", "distributed": "distributed"}


def core_packages():
    """core's packages (folders with an __init__.py) under their installed names."""
    return sorted("mc_ao_core" + ("." + ".".join(p.parent.relative_to(ROOT / "core").parts) if p.parent != ROOT / "core" else "")
                  for p in (ROOT / "core").rglob("__init__.py") if "__pycache__" not in p.parts)


def test_every_package_of_the_core_is_installed():
    setuptools = PROJECT["tool"]["setuptools"]
    assert setuptools["package-dir"] == {"mc_ao_core": "core"}
    assert sorted(setuptools["packages"]) == core_packages()


def test_the_dependencies_the_core_imports_are_declared():
    """Every module outside the standard library that core/ imports is a declared dependency (distributed,
    for workers=Client, an optional one)."""
    imported = set()
    for path in (ROOT / "core").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                imported |= {alias.name.partition(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                imported.add(node.module.partition(".")[0])
    third_party = {name for name in imported if name not in sys.stdlib_module_names and name != "core"}
    declared = {dep.split(">")[0].split("=")[0].split("<")[0].strip() for dep in PROJECT["project"]["dependencies"]}
    optional = {dep for deps in PROJECT["project"]["optional-dependencies"].values() for dep in deps}
    assert {DISTRIBUTIONS[name] for name in third_party} <= declared | optional, third_party
    assert {DISTRIBUTIONS[n] for n in ("numpy", "embreex", "OpenImageIO")} <= declared


BAKE = """
import sys
import numpy as np
{imports}
P = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
F = np.array([[0, 1, 2], [0, 2, 3]])
ground = Mesh(P, F, uvs=(P[F][:, :, :2] + 1) / 2)
lid = Mesh(P * [0.4, 0.4, 0] + [0, 0, 0.5], F)
r = bake_ao(ground, [lid], resolution=32, samples=16, seed=3, workers=1, threads=2)
print(bake_ao.__module__, flush=True)
sys.stdout.buffer.write(r.ao.tobytes())
"""


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The checkout installed by pip (its own build, no dependencies: this Python has them) into a folder
    of its own: put on PYTHONPATH, it is what `pip install .` gives."""
    site = tmp_path_factory.mktemp("site")
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(site),
                           str(ROOT)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return site


def test_installed_core_bakes_from_another_folder_the_same_bits(installed, tmp_path):
    """`import mc_ao_core` from a folder that is not the checkout (so `core` is not importable) bakes the
    same bits as `from core import ...` in the checkout."""
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(installed)}
    there = subprocess.run([sys.executable, "-c", BAKE.format(imports="from mc_ao_core import Mesh, bake_ao")],
                           cwd=tmp_path, env=env, capture_output=True, timeout=300)
    assert there.returncode == 0, there.stderr.decode()
    assert there.stdout.startswith(b"mc_ao_core."), there.stdout[:80]
    missing = subprocess.run([sys.executable, "-c", "import core"], cwd=tmp_path, env=env, capture_output=True)
    assert missing.returncode != 0  # what was baked came from the installed package
    here = subprocess.run([sys.executable, "-c", BAKE.format(imports="from core import Mesh, bake_ao")],
                          cwd=ROOT, env={"PATH": "/usr/bin:/bin"}, capture_output=True, timeout=300)
    assert here.returncode == 0, here.stderr.decode()
    assert here.stdout.startswith(b"core.")
    assert there.stdout.split(b"\n", 1)[1] == here.stdout.split(b"\n", 1)[1]


E2E = """
import json, sys
import numpy as np
from mc_ao_core import Mesh, bake_ao

P = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
F = np.array([[0, 1, 2], [0, 2, 3]])
ground = Mesh(P, F, uvs=(P[F][:, :, :2] + 1) / 2)
lid = Mesh(P * [0.4, 0.4, 0] + [0, 0, 0.5], F)


def bake(workers):
    r = bake_ao(ground, [lid], resolution=32, samples=16, seed=4, workers=workers, threads=1)
    return {"ao": r.ao.tobytes().hex(), "warnings": r.report.warnings or [],
            "processes": [m["process"] for m in r.report.worker_memory]}


if __name__ == "__main__":  # worker processes and Dask's import this file again: bake in the parent only
    out = {"1": bake(1)}
    if sys.argv[1] == "processes":
        out["2"] = bake(2)
    else:
        from distributed import Client, LocalCluster

        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \\
                Client(cluster) as client:
            out["dask"] = bake(client)
    print(json.dumps(out))
"""


def e2e(installed, tmp_path, how):
    """The installed core baking from another folder, in this process and ``how`` ('processes' or
    'dask'): {"1": ..., other: ...}, each the AO's bytes, the report's warnings and its processes."""
    (tmp_path / "e2e.py").write_text(E2E)
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(installed)}
    proc = subprocess.run([sys.executable, "e2e.py", how], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    import json

    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_installed_core_bakes_in_worker_processes_the_same_bits(installed, tmp_path):
    out = e2e(installed, tmp_path, "processes")
    assert out["2"]["warnings"] == [] and len(out["2"]["processes"]) > 1, out["2"]  # no fallback to threads
    assert out["2"]["ao"] == out["1"]["ao"]


def test_installed_core_bakes_on_a_dask_local_cluster_the_same_bits(installed, tmp_path):
    pytest.importorskip("distributed")
    out = e2e(installed, tmp_path, "dask")
    assert out["dask"]["warnings"] == [] and out["dask"]["ao"] == out["1"]["ao"]
