"""A bake's objects baked one after another on a worker thread, reporting through a queue of messages
that the operator's modal session and the script's loop both read (:func:`dispatch`). No bpy.

- :class:`BakeRun`: the worker thread and its messages;
- :func:`dispatch`: one message to a handler's ``on_*`` method;
- :func:`empty_bake_problem`: a finished bake that baked nothing is an error, never a success.
"""

import queue
import threading
import time
import traceback

import numpy as np

from . import corelink

# Bakes in flight (operators.is_running() and unregister() read it).
RUNS = set()


class BakeRun:
    """Runs the jobs one after another on a worker thread and reports through ``messages``.

    Messages are tuples: ("progress", job, fraction), ("tile", job, rows, cols, block),
    ("done", job, {quantity: result}) (None: the job's own bake), ("cancelled", job), ("error", job, exception),
    ("crash", job, exception, traceback text), and ("end",) last. A job that fails does not stop
    the ones after it; a cancel does. ``started[job]`` is the time.monotonic() at which the worker
    began that job.
    """

    def __init__(self, jobs, settings, threads, live, quantities=(None,)):
        self.jobs = jobs
        # What each job is baked for: None, its own bake (Job.quantity), then each other core
        # quantity an output needs (one more core bake of the job, unless it is the job's own);
        # "done" carries {quantity: result}, None for the job's own.
        self.quantities = [None] + [q for q in quantities if q is not None]
        self.settings = settings
        self.threads = threads
        self.live = live
        self.cancel = threading.Event()
        self.messages = queue.SimpleQueue()
        self.started = {}
        # Imported here, in the main thread, so that the worker finds it loaded.
        self.core = corelink.load()
        self.thread = threading.Thread(target=self._work, name="mc_ao bake", daemon=True)

    def start(self):
        RUNS.add(self)
        self.thread.start()

    def stop(self):
        """Cancel the bake and wait for the worker to finish (it checks the cancel event often)."""
        self.cancel.set()
        if self.thread.is_alive():
            self.thread.join()
        RUNS.discard(self)

    def next_message(self, poll=0.25):
        """The next message, waiting as long as it takes; Ctrl-C (KeyboardInterrupt) gets through."""
        while True:
            try:
                return self.messages.get(timeout=poll)
            except queue.Empty:
                pass

    def _work(self):
        try:
            self._work_jobs()
        finally:
            # Always last, whatever happened above: the main thread waits for it.
            self.messages.put(("end",))

    def _needs(self, job):
        """The core quantities ``job`` needs: its own, then each other one an output reads."""
        own = getattr(job, "quantity", "ao")
        return [own] + [q for q in self.quantities if q not in (None, own)]

    def _group(self, i):
        """The jobs from ``i`` on that are other quantities of job ``i``'s object, with every quantity
        they need, when that is more than one (they are then baked together, one core.bake: one set-up,
        each quantity its own rays); else None."""
        job = self.jobs[i]
        if not hasattr(job, "run_maps"):
            return None
        members = [i]
        for j in range(i + 1, len(self.jobs)):
            other = self.jobs[j]
            if not (hasattr(other, "quantity") and job.shares_bake_with(other)):
                break
            members.append(j)
        quantities = list(dict.fromkeys(q for j in members for q in self._needs(self.jobs[j])))
        return (members, quantities) if len(quantities) > 1 else None

    def _run_group(self, i, group, put, on_tile, ahead):
        """Bake the quantities of ``group`` (from :meth:`_group`) in one core bake through job ``i``;
        job ``i``'s results, the others' kept in ``ahead`` for their turn."""
        members, quantities = group
        own = self.jobs[i].quantity

        def progress(fraction):
            put(("progress", i, fraction))

        def tile(quantity, rows, cols, block):
            if quantity == own:
                on_tile(rows, cols, block)

        baked = self.jobs[i].run_maps(self.settings, self.threads, quantities, progress=progress, cancel=self.cancel,
                                      on_tile=tile if self.live else None)
        for j in members:
            mine = self.jobs[j].quantity
            ahead[j] = {q: baked[q] for q in self._needs(self.jobs[j]) if q in self.quantities}
            ahead[j][None] = baked[mine]
        return ahead.pop(i)

    def _work_jobs(self):
        put = self.messages.put
        ahead = {}  # job index -> its results, baked with an earlier job of the same object
        for i, job in enumerate(self.jobs):
            if self.cancel.is_set():
                put(("cancelled", i))
                break
            self.started[i] = time.monotonic()

            def on_tile(rows, cols, block, i=i):
                put(("tile", i, rows, cols, np.array(block, dtype=np.float32)))

            results = {}
            try:
                own = getattr(job, "quantity", "ao")
                runs = [q for q in self.quantities if q != own]
                if i in ahead:  # baked with an earlier job of the same object (below)
                    results = ahead.pop(i)
                    put(("progress", i, 1.0))
                    runs = []
                else:
                    group = self._group(i)
                    if group is not None:
                        results = self._run_group(i, group, put, on_tile, ahead)
                        runs = []
                for k, quantity in enumerate(runs):
                    def progress(fraction, i=i, k=k, n=len(runs)):
                        put(("progress", i, (k + fraction) / n))

                    results[quantity] = job.run(
                        self.settings, self.threads, progress=progress, cancel=self.cancel,
                        on_tile=on_tile if self.live and k == 0 else None,
                        **({"quantity": quantity} if k else {}),
                    )
                if own in self.quantities:
                    results[own] = results[None]
            except self.core.BakeCancelled:
                put(("cancelled", i))
                break
            except self.core.McAoError as exc:  # this object's input: the others may still bake
                put(("error", i, exc))
                continue
            except Exception as exc:  # a bug, or the machine out of memory: report it, keep the trace
                put(("crash", i, exc, traceback.format_exc()))
                continue
            problem = empty_bake_problem(results[None])
            if problem is not None:  # never a success that baked nothing (nor its all-zero files)
                put(("error", i, self.core.MeshError(problem)))
                continue
            put(("done", i, results))


def empty_bake_problem(result):
    """Why a finished bake baked nothing (no covered texel, no tile, no corner), or None when it baked.

    The core's report says why: triangles without area, UV triangles without area, UVs outside the
    image (or outside the UDIM tiles). The core may raise core.MeshError for this itself; either way
    the object fails with a message, and no file is written.
    """
    mask = getattr(result, "mask", None)
    if mask is None or np.any(mask):
        return None
    report = getattr(result, "report", None) or {}
    reasons = []
    for key, text in (("degenerate_triangles", "of its triangles have no area"),
                      ("degenerate_uv_triangles", "of its UV triangles have no area in the UV map"),
                      ("uv_outside_triangles", "of its UV triangles lie outside the image's UV square [0, 1]"),
                      ("uv_outside_udim_triangles", "of its UV triangles lie outside the UDIM tiles 1001 to 2000")):
        n = int(report.get(key, 0) or 0)
        if n:
            reasons.append(f"{n} {text}")
    why = "; ".join(reasons) or "its UV triangles are too small to cover a texel centre at this resolution"
    return f"the bake covered no texel ({why}): nothing was written"


#: BakeRun message kind -> the handler method dispatch() calls with the message's other items.
HANDLER_METHODS = {"progress": "on_progress", "tile": "on_tile", "done": "on_done", "error": "on_failed",
                   "crash": "on_crashed", "cancelled": "on_cancelled"}


def dispatch(message, handler):
    """Hand one BakeRun message to ``handler``; True at the end of the run ("end").

    The operator's modal session and the script's loop are both handlers: ``on_progress(i, fraction)``,
    ``on_tile(i, rows, cols, block)``, ``on_done(i, results)``, ``on_failed(i, error)`` (the core refused
    the object's input, or it baked nothing), ``on_crashed(i, exc, trace)``, ``on_cancelled(i)``; a
    handler without a method ignores that kind.
    """
    kind, *args = message
    if kind == "end":
        return True
    method = getattr(handler, HANDLER_METHODS[kind], None)
    if method is not None:
        method(*args)
    return False


# -- settings --------------------------------------------------------------------------------------
