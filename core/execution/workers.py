"""Tiles baked in worker processes: every core of the machine, none of them waiting on another's GIL.

A bake with ``workers`` > 1 (:func:`core.bake_ao`) sends its input once to each worker of a
persistent pool; each builds the same bake (:class:`core.pipeline.bake.TexelBake`: the same tiles, its own
Embree scene) and bakes the tiles it is dealt, one at a time as it frees up, ``threads`` threads
each (they share a tile's chunks of rays, :mod:`core.engine.scheduler`). A tile's values come back as
plain arrays and the parent assembles the images, the margin and the bent normals. Texels draw their
samples by (seed, texel, index) alone and a tile's sums are added in one order, so the images, errors
and sample counts are bit-identical for any workers x threads x tiling on one machine.

How the processes are started and kept (each point is a trap met in Blender):

- Workers are new interpreters (``sys.executable -c``), on every OS: never fork (it would copy
  Blender's whole process), and not :mod:`multiprocessing` (its spawn re-runs a ``__main__`` that
  Blender gave a file name, and pickles functions by their module's name, which in the installed
  extension is ``bl_ext.<repository>.mc_ao.core``, a package Blender makes at run time that a new
  interpreter cannot import). A worker gets the parent's ``sys.path`` and imports this package as
  top-level ``core`` from the folder that holds it: numpy, embreex and the core, never bpy.
- Messages are pickles of plain data (arrays, numbers, strings, dicts) over the worker's stdin and a
  copy of its stdout (its own fd 1 is pointed at stderr, so that nothing a library prints can break a
  message); never a pickled core object. A worker's error comes back as its class name and message
  and is raised here as the core's own class (``except MeshError`` still works).
- The lifeline: a worker reads its stdin on a thread of its own, and ends itself the moment it reads
  the end of it, which happens when the parent process is gone, however it ended (killed, crashed, or
  Blender closed): no worker outlives the process that owns the pool. :func:`shutdown` ends the pool
  (the add-on calls it when it is disabled; the interpreter's exit calls it too).
- Threads inside a worker: OpenBLAS, OpenMP and MKL are set to one thread each, so that workers x
  threads never oversubscribe the cores.
- Progress counts the tiles' samples as they are traced, a message per 1/512 of a worker's share of
  the work, never per chunk; cancel reaches a worker between chunks, and a worker still building its
  scene is ended (the next bake starts a fresh one).
- A worker keeps the last bake's occlusion scenes (Embree's, and the tracer's arrays) and traces in
  them when the next bake sends the same meshes (a digest of the target's and the occluders'
  positions and triangles, :func:`scene_key`): an artist baking again after changing the samples,
  the resolution or the distance does not wait for them. One scene at a time: a bake of other meshes
  drops it before building its own, so a worker's peak does not grow; between bakes an idle worker
  holds it (what :func:`shutdown` or a bake of other meshes frees). Selected-to-active bakes keep none.
- Tiles are dealt one to each worker in turn with the set-up (a worker starts its first the moment
  its scene is built), then each gets its next as it returns one, ``AHEAD`` at most and one only once
  fewer tiles are left than workers.
- A worker that dies (killed, out of memory) fails the bake with :class:`BakeWorkerError`, nothing is
  written, and the next bake gets a fresh pool.
- The self-test: a new pool's workers each bake a tiny scene first and must give this process's bits
  (:func:`self_test`); where one cannot start or differs, bakes run on threads of this process with a
  warning saying why (``report['warnings']``), and the pool is not tried again in this session.

What each OS needs (tested here on Linux only; the rest is what the code relies on): an interpreter at
``sys.executable`` that can run ``-c`` (Blender sets it to its bundled Python on Linux, Windows and
macOS; the bpy module's is the venv's), anonymous pipes (``subprocess.PIPE``; on Windows the worker's
``os.dup``/``os.dup2`` of fds 1 and 2 work on the C runtime's descriptors) and the wheels' embreex on the
parent's ``sys.path``, which the worker takes. No ``/dev/shm``, no ``fork``, no signals: the lifeline is
the pipe, which every OS closes when a process ends. macOS and Windows have no ``sched_getaffinity``
(the core count is ``os.cpu_count()``) and no cgroup (the memory is what the machine has available).
"""

import atexit
import dataclasses
import json
import os
import pickle
import queue
import struct
import subprocess
import sys
import threading
import traceback

import numpy as np

from . import cost as _cost
from ..base import errors as _errors
from ..base.errors import BakeCancelled, McAoError, SettingsError
from ..engine.scheduler import Scheduler, is_cancelled, run_all

_HEADER = struct.Struct("<Q")
#: Tiles dealt to a worker ahead of the one it bakes, so that it never waits for the parent.
AHEAD = 2
#: Progress messages per worker and bake, at most (a message per chunk would let a busy parent slow them).
PROGRESS_STEPS = 512


class BakeWorkerError(McAoError, RuntimeError):
    """A worker process ended before its bake did (killed, or out of memory)."""


def send(stream, obj):
    """Write ``obj`` as a message: a pickle (protocol 5) whose arrays travel out of band, each
    array's bytes written straight from its memory after the pickle (no copy of them into the
    pickle, none on the way in: a worker's scene arrives in the buffers its arrays then use)."""
    buffers = []
    data = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    views = [b.raw() for b in buffers]
    stream.write(_HEADER.pack(len(data)) + _HEADER.pack(len(views)) + b"".join(_HEADER.pack(v.nbytes) for v in views))
    stream.write(data)
    for v in views:
        stream.write(v)
    stream.flush()


def receive(stream):
    """The next message, or None at the end of the stream."""
    head = _read(stream, 2 * _HEADER.size)
    if head is None:
        return None
    size, count = _HEADER.unpack(head[:_HEADER.size])[0], _HEADER.unpack(head[_HEADER.size:])[0]
    sizes = _read(stream, count * _HEADER.size) if count else b""
    if sizes is None:
        return None
    data = _read(stream, size)
    if data is None:
        return None
    buffers = []
    for i in range(count):
        buf = _read(stream, _HEADER.unpack_from(sizes, i * _HEADER.size)[0])
        if buf is None:
            return None
        buffers.append(buf)
    return pickle.loads(data, buffers=buffers)


def _read(stream, n):
    """``n`` bytes of ``stream`` in one writable buffer (an array unpickled from it uses it as it
    is), or None at the end of the stream."""
    out = bytearray(n)
    view, got = memoryview(out), 0
    while got < n:
        k = stream.readinto(view[got:])
        if not k:
            return None
        got += k
    return out


def mesh_data(mesh):
    """A :class:`core.Mesh` as plain data for a worker (its corner normals as given: the worker
    computes the unit ones, the same bits; none for a flat-shaded mesh)."""
    return dict(positions=mesh.positions, triangles=mesh.triangles, uvs=mesh.uvs, normals=mesh.given_normals(),
                name=mesh.name)


def _mesh(data):
    from ..geometry.mesh import Mesh

    return None if data is None else Mesh(**data)


def _error(name, message):
    """The core's exception class ``name`` (a worker's error) with its message."""
    cls = getattr(_errors, name, None)
    if isinstance(cls, type) and issubclass(cls, Exception):
        return cls(message)
    builtin = {"MemoryError": MemoryError, "ValueError": ValueError, "TypeError": TypeError}.get(name)
    if builtin is not None:
        return builtin(message)
    return BakeWorkerError(f"a worker process failed: {name}: {message}")


# -- memory: what each process holds -----------------------------------------------------------------

def process_memory():
    """(resident bytes now, peak resident bytes) of this process: VmRSS and VmHWM from
    /proc/self/status (Linux); elsewhere (None, the peak from getrusage where there is one)."""
    now = peak = None
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    now = int(line.split()[1]) * 1024
                elif line.startswith("VmHWM:"):
                    peak = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if peak is None:
        try:
            import resource

            # ru_maxrss: bytes on macOS, KiB elsewhere.
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * (1 if sys.platform == "darwin" else 1024)
        except (ImportError, OSError, AttributeError):
            pass
    return now, peak


def reset_peak():
    """Start this process's peak (VmHWM) afresh, where Linux allows it (writing 5 to
    /proc/self/clear_refs); a worker does it before each bake, so its peak is that bake's."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def held_bytes(*roots, depth=8):
    """Bytes of the numpy arrays reachable from ``roots`` through attributes, dicts, lists and
    tuples (each memory block counted once, views and slices by their base): what a bake holds in
    its meshes, tables and scenes' arrays. Embree's own scene memory is not an array and is not
    counted here."""
    seen_obj, blocks = set(), {}
    todo = [(r, 0) for r in roots]
    while todo:
        obj, d = todo.pop()
        if obj is None or id(obj) in seen_obj:
            continue
        seen_obj.add(id(obj))
        if isinstance(obj, np.ndarray):
            base = obj
            while isinstance(base.base, np.ndarray):
                base = base.base
            if base.base is None or isinstance(base.base, (bytes, bytearray, memoryview)):
                blocks[id(base)] = base.nbytes
            else:  # a view of memory numpy does not own (a buffer, a pickle's): its own size
                blocks[id(obj)] = max(blocks.get(id(obj), 0), obj.nbytes)
            continue
        if d >= depth or isinstance(obj, (str, bytes, int, float, bool, type)) or callable(obj) and not hasattr(obj, "__dict__"):
            continue
        if isinstance(obj, dict):
            todo.extend((v, d + 1) for v in obj.values())
        elif isinstance(obj, (list, tuple, set, frozenset)):
            todo.extend((v, d + 1) for v in obj)
        else:
            attrs = getattr(obj, "__dict__", None)
            if isinstance(attrs, dict):
                todo.extend((v, d + 1) for v in attrs.values())
            for name in getattr(type(obj), "__slots__", ()):
                todo.append((getattr(obj, name, None), d + 1))
    return int(sum(blocks.values()))


def memory_entry(process, held_from=(), start=None, ready=None):
    """One process's line of ``report['worker_memory']``: its resident bytes now, its peak, and the
    bytes of the arrays its bake holds (see :func:`core.pipeline.bake.bake_ao`)."""
    now, peak = process_memory()
    out = {"process": process, "pid": os.getpid(), "rss": now, "peak": peak, "held": held_bytes(*held_from)}
    if start is not None:
        out["start"] = start
    if ready is not None:
        out["ready"] = ready
    return out


# -- the worker process ---------------------------------------------------------------------------------

def main():
    """A worker: bake what the parent sends until the parent is gone (see the module docstring)."""
    out = os.fdopen(os.dup(1), "wb", buffering=0)
    os.dup2(2, 1)  # whatever a library prints goes to stderr, never into a message
    sys.stdout = sys.stderr
    inp = sys.stdin.buffer
    lock = threading.Lock()
    tasks = queue.Queue()
    current = {"bake": None, "cancel": threading.Event()}

    def reply(*msg):
        with lock:
            send(out, msg)

    def reader():
        while True:
            msg = receive(inp)
            if msg is None:
                os._exit(0)  # the lifeline: the parent is gone
            if msg[0] == "cancel":
                if msg[1] == current["bake"]:
                    current["cancel"].set()
                continue
            if msg[0] == "setup":  # a new bake: cancels of the last one no longer apply
                current["bake"], current["cancel"] = msg[1], threading.Event()
            tasks.put(msg)
            del msg  # not kept while waiting for the next one: a setup's arrays belong to its bake

    threading.Thread(target=reader, name="mc_ao-lifeline", daemon=True).start()
    try:
        reply("hello", 0, self_test())
    except BaseException as e:
        reply("hello", 0, f"the self-test bake failed: {type(e).__name__}: {e}")
    bake = shared = None
    threads = 1
    while True:
        kind, bake_id, *args = tasks.get()
        try:
            if kind == "setup":
                bake = shared = None  # the last bake's tables go before the next one's are built
                job = args.pop()  # only the bake keeps what it needs of the input: the job's arrays go
                key = scene_key(job)
                if _SCENE.get("key") != key:
                    _SCENE.clear()  # another scene: the last one's Embree scenes go before it is built
                reset_peak()
                start = process_memory()[0]
                bake, shared, threads = _setup(job, current["cancel"], lambda work: reply("progress", bake_id, work),
                                               scene=(key, _SCENE))
                tiles = 0
                del job
                ready = process_memory()[0]
                reply("ready", bake_id)
            elif bake is None:
                continue  # a tile or the totals of a bake whose set-up failed (its error was sent)
            elif kind == "tile":
                outs = []
                run_all(lambda key: outs.append(bake.tile(key, directions=False)), [args[0]], threads, shared, None)
                tiles += 1
                reply("tile", bake_id, vars(outs[0]))
            elif kind == "finish":
                shared.flush()
                reply("finish", bake_id, dict(rays=shared.rays, trace_seconds=shared.trace_seconds,
                                             trace_cpu_seconds=shared.trace_cpu_seconds,
                                             counters=bake.start.counters(),
                                             memory=dict(memory_entry("worker", (bake,), start, ready),
                                                         scene_reused=bake.scene_reused, tiles=tiles)))
                bake = shared = None
            elif kind == "exit":
                return
        except BakeCancelled:
            reply("cancelled", bake_id)
        except BaseException as e:  # every error goes back to the parent, by name
            reply("error", bake_id, type(e).__name__, str(e), traceback.format_exc())


def self_test():
    """A digest of a tiny bake (a plane under a lid, 16^2 x 8, one thread): what every worker and the
    parent must agree on before a pool is used (the same numpy, Embree and instruction paths)."""
    import hashlib

    from ..pipeline.bake import bake_ao
    from ..geometry.mesh import Mesh

    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    lid = Mesh(p * [0.6, 0.6, 0] + [0.2, 0.2, 0.3], f, name="lid")
    r = bake_ao(Mesh(p, f, uvs=p[f][:, :, :2], name="plane"), [lid], resolution=16, samples=8, threads=1)
    return hashlib.sha256(r.ao.tobytes() + r.stderr.tobytes()).hexdigest()


#: The last bake's occlusion scenes in this worker (see :func:`_setup`): ``key`` (:func:`scene_key`),
#: ``count`` (the meshes its tracer holds: the target alone, or with its occluders) and ``tracer``.
_SCENE = {}


def scene_key(job):
    """A digest of what a bake's occlusion scenes are built from: the target's and the occluders'
    positions and triangles as sent (their dtypes and shapes too). The same key, the same scenes:
    the meshes are moved into the bake's frame by the same arithmetic on the same bits."""
    import hashlib

    h = hashlib.blake2b(digest_size=20)
    for m in [job["target"]] + list(job["occluders"]):
        for name in ("positions", "triangles"):
            a = np.ascontiguousarray(m[name])
            h.update(f"{name}{a.dtype.str}{a.shape};".encode())
            h.update(memoryview(a).cast("B"))
    return h.hexdigest()


def _reuse_scene(pro, scene):
    """Let the prologue ``pro`` trace in the last bake's Embree scenes where they were built from the
    same meshes (``scene``: (its key, :data:`_SCENE`)): an artist baking again after changing the
    samples, the resolution or the distance does not wait for them again. Returns what keeps them for
    the next bake (:func:`_keep_scene`)."""
    key, kept = scene if scene is not None else (None, None)
    if kept and kept.get("key") == key:
        meshes = [pro.target] + pro.occluders
        if kept["count"] <= len(meshes):
            # The tracer sees these meshes (bit for bit the ones it was built from): Prologue.tracer shares it.
            pro._tracer = (meshes[:kept["count"]], kept["tracer"])
    return key, kept


def _reused(pro, scene):
    """Whether ``pro`` traces in the last bake's scenes (its tracer is the one kept)."""
    last = getattr(pro, "_tracer", None)
    return bool(scene and scene[1] and last is not None and scene[1].get("tracer") is last[1])


def _keep_scene(pro, scene):
    """Keep the tracer ``pro`` traced in as the last scene (one scene at a time: memory does not grow)."""
    key, kept = scene
    if kept is None:
        return
    kept.clear()
    last = getattr(pro, "_tracer", None)
    if last is not None and key is not None:
        meshes, tracer = last
        tracer._meshes = list(meshes)  # this bake's meshes (the same bits): the last bake's go
        kept.update(key=key, count=len(meshes), tracer=tracer)


def _setup(job, cancel, progress, scene=None):
    """The bake of ``job`` in this process: (bake, its scheduler, threads). ``scene``: (its key, the
    last scene kept, :data:`_SCENE`) to trace in that scene's Embree scenes where the meshes are the
    same, and to keep this bake's for the next one."""
    from ..pipeline.bake import Prologue, texel_bake
    from ..engine.settings import BakeSettings

    s = BakeSettings(**job["settings"])
    if job.get("kind") == "vertex":
        from ..targets.corners import vertex_bake

        pro = Prologue(_mesh(job["target"]), [_mesh(o) for o in job["occluders"]], s, cancel, uvs=False)
        scene = _reuse_scene(pro, scene)
        bake = vertex_bake(pro, s, job["corners"], job.get("quantities", [s.quantity]), job["merge"],
                           job["bent_normals"], job["block"])
        shared = CountingScheduler(bake.planned, progress, cancel, job["quantum"])
        bake.trace_setup(shared, cancel)
        bake.scene_reused = _reused(pro, scene)
        _keep_scene(pro, scene)
        return bake, shared, s.threads
    # Popped: the job holds nothing of the target past its use (its UVs go once the bake has its UV triangles).
    pro = Prologue(_mesh(job.pop("target")), [_mesh(o) for o in job["occluders"]], s, cancel, uvs=True,
                   highpoly=None if job["highpoly"] is None else [_mesh(m) for m in job["highpoly"]],
                   extrusion=job["extrusion"], max_ray_distance=job["max_ray_distance"], cage=_mesh(job["cage"]),
                   bent_normals=job["bent_normals"])
    scene = _reuse_scene(pro, scene) if pro.s2a is None else (None, scene[1] if scene else None)
    bake = texel_bake(pro, s, job.get("quantities", [s.quantity]), job["bent_normals"],
                      guide=job.get("guide", False))
    # The UVs served the UV triangles the bake now holds; a worker bakes tiles from those alone and
    # lets the UVs go (48 bytes a triangle; the parent keeps them for the images and the denoiser).
    pro.target.uvs = None
    shared = CountingScheduler(bake.planned, progress, cancel, job["quantum"])
    bake.trace_setup(shared, cancel)
    bake.scene_reused = _reused(pro, scene)
    _keep_scene(pro, scene)
    return bake, shared, s.threads


class CountingScheduler(Scheduler):
    """A worker's scheduler: hands the work done to ``report`` as counts, once per ``quantum`` samples."""

    def __init__(self, total, report, cancel, quantum):
        super().__init__(total, None, cancel)
        self.report, self.quantum, self.pending_work = report, quantum, 0

    def advance(self, work, rays=0, trace_seconds=0.0, trace_cpu_seconds=0.0):
        super().advance(work, rays, trace_seconds, trace_cpu_seconds)
        with self.lock:
            self.pending_work += work
            if self.pending_work < self.quantum:
                return
            work, self.pending_work = self.pending_work, 0
        self.report(work)

    def flush(self):
        with self.lock:
            work, self.pending_work = self.pending_work, 0
        if work:
            self.report(work)


# -- the pool ---------------------------------------------------------------------------------------------

def _core_root():
    """The folder that holds this package (the repository, or the installed extension's folder)."""
    return os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


_BOOT = ("import sys, json; sys.path[:0] = json.loads(sys.argv[1]); import core.execution.workers as w; "
         "assert w.__file__.startswith(sys.argv[2]), 'another core was imported'; w.main()")


class _Worker:
    def __init__(self, threads, inbox, index):
        env = dict(os.environ)
        for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
            env[name] = "1"
        root = _core_root()
        path = [root] + [p for p in sys.path if p and p != root]
        self.process = subprocess.Popen([sys.executable, "-c", _BOOT, json.dumps(path), os.path.join(root, "core")],
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        self.index, self.busy, self.ready, self.alive = index, [], False, True
        self.lock = threading.Lock()
        threading.Thread(target=self._read, args=(inbox,), name=f"mc_ao-worker-{index}", daemon=True).start()

    def _read(self, inbox):
        stdout = self.process.stdout
        while True:
            try:
                msg = receive(stdout)
            except Exception:  # a torn message: the worker died writing it
                msg = None
            if msg is None:
                self.alive = False
                inbox.put((self, ("died",)))
                return
            inbox.put((self, msg))

    def send(self, *msg):
        with self.lock:
            send(self.process.stdin, msg)

    def end(self):
        self.alive = False
        try:
            self.process.kill()
        except OSError:
            pass
        self.process.wait()


class Pool:
    """``workers`` worker processes of ``threads`` threads each, kept for later bakes."""

    def __init__(self, workers, threads):
        self.workers_wanted, self.threads = int(workers), int(threads)
        self.inbox = queue.Queue()
        self.workers = [_Worker(self.threads, self.inbox, i) for i in range(self.workers_wanted)]
        self.broken = False
        self.bake_id = 0
        self.lock = threading.Lock()  # one bake at a time
        self.failed = self._check()

    def _check(self):
        """None when every worker started and its self-test bake gave this process's bits, else why
        not (the bake then runs on threads, with a warning that says so)."""
        want = self_test()
        waiting = set(self.workers)
        why = None
        while waiting:
            w, msg = self.inbox.get()
            waiting.discard(w)
            if msg[0] == "died":
                why = why or (f"worker process {w.index} ended at start-up (exit code {w.process.poll()}): "
                              "see its message above")
            elif msg[0] == "hello" and msg[2] != want:
                why = why or (msg[2] if msg[2].startswith("the self-test") else
                              f"worker process {w.index} baked the self-test differently from this process")
        if why is not None:
            self.broken = True
        return why

    def close(self):
        for w in self.workers:
            if w.alive:
                try:
                    w.send("exit", 0)
                except OSError:
                    pass
            w.end()
        self.workers = []

    def run(self, job, keys, planned, store, progress, cancel):
        """Bake ``keys`` (tile keys) of the bake ``job`` (plain data) on the workers; ``store(TileOut)``
        for each tile as it comes back. Returns (rays, trace seconds, trace CPU seconds, the start
        stage's counters summed)."""
        from ..pipeline.bake import TileOut

        with self.lock:
            self.bake_id += 1
            bake_id = self.bake_id
            quantum = max(1, planned // (PROGRESS_STEPS * len(self.workers)))
            job = dict(job, quantum=quantum, settings=dict(job["settings"], threads=self.threads, auto_tiles=False))
            for w in self.workers:
                w.send("setup", bake_id, job)
                w.ready, w.busy, w.asked = False, [], False
            todo = list(keys)
            todo.reverse()
            out_standing = set()  # workers holding a tile or not yet ready
            done = 0
            finished = {}
            failure = None
            cancelled = False

            def deal(w, ahead=AHEAD):
                """Keep ``ahead`` tiles with the worker (it starts the next while its last result is
                on its way), one only once fewer tiles are left than workers (the last tiles go to
                the workers that free up, not to one already holding another); once none is left,
                ask it for its totals (once)."""
                while todo and failure is None and not cancelled and (
                        not w.busy or len(w.busy) < ahead and len(todo) >= len(self.workers)):
                    key = todo.pop()
                    w.busy.append(key)
                    w.send("tile", bake_id, key)
                if not w.busy and not w.asked and failure is None and not cancelled:
                    w.asked = True
                    w.send("finish", bake_id)

            # The first tiles go with the set-up, one to each worker in turn before any gets its next:
            # a worker starts them the moment its scene is built, without waiting for its "ready" to
            # reach this process and the tiles to come back.
            for ahead in range(1, AHEAD + 1):
                for w in self.workers:
                    deal(w, ahead)
            pending = set(self.workers)
            try:
                while pending:
                    try:
                        w, msg = self.inbox.get(timeout=0.05)
                    except queue.Empty:
                        if not cancelled and failure is None and is_cancelled(cancel):
                            cancelled = True
                            self._cancel(bake_id, pending)
                        continue
                    kind = msg[0]
                    if kind == "died":
                        if w in pending:
                            failure = failure or BakeWorkerError(
                                f"worker process {w.index} ended before the bake did (exit code "
                                f"{w.process.poll()}; killed, or out of memory?); nothing was written")
                            pending.discard(w)
                            self.broken = True
                            self._cancel(bake_id, pending)
                        continue
                    if msg[1] != bake_id:
                        continue  # a late message of an earlier bake
                    if kind == "progress":
                        done += msg[2]
                        if progress is not None:
                            progress(min(done / max(planned, 1), 1.0))
                    elif kind == "ready":
                        w.ready = True
                        deal(w)
                    elif kind == "tile":
                        w.busy.remove(msg[2]["key"])
                        if failure is None and not cancelled:
                            store(TileOut(**msg[2]))
                        deal(w)
                        if (failure is not None or cancelled) and not w.busy:
                            pending.discard(w)  # stopped, and nothing of it left to wait for
                    elif kind == "finish":
                        finished[w] = msg[2]
                        pending.discard(w)
                    elif kind in ("cancelled", "error"):
                        if kind == "error" and failure is None and not cancelled:
                            failure = _error(msg[2], msg[3])
                            failure.worker_traceback = msg[4]
                            self._cancel(bake_id, pending - {w})
                        pending.discard(w)
                    if not cancelled and failure is None and is_cancelled(cancel):
                        cancelled = True
                        self._cancel(bake_id, pending)
            except BaseException:
                self.broken = True
                raise
            if failure is not None:
                raise failure
            if cancelled:
                raise BakeCancelled("the bake was cancelled; nothing was written")
            if progress is not None:
                progress(1.0)
            parts = list(finished.values())
            counters = _sum_counters(parts)
            counters["worker_memory"] = [dict(p["memory"], process=f"worker {w.index}") for w, p in
                                         sorted(finished.items(), key=lambda item: item[0].index) if "memory" in p]
            return (sum(p["rays"] for p in parts), sum(p["trace_seconds"] for p in parts),
                    sum(p["trace_cpu_seconds"] for p in parts), counters)

    def _cancel(self, bake_id, workers):
        """Stop ``workers`` between chunks; one still building its scene is ended (the pool is then
        made anew by the next bake)."""
        for w in list(workers):
            if not w.ready:
                w.end()
                workers.discard(w)
                self.broken = True
            elif not w.busy:
                workers.discard(w)  # idle (its totals asked for, or nothing dealt): nothing to stop
            else:
                try:
                    w.send("cancel", bake_id)
                except OSError:
                    workers.discard(w)


# -- one bake across machines: the same tile task on a Dask cluster -------------------------------------

#: The bakes a Dask worker process has set up, by token (a bake's tiles reuse its scene); the last few.
_DASK_BAKES = {}
_DASK_KEEP = 2


def _dask_tile(token, job, key):
    """One tile of the bake ``job`` on a Dask worker: (the tile's values, this process's totals so far),
    as plain data. The bake is set up once per process and token; a task that is run again (its
    worker was lost) gives the same values."""
    entry = _DASK_BAKES.get(token)
    if entry is None:
        bake, shared, threads = _setup(dict(job, quantum=1 << 62), threading.Event(), lambda work: None)
        entry = _DASK_BAKES[token] = (bake, shared, threads, threading.Lock())
        while len(_DASK_BAKES) > _DASK_KEEP:
            _DASK_BAKES.pop(next(iter(_DASK_BAKES)))
    bake, shared, threads, lock = entry
    with lock:  # one tile of a bake at a time in a process (its threads share the tile's chunks)
        outs = []
        run_all(lambda k: outs.append(bake.tile(k, directions=False)), [key], threads, shared, None)
        totals = dict(rays=shared.rays, trace_seconds=shared.trace_seconds,
                      trace_cpu_seconds=shared.trace_cpu_seconds, counters=bake.start.counters())
    return vars(outs[0]), (os.getpid(), id(entry)), totals


def is_dask_client(workers):
    return hasattr(workers, "submit") and hasattr(workers, "scatter") and hasattr(workers, "gather")


def run_dask(client, job, keys, planned, store, progress, cancel, threads=1):
    """Bake ``keys`` of ``job`` as tasks on the Dask cluster of ``client``; ``store`` each tile as it
    comes back. The job goes to every worker once; a worker lost mid-bake has its tiles redone
    elsewhere (the tasks are pure). Returns what :meth:`Pool.run` returns."""
    import uuid

    from distributed import as_completed

    from ..pipeline.bake import TileOut

    token = uuid.uuid4().hex
    job = dict(job, settings=dict(job["settings"], threads=int(threads), auto_tiles=False))
    [shared_job] = client.scatter([job], broadcast=True, hash=False)
    futures = [client.submit(_dask_tile, token, shared_job, key, key=f"mc_ao-tile-{token}-{i}", retries=3,
                             pure=False) for i, key in enumerate(keys)]
    totals, done = {}, 0
    try:
        for fut in as_completed(futures):
            if is_cancelled(cancel):
                raise BakeCancelled("the bake was cancelled; nothing was written")
            try:
                out, process, total = fut.result()
            except BaseException as e:
                name = type(e).__name__
                raise _error(name, str(e)) if isinstance(e, McAoError) else e
            store(TileOut(**out))
            totals[process] = total  # each process's latest totals: a redone tile counts once
            done += 1
            if progress is not None:
                progress(min(done / max(len(keys), 1), 1.0))
    except BaseException:
        client.cancel(futures)
        raise
    parts = list(totals.values())
    counters = _sum_counters(parts)
    return (sum(p["rays"] for p in parts), sum(p["trace_seconds"] for p in parts),
            sum(p["trace_cpu_seconds"] for p in parts), counters)


def _sum_counters(parts):
    """The start stages' counters of several processes, added up (texts: the first given; a bake of
    several quantities has each quantity's counters under its name, added up the same way)."""
    counters = {}
    for p in parts:
        _add_counters(counters, p["counters"])
    return counters


def _add_counters(into, counters):
    for k, v in counters.items():
        if isinstance(v, dict):
            _add_counters(into.setdefault(k, {}), v)
        elif isinstance(v, (int, float)) and k != "directions_per_point":
            into[k] = into.get(k, 0) + v
        elif into.get(k) is None:
            into[k] = v


_POOL = None
_POOL_LOCK = threading.Lock()


def cpu_count():
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def memory_limit():
    """Bytes of memory this process may still use: the smaller of the machine's available memory and
    what its container (cgroup v2 or v1) has left; None if neither is known."""
    from ..engine.settings import available_memory

    limits = [available_memory()]
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            with open(limit_file) as f:
                text = f.read().strip()
            if text == "max":
                continue
            with open(usage_file) as f:
                limits.append(int(text) - int(f.read().strip()))
        except (OSError, ValueError):
            continue
    known = [x for x in limits if x is not None]
    return min(known) if known else None


def auto_workers(triangles, cores=None, memory=None):
    """(workers, threads each) for a bake of ``triangles``: a count (every mesh, costed as the
    target's) or (target, occluder, high-poly) triangles. One worker a core, fewer with more threads
    each where memory holds fewer copies of the scene (threads share one): the workers and what the
    parent adds while they bake within 80% of ``memory`` (None: :func:`memory_limit`, the machine's
    available memory or what its container's cgroup has left, whichever is less)."""
    cores = cpu_count() if cores is None else cores
    memory = memory_limit() if memory is None else memory
    target, occluders, highpoly = (int(triangles), 0, 0) if np.ndim(triangles) == 0 else map(int, triangles)
    # core.execution.cost's measured figures: each worker's peak (its tables and Embree scenes, its interpreter
    # and sample pool), and the parent's share while they bake.
    per_worker = _cost.process_bytes(target, occluders, highpoly)
    parent = _cost.parent_bytes(target, occluders + highpoly)
    workers = cores if memory is None else max(1, min(cores, int((memory * 0.8 - parent) // per_worker)))
    return workers, max(1, cores // workers)


def check_workers(workers):
    """``workers`` as given to :func:`core.bake_ao`: 1, a count, 'auto', or a ``distributed.Client``
    (refused otherwise)."""
    if isinstance(workers, str) and workers == "auto" or is_dask_client(workers):
        return workers
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise SettingsError(f"workers must be a positive integer or 'auto', got {workers!r}")
    return int(workers)


def processes_of(workers, threads, settings, triangles):
    """(processes, threads each) of a bake given ``workers`` (1, N or 'auto', checked) and the
    ``threads`` argument: with workers, ``threads`` counts each worker's threads (None: one each, or
    what 'auto' picks); workers=1 is this process with ``settings.threads``."""
    if is_dask_client(workers):
        return workers, 1 if threads is None else settings.threads
    if workers == 1:
        return 1, settings.threads
    if workers == "auto":
        processes, per_worker = auto_workers(triangles)
        if threads is None:
            return processes, per_worker
        # Threads asked for each: as many workers as the cores hold at that many threads each.
        return max(1, min(processes, cpu_count() // settings.threads)), settings.threads
    return workers, 1 if threads is None else settings.threads


def in_process(processes):
    """Whether a bake of :func:`processes_of`'s ``processes`` runs in this process."""
    return not is_dask_client(processes) and processes == 1


def worker_count(processes):
    """How many processes bake the tiles (a Dask cluster's workers now)."""
    if is_dask_client(processes):
        return max(1, len(processes.scheduler_info().get("workers", {})))
    return processes


def run_tiles(processes, threads, job, keys, planned, store, progress, cancel):
    """Bake ``keys`` of ``job`` on the local pool or a Dask cluster (:func:`run_dask`)."""
    if is_dask_client(processes):
        return run_dask(processes, job, keys, planned, store, progress, cancel, threads)
    return pool_for(processes, threads).run(job, keys, planned, store, progress, cancel)


def bake_tiles(bake, keys, processes, threads, job, store, progress, cancel, on_rays=None):
    """Bake ``keys`` of ``bake`` (a :class:`core.pipeline.bake.TexelBake` or :class:`core.targets.corners.VertexBake`,
    its prologue done) in this process on ``bake.s.threads`` threads, or on ``processes`` worker
    processes of ``threads`` threads (or a Dask cluster); ``store`` each tile's
    :class:`core.pipeline.bake.TileOut`. ``job()`` makes the plain data workers rebuild the bake from (only
    when they bake). Where a local pool cannot be used (its self-test failed), this process bakes.

    Returns (rays, trace seconds, trace CPU seconds, the start stage's counters, the reason the pool
    was not used or None). The counters hold ``worker_memory``: a :func:`memory_entry` of this
    process, then one of each worker process that baked."""
    fallback = usable_pool(processes, threads)
    if fallback is None and not in_process(processes):
        if on_rays is not None:
            raise SettingsError("on_rays sees the rays of this process only: bake with workers=1 to record them")
        rays, seconds, cpu, counters = run_tiles(processes, threads, job(), keys, bake.planned, store, progress, cancel)
        counters["worker_memory"] = [memory_entry("parent", (bake,))] + counters.get("worker_memory", [])
        return rays, seconds, cpu, counters, None
    shared = Scheduler(bake.planned, progress, cancel)
    bake.trace_setup(shared, cancel, on_rays)
    run_all(lambda key: store(bake.tile(key)), keys, bake.s.threads, shared, progress)
    counters = bake.start.counters()
    counters["worker_memory"] = [memory_entry("parent", (bake,))]
    return shared.rays, shared.trace_seconds, shared.trace_cpu_seconds, counters, fallback


def usable_pool(processes, threads):
    """None when the local pool of ``processes`` started and passed its self-test (or the tiles go to
    a Dask cluster), else the reason it cannot be used (the bake then runs on threads)."""
    if in_process(processes) or is_dask_client(processes):
        return None
    try:
        return pool_for(processes, threads).failed
    except OSError as e:  # the interpreter could not be started at all
        return f"worker processes could not be started ({e})"


def pool_for(workers, threads):
    """The persistent pool of ``workers`` processes of ``threads`` threads (made anew when the count
    changed or the last one broke)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is not None and _POOL.failed and (_POOL.workers_wanted, _POOL.threads) == (workers, threads):
            return _POOL  # its self-test failed: not tried again in this session
        if _POOL is not None and (_POOL.broken or len(_POOL.workers) != workers or _POOL.threads != threads
                                  or not all(w.alive for w in _POOL.workers)):
            _POOL.close()
            _POOL = None
        if _POOL is None:
            _POOL = Pool(workers, threads)
        return _POOL


def shutdown():
    """End the pool's workers (the add-on's unregister, and the interpreter's exit)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is not None:
            _POOL.close()
            _POOL = None


atexit.register(shutdown)

__all__ = ["BakeWorkerError", "Pool", "pool_for", "processes_of", "shutdown", "auto_workers", "check_workers", "memory_limit",
           "mesh_data", "main"]
