"""The pool of worker processes: every core of the machine, none of them waiting on another's GIL.

A bake with ``workers`` > 1 (:func:`core.bake_ao`) sends its input once to each worker of a
persistent pool; each builds the same bake (in the module a :class:`core.execution.contracts.Remote`
names, :mod:`core.pipeline.entry`: the same tiles, its own Embree scene) and bakes the tiles it is
dealt, one at a time as it frees up, ``threads`` threads each (they share a tile's chunks of rays,
:mod:`core.engine.scheduler`). A tile's values come back as
plain arrays and the parent assembles the images, the margin and the bent normals. Texels draw their
samples by (seed, texel, index) alone and a tile's sums are added in one order, so the images, errors
and sample counts are bit-identical for any workers x threads x tiling on one machine.

How the processes are started and kept (each point is a trap met in Blender):

- Workers are new interpreters (``sys.executable -I -c``), on every OS: never fork (it would copy
  Blender's whole process), and not :mod:`multiprocessing` (its spawn re-runs a ``__main__`` that
  Blender gave a file name, and pickles functions by their module's name, which in the installed
  extension is ``bl_ext.<repository>.mc_ao.core``, a package Blender makes at run time that a new
  interpreter cannot import). A worker runs only the core and its dependencies, from where this
  process found them (:func:`boot`): isolated (``-I``: no working folder, no PYTHONPATH, no user site
  on its path: a ``json.py`` or ``numpy.py`` beside a user's .blend never runs in it), in the core's
  own folder, with this process's ``sys.path`` (less its working folder) passed explicitly, the core's
  enclosing packages made as empty packages of this process's folders (Blender's ``bl_ext`` exists only
  in Blender), and the core imported under this process's name for it (``core``, pip's
  ``mc_ao_core``, the extension's), checked to be this process's file: numpy, embreex and the core,
  never bpy. A worker that ends at start-up fails the pool with what it wrote to its standard error
  (which otherwise goes on to this process's).
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
  positions and triangles, :func:`core.pipeline.remote.scene_key`): an artist baking again after changing the samples,
  the resolution or the distance does not wait for them. One scene at a time: a bake of other meshes
  drops it before building its own, so a worker's peak does not grow; between bakes an idle worker
  holds it (what :func:`shutdown` or a bake of other meshes frees). Selected-to-active bakes keep none.
- Tiles are dealt one to each worker in turn with the set-up (a worker starts its first the moment
  its scene is built), then each gets its next as it returns one, ``AHEAD`` at most and one only once
  fewer tiles are left than workers.
- A worker that dies (killed, out of memory) fails the bake with :class:`BakeWorkerError`, nothing is
  written, and the next bake gets a fresh pool.
- The self-test: a new pool's workers each bake a tiny scene first and must give this process's bits
  (the ``self_test`` of its :class:`core.execution.contracts.Remote`); where one cannot start or
  differs, bakes run on threads of this process with a warning saying why (``report['warnings']``),
  and the pool is not tried again in this session.

What each OS needs (tested here on Linux only; the rest is what the code relies on): an interpreter at
``sys.executable`` that can run ``-c`` (Blender sets it to its bundled Python on Linux, Windows and
macOS; the bpy module's is the venv's), anonymous pipes (``subprocess.PIPE``; on Windows the worker's
``os.dup``/``os.dup2`` of fds 1 and 2 work on the C runtime's descriptors) and the wheels' embreex on the
parent's ``sys.path``, which the worker takes. No ``/dev/shm``, no ``fork``, no signals: the lifeline is
the pipe, which every OS closes when a process ends. macOS and Windows have no ``sched_getaffinity``
(the core count is ``os.cpu_count()``) and no cgroup (the memory is what the machine has available).
"""

import atexit
import json
import os
import queue
import subprocess
import sys
import threading
import time

from ..engine.scheduler import is_cancelled
from ..engine.tilebaker import TileOut
from ..base.errors import BakeCancelled
from .messages import BakeWorkerError, error_of, receive, send, sum_counters

#: Tiles dealt to a worker ahead of the one it bakes, so that it never waits for the parent.
AHEAD = 2
#: Progress messages per worker and bake, at most (a message per chunk would let a busy parent slow them).
PROGRESS_STEPS = 512


def _core_package():
    """The core package's full name in this process (``core`` in the repository, ``mc_ao_core`` installed
    with pip, ``bl_ext.<repository>.mc_ao.core`` in Blender's extension) and its folder."""
    name = __name__.rsplit(".", 2)[0]  # <core>.execution.pool
    return name, os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


#: How much of a worker's standard error is kept for the message of a worker that fails at start.
STDERR_TAIL = 4096

#: The command a worker interpreter runs (``python -I -c BOOT ARGS``; see :func:`boot_args`). Isolated
#: (-I: no working folder, no PYTHONPATH, no user site on the path) and in a neutral working folder, it
#: imports nothing but the standard library's json, types and importlib before it sets the path it is
#: given; then it makes the core's enclosing packages as empty packages of the folders the parent has
#: them in (their __init__ does not run: Blender's ``bl_ext`` exists only in Blender), imports the
#: entry under the core's full name, and checks it came from the parent's file.
BOOT = ("import sys, json, types, importlib; a = json.loads(sys.argv[1]); sys.path[:] = a['path']\n"
        "for n, p in a['packages']:\n"
        "    m = types.ModuleType(n); m.__path__, m.__package__ = p, n; sys.modules[n] = m\n"
        "w = importlib.import_module(a['module'])\n"
        "if w.__file__ != a['file']:\n"
        "    sys.exit(f\"mc_ao worker: {a['module']} came from {w.__file__}, not the parent's {a['file']}\")\n"
        "w.main()")


def boot_args(entry):
    """The plain data a worker boots from (JSON in its argv[1]): ``path``, this process's ``sys.path``
    (absolute, without its working folder, which is a user's folder: a ``json.py`` or ``numpy.py`` there
    must not run in a worker) with the folder that holds the core first when the core is top-level;
    ``packages``, the core's enclosing packages and their folders; ``module``, ``entry`` under the
    core's full name; ``file``, where this process has that module."""
    name, folder = _core_package()
    cwd = os.getcwd()
    path = [os.path.abspath(p) for p in sys.path if p and os.path.abspath(p) != cwd]
    if "." not in name:
        root = os.path.dirname(folder)
        path = [root] + [p for p in path if p != root]
    parts = name.split(".")
    # (Blender's bl_ext is a plain module whose repositories are put in sys.modules: no __path__ of its own)
    packages = [(".".join(parts[:k]), list(getattr(sys.modules[".".join(parts[:k])], "__path__", [])))
                for k in range(1, len(parts))]
    module = f"{name}.{entry}"
    return {"path": list(dict.fromkeys(path)), "packages": packages, "module": module,
            "file": os.path.join(folder, *entry.split(".")) + ".py"}


def boot(entry):
    """The command line of a worker that boots into ``entry`` (a module inside the core package)."""
    return [sys.executable, "-I", "-c", BOOT, json.dumps(boot_args(entry))]


class _Worker:
    def __init__(self, threads, inbox, index, entry):
        env = dict(os.environ)
        for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
            env[name] = "1"
        # A neutral working folder: the core's own (a user's folder may hold a json.py or a numpy.py).
        self.process = subprocess.Popen(boot(entry), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, env=env, cwd=_core_package()[1])
        self.index, self.busy, self.ready, self.alive = index, [], False, True
        self.lock = threading.Lock()
        self.stderr_tail = b""
        threading.Thread(target=self._read, args=(inbox,), name=f"mc_ao-worker-{index}", daemon=True).start()
        self.stderr_reader = threading.Thread(target=self._stderr, name=f"mc_ao-worker-{index}-stderr", daemon=True)
        self.stderr_reader.start()

    def _stderr(self):
        """What the worker writes to its standard error goes on to this process's, as it comes; the last
        of it is kept for the message of a worker that ends at start-up."""
        err = self.process.stderr
        out = getattr(sys.stderr, "buffer", None)
        while True:
            chunk = err.read1(65536) if hasattr(err, "read1") else err.read(65536)
            if not chunk:
                return
            self.stderr_tail = (self.stderr_tail + chunk)[-STDERR_TAIL:]
            try:
                if out is not None:
                    out.write(chunk)
                    out.flush()
                else:
                    sys.stderr.write(chunk.decode("utf-8", "replace"))
            except (OSError, ValueError):
                pass  # this process's stderr is gone: the tail is still kept

    def startup_message(self):
        """What the worker last wrote to its standard error (its own reason for ending), in a line or a few."""
        try:
            self.process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            pass
        self.stderr_reader.join(timeout=5)  # its stderr read to its end
        text = self.stderr_tail.decode("utf-8", "replace").strip()
        lines = [line for line in text.splitlines() if line.strip()]
        return " / ".join(lines[-6:])

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
    """``workers`` worker processes of ``threads`` threads each, kept for later bakes. ``remote``: a
    :class:`core.execution.contracts.Remote`, the module a worker boots into and the self-test every
    worker must match."""

    def __init__(self, workers, threads, remote):
        global _STARTED_IN
        t0 = time.perf_counter()
        self.workers_wanted, self.threads, self.remote = int(workers), int(threads), remote
        self.inbox = queue.Queue()
        self.workers = [_Worker(self.threads, self.inbox, i, remote.entry) for i in range(self.workers_wanted)]
        self.broken = False
        self.bake_id = 0
        self.scene = None  # the token of the scene the workers keep from the last bake (the job's "scene_key")
        self.lock = threading.Lock()  # one bake at a time
        self.failed = self._check()
        self.started_in = time.perf_counter() - t0
        if self.failed is None:
            _STARTED_IN = self.started_in

    def _check(self):
        """None when every worker started and its self-test bake gave this process's bits, else why
        not (the bake then runs on threads, with a warning that says so)."""
        want = self.remote.self_test()
        waiting = set(self.workers)
        why = None
        while waiting:
            w, msg = self.inbox.get()
            waiting.discard(w)
            if msg[0] == "died":
                said = w.startup_message()
                why = why or (f"worker process {w.index} ended at start-up (exit code {w.process.poll()})"
                              + (f": {said}" if said else ", saying nothing"))
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
        with self.lock:
            self.bake_id += 1
            bake_id = self.bake_id
            quantum = max(1, planned // (PROGRESS_STEPS * len(self.workers)))
            job = dict(job, quantum=quantum, threads=self.threads)
            self.scene = job.get("scene_key")
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
                            failure = error_of(msg[2], msg[3])
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
            counters = sum_counters(parts)
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


_POOL = None
_POOL_LOCK = threading.Lock()
#: Wall seconds the last pool that passed its self-test took to start in this process (None: none yet).
_STARTED_IN = None


def pool_state(workers, threads, remote):
    """What a bake on ``workers`` processes of ``threads`` threads running ``remote`` would find, without
    starting anything: ('running', the token of the scene its workers keep), ('failed', why: its
    self-test failed, bakes run on threads) or ('none', the wall seconds a start took in this process,
    or None when none has started yet)."""
    with _POOL_LOCK:
        p = _POOL
        if p is not None and (p.workers_wanted, p.threads, p.remote) == (workers, threads, remote):
            if p.failed:
                return "failed", p.failed
            if not p.broken and len(p.workers) == workers and all(w.alive for w in p.workers):
                return "running", p.scene
        return "none", _STARTED_IN


def pool_for(workers, threads, remote):
    """The persistent pool of ``workers`` processes of ``threads`` threads running ``remote`` (made anew
    when the count changed or the last one broke)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is not None and _POOL.failed and (_POOL.workers_wanted, _POOL.threads) == (workers, threads):
            return _POOL  # its self-test failed: not tried again in this session
        if _POOL is not None and (_POOL.broken or len(_POOL.workers) != workers or _POOL.threads != threads
                                  or _POOL.remote != remote or not all(w.alive for w in _POOL.workers)):
            _POOL.close()
            _POOL = None
        if _POOL is None:
            _POOL = Pool(workers, threads, remote)
        return _POOL


def pool_ready(workers, threads):
    """Whether the persistent pool of ``workers`` processes of ``threads`` threads is running and
    usable: the next bake of that shape starts no process (core.execution.cost prices a start)."""
    pool = _POOL
    return bool(pool is not None and not pool.broken and not pool.failed and len(pool.workers) == workers
                and pool.threads == threads and all(w.alive for w in pool.workers))


def shutdown():
    """End the pool's workers (the add-on's unregister, and the interpreter's exit)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is not None:
            _POOL.close()
            _POOL = None


atexit.register(shutdown)


__all__ = ["Pool", "pool_for", "pool_ready", "shutdown", "boot", "AHEAD", "PROGRESS_STEPS"]
