"""The worker boot through the Blender binary (not the bpy module), the extension installed from its zip:
``blender -b --factory-startup --python tests/gui/check_worker_boot.py`` inside ../shared/tools/blender-gui.sh,
with $MC_AO_ZIP. The working folder holds a json.py and a numpy.py that must never run; the installed
core is ``bl_ext.<repository>.mc_ao.core``, which a new interpreter cannot import by that name unless the
boot makes its enclosing packages. Prints CHECK_WORKER_BOOT passed/FAILED and exits 0/1."""

import os
import sys
import tempfile
import textwrap

import bpy

ZIP = os.environ["MC_AO_ZIP"]
REPO = "mc_ao_boot"
SABOTAGE = textwrap.dedent("""
    import os, sys
    open(os.path.join(os.path.dirname(os.path.abspath(__file__)), __name__ + ".ran"), "w").close()
    sys.exit("{name}.py from the working folder ran")
""")

directory = tempfile.mkdtemp(prefix="mc_ao_boot_repo_")
bpy.context.preferences.extensions.repos.new(name="MC AO boot", module=REPO, custom_directory=directory, source="USER")
print("install:", bpy.ops.extensions.package_install_files(filepath=ZIP, repo=REPO, enable_on_install=True), flush=True)
import importlib  # noqa: E402

core = importlib.import_module(f"bl_ext.{REPO}.mc_ao.core")
import numpy as np  # noqa: E402

folder = tempfile.mkdtemp(prefix="mc_ao_boot_assets_")
for name in ("json", "numpy"):
    with open(os.path.join(folder, f"{name}.py"), "w") as f:
        f.write(SABOTAGE.format(name=name))
os.chdir(folder)
P = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
F = np.array([[0, 1, 2], [0, 2, 3]])
ground = core.Mesh(P, F, uvs=(P[F][:, :, :2] + 1) / 2)
lid = core.Mesh(P * [0.4, 0.4, 0] + [0, 0, 0.5], F)
two = core.bake_ao(ground, [lid], resolution=32, samples=16, workers=2, threads=1)
one = core.bake_ao(ground, [lid], resolution=32, samples=16, workers=1, threads=1)
processes = [m["process"] for m in two.report["worker_memory"]]
ran = sorted(n for n in os.listdir(folder) if n.endswith(".ran"))
problems = []
if processes != ["parent", "worker 0", "worker 1"]:
    problems.append(f"processes {processes}, warnings {two.report.get('warnings')}")
if ran:
    problems.append(f"ran in a worker: {ran}")
if not (two.ao == one.ao).all():
    problems.append("workers and one process differ")
print("core:", core.__name__, "python:", sys.version.split()[0], "processes:", processes, flush=True)
print("CHECK_WORKER_BOOT", "passed" if not problems else "FAILED: " + "; ".join(problems), flush=True)
core.execution.pool.shutdown() if hasattr(core.execution.pool, "shutdown") else None
sys.exit(1 if problems else 0)
