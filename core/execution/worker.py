"""The worker process: bakes what its parent sends, tile by tile, until the parent is gone.

It knows no bake kinds: the layer above hands it what builds a bake from a job (a
:class:`core.execution.contracts.WorkerSide`, :mod:`core.pipeline.entry`), and it bakes the tiles it is
dealt on its threads, sending each tile's values back as plain data, its progress as counts of
samples, and its totals and memory at the end.
"""

import os
import queue
import sys
import threading
import traceback

from ..base.errors import BakeCancelled
from ..base.machine import process_memory, reset_peak
from ..engine.scheduler import Scheduler, run_all
from .memory import memory_entry
from .messages import receive, send


def main(remote):
    """A worker: bake what the parent sends until the parent is gone (see :mod:`core.execution.pool`).

    ``remote`` is the layer above's side of a worker (a :class:`core.execution.contracts.WorkerSide`): ``self_test()``
    (the digest of a tiny bake), ``forget(job)`` (let go what the last bake kept that ``job`` will not
    use) and ``build(job, cancel, progress)`` (the bake of ``job``: (bake, scheduler, threads)). The
    bake has ``tile(key, directions=False)``, ``start.counters()`` and ``scene_reused``."""
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
        reply("hello", 0, remote.self_test())
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
                remote.forget(job)  # what the last bake kept and this one will not use goes before it is built
                reset_peak()
                start = process_memory()[0]
                bake, shared, threads = remote.build(job, current["cancel"],
                                                     lambda work: reply("progress", bake_id, work))
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
                                                         scene_reused=bake.scene_reused, tiles=tiles,
                                                         request=bake.request_data)))
                bake = shared = None
            elif kind == "exit":
                return
        except BakeCancelled:
            reply("cancelled", bake_id)
        except BaseException as e:  # every error goes back to the parent, by name
            reply("error", bake_id, type(e).__name__, str(e), traceback.format_exc())


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


__all__ = ["main", "CountingScheduler"]
