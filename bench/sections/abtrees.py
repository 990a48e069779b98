"""One workload, two trees of the core, alternated: is a change to the core slower? (CPU time, not wall).

    .venv/bin/python -m bench.sections.abtrees --before COMMIT [--after COMMIT] [--pairs 7]

Each run is a fresh process (``python -c``, the tree's root on ``sys.path``) that bakes the same
workload through the core's public calls: the bench's Suzanne scene as an image on one thread and on
two worker processes, AO and thickness maps together, face corners, denoised, and the
selected-to-active terrain. Its cost is the CPU time of the process and every process it started
(the worker processes: ``RUSAGE_CHILDREN`` of this one, which waits for them all), so that the
machine's other load changes it little; runs of the two trees alternate, each first in every other
pair (before, after, after, before, ...), and the result is each pair's ratio after / before and their median. Wall times and the load are
printed beside them.
"""

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

WORKLOAD = r"""
import sys, time
import numpy as np
from core import Mesh, bake_ao, bake_maps, bake_vertex_ao

d = np.load(sys.argv[1], allow_pickle=False)
target = Mesh(d["P"], d["F"], uvs=d["UV"], normals=d["N"], name="Suzanne")
occ = [Mesh(d[f"O{i}P"], d[f"O{i}F"], name=f"o{i}") for i in range(int(d["occluders"]))]
dist = float(d["distance"])
bake_ao(target, occ, resolution=256, samples=64, max_distance=dist, threads=1)
bake_ao(target, occ, resolution=256, samples=64, max_distance=dist, workers=2, threads=1)
bake_maps(target, occ, resolution=128, samples=32, max_distance=dist, threads=1)
bake_vertex_ao(target, occ, samples=64, max_distance=dist, threads=1)
bake_ao(target, occ, resolution=128, samples=32, max_distance=dist, threads=1, denoise=True)
t = np.linspace(0.0, 1.0, 65)
u, v = np.meshgrid(t, t)
z = 0.1 * np.sin(6 * u) * np.sin(5 * v)
p = np.stack([(u - 0.5) * 4, (v - 0.5) * 4, z], -1).reshape(-1, 3)
i = np.arange(64)
a = (i[None, :] + 65 * i[:, None]).ravel()
q = np.stack([a, a + 1, a + 66, a + 65], 1)
high = Mesh(p, np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]]), name="high")
lp = np.array([[-2, -2, -0.5], [2, -2, -0.5], [2, 2, -0.5], [-2, 2, -0.5]], float)
f = np.array([[0, 1, 2], [0, 2, 3]])
low = Mesh(lp, f, uvs=(lp[f][:, :, :2] + 2) / 4, name="low")
bake_ao(low, [], resolution=128, samples=32, max_distance=0.5, highpoly=[high], extrusion=1.0, threads=1)
"""


def tree_of(commit, into):
    """The core of ``commit`` (and its _version) under ``into``/core."""
    data = subprocess.run(["git", "-C", str(ROOT), "archive", commit, "core"], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=data, check=True)
    return into


def run(root, scene):
    """(CPU seconds of the run and its children, wall seconds) of the workload in ``root``'s core."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    env = dict(os.environ, PYTHONPATH=str(root), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    subprocess.run([sys.executable, "-c", WORKLOAD, str(scene)], cwd=str(root), env=env, check=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="the commit whose core is the baseline")
    ap.add_argument("--after", default=None, help="the commit to compare (default: this working tree)")
    ap.add_argument("--pairs", type=int, default=7)
    args = ap.parse_args(argv)
    scene = ROOT / "bench" / "data" / "scene_suzanne.npz"
    tmp = Path(tempfile.mkdtemp(prefix="abtrees-"))
    try:
        (tmp / "before").mkdir()
        tree_of(args.before, tmp / "before")
        if args.after:
            (tmp / "after").mkdir()
            tree_of(args.after, tmp / "after")
            b = tmp / "after"
        else:
            b = ROOT
        run(tmp / "before", scene), run(b, scene)  # warm the file caches
        ratios = []
        print("pair  before CPU s  after CPU s  ratio  (wall before, after)  load", flush=True)
        for k in range(args.pairs):
            # ABBA: each tree runs first in every other pair, so a drift in the machine's load does not
            # favour the one that runs second.
            if k % 2 == 0:
                ca, wa = run(tmp / "before", scene)
                cb, wb = run(b, scene)
            else:
                cb, wb = run(b, scene)
                ca, wa = run(tmp / "before", scene)
            ratios.append(cb / ca)
            print(f"{k + 1:4d}  {ca:12.2f}  {cb:11.2f}  {cb / ca:5.3f}  ({wa:.2f}, {wb:.2f})  "
                  f"{os.getloadavg()[0]:.1f}", flush=True)
        print(f"median ratio after / before: {statistics.median(ratios):.3f} over {len(ratios)} pairs "
              f"(min {min(ratios):.3f}, max {max(ratios):.3f})")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
