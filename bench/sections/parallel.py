"""Threads or processes: the automatic choice (``workers='auto'``, threads automatic) against this
process's threads and worker processes, and the figures core.execution.cost's model of it is built on.

Part 1, the choice (``--cases suz128 suz256 suz512 dense``): the bench's Suzanne scene at 128^2, 256^2
and 512^2 x 128 and dense.blend's 524k-triangle terrain at 1024^2 x 32, each baked through
``core.bake_ao`` on every core's threads of this process, on as many worker processes of one thread,
and with both automatic, in rounds whose order rotates (so that a drift of the machine's load favours
none), the pool running and its workers keeping the scene (as in a session of bakes: a first bake of
the meshes starts it). Each run's wall time and the CPU time of this process and its workers; what
the automatic bake chose and the model's prediction of both. On a shared machine read the CPU
columns: the wall times and their ratios need a quiet machine (the choice is about wall time).

Part 2, the model's inputs (``--components``): on the same cases, in this process and one thread,
the steps a worker process repeats per bake (timed on the job a worker receives: its checks,
prologue, surface table, Embree scene; with the scene kept and built), the job's bytes as written to
the worker (both against the same job with the target's UVs in place of the parent's layout, which
each worker then lays out again: UV triangles, tiles and bins), and each tile's CPU time at the tiles worker processes get, with the pool's dealing simulated
(in order and largest first) against an even split: the tail the last whole tiles leave.

Run: ``.venv/bin/python -m bench.sections.parallel [--cases ...] [--rounds N] [--components]
[--dense-npz PATH]``; dense.blend's terrain is read with bpy once into PATH (default
``/tmp/mc_ao_dense_terrain.npz``, 44 MB). Writes ``bench/results/parallel.{txt,json}`` unless
``--no-save``.
"""

import argparse
import heapq
import json
import os
import statistics
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness.common import RESULTS, git_state, load_average, machine  # noqa: E402
from bench.harness.mcao import _children_cpu  # noqa: E402
from bench.harness.stagetimer import StageTimer  # noqa: E402

SCENE_NPZ = ROOT / "bench" / "data" / "scene_suzanne.npz"
DENSE_NPZ = Path("/tmp/mc_ao_dense_terrain.npz")
#: (resolution, samples) of each case; dense.blend's distance is the bench's (bench/sections/equal.py).
CASES = {"suz128": (128, 128), "suz256": (256, 128), "suz512": (512, 128), "dense": (1024, 32)}
DENSE_DISTANCE = 1.0


def suzanne():
    from core import Mesh

    d = np.load(SCENE_NPZ)
    target = Mesh(d["P"], d["F"], d["UV"], d["N"], name="Suzanne")
    occ = [Mesh(d[f"O{i}P"], d[f"O{i}F"], name=f"occluder{i}") for i in range(int(d["occluders"]))]
    return target, occ, float(d["distance"])


def dense(path=DENSE_NPZ):
    """dense.blend's Terrain as the operator extracts it (bpy once, then the cached arrays)."""
    from core import Mesh

    if not Path(path).exists():
        import bpy

        from bench.harness.scene import scene_arrays

        bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / "dense.blend"))
        t, _ = scene_arrays(bpy, "Terrain")
        np.savez(path, positions=t.positions, triangles=t.triangles, uvs=t.uvs, normals=t.normals)
    d = np.load(path)
    return Mesh(d["positions"], d["triangles"], d["uvs"], d["normals"], name="Terrain"), [], DENSE_DISTANCE


def scene_of(case, dense_npz):
    return dense(dense_npz) if case == "dense" else suzanne()


def _bake(scene, res, spp, **kw):
    from core import bake_ao

    target, occ, distance = scene
    return bake_ao(target, occ, resolution=res, samples=spp, max_distance=distance, margin=16, **kw)


def modes(cores):
    return {"threads": dict(workers=1, threads=cores), "processes": dict(workers=cores, threads=1),
            "auto": dict(workers="auto")}


def choice_runs(case, scene, rounds, cores):
    """Part 1 for one case: rounds of the three modes, their order rotating."""
    res, spp = CASES[case]
    m = modes(cores)
    # The pool running, its workers keeping this scene (a first bake of the meshes starts it).
    _bake(scene, 32, 1, workers=cores, threads=1)
    names = list(m)
    runs = {k: [] for k in names}
    loads = [load_average()]
    for i in range(rounds):
        order = names[i % 3:] + names[:i % 3]
        for name in order:
            c0, ch0, w0 = time.process_time(), _children_cpu(), time.perf_counter()
            r = _bake(scene, res, spp, **m[name])
            wall = time.perf_counter() - w0
            cpu = time.process_time() - c0 + _children_cpu() - ch0
            runs[name].append({"wall": wall, "cpu": cpu, "parallel": r.report.parallel})
        loads.append(load_average())
    out = {"case": case, "resolution": res, "samples": spp, "rounds": rounds, "load": loads}
    for name in names:
        out[name] = {"wall": [x["wall"] for x in runs[name]], "cpu": [x["cpu"] for x in runs[name]]}
    out["auto_chose"] = [x["parallel"] for x in runs["auto"]]
    return out


def print_choice(c, file=sys.stdout):
    med = {k: (statistics.median(c[k]["wall"]), statistics.median(c[k]["cpu"])) for k in ("threads", "processes", "auto")}
    best_wall = min(med["threads"][0], med["processes"][0])
    chose = c["auto_chose"][-1]
    pred = chose.get("predicted_seconds", {})
    print(f"  {c['case']:7s} {c['resolution']:5d}^2 x {c['samples']:<4d} "
          + "  ".join(f"{k} {med[k][0]:6.2f} / {med[k][1]:6.2f}" for k in ("threads", "processes", "auto"))
          + f"   auto/best wall {med['auto'][0] / best_wall:5.3f}   chose {chose['processes']}x{chose['threads']}"
          + (f" (model: threads {pred['threads']:.2f} s, processes {pred['processes']:.2f} s)" if pred else "")
          + f"   load {c['load'][0][0]:.0f}-{max(x[0] for x in c['load']):.0f}", file=file)


def _capture_job(scene, res, spp, workers):
    """The job a worker process receives for this bake (the parent's ``job()``), without baking."""
    import core.pipeline.run as run_mod

    got = {}
    original = run_mod.bake_tiles

    def spy(remote, bake, keys, processes, threads, job, *a, **kw):
        got["job"], got["tiles"] = job(), len(keys)
        raise _Captured()

    run_mod.bake_tiles = spy
    try:
        _bake(scene, res, spp, workers=workers, threads=1)
    except _Captured:
        pass
    finally:
        run_mod.bake_tiles = original
    return got["job"], got["tiles"]


class _Captured(Exception):
    pass


#: A worker's set-up steps (core functions by name, bench.harness.stagetimer).
WORKER_STEPS = [("scene key", "scene_key_of"), ("checks (meshes)", "check"), ("prologue (frame)", "Prologue.__init__"),
                ("UV triangles", "prepare"), ("tiles: fit and bins", "bin_triangles"),
                ("surface table", "SurfaceTable.build"), ("Embree scene", "Tracer.__init__"),
                ("pattern pool", "TexelPattern.__init__"), ("worker set-up: the rest", "build")]


def simulate(costs, workers, order):
    """The pool's dealing: each tile to the worker that frees first, in ``order``: the last one done."""
    heap = [(0.0, i) for i in range(workers)]
    for k in order:
        t, i = heapq.heappop(heap)
        heapq.heappush(heap, (t + costs[k], i))
    return max(t for t, _ in heap)


def wire_bytes(job):
    """The bytes of ``job`` as the pool writes it to a worker (core.execution.messages.send: the pickle
    and its arrays out of band)."""
    import pickle

    buffers = []
    data = pickle.dumps(job, protocol=5, buffer_callback=buffers.append)
    return len(data) + sum(b.raw().nbytes for b in buffers)


def uv_job(job, target):
    """``job`` as a worker got it before it was sent the parent's layout: the target with its UVs, each
    worker laying them out again (UV triangles, tiles, bins): the same tiles, the same bits."""
    out = dict(job, target=dict(job["target"], uvs=target.uvs))
    out.pop("layout", None)
    return out


def components(case, scene, cores, rounds=3):
    """Part 2 for one case (this process, one thread, thread CPU). A worker's set-up from the job the
    parent sends (its layout) and from that job with the target's UVs in place of the layout (``uvs``),
    each with its scene built and kept, alternated over ``rounds`` (medians)."""
    import core.pipeline.remote as remote
    import core.targets.texels as texels
    from core.engine.settings import auto_tile_shape

    res, spp = CASES[case]
    job, tiles = _capture_job(scene, res, spp, cores)
    job = dict(job, quantum=1 << 62, threads=1)
    jobs = {"layout": job, "uvs": uv_job(job, scene[0])}
    job_bytes = {form: wire_bytes(j) for form, j in jobs.items()}
    runs = {(form, kept): [] for form in jobs for kept in (False, True)}
    for i in range(rounds):
        for form in (list(jobs) if i % 2 == 0 else list(jobs)[::-1]):
            for kept in (False, True):
                remote._SCENE.clear()
                if kept:
                    j = dict(jobs[form])
                    remote.forget(j)
                    remote.build(j, threading.Event(), lambda w: None)
                timer = StageTimer(WORKER_STEPS)
                j = dict(jobs[form])
                with timer.run():
                    remote.forget(j)
                    remote.build(j, threading.Event(), lambda w: None)
                runs[form, kept].append((timer.total, {lab: s for lab, s, _ in timer.table() if s > 0}))
    setup = {}
    for (form, kept), got in runs.items():
        total = statistics.median(t for t, _ in got)
        steps = {lab: statistics.median(st.get(lab, 0.0) for _, st in got) for lab in got[0][1]}
        setup.setdefault(form, {})["kept" if kept else "built"] = {"thread_cpu": total, "steps": steps,
                                                                  "runs": [t for t, _ in got]}
    remote._SCENE.clear()
    # Each tile's thread CPU at the tiles worker processes get, on one thread here.
    tw, th = auto_tile_shape(res, res, 2 * cores, spp)
    costs = {}
    original = texels.TexelBake.tile

    def timed(self, key, *a, **kw):
        t0 = time.thread_time()
        out = original(self, key, *a, **kw)
        costs[key] = time.thread_time() - t0
        return out

    texels.TexelBake.tile = timed
    try:
        t0 = time.thread_time()
        r = _bake(scene, res, spp, threads=1, tile_size=(tw, th))
        total = time.thread_time() - t0
    finally:
        texels.TexelBake.tile = original
    keys = sorted(costs)
    even = sum(costs.values()) / cores
    return {"case": case, "triangles": int(scene[0].triangle_count), "job_bytes": job_bytes["layout"],
            "job_bytes_uvs": job_bytes["uvs"], "tiles": len(keys), "worker_setup": setup["layout"],
            "worker_setup_uvs": setup["uvs"], "rounds": rounds, "one_thread_cpu": total, "rays": int(r.rays),
            "covered": int(r.mask.sum()), "tile_cpu": sum(costs.values()),
            "tail_in_order": simulate(costs, cores, keys) / even - 1,
            "tail_largest_first": simulate(costs, cores, sorted(keys, key=lambda k: -costs[k])) / even - 1,
            "load": load_average()}


def print_components(c, file=sys.stdout):
    per_tri = 1e9 / max(c["triangles"], 1)
    for form, name in (("", "layout sent"), ("_uvs", "UVs sent")):
        b, k = c["worker_setup" + form]["built"], c["worker_setup" + form]["kept"]
        print(f"  {c['case']:7s} {name:11s} {c['triangles']} triangles, job {c['job_bytes' + form] / 1e6:.1f} MB; "
              f"a worker's set-up {1e3 * b['thread_cpu']:.0f} ms ({per_tri * b['thread_cpu']:.0f} ns a triangle; "
              f"scene kept {1e3 * k['thread_cpu']:.0f} ms): "
              + ", ".join(f"{s} {1e3 * v:.0f}" for s, v in b["steps"].items()), file=file)
    print(f"  {c['case']:7s} one thread {c['one_thread_cpu']:.2f} s ({c['tiles']} tiles {c['tile_cpu']:.2f} s); tail "
          f"over an even split: dealt in order +{100 * c['tail_in_order']:.0f}%, largest first "
          f"+{100 * c['tail_largest_first']:.0f}%; medians of {c['rounds']} rounds; load {c['load'][0]:.0f}", file=file)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--components", action="store_true", help="part 2 only: the model's inputs")
    ap.add_argument("--cores", type=int, default=None, help="threads / worker processes (default: every core)")
    ap.add_argument("--dense-npz", default=str(DENSE_NPZ))
    ap.add_argument("--no-save", action="store_true")
    ap.add_argument("--stem", default=None)
    a = ap.parse_args(argv)
    from core.base.machine import cpu_count

    cores = a.cores or cpu_count()
    out = {"machine": machine(), "git": git_state(), "when": time.strftime("%Y-%m-%dT%H:%M:%S"), "cores": cores}
    lines = []

    class Tee:
        def write(self, s):
            sys.stdout.write(s)
            sys.stdout.flush()
            lines.append(s)

    tee = Tee()
    print(f"threads or processes ({out['when']}, {out['git']['commit']}, {cores} cores, {out['machine']['cpu']})",
          file=tee)
    if a.components:
        print("the model's inputs (one thread, thread CPU):", file=tee)
        out["components"] = []
        for case in a.cases:
            c = components(case, scene_of(case, a.dense_npz), cores, a.rounds)
            out["components"].append(c)
            print_components(c, tee)
    else:
        print(f"wall / CPU seconds, medians of {a.rounds} rounds (threads: {cores} of this process; processes: "
              f"{cores} workers of one thread, the pool running; auto: both automatic)", file=tee)
        out["choice"] = []
        for case in a.cases:
            c = choice_runs(case, scene_of(case, a.dense_npz), a.rounds, cores)
            out["choice"].append(c)
            print_choice(c, tee)
    if not a.no_save:
        stem = a.stem or ("parallel-components" if a.components else "parallel")
        (RESULTS / f"{stem}.json").write_text(json.dumps(out, indent=1, default=float))
        (RESULTS / f"{stem}.txt").write_text("".join(lines))


if __name__ == "__main__":
    main()
