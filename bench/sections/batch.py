"""Batch throughput: assets per minute with 1 and 2 workers here, and what that means for a farm.

    .venv/bin/python -m bench.sections.batch     # 12 assets, 256 x 256, 64 samples, and one at 1024 x 1024: about 5 minutes on 2 cores
    .venv/bin/python -m bench.sections.batch --quick # 6 assets, 128 x 128, 16 samples

Builds a library of copies of one asset (tests/batch_assets.py: a ground plane and a block, two
objects to bake, EXR), then runs ``scripts/bake_batch.py`` on it, as a user would, with

- the local runner, 1 worker (each bake gets every core) and 2 workers (one core each);
- the Dask runner, 2 worker processes (a LocalCluster on 127.0.0.1, its start-up included);
- the local runner again on the finished output (every task skipped).

From the 1-worker run it splits the cost of one asset into the bake itself (the objects' seconds
in bake_ao.py's summaries) and the rest (a process, importing Blender, opening the file, writing),
and from the bakes' ray throughput projects the time of a 10,000-asset library on a 50-node farm,
for the measured asset and for the same asset baked at 1024 x 1024 and 128 samples (measured too, one
task with every core; --quick: 256 x 256, 32 samples). That projection is
on paper: it assumes nodes like this machine, tasks that do not wait on each other, a shared file
system that keeps up, and no farm overhead beyond what one task costs here (Flamenco and Deadline
add seconds per task of dispatch; see the notes it prints).

Writes bench/results/batch.json and batch.txt (``--quick``: batch-quick.*). Never a timed assertion.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..harness.common import RESULTS, ROOT, git_state, machine

BATCH = ROOT / "scripts" / "bake_batch.py"
ASSETS = ROOT / "tests" / "batch_assets.py"
LIBRARY = 10_000
NODES = 50


def run_batch(manifest, output, *args):
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, str(BATCH), str(manifest), "--output", str(output), "--blender", "bpy",
                           "--quiet", *map(str, args)], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"bake_batch.py failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    data = json.loads((Path(output) / "mc_ao_batch.json").read_text())
    return wall, data


def measure(count, resolution, samples, folder):
    subprocess.run([sys.executable, str(ASSETS), str(folder), "--copies", str(count), "--resolution",
                    str(resolution), "--samples", str(samples)], check=True, capture_output=True)
    manifest = folder / "manifest.toml"
    runs = {}
    for label, out, args in [
        ("local, 1 worker", "one", ["--workers", 1]),
        ("local, 2 workers", "two", ["--workers", 2]),
        ("dask, 2 workers", "dask", ["--runner", "dask", "--workers", 2]),
        ("local, 2 workers, all done (rerun)", "two", ["--workers", 2]),
    ]:
        wall, data = run_batch(manifest, folder / out, *args)
        tasks = [t for t in data["tasks"] if t["status"] != "skipped"]
        runs[label] = {
            "wall_seconds": wall,
            "assets_per_minute": 60 * count / wall,
            "counts": data["counts"],
            "bake_seconds": sum(t["bake_seconds"] for t in tasks),
            "task_seconds": sum(t["seconds"] for t in tasks),
            "rays": sum(t["rays"] for t in tasks),
        }
        print(f"  {label:36s} {wall:7.1f} s  {60 * count / wall:7.1f} assets/min", flush=True)
    return runs


def measure_production(resolution, samples, folder):
    """One asset at a production size, 1 worker (every core on its bake), as a farm node runs a task."""
    folder.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, str(ASSETS), str(folder), "--copies", "1", "--resolution", str(resolution),
                    "--samples", str(samples)], check=True, capture_output=True)
    wall, data = run_batch(folder / "manifest.toml", folder / "out", "--workers", 1)
    task = data["tasks"][0]
    print(f"  {'one asset at %dx%d, %d samples' % (resolution, resolution, samples):36s} {wall:7.1f} s", flush=True)
    return {"resolution": resolution, "samples": samples, "wall_seconds": wall,
            "bake_seconds": task["bake_seconds"], "rays": task["rays"]}


def estimate(runs, production, count, cores):
    """The farm projection from the 1-worker run (every core on one bake, as a farm node runs a task)."""
    one = runs["local, 1 worker"]
    per_asset = one["wall_seconds"] / count
    bake = one["bake_seconds"] / count
    overhead = per_asset - bake
    rays_per_second = one["rays"] / one["bake_seconds"]  # all cores of this machine
    best = max(runs["local, 1 worker"]["assets_per_minute"], runs["local, 2 workers"]["assets_per_minute"])
    out = {"per_asset_seconds": per_asset, "bake_seconds": bake, "overhead_seconds": overhead,
           "rays_per_asset": one["rays"] / count, "rays_per_second": rays_per_second,
           "cores_per_node": cores, "nodes": NODES, "library": LIBRARY}
    # as measured: each node runs like this machine at its better worker count
    out["measured_hours"] = LIBRARY / (best * NODES) / 60
    # a production-size bake of the same asset, measured: one task per node at a time
    out["production"] = dict(production, hours=LIBRARY * production["wall_seconds"] / NODES / 3600,
                             rays_per_second=production["rays"] / production["bake_seconds"])
    return out


def report(result):
    m, r, e = result["machine"], result["runs"], result["estimate"]
    lines = [f"mc_ao batch benchmark ({result['mode']}), {result['assets']} assets of 2 objects, "
             f"{result['resolution']}x{result['resolution']}, {result['samples']} samples, EXR",
             f"machine: {m['cpu']}, {m['cores']} cores; commit {result['git']['commit']}", "",
             f"{'run':38s} {'seconds':>8s} {'assets/min':>11s} {'bake s':>8s}"]
    for label, run in r.items():
        lines.append(f"{label:38s} {run['wall_seconds']:8.1f} {run['assets_per_minute']:11.1f} {run['bake_seconds']:8.1f}")
    p = e["production"]
    lines += [
        "",
        f"one asset, 1 worker: {e['per_asset_seconds']:.2f} s = {e['bake_seconds']:.2f} s baking + "
        f"{e['overhead_seconds']:.2f} s process, Blender import, file open and write",
        f"ray throughput: {e['rays_per_second'] / 1e6:.2f} Mrays/s on {e['cores_per_node']} cores",
        "",
        f"paper estimate, {e['library']:,} assets on {e['nodes']} nodes like this one:",
        f"  as measured: {e['measured_hours'] * 60:.0f} minutes ({e['measured_hours']:.2f} h)",
        f"  at {p['resolution']}x{p['resolution']}, {p['samples']} samples (measured: {p['wall_seconds']:.1f} s per "
        f"asset, {p['bake_seconds']:.1f} s of it baking at {p['rays_per_second'] / 1e6:.1f} Mrays/s): "
        f"{p['hours']:.1f} h",
        "  assumes: independent tasks, a shared file system that keeps up, no dispatch cost beyond a",
        "  task's own (a farm manager adds seconds per task: at 10,000 tasks, 1 s each is 3.3 min on 50",
        "  nodes), nodes of this size; bakes scale with cores (bit-identical for any thread count),",
        "  the per-task overhead does not.",
    ]
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--assets", type=int)
    p.add_argument("--keep", type=Path, help="build the library here and keep it (default: a temporary folder)")
    args = p.parse_args(argv)
    count = args.assets or (6 if args.quick else 12)
    resolution, samples = (128, 16) if args.quick else (256, 64)
    info = machine()
    print(f"batch benchmark: {count} assets, {resolution}x{resolution}, {samples} samples", flush=True)
    with tempfile.TemporaryDirectory(prefix="mc_ao_bench_batch_") as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        runs = measure(count, resolution, samples, folder)
        production = measure_production(*((256, 32) if args.quick else (1024, 128)), folder / "production")
    result = {"mode": "quick" if args.quick else "full", "assets": count, "resolution": resolution,
              "samples": samples, "machine": info, "git": git_state(), "runs": runs,
              "estimate": estimate(runs, production, count, info["cores"])}
    text = report(result)
    print()
    print(text)
    RESULTS.mkdir(exist_ok=True)
    name = "batch-quick" if args.quick else "batch"
    (RESULTS / f"{name}.json").write_text(json.dumps(result, indent=1) + "\n")
    (RESULTS / f"{name}.txt").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
