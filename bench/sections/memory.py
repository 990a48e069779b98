"""Memory per triangle and per process: what each worker holds, and the peak of all processes together.

    .venv/bin/python -m bench.sections.memory                    # every case below but the 10M one
    .venv/bin/python -m bench.sections.memory --big              # and the 10M-triangle high-poly (about 4 GB)
    .venv/bin/python -m bench.sections.memory --stem memory-before   # write memory-before.* instead

Each case runs in a fresh interpreter (``--child``), which builds its meshes from numpy arrays (no
Blender), starts the worker pool, reads the workers' resident size once they are idle (an
interpreter with numpy, embreex and the core: their baseline), then bakes while a thread polls the
resident size (VmRSS) and the proportional set size (PSS, /proc/PID/smaps_rollup) of itself and of
every worker every 20 ms: the largest sum of PSS is the peak of all processes together, the figure
the targets are read against (PSS shares each page among the processes that map it, so shared
libraries and shared arrays count once; RSS counts them once per process and overstates the sum).
After the bake each process's own peak (VmHWM, read from /proc/PID/status) is taken, and the bake's
``report['worker_memory']`` where the core gives one.

Cases (all core.bake_ao, 1 thread per worker):

- ``embree``: one Embree scene of an N-triangle grid alone, robust and not (bytes a triangle):
  what "beyond Embree" is measured against;
- ``highpoly``: an N-triangle displaced grid (4 x 4, bumps of +-0.25, flat shaded, no UVs) baked
  onto a 2-triangle plane 0.5 below it (extrusion 1, AO distance 0.5) at 256^2 x 16, on W workers;
  per high-poly triangle: each process's peak beyond its baseline (the parent's: beyond its input
  arrays);
- ``occluder``: the same grid as an occluder 0.5 above that plane (AO distance 1), the plane's own
  AO at 256^2 x 16 on W workers: per occluder triangle, as for the high-poly;
- ``target``: an N-triangle displaced grid's own AO (UVs over [0, 1]^2, AO distance 0.5) at
  1024^2 x 16 on W workers: each worker's peak beyond its baseline and beyond its Embree scene
  (``embree`` case, scaled), per triangle;
- ``target-uvs``: the same with the job a worker got before it was sent the parent's layout (the
  target's UVs, laid out again in each worker): what sending the layout saves;
- ``large``: an 8192-triangle grid at 8192^2 x 4 spp on 2 workers: the parent and every worker
  together (the image planes dominate).

Writes bench/results/<stem>.json and <stem>.txt (stem ``memory`` unless given). Never a timed assertion.
"""

import argparse
import gc
import json
import math
import subprocess
import sys
import threading
import time

import numpy as np

from ..harness.common import RESULTS, ROOT, git_state, load_average, machine

MB = 1e6


def status(pid="self", field="VmRSS"):
    """A field of /proc/PID/status in bytes (None if the process is gone)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def pss(pid="self"):
    """The proportional set size of a process in bytes (/proc/PID/smaps_rollup; None if the process is
    gone or the kernel has no smaps_rollup)."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                if line.startswith("Pss:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def grid(n, uvs, size=4.0, amplitude=0.25):
    """An n x n quad grid (2 n^2 triangles) over [-size/2, size/2]^2 displaced by smooth bumps:
    positions (V, 3) float64, triangles (T, 3) int64, and per-corner UVs (T, 3, 2) or None. Built
    without the temporaries of bench.harness.scene.displaced_grid (its UVs of every grid point)."""
    t = np.linspace(0.0, 1.0, n + 1)
    P = np.empty((n + 1, n + 1, 3))
    P[..., 0] = (t[None, :] - 0.5) * size
    P[..., 1] = (t[:, None] - 0.5) * size
    z = P[..., 2]
    z[:] = 0.0
    rng = np.random.default_rng(0)
    for _ in range(6):
        kx, ky = rng.uniform(1.0, 4.0, 2)
        ph = rng.uniform(0, 2 * math.pi, 2)
        z += np.sin(2 * math.pi * kx * t + ph[0])[None, :] * np.sin(2 * math.pi * ky * t + ph[1])[:, None]
    z *= amplitude / 3
    P = P.reshape(-1, 3)
    a = (np.arange(n)[None, :] + (n + 1) * np.arange(n)[:, None]).reshape(-1)
    F = np.empty((2, n * n, 3), np.int64)
    F[0, :, 0] = F[1, :, 0] = a
    F[0, :, 1] = a + 1
    F[0, :, 2] = F[1, :, 1] = a + n + 2
    F[1, :, 2] = a + n + 1
    F = F.reshape(-1, 3)
    UV = None
    if uvs:
        UV = np.empty((len(F), 3, 2))
        for k in range(3):
            UV[:, k, 0] = (F[:, k] % (n + 1)) / n
            UV[:, k, 1] = (F[:, k] // (n + 1)) / n
    return P, F, UV


def grid_side(triangles):
    return max(1, int(round(math.sqrt(triangles / 2))))


class Poller:
    """The resident sizes (RSS) and proportional set sizes (PSS) of this process and ``pids`` every
    ``step`` seconds: the largest sum of each, and each process's largest."""

    def __init__(self, pids, step=0.02):
        self.pids, self.step = ["self"] + list(pids), step
        self.peak_total, self.peak = 0, {p: 0 for p in self.pids}
        self.peak_pss_total, self.peak_pss = 0, {p: 0 for p in self.pids}
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self):
        while not self.stop.is_set():
            self.sample()
            time.sleep(self.step)

    def sample(self):
        total = total_pss = 0
        for p in self.pids:
            v, q = status(p) or 0, pss(p) or 0
            total += v
            total_pss += q
            self.peak[p] = max(self.peak[p], v)
            self.peak_pss[p] = max(self.peak_pss[p], q)
        self.peak_total = max(self.peak_total, total)
        self.peak_pss_total = max(self.peak_pss_total, total_pss)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join()


def child(case, triangles, workers, res, spp):
    sys.path.insert(0, str(ROOT))
    from core import Mesh, bake_ao
    from core.execution import pool as W
    from core.pipeline import run as pipeline_run

    out = {"case": case, "triangles": triangles, "workers": workers, "resolution": res, "spp": spp}
    base = status()
    if case == "embree":
        from core.tracing.tracer import embree_scene

        P, F, _ = grid(grid_side(triangles), False)
        mesh = Mesh(P, F, name="grid")
        out["triangles"] = len(F)
        for robust in (False, True):
            gc.collect()
            before = status()
            scene = embree_scene([mesh], robust=robust)[0]
            gc.collect()
            out[f"embree_bytes_robust_{robust}"] = status() - before
            out[f"embree_bytes_per_triangle_robust_{robust}"] = (status() - before) / len(F)
            del scene
        return out
    if case == "highpoly":
        P, F, _ = grid(grid_side(triangles), False)
        inputs = [P, F]
        lowp = np.array([[-2, -2, -0.5], [2, -2, -0.5], [2, 2, -0.5], [-2, 2, -0.5]], float)
        tri = np.array([[0, 1, 2], [0, 2, 3]])
        target = Mesh(lowp, tri, uvs=(lowp[tri][:, :, :2] + 2) / 4, name="low")
        high = Mesh(P, F, name="high")
        kwargs = dict(highpoly=[high], extrusion=1.0, max_distance=0.5)
    elif case == "occluder":
        P, F, _ = grid(grid_side(triangles), False)
        inputs = [P, F]
        lowp = np.array([[-2, -2, -0.5], [2, -2, -0.5], [2, 2, -0.5], [-2, 2, -0.5]], float)
        tri = np.array([[0, 1, 2], [0, 2, 3]])
        target = Mesh(lowp, tri, uvs=(lowp[tri][:, :, :2] + 2) / 4, name="low")
        kwargs = dict(occluders=[Mesh(P, F, name="occluder")], max_distance=1.0)
    elif case in ("target", "target-uvs"):
        P, F, UV = grid(grid_side(triangles), True)
        inputs = [P, F, UV]
        target = Mesh(P, F, uvs=UV, name="grid")
        kwargs = dict(max_distance=0.5)
    elif case == "large":
        P, F, UV = grid(64, True)
        inputs = [P, F, UV]
        target = Mesh(P, F, uvs=UV, name="grid")
        kwargs = dict(max_distance=0.5)
    else:
        raise SystemExit(f"unknown case {case!r}")
    if case == "target-uvs":
        # The job as it was before workers were sent the parent's layout: the target's UVs, laid out
        # again in each worker (the same tiles, the same bits).
        job_of = pipeline_run.Texels.job

        def uv_job(self):
            job = job_of(self)
            job["target"]["uvs"] = self.checked.target.uvs
            job.pop("layout", None)
            return job

        pipeline_run.Texels.job = uv_job
    out["triangles"] = len(F)
    out["input_bytes"] = int(sum(a.nbytes for a in inputs))
    gc.collect()
    out["parent_rss_before"] = status()
    out["parent_rss_start"] = base
    pids = []
    if workers > 1:
        pool = pipeline_run.pool(workers, 1)
        pids = [w.process.pid for w in pool.workers]
        time.sleep(0.5)
        out["worker_rss_idle"] = [status(p) for p in pids]
    t0 = time.perf_counter()
    with Poller(pids) as poll:
        r = bake_ao(target, resolution=res, samples=spp, workers=workers, threads=None if workers > 1 else 1,
                    **kwargs)
    out["seconds"] = time.perf_counter() - t0
    out["peak_total_polled"] = poll.peak_total
    out["peak_polled"] = [poll.peak[p] for p in poll.pids]
    out["peak_total_pss"] = poll.peak_pss_total
    out["peak_pss"] = [poll.peak_pss[p] for p in poll.pids]
    out["parent_hwm"] = status("self", "VmHWM")
    out["worker_hwm"] = [status(p, "VmHWM") for p in pids]
    out["covered_texels"] = int(r.mask.sum())
    out["rays"] = r.rays
    out["worker_memory"] = r.report.get("worker_memory")
    out["warnings"] = r.report.get("warnings")
    W.shutdown()
    return out


def run_case(case, triangles=0, workers=1, res=0, spp=0):
    cmd = [sys.executable, "-m", "bench.sections.memory", "--child", case, str(triangles), str(workers), str(res),
           str(spp)]
    print("running", " ".join(cmd[3:]), flush=True)
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        print(p.stderr[-3000:])
        return {"case": case, "error": p.stderr[-2000:]}
    return json.loads(p.stdout.strip().splitlines()[-1])


def figures(rows):
    """The derived figures: per triangle, per process."""
    emb = {}
    for r in rows:
        if r.get("case") == "embree" and "error" not in r:
            emb = r
    per_tri_embree = emb.get("embree_bytes_per_triangle_robust_False")
    per_tri_match = emb.get("embree_bytes_per_triangle_robust_True")
    for r in rows:
        if "error" in r or r["case"] == "embree":
            continue
        T = r["triangles"]
        d = r["derived"] = {"peak_total_gb": r["peak_total_polled"] / 1e9,
                            "peak_total_pss_gb": r["peak_total_pss"] / 1e9 if "peak_total_pss" in r else None,
                            "parent_peak_gb": r["parent_hwm"] / 1e9,
                            "parent_peak_beyond_inputs_per_triangle": (r["parent_hwm"] - r["parent_rss_before"]) / T}
        if r["workers"] > 1:
            d["worker_peak_gb"] = [h / 1e9 for h in r["worker_hwm"]]
            beyond = [(h - i) / T for h, i in zip(r["worker_hwm"], r["worker_rss_idle"])]
            d["worker_peak_beyond_idle_per_triangle"] = beyond
            if r["case"].startswith("target") and per_tri_embree:
                d["worker_peak_beyond_embree_per_triangle"] = [b - per_tri_embree for b in beyond]
            if r["case"] in ("highpoly", "occluder") and per_tri_embree:
                d["embree_per_triangle"] = {"occlusion": per_tri_embree, "matching (robust)": per_tri_match}
            wm = r.get("worker_memory")
            if wm:
                d["worker_held_per_triangle"] = [w.get("held", 0) / T for w in wm if w.get("process") != "parent"]
    return rows


def table(rows, stem):
    lines = [f"bench.sections.memory ({stem}): peak resident memory, 1 thread per worker; GB = 1e9 bytes"]
    for r in rows:
        if "error" in r:
            lines.append(f"{r['case']}: failed ({r['error'].strip().splitlines()[-1] if r['error'].strip() else '?'})")
            continue
        if r["case"] == "embree":
            lines.append(f"embree: one scene of {r['triangles']} triangles: "
                         f"{r['embree_bytes_per_triangle_robust_False']:.0f} B/tri (occlusion, not robust), "
                         f"{r['embree_bytes_per_triangle_robust_True']:.0f} B/tri (robust)")
            continue
        d = r["derived"]
        head = (f"{r['case']}: {r['triangles']} triangles, {r['resolution']}^2 x {r['spp']}, {r['workers']} "
                f"worker{'s' if r['workers'] > 1 else ''} ({'in this process' if r['workers'] == 1 else 'processes'}),"
                f" {r['seconds']:.1f} s")
        lines.append(head)
        if d.get("peak_total_pss_gb") is not None:
            lines.append(f"    all processes together, summed PSS (polled): {d['peak_total_pss_gb']:.2f} GB; per process "
                         + ", ".join(f"{b / 1e9:.2f}" for b in r["peak_pss"]) + " GB (parent first)")
        lines.append(f"    all processes together, summed RSS (polled): {d['peak_total_gb']:.2f} GB; parent peak "
                     f"{d['parent_peak_gb']:.2f} GB ({d['parent_peak_beyond_inputs_per_triangle']:.0f} B/tri beyond "
                     f"its inputs, {r['input_bytes'] / r['triangles']:.0f} B/tri of inputs)")
        if r["workers"] > 1:
            lines.append("    workers: peak " + ", ".join(f"{g:.2f}" for g in d["worker_peak_gb"]) + " GB; idle "
                         + ", ".join(f"{i / 1e6:.0f}" for i in r["worker_rss_idle"]) + " MB; beyond idle "
                         + ", ".join(f"{b:.0f}" for b in d["worker_peak_beyond_idle_per_triangle"]) + " B/tri")
            if "worker_peak_beyond_embree_per_triangle" in d:
                lines.append("    beyond idle and its Embree scene: "
                             + ", ".join(f"{b:.0f}" for b in d["worker_peak_beyond_embree_per_triangle"])
                             + " B/tri per worker (target 150)")
            if "worker_held_per_triangle" in d:
                lines.append("    held arrays (report['worker_memory']): "
                             + ", ".join(f"{b:.0f}" for b in d["worker_held_per_triangle"]) + " B/tri per worker")
    return "\n".join(lines)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "--child":
        case, t, w, res, spp = argv[1], int(argv[2]), int(argv[3]), int(argv[4]), int(argv[5])
        print(json.dumps(child(case, t, w, res, spp)))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--big", action="store_true", help="also the 10M-triangle high-poly on 2 workers")
    ap.add_argument("--stem", default="memory")
    ap.add_argument("--triangles", type=int, default=2_000_000, help="the high-poly and target cases' size")
    ap.add_argument("--cases", nargs="*", default=["embree", "highpoly1", "highpoly", "occluder", "target", "large"])
    args = ap.parse_args(argv)
    started = time.strftime("%Y-%m-%d %H:%M")
    load_before = load_average()
    T = args.triangles
    plan = {"embree": ("embree", T, 1, 0, 0), "highpoly1": ("highpoly", T, 1, 256, 16),
            "highpoly": ("highpoly", T, 2, 256, 16), "occluder": ("occluder", T, 2, 256, 16), "target": ("target", T, 2, 1024, 16),
            "target-uvs": ("target-uvs", T, 2, 1024, 16),
            "large": ("large", 0, 2, 8192, 4)}
    rows = [run_case(*plan[c]) for c in args.cases]
    if args.big:
        rows.append(run_case("highpoly", 10_000_000, 2, 256, 16))
    rows = figures(rows)
    text = table(rows, args.stem)
    print(text)
    record = {"started": started, "machine": machine(), "git": git_state(), "load_before": load_before,
              "load_after": load_average(),
              "targets": {"highpoly 10M, 256^2 x 16, 2 workers": "summed PSS of all processes < 3 GB",
                          "target 2M, 1024^2 x 16": "each worker: Embree + 150 B/tri",
                          "8192^2 x 4": "summed PSS of the parent and every worker < 1.5 GB"},
              "rows": rows}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{args.stem}.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / f"{args.stem}.txt").write_text(text + "\n")


if __name__ == "__main__":
    main()
