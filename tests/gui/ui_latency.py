"""How responsive the real Blender UI stays while Bake AO runs: the latency of a 10 ms timer.

Run by tests/gui/latency.sh inside ../shared/tools/blender-gui.sh (a real Blender GUI on a virtual
screen): ``blender --factory-startup sample_scenes/suzanne.blend --python tests/gui/ui_latency.py``.

It installs the zip named by $MC_AO_ZIP into a temporary user repository (Install from Disk), enables
it, and first bakes a tiny scene with the installed core directly, ``workers=2`` against
``workers=1``, comparing the bits (worker processes started from inside the real Blender). Then it
selects Suzanne, sets the scene's MC AO resolution and samples ($MC_AO_LAT_RES, $MC_AO_LAT_SAMPLES),
and runs the modes of $MC_AO_LAT_MODES one after another:

- ``idle``: no bake, for $MC_AO_LAT_IDLE seconds;
- ``burn``: no bake, $MC_AO_LAT_WORKERS busy processes beside Blender for as long (CPU load that never
  takes Blender's GIL: what worker processes cost the UI on a machine with no core to spare);
- ``idle-redraw``, ``burn-redraw``: no bake, but new progress texts in the 3D Viewport's header and
  the status bar every 0.1 s, as the operator sets them while it bakes (so Blender redraws), alone
  and beside the busy processes of ``burn``;
- ``gil``: no bake, one busy Python thread inside Blender for as long (what the GIL costs the UI);
- ``threads``: Bake AO as the add-on runs it (its worker thread, the core's threads);
- ``workers``: the same, with the installed core's ``bake`` given a request of ``workers=$MC_AO_LAT_WORKERS``
  (the operator reaches the core as ``corelink.load().bake``, so the package attribute is what
  is replaced); the first such bake starts the pool (cold), later ones reuse it (warm);
- ``threads-nice``, ``workers-nice``: the same bakes with the baking threads, or the worker
  processes, at nice $MC_AO_LAT_NICE (the pool is made before the bake, so that its workers are reniced);
- ``threads-quiet``, ``workers-quiet``: the same bakes with the add-on's progress texts and live
  image updates switched off (the image is written once, at the end), so that Blender hardly
  redraws: what the bake itself (its GIL, its CPU) costs the timer;
- ``threads-hidden``, ``workers-hidden``: the same bakes with nothing showing the AO image (the Image
  Editor empty, the viewport in material colours): the add-on still updates the image, nothing draws it;
- ``shot``: a ``workers`` bake into a new image, during which a screenshot is taken (its figures carry
  the shot's load).

Besides the intervals it records, per mode: the CPU time of Blender's main thread and of the whole
Blender process, the time the add-on's modal handler (BakeSession.on_event, and its live image update
_flush_live) took on the main thread, how many times the 3D Viewport and the Image Editor drew, and
for each bake the CPU time of the worker processes.

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
MODES = os.environ.get("MC_AO_LAT_MODES", "idle burn gil idle-redraw burn-redraw threads workers threads-quiet "
                       "workers-quiet threads-nice workers-nice threads workers shot").split()
OBJECT = os.environ.get("MC_AO_LAT_OBJECT", "Suzanne")
NICE = int(os.environ.get("MC_AO_LAT_NICE", "10"))
INTERVAL = 0.010
REPO = "mc_ao_lat"
ADDON = f"bl_ext.{REPO}.mc_ao"

results = {"modes": [], "direct": None}
state = {"recording": False, "intervals": [], "last": None, "inject_workers": False, "bakes": [], "main": {},
         "draws": {}}


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
    state["main"], state["draws"] = {}, {}
    state["cpu0"] = (time.thread_time(), process_cpu())
    state["intervals"], state["last"], state["recording"] = [], None, True


def process_cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def stop_recording():
    state["recording"] = False
    state["cpu"] = {"main_thread_cpu_s": time.thread_time() - state["cpu0"][0],
                    "blender_cpu_s": process_cpu() - state["cpu0"][1]}
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
    pool = core().execution.pool._POOL
    if pool is None:
        return None
    return {"workers": [w.process.pid for w in pool.workers], "alive": [bool(w.alive) for w in pool.workers],
            "threads": pool.threads, "failed": pool.failed, "broken": pool.broken,
            "cpu_s": {w.process.pid: cpu_of(w.process.pid) for w in pool.workers}}


def instrument_operator():
    """Time the add-on's main-thread work: BakeSession.on_event (each modal timer tick: the queue's
    messages, the live image update) and, inside it, _flush_live (pixels into the image)."""
    session = importlib.import_module(ADDON + ".mc_ao.operators").BakeSession

    def timed(name, fn):
        def wrapper(*args, **kw):
            if state.get("quiet") and name == "flush_live":
                return None  # no live image updates (nor their redraws): the image is written at the end
            t0 = time.perf_counter()
            try:
                return fn(*args, **kw)
            finally:
                dt = time.perf_counter() - t0
                acc = state["main"].setdefault(name, {"n": 0, "s": 0.0, "max_ms": 0.0})
                acc["n"] += 1
                acc["s"] += dt
                acc["max_ms"] = max(acc["max_ms"], dt * 1000.0)
        return wrapper

    missing = [n for n in ("on_event", "_flush_live", "set_texts") if not hasattr(session, n)]
    if missing:  # the add-on changed: measure the intervals without these figures (and no quiet modes)
        log("BakeSession lacks", missing, "- no main-thread figures, quiet modes bake as usual")
        results["instrumented"] = False
        return
    results["instrumented"] = True
    session.on_event = timed("on_event", session.on_event)
    session._flush_live = timed("flush_live", session._flush_live)
    set_texts = session.set_texts

    def quiet_texts(self, context, text):
        if not state.get("quiet") or text is None:
            return set_texts(self, context, text)

    session.set_texts = quiet_texts


def draw_counter(name):
    def count():
        if state["recording"]:
            state["draws"][name] = state["draws"].get(name, 0) + 1
    return count


def patch_core():
    """Replace the installed core's bake (the operator's one core call) by one that records each bake
    and, while state['inject_workers'], bakes in worker processes."""
    c = core()
    orig = c.bake

    def bake(target, occluders, request, **kw):
        if state["inject_workers"]:
            request = request.replace(workers=WORKERS)
        nice = state.get("nice")
        if nice and state["inject_workers"]:
            # The pool the bake will use (threads=None: one thread a worker), its workers made nice.
            pool = c.pipeline.run.pool(WORKERS, 1 if request.threads is None else request.threads)
            for w in pool.workers:
                os.setpriority(os.PRIO_PROCESS, w.process.pid, nice)
        elif nice:
            # This thread (the operator's) and the core's threads it starts, which inherit its nice value.
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
        before = pool_state()
        cpu0 = resource.getrusage(resource.RUSAGE_SELF)
        t0 = time.perf_counter()
        record = {"kwargs": {k: getattr(request, k) for k in ("workers", "threads", "resolution", "samples")}}
        try:
            results = orig(target, occluders, request, **kw)
            r = next(iter(results.values()))
        except BaseException as e:
            record["error"] = f"{type(e).__name__}: {e}"
            state["bakes"].append(record)
            raise
        finally:
            if nice:
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 0)
                pool = c.execution.pool._POOL
                for w in (pool.workers if pool is not None else ()):
                    os.setpriority(os.PRIO_PROCESS, w.process.pid, 0)
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
        return results

    c.bake = bake
    log("patched", c.__name__ + ".bake")


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
    c.execution.pool.shutdown()
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
    region = next(r for r in views[0].regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=views[0], region=region):
        bpy.ops.view3d.view_selected()


def display(hidden):
    """hidden: nothing shows the AO image (the Image Editor empty, the viewport's solid shading in
    material colours), so that the bake's image updates cost no drawing."""
    _, scr = screen()
    state["hidden"] = hidden
    for area in scr.areas:
        if area.type == "IMAGE_EDITOR" and hidden:
            area.spaces.active.image = None
        if area.type == "VIEW_3D":
            area.spaces.active.shading.color_type = "MATERIAL" if hidden else "TEXTURE"


def show_image():
    if state.get("hidden"):
        return
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
    instrument_operator()
    bpy.types.SpaceView3D.draw_handler_add(draw_counter("view3d"), (), "WINDOW", "POST_PIXEL")
    bpy.types.SpaceImageEditor.draw_handler_add(draw_counter("image_editor"), (), "WINDOW", "POST_PIXEL")
    scene_setup()
    split_view()
    bpy.app.timers.register(setup2, first_interval=1.0)


@guarded
def setup2():
    arrange()
    import gpu

    results.update(gpu=f"{gpu.platform.vendor_get()} | {gpu.platform.renderer_get()} | {gpu.platform.version_get()}",
                   blender=bpy.app.version_string, python=sys.version.split()[0], executable=sys.executable,
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
    bpy.app.timers.register(next_mode, first_interval=5.0)
    return None


@guarded
def next_mode():
    if not MODES:
        return finish()
    mode = MODES.pop(0)
    log("mode", mode)
    state["mode"] = {"mode": mode, "load_before": os.getloadavg()}
    state["inject_workers"] = mode in ("workers", "shot", "workers-hidden", "workers-nice", "workers-quiet")
    state["nice"] = NICE if mode.endswith("-nice") else 0
    state["quiet"] = mode.endswith("-quiet")
    display(hidden=mode.endswith("-hidden"))
    if mode == "shot":  # a new image, so that the screenshot shows it filling in
        image = bpy.data.images.get(f"{OBJECT}_AO")
        if image is not None:
            bpy.data.images.remove(image)
    state["bakes_before"] = len(state["bakes"])
    if mode.startswith("workers"):
        state["mode"]["pool"] = "warm" if core().execution.pool._POOL is not None else "cold"
    start_recording()
    state["t0"] = time.perf_counter()
    if mode in ("idle-redraw", "burn-redraw"):
        # What the operator does on every tick (0.1 s) while it bakes: new progress texts in the 3D
        # Viewport's header and the status bar, so Blender redraws them; no bake.
        state["redraw"] = 0
        bpy.app.timers.register(redraw, first_interval=0.1)
    if mode == "burn-redraw":
        state["burners"] = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(WORKERS)]
    if mode in ("idle", "idle-redraw", "burn-redraw"):
        bpy.app.timers.register(end_idle, first_interval=IDLE_SECONDS)
        return None
    if mode == "burn":  # CPU load outside Blender's GIL: two busy processes
        state["burners"] = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(WORKERS)]
        bpy.app.timers.register(end_idle, first_interval=IDLE_SECONDS)
        return None
    if mode == "gil":  # a busy Python thread in Blender's process: the GIL's load
        state["spin"] = True
        threading.Thread(target=spin, daemon=True).start()
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


def redraw():
    if state.get("redraw") is None:
        window, scr = screen()
        for area in scr.areas:
            if area.type == "VIEW_3D":
                area.header_text_set(None)
        window.workspace.status_text_set(None)
        return None
    state["redraw"] += 1
    window, scr = screen()
    text = f"MC AO: baking Suzanne (1/1), {state['redraw'] % 100}% - Esc to cancel"
    for area in scr.areas:
        if area.type == "VIEW_3D":
            area.header_text_set(text)
    window.workspace.status_text_set(text)
    return 0.1


def spin():
    while state["spin"]:
        pass


@guarded
def end_idle():
    state["spin"] = False
    state["redraw"] = None
    for p in state.pop("burners", []):
        p.kill()
        p.wait()
    ms = stop_recording()
    close_mode(ms, time.perf_counter() - state["t0"])
    bpy.app.timers.register(next_mode, first_interval=2.0)


@guarded
def watch():
    elapsed = time.perf_counter() - state["t0"]
    if running():
        state["seen_running"] = True
        show_image()  # the operator may make the image after the invoke
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
    m.update(seconds=seconds, load_after=os.getloadavg(), **stats(ms), **state["cpu"],
             addon_main=state["main"], draws=state["draws"])
    bakes = state["bakes"][state["bakes_before"]:]
    m["bakes"] = bakes
    if m["mode"] not in ("idle", "burn", "gil", "idle-redraw", "burn-redraw"):
        image = bpy.data.images.get(f"{OBJECT}_AO")
        m["image"] = None if image is None else list(image.size)
        if m["mode"] == "threads":
            state["expected"] = seconds
    np.save(os.path.join(OUT, f"intervals_{len(results['modes'])}_{m['mode']}.npy"), ms)
    results["modes"].append(m)
    write("results.json", results)
    log(m["mode"], json.dumps({k: v for k, v in m.items() if k != "bakes"}, default=str))


def table():
    """One row a mode: the bake's wall time, the 10 ms timer's intervals, and where the CPU went."""
    lines = [f"{'mode':<22} {'bake s':>6} {'ticks':>5} {'p50 ms':>7} {'p95 ms':>7} {'p99 ms':>7} {'max ms':>7} "
             f"{'main cpu s':>10} {'addon main s':>12} {'flush max ms':>12} {'draws':>5} {'blender cpu s':>13} "
             f"{'worker cpu s':>12} {'load':>5}"]
    for m in results["modes"]:
        name = m["mode"] + (f" ({m['pool']})" if "pool" in m else "")
        bake = (m.get("bakes") or [{}])[0]
        secs = f"({m['seconds']:.0f})" if m["mode"] in ("idle", "burn", "gil", "idle-redraw", "burn-redraw") else f"{m['seconds']:.1f}"
        wcpu = bake.get("worker_cpu_s")
        main = m.get("addon_main", {})
        lines.append(
            f"{name:<22} {secs:>6} {m['n']:>5} {m['p50_ms']:>7.1f} {m['p95_ms']:>7.1f} {m['p99_ms']:>7.1f} "
            f"{m['max_ms']:>7.1f} {m['main_thread_cpu_s']:>10.1f} {main.get('on_event', {}).get('s', 0.0):>12.1f} "
            f"{main.get('flush_live', {}).get('max_ms', 0.0):>12.0f} {sum(m['draws'].values()):>5} "
            f"{m['blender_cpu_s']:>13.1f} {(wcpu if wcpu is not None else 0.0):>12.1f} {m['load_before'][0]:>5.1f}")
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
    core().execution.pool.shutdown()
    bpy.ops.wm.quit_blender()


os.makedirs(OUT, exist_ok=True)
bpy.app.timers.register(setup, first_interval=2.0)
