"""Peak memory of one core.bake_ao, measured in a fresh process: ``python -m bench.harness.memprobe scene.npz RES SPP THREADS``.

Prints one JSON line: RSS before the bake (after imports and the meshes), peak RSS (VmHWM), bake
seconds, rays and the share inside embreex. No bpy is imported, so the figure is the core's own.
"""

import json
import resource
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def rss_mib(field="VmRSS"):
    """This process's resident set (VmRSS) or its high-water mark (VmHWM), in MiB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    return float("nan")


def load_scene(path):
    import numpy as np

    from core import Mesh

    z = np.load(path)
    target = Mesh(z["P"], z["F"], z["UV"], z["N"], name="Suzanne")
    k = int(z["occluders"])
    occ = [Mesh(z[f"O{i}P"], z[f"O{i}F"], name=f"occluder{i}") for i in range(k)]
    return target, occ, float(z["distance"])


def main(argv):
    path, res, spp, threads = argv[0], int(argv[1]), int(argv[2]), int(argv[3])
    from core import bake_ao

    target, occ, distance = load_scene(path)
    before = rss_mib()
    # RSS every 20 ms, and when tracing ended (progress reached 1): is the peak in the tiles or in
    # what comes after them (result planes, margin dilation)?
    samples, done_at, stop = [], [None], threading.Event()

    def watch():
        while not stop.is_set():
            samples.append((time.perf_counter(), rss_mib()))
            time.sleep(0.02)

    def progress(f):
        if f >= 1.0 and done_at[0] is None:
            done_at[0] = time.perf_counter()

    w = threading.Thread(target=watch, daemon=True)
    w.start()
    t0 = time.perf_counter()
    r = bake_ao(target, occ, resolution=res, samples=spp, threads=threads, max_distance=distance, margin=16,
                progress=progress)
    wall = time.perf_counter() - t0
    stop.set()
    w.join()
    # VmHWM, not ru_maxrss: Linux carries ru_maxrss across fork + exec, so a probe started by the
    # benchmark (which holds Blender, over 1 GB) would report its parent's size, not its own.
    peak = rss_mib("VmHWM")
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
    split = done_at[0] or time.perf_counter()
    during = max((m for t, m in samples if t <= split), default=float("nan"))
    after = max((m for t, m in samples if t > split), default=float("nan"))
    print(json.dumps({"resolution": res, "samples": spp, "threads": threads, "rss_before_mib": before,
                      "peak_rss_mib": peak, "ru_maxrss_mib": maxrss, "peak_rss_tracing_mib": during, "peak_rss_after_tracing_mib": after,
                      "seconds_after_tracing": time.perf_counter() - split if done_at[0] else None,
                      "seconds": wall, "bake_seconds": r.seconds, "rays": r.rays,
                      "texels": int(r.mask.sum()), "trace_share": r.trace_seconds / (r.seconds * r.threads)}))


if __name__ == "__main__":
    main(sys.argv[1:])
