"""How responsive the real Blender UI stays while Bake AO runs: the latency of a 10 ms timer.

Run by tests/gui/latency.sh inside ../shared/tools/blender-gui.sh (a real Blender GUI on a virtual
screen): ``blender --factory-startup sample_scenes/suzanne.blend --python tests/gui/ui_latency.py``.

It installs the zip named by $MC_AO_ZIP into a temporary user repository (Install from Disk), enables
it, and first bakes a tiny scene with the installed core directly, ``workers=2`` against
``workers=1``, comparing the bits (worker processes started from inside the real Blender). Then it
selects Suzanne, sets the scene's MC AO resolution and samples ($MC_AO_LAT_RES, $MC_AO_LAT_SAMPLES),
and runs the modes of $MC_AO_LAT_MODES one after another:

- ``idle``: no bake, for $MC_AO_LAT_IDLE seconds;
- ``threads``: Bake AO as the add-on runs it (its worker thread, the core's threads);
- ``workers``: the same, with the installed core's ``bake_ao`` given ``workers=$MC_AO_LAT_WORKERS``
  (the operator reaches the core as ``corelink.load().bake_ao``, so the package attribute is what
  is replaced); the first such bake starts the pool (cold), later ones reuse it (warm);
- ``shot``: a ``workers`` bake during which a screenshot is taken (its figures carry the shot's load).

Each bake is started the way the button starts it, ``bpy.ops.object.mc_ao_bake('INVOKE_DEFAULT')``
with the 3D Viewport as its context (modal, Esc would cancel). Meanwhile a ``bpy.app.timers``
callback that re-arms itself every 0.010 s records the interval between its calls
(``time.perf_counter``), from the invoke until the operator has finished. Everything goes to
$MC_AO_LAT_OUT/results.json and a table, table.txt; Blender quits at the end.
"""

import importlib
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import threading
import time
import traceback

import bpy
import numpy as np

OUT = os.environ.get("MC_AO_LAT_OUT", "/tmp/out/mc_ao_latency")
ZIP = os.environ["MC_AO_ZIP"]
RES = int(os.environ.get("MC_AO_LAT_RES", "1024"))
SAMPLES = int(os.environ.get("MC_AO_LAT_SAMPLES", "128"))
WORKERS = int(os.environ.get("MC_AO_LAT_WORKERS", "2"))
IDLE_SECONDS = float(os.environ.get("MC_AO_LAT_IDLE", "15"))
MODES = os.environ.get("MC_AO_LAT_MODES", "idle threads workers workers threads shot").split()
OBJECT = os.environ.get("MC_AO_LAT_OBJECT", "Suzanne")
INTERVAL = 0.010
REPO = "mc_ao_lat"
ADDON = f"bl_ext.{REPO}.mc_ao"

results = {"modes": [], "direct": None}
state = {"recording": False, "intervals": [], "last": None, "inject_workers": False, "bakes": []}


def log(*args):
    print("[ui_latency]", *args, flush=True)


def write(name, data):
    path = os.path.join(OUT, name)
    with open(path + ".tmp", "w") as fh:
        json.dump(data, fh, indent=1, default=str)
    os.replace(path + ".tmp", path)


def guarded(step):
    """A timer step that, if it fails, writes error.json (latency.sh stops on it) instead of hanging."""
    def run(*args):
        try:
            return step(*args)
        except Exception:
            traceback.print_exc()
            write("error.json", {"step": step.__name__, "error": traceback.format_exc()})
            return None
    return run


# -- the 10 ms timer -----------------------------------------------------------------------------

def tick():
    now = time.perf_counter()
    if state["recording"]:
        if state["last"] is not None:
            state["intervals"].append(now - state["last"])
        state["last"] = now
    return INTERVAL


def start_recording():
    state["intervals"], state["last"], state["recording"] = [], None, True


def stop_recording():
    state["recording"] = False
    return np.array(state["intervals"]) * 1000.0


def stats(ms):
    if not len(ms):
        return {"n": 0}
    p50, p95, p99 = np.percentile(ms, [50, 95, 99])
    return {"n": int(len(ms)), "p50_ms": float(p50), "p95_ms": float(p95), "p99_ms": float(p99),
            "max_ms": float(ms.max()), "mean_ms": float(ms.mean()),
            "over_50ms": int((ms > 50).sum()), "over_100ms": int((ms > 100).sum())}


# -- the core, installed and patched ---------------------------------------------------------------

def install():
    repos = bpy.context.preferences.extensions.repos
    directory = tempfile.mkdtemp(prefix="mc_ao_lat_repo_")
    repos.new(name="MC AO latency", module=REPO, custom_directory=directory, source="USER")
    result = bpy.ops.extensions.package_install_files(filepath=ZIP, repo=REPO, enable_on_install=True)
    enabled = ADDON in bpy.context.preferences.addons
    log("install:", result, "enabled:", enabled)
    if not enabled:
        raise RuntimeError(f"{ADDON} is not enabled after installing {ZIP}")


def core():
    return importlib.import_module(ADDON + ".core")


def cpu_of(pid):
    """User + system CPU seconds of a process, from /proc (0 when it is gone)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields = fh.read().rpartition(")")[2].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except OSError:
        return 0.0


def pool_state():
    pool = core().workers._POOL
    if pool is None:
        return None
    return {"workers": [w.process.pid for w in pool.workers], "alive": [bool(w.alive) for w in pool.workers],
            "threads": pool.threads, "failed": pool.failed, "broken": pool.broken,
            "cpu_s": {w.process.pid: cpu_of(w.process.pid) for w in pool.workers}}


def patch_core():
    """Replace the installed core's bake_ao (what the operator calls) by one that records each bake
    and, while state['inject_workers'], bakes in worker processes."""
    c = core()
    orig = c.bake_ao

    def bake_ao(*args, **kw):
        if state["inject_workers"]:
            kw["workers"] = WORKERS
        before = pool_state()
        cpu0 = resource.getrusage(resource.RUSAGE_SELF)
        t0 = time.perf_counter()
        record = {"kwargs": {k: v for k, v in kw.items() if k in ("workers", "threads", "resolution", "samples")}}
        try:
            r = orig(*args, **kw)
        except BaseException as e:
            record["error"] = f"{type(e).__name__}: {e}"
            state["bakes"].append(record)
            raise
        cpu1 = resource.getrusage(resource.RUSAGE_SELF)
        after = pool_state()
        worker_cpu = None
        if after is not None:
            old = (before or {}).get("cpu_s", {})
            worker_cpu = sum(after["cpu_s"][p] - old.get(p, 0.0) for p in after["workers"])
        record.update(seconds=time.perf_counter() - t0, core_seconds=r.seconds, result_threads=r.threads,
                      rays=r.rays, warnings=r.report.get("warnings"), pool=after, worker_cpu_s=worker_cpu,
                      blender_cpu_s=(cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime))
        state["bakes"].append(record)
        return r

    c.bake_ao = bake_ao
    log("patched", c.__name__ + ".bake_ao")


# -- worker processes from inside Blender, without the operator ------------------------------------

def tiny_scene(c):
    n = 12
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    z = 0.05 * np.sin(6 * x) * np.cos(5 * y)
    P = np.stack([x, y, z], -1).reshape(-1, 3)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    F = np.concatenate([np.stack([i, i + 1, i + n + 2], -1).reshape(-1, 3),
                        np.stack([i, i + n + 2, i + n + 1], -1).reshape(-1, 3)])
    target = c.Mesh(P, F, uvs=P[F][:, :, :2], name="bumps")
    lid = c.Mesh(np.array([[0.2, 0.2, 0.4], [0.8, 0.2, 0.4], [0.8, 0.8, 0.4], [0.2, 0.8, 0.4]]),
                 np.array([[0, 1, 2], [0, 2, 3]]), name="lid")
    return target, [lid]


def direct_check():
    """Bake the tiny scene with workers=WORKERS and workers=1 in this Blender; compare the bits."""
    c = core()
    out = {"sys_executable": sys.executable, "python": sys.version, "platform": platform.platform()}
    try:
        probe = subprocess.run([sys.executable, "-c", "import sys, numpy, embreex; print(sys.version.split()[0],"
                                " numpy.__version__, embreex.__file__)"],
                               capture_output=True, text=True, timeout=120, env=dict(os.environ,
                               PYTHONPATH=os.pathsep.join(p for p in sys.path if p)))
        out["probe"] = {"rc": probe.returncode, "stdout": probe.stdout.strip(), "stderr": probe.stderr.strip()[-2000:]}
    except Exception as e:
        out["probe"] = {"error": f"{type(e).__name__}: {e}"}
    target, occ = tiny_scene(c)
    args = dict(resolution=48, samples=32, max_distance=0.7, seed=3, margin=2)
    try:
        ref = c.bake_ao(target, occ, workers=1, **args)
        t0 = time.perf_counter()
        r = c.bake_ao(target, occ, workers=WORKERS, **args)
        out["workers_seconds_cold"] = time.perf_counter() - t0
        out["pool"] = pool_state()
        out["warnings"] = r.report.get("warnings")
        out["identical"] = {name: bool(np.array_equal(getattr(ref, name), getattr(r, name)))
                            for name in ("ao", "stderr", "samples", "mask")}
        out["same_rays"] = r.rays == ref.rays
        out["ok"] = (all(out["identical"].values()) and out["same_rays"] and not out["warnings"]
                     and out["pool"] is not None and out["pool"]["failed"] is None
                     and all(out["pool"]["alive"]) and len(out["pool"]["workers"]) == WORKERS)
    except Exception:
        out["error"] = traceback.format_exc()
        out["ok"] = False
    # The operator's first workers bake then starts its own pool (cold).
    c.workers.shutdown()
    log("direct workers check:", json.dumps(out, default=str))
    return out


# -- the scene and the screen -------------------------------------------------------------------

def scene_setup():
    obj = bpy.data.objects[OBJECT]
    for o in bpy.context.view_layer.objects:
        o.select_set(o is obj)
    bpy.context.view_layer.objects.active = obj
    settings = bpy.context.scene.mc_ao
    settings.resolution = RES
    settings.samples = SAMPLES
    log("scene: bake", OBJECT, "at", settings.resolution, "x", settings.samples, "spp")


def screen():
    window = bpy.context.window_manager.windows[0]
    return window, window.screen


def split_view():
    window, scr = screen()
    area = max((a for a in scr.areas if a.type == "VIEW_3D"), key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.screen.area_split(direction="VERTICAL", factor=0.5)


def arrange():
    """Left: the 3D Viewport (textured solid shading); right: an Image Editor for the AO image."""
    window, scr = screen()
    views = sorted((a for a in scr.areas if a.type == "VIEW_3D"), key=lambda a: a.x)
    views[-1].type = "IMAGE_EDITOR"
    space = views[0].spaces.active
    space.shading.type = "SOLID"
    space.shading.color_type = "TEXTURE"
    space.show_region_ui = True


def show_image():
    window, scr = screen()
    image = bpy.data.images.get(f"{OBJECT}_AO")
    for area in scr.areas:
        if area.type == "IMAGE_EDITOR" and image is not None and area.spaces.active.image != image:
            area.spaces.active.image = image
            region = next(r for r in area.regions if r.type == "WINDOW")
            with bpy.context.temp_override(window=window, area=area, region=region):
                bpy.ops.image.view_all(fit_view=True)


def invoke_bake():
    window, scr = screen()
    area = max((a for a in scr.areas if a.type == "VIEW_3D"), key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=area, region=region):
        return bpy.ops.object.mc_ao_bake("INVOKE_DEFAULT")


def running():
    operators = sys.modules.get(f"{ADDON}.mc_ao.operators")
    return operators is not None and bool(operators._RUNS)


def screenshot(name):
    path = os.path.join(OUT, name)
    return subprocess.Popen(f"xwd -root -silent | xwdtopnm 2>/dev/null | pnmtopng > {path}", shell=True)


# -- the run ------------------------------------------------------------------------------------

@guarded
def setup():
    install()
    results["direct"] = direct_check()
    write("direct.json", results["direct"])
    patch_core()
    scene_setup()
    split_view()
    bpy.app.timers.register(setup2, first_interval=1.0)


@guarded
def setup2():
    arrange()
    results.update(blender=bpy.app.version_string, python=sys.version.split()[0], executable=sys.executable,
                   resolution=RES, samples=SAMPLES, workers=WORKERS, cpus=os.cpu_count(),
                   affinity=len(os.sched_getaffinity(0)), load_before=os.getloadavg())
    write("ready.json", {"ok": True})
    bpy.app.timers.register(tick, first_interval=INTERVAL, persistent=True)
    bpy.app.timers.register(wait_go, first_interval=0.2)


@guarded
def wait_go():
    """latency.sh closes the splash screen (Esc), then writes go: a popup would block the UI."""
    if not os.path.exists(os.path.join(OUT, "go")):
        return 0.2
    bpy.app.timers.register(next_mode, first_interval=3.0)
    return None


@guarded
def next_mode():
    if not MODES:
        return finish()
    mode = MODES.pop(0)
    log("mode", mode)
    state["mode"] = {"mode": mode, "load_before": os.getloadavg()}
    state["inject_workers"] = mode in ("workers", "shot")
    state["bakes_before"] = len(state["bakes"])
    if mode == "workers":
        state["mode"]["pool"] = "warm" if core().workers._POOL is not None else "cold"
    start_recording()
    state["t0"] = time.perf_counter()
    if mode == "idle":
        bpy.app.timers.register(end_idle, first_interval=IDLE_SECONDS)
        return None
    result = invoke_bake()
    state["mode"]["invoke"] = sorted(result)
    if "RUNNING_MODAL" not in result:
        raise RuntimeError(f"Bake AO did not start: {result}")
    state["seen_running"] = False
    state["shot_taken"] = mode != "shot"
    show_image()
    bpy.app.timers.register(watch, first_interval=0.1)
    return None


@guarded
def end_idle():
    ms = stop_recording()
    close_mode(ms, time.perf_counter() - state["t0"])
    bpy.app.timers.register(next_mode, first_interval=2.0)


@guarded
def watch():
    elapsed = time.perf_counter() - state["t0"]
    if running():
        state["seen_running"] = True
        if not state["shot_taken"] and elapsed > 0.45 * state.get("expected", 10.0):
            state["shot_taken"] = True
            state["mode"]["shot"] = "during_workers_bake.png"
            state["mode"]["shot_at_s"] = elapsed
            screenshot("during_workers_bake.png")
        return 0.1
    if not state["seen_running"] and elapsed < 5.0:
        return 0.1
    ms = stop_recording()
    close_mode(ms, elapsed)
    screenshot(f"after_{len(results['modes'])}_{state['mode']['mode']}.png")
    bpy.app.timers.register(next_mode, first_interval=3.0)
    return None


def close_mode(ms, seconds):
    m = state["mode"]
    m.update(seconds=seconds, load_after=os.getloadavg(), **stats(ms))
    bakes = state["bakes"][state["bakes_before"]:]
    m["bakes"] = bakes
    if m["mode"] != "idle":
        image = bpy.data.images.get(f"{OBJECT}_AO")
        m["image"] = None if image is None else list(image.size)
        if m["mode"] == "threads":
            state["expected"] = seconds
    np.save(os.path.join(OUT, f"intervals_{len(results['modes'])}_{m['mode']}.npy"), ms)
    results["modes"].append(m)
    write("results.json", results)
    log(m["mode"], json.dumps({k: v for k, v in m.items() if k != "bakes"}, default=str))


def table():
    lines = [f"{'mode':<16} {'bake s':>7} {'n':>5} {'p50 ms':>7} {'p95 ms':>7} {'p99 ms':>7} {'max ms':>7} "
             f"{'>50ms':>6} {'blender cpu s':>13} {'worker cpu s':>12}  load"]
    for m in results["modes"]:
        name = m["mode"] + (f" ({m['pool']})" if "pool" in m else "")
        bake = (m.get("bakes") or [{}])[0] if m["mode"] != "idle" else {}
        secs = f"{m['seconds']:.1f}" if m["mode"] != "idle" else f"({m['seconds']:.0f})"
        wcpu = bake.get("worker_cpu_s")
        lines.append(f"{name:<16} {secs:>7} {m['n']:>5} {m['p50_ms']:>7.1f} {m['p95_ms']:>7.1f} {m['p99_ms']:>7.1f} "
                     f"{m['max_ms']:>7.1f} {m['over_50ms']:>6} "
                     f"{bake.get('blender_cpu_s', float('nan')):>13.1f} "
                     f"{(wcpu if wcpu is not None else float('nan')):>12.1f}  "
                     f"{m['load_before'][0]:.1f}")
    return "\n".join(lines) + "\n"


def finish():
    results["load_after"] = os.getloadavg()
    write("results.json", results)
    with open(os.path.join(OUT, "table.txt"), "w") as fh:
        fh.write(table())
    log("table\n" + table())
    write("done.json", {"ok": True})
    bpy.app.timers.register(quit_blender, first_interval=1.0)
    return None


def quit_blender():
    core().workers.shutdown()
    bpy.ops.wm.quit_blender()


os.makedirs(OUT, exist_ok=True)
bpy.app.timers.register(setup, first_interval=2.0)
