"""The benchmark, in one command: ``.venv/bin/python -m bench [--quick] [--sections ...]``.

mc_ao against Cycles' AO bake (equal samples, equal error, agreement), against raw Embree (the
ceiling), and against itself (threads, resolution, triangles, memory), all measured in one run on
this machine. Prints a table and writes bench/results/run-<time>-<mode>.json, plus latest.json
(full mode) or latest-quick.json (quick mode).
"""

import argparse
import datetime as _dt
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# Blender's user folders go to a temporary place, before bpy is first imported.
_USER_DIR = tempfile.mkdtemp(prefix="mc_ao_bench_blender_")
os.environ.setdefault("BLENDER_USER_RESOURCES", _USER_DIR)

import numpy as np  # noqa: E402

from . import report  # noqa: E402
from .common import RESULTS, Clock, git_state, load_average, log, machine, write_json  # noqa: E402

FULL = dict(
    es_res=(128, 256, 512), es_spp=128, es_repeats={128: 3, 256: 3, 512: 2},
    ee_res=128, ref_spp=4096, cyc_spp=(8, 16, 32, 64, 128, 256, 512), mc_spp=(8, 16, 32, 64, 128, 256, 512),
    adaptive_errors=(0.08, 0.04, 0.02, 0.01), adaptive_cap=1024, adaptive_min=16, cyc_check_spp=1024,
    ee_repeats=2,
    ag_res=128, ag_spp=1024, lid_res=32, lid_spp=4096, dist_res=16, dist_spp=1024, dist_d=0.5,
    contact_res=128, contact_spp=256, placement_spp=1024,
    ceil_res=256, ceil_spp=64, prof_res=256, prof_spp=128,
    thr_res=512, thr_spp=64, thr_repeats=3,
    scale_res=(256, 512, 1024, 2048), scale_spp=16, scale_res_1spp=(256, 1024),
    tri_n=(71, 224, 707), tri_res=512, tri_spp=16,
    mem_res=4096, mem_spp=4,
)
QUICK = dict(
    FULL,
    es_res=(128, 256), es_spp=64, es_repeats={128: 2, 256: 1},
    ee_res=96, ref_spp=1024, cyc_spp=(8, 32, 128), mc_spp=(8, 32, 128), adaptive_errors=(0.04, 0.01),
    adaptive_cap=512, cyc_check_spp=256, ee_repeats=1,
    ag_res=96, ag_spp=256, lid_res=16, lid_spp=1024, dist_res=8, dist_spp=256, contact_res=96, contact_spp=64, placement_spp=256,
    ceil_res=128, ceil_spp=32, prof_res=128, prof_spp=64,
    thr_res=256, thr_spp=32, thr_repeats=1,
    scale_res=(256, 512, 1024), scale_spp=8, scale_res_1spp=(256,),
    tri_n=(71, 224), tri_res=256, tri_spp=8,
    mem_res=0,
)
SECTIONS = ("equal_samples", "equal_error", "agreement", "ceiling", "threads", "resolution", "triangles", "memory")
DEVICE_RESULTS = RESULTS / "device.json"
SCENE_COPY = Path(__file__).resolve().parent / "data" / "scene_suzanne.npz"


class Context:
    """What the sections share: bpy, the scene's objects and its arrays, settings, the clock."""

    def __init__(self, cfg, threads):
        import bpy

        from . import scene

        self.bpy, self.cfg, self.threads = bpy, cfg, threads
        self.root = ROOT
        self.clock = Clock()
        self._scene = scene
        self._npz = None
        self.restore_scene()
        self.scene_npz()  # also what bench/device.py bakes on the device machine

    def restore_scene(self):
        s = self._scene
        s.reset_blender(self.bpy)
        self.objs = s.build_scene(self.bpy)
        ta, oa = s.scene_arrays(self.bpy, "Suzanne")
        self.arrays = (ta, oa)
        self.target, self.occluders = s.core_meshes(ta, oa)

    def scene_npz(self):
        """The benchmark scene's arrays (target Suzanne and its occluders) as an .npz, for subprocesses."""
        if self._npz is None:
            ta, oa = self.arrays
            data = {"P": ta.positions, "F": ta.triangles, "UV": ta.uvs, "N": ta.normals,
                    "occluders": len(oa), "distance": self._scene.DISTANCE}
            for i, o in enumerate(oa):
                data[f"O{i}P"], data[f"O{i}F"] = o.positions, o.triangles
            SCENE_COPY.parent.mkdir(exist_ok=True)
            np.savez_compressed(SCENE_COPY, **data)
            self._npz = SCENE_COPY
        return self._npz


def targets(res):
    """The issue's targets against this run's figures: (name, target, value, met)."""
    out = []
    es = res.get("equal_samples")
    if es:
        worst = min(es["rows"], key=lambda r: r["ratio_time"])
        worst_t = min(es["rows"], key=lambda r: r["ratio_tsps"])
        out.append(dict(name="equal samples: mc_ao texel-samples/s vs Cycles", target=">= 3x",
                        value=f"{worst_t['ratio_tsps']:.2f}x own texels, {worst['ratio_time']:.2f}x same-job time "
                              f"(worst of {', '.join(str(r['resolution']) for r in es['rows'])}; best "
                              f"{max(r['ratio_time'] for r in es['rows']):.2f}x; CPU-time ratio "
                              f"{min(r['ratio_cpu'] for r in es['rows']):.2f}..{max(r['ratio_cpu'] for r in es['rows']):.2f}x)",
                        met=worst["ratio_time"] >= 3 and worst_t["ratio_tsps"] >= 3))
    ee = res.get("equal_error")
    if ee and ee.get("best", {}).get("ratio") is not None:
        sob = ee["fitted"].get("sobol", {})
        v = f"{ee['best']['ratio']:.2f} ({ee['best']['config']}, fitted times"
        if ee["best"].get("ratio_cpu") is not None:
            v += f"; {ee['best']['ratio_cpu']:.2f} in CPU time"
        v += ")"
        if sob.get("ratio") is not None and ee["best"]["config"] != "sobol":
            v += f"; sobol {sob['ratio']:.2f}"
        out.append(dict(name="equal error: mc_ao time / Cycles time at Cycles' 128-spp RMSE", target="<= 0.20",
                        value=v, met=ee["best"]["ratio"] <= 0.2))
    ce = res.get("ceiling")
    th = res.get("threads")
    if ce or th:
        shares = []
        if ce:
            shares.append(("1 thread", ce["bake"]["trace_share"]))
        if th:
            shares.append(("2 threads", th["rows"][1]["trace_share"]))
        out.append(dict(name="share of bake time inside embreex", target=">= 85%",
                        value=", ".join(f"{100 * s:.0f}% ({k})" for k, s in shares),
                        met=all(s >= 0.85 for _, s in shares)))
    if th:
        out.append(dict(name="speed-up from 1 to 2 threads", target=">= 1.8x",
                        value=f"{th['speedup_1_to_2']:.2f}x", met=th["speedup_1_to_2"] >= 1.8))
    mem = res.get("memory")
    if mem and "peak_rss_mib" in mem:
        out.append(dict(name=f"peak memory of a {mem['resolution']}^2 bake", target="< 1.5 GB",
                        value=f"{mem['peak_rss_mib'] * 2**20 / 1e9:.2f} GB", met=mem["peak_rss_mib"] * 2**20 < 1.5e9))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes and fewer samples (about 2 minutes)")
    ap.add_argument("--sections", nargs="+", choices=SECTIONS, default=list(SECTIONS))
    ap.add_argument("--threads", type=int, default=None, help="threads for both bakers (default: all cores)")
    ap.add_argument("--no-save", action="store_true", help="print the table, write no JSON")
    args = ap.parse_args(argv)
    cfg = QUICK if args.quick else FULL
    threads = args.threads or len(os.sched_getaffinity(0))
    started = time.time()
    load0 = load_average()
    ctx = Context(cfg, threads)
    from . import agreement, ceiling, equal, scaling

    runners = {"equal_samples": equal.equal_samples, "equal_error": equal.equal_error,
               "agreement": agreement.agreement, "ceiling": ceiling.ceiling, "threads": scaling.threads,
               "resolution": scaling.resolution, "triangles": scaling.triangles, "memory": scaling.memory}
    res = {}
    for name in SECTIONS:
        if name in args.sections:
            log(f"== {name}", ctx.clock)
            res[name] = runners[name](ctx)
    if DEVICE_RESULTS.exists():
        res["device"] = json.loads(DEVICE_RESULTS.read_text())
    import bpy

    data = {"mode": "quick" if args.quick else "full", "started": _dt.datetime.fromtimestamp(started).isoformat(
        timespec="seconds"), "duration_s": time.time() - started, "threads": threads, "machine": machine(),
        "blender": bpy.app.version_string, "git": git_state(), "load_average_start": load0,
        "load_average_end": load_average(), "config": cfg, "results": res}
    data["targets"] = targets(res)
    text = report.table(data)
    print(text)
    if not args.no_save:
        stamp = _dt.datetime.fromtimestamp(started).strftime("%Y%m%d-%H%M%S")
        path = write_json(data, f"run-{stamp}-{data['mode']}.json")
        if set(args.sections) == set(SECTIONS):
            latest = "latest" if not args.quick else "latest-quick"
            shutil.copyfile(path, RESULTS / f"{latest}.json")
            (RESULTS / f"{latest}.txt").write_text(text + "\n")
            if not args.quick:
                try:
                    from . import plot

                    plot.main([str(RESULTS / "latest.json")])
                except Exception as exc:  # a figure is a nicety; the numbers are written already
                    log(f"no figure: {exc}", ctx.clock)
        log(f"wrote {path}", ctx.clock)
    shutil.rmtree(_USER_DIR, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
