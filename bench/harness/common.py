"""Shared helpers of the benchmark: machine description, timing, masks and error measures."""

import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
RESULTS = Path(__file__).resolve().parents[1] / "results"


def git_state():
    def run(*args):
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    return {"commit": run("rev-parse", "--short", "HEAD"),
            "core_dirty": bool(run("status", "--porcelain", "--", "core"))}


def machine():
    """What the numbers were measured on (and how busy it was)."""
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    mem = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    mem = round(int(line.split()[1]) / 2**20, 1)
    except OSError:
        pass
    info = {"cpu": cpu, "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
            "memory_gib": mem, "python": sys.version.split()[0], "numpy": np.__version__,
            "platform": platform.platform()}
    try:
        import embreex
        info["embreex"] = getattr(embreex, "__version__", "?")
    except ImportError:
        pass
    return info


def load_average():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


class Clock:
    """Wall seconds since the benchmark started, for the log."""

    def __init__(self):
        self.t0 = time.perf_counter()

    def __call__(self):
        return time.perf_counter() - self.t0


def log(msg, clock=None):
    stamp = f"[{clock():6.1f}s] " if clock is not None else ""
    print(stamp + msg, file=sys.stderr, flush=True)


def erode(mask, r=1):
    """Texels whose (2r+1)^2 neighbourhood is all inside ``mask`` (away from island edges)."""
    from scipy import ndimage

    return ndimage.binary_erosion(mask, np.ones((2 * r + 1, 2 * r + 1), bool))


def rmse(a, b, sel):
    d = np.asarray(a, np.float64)[sel] - np.asarray(b, np.float64)[sel]
    return float(np.sqrt(np.mean(d * d))) if d.size else float("nan")


def mean_diff(a, b, sel):
    """Mean of a - b over ``sel``, its standard error (texels taken as independent), and z = mean / se."""
    d = np.asarray(a, np.float64)[sel] - np.asarray(b, np.float64)[sel]
    if d.size < 2:
        return {"n": int(d.size), "mean": float("nan"), "se": float("nan"), "z": float("nan")}
    m, se = float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size))
    return {"n": int(d.size), "mean": m, "se": se, "z": m / se if se > 0 else float("inf")}


def interp_time_at(times, errors, target):
    """The time at which a series (times, errors) reaches ``target`` error, by log-log interpolation
    between the two measurements that bracket it; None when the series never gets there."""
    pts = sorted(zip(times, errors))
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 >= target >= e1 and e0 > 0 and e1 > 0 and e0 != e1:
            f = (np.log(target) - np.log(e0)) / (np.log(e1) - np.log(e0))
            return float(np.exp(np.log(t0) + f * (np.log(t1) - np.log(t0))))
    if pts and pts[0][1] <= target:
        return float(pts[0][0])  # already there at the cheapest point: an upper bound
    return None


def write_json(data, name):
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / name
    with open(path, "w") as f:
        json.dump(data, f, indent=1, default=_jsonable)
        f.write("\n")
    return path


def _jsonable(x):
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"not JSON serialisable: {type(x)}")
