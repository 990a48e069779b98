"""The scheduler: the bake's work items on threads, chunks of rays shared out, committed in order.

A bake is a list of items (tiles of texels, blocks of mesh vertices). :func:`run_all` gives them to
``threads`` threads; each item's baker splits its rays into chunks and hands them to
:meth:`Scheduler.run_chunks`, which lets threads that have no item left compute them too, while the
item's own thread commits every chunk's result in the chunks' order. So each texel's sums are added
in the same order whoever traced its rays: bakes are bit-identical for any thread count.

:class:`Scheduler` also carries what the threads share: progress (reported on the bake's own events,
each chunk and each item, never on a clock), cancellation, the first error, and the ray counts and
times inside Embree.
"""

import threading
from concurrent.futures import ThreadPoolExecutor

from ..base.errors import BakeCancelled

def is_cancelled(cancel):
    if cancel is None:
        return False
    if hasattr(cancel, "is_set"):
        return cancel.is_set()
    return bool(cancel())


class Scheduler:
    """State the worker threads share: progress, cancellation, errors, timing, and the chunks of
    rays a thread with no tile left may trace for another (:meth:`run_chunks`).

    Progress is reported on the bake's own events (each chunk of rays traced, each tile finished),
    never throttled by a clock: what a caller sees does not depend on how fast the machine is.
    Callers that draw a progress bar throttle their drawing themselves.
    """

    def __init__(self, total_work, progress, cancel):
        self.lock = threading.Lock()
        self.total = max(total_work, 1)
        self.done = 0
        self.progress = progress
        self.cancel = cancel
        self.stop = threading.Event()
        self.trace_seconds = 0.0
        self.trace_cpu_seconds = 0.0
        self.rays = 0
        # Chunks open to helpers (see run_chunks); set up by run_all when it runs several threads.
        self.jobs = None
        self.changed = threading.Condition(threading.Lock())
        self.pending = 0

    def check(self):
        if self.stop.is_set():
            raise Stop()
        if is_cancelled(self.cancel):
            self.halt()
            raise Stop()

    def halt(self):
        """Stop every worker: set ``stop`` and wake the threads waiting for chunks to help with."""
        self.stop.set()
        with self.changed:
            self.changed.notify_all()

    def advance(self, work, rays=0, trace_seconds=0.0, trace_cpu_seconds=0.0):
        with self.lock:
            self.done += work
            self.rays += rays
            self.trace_seconds += trace_seconds
            self.trace_cpu_seconds += trace_cpu_seconds
            if self.progress is not None and work > 0:
                self.progress(min(self.done / self.total, 1.0))

    def run_chunks(self, chunks, compute, commit):
        """commit(chunk, compute(chunk)) for every chunk, the commits in order on this thread.

        With several threads, the chunks are open to the threads that have no item of their own
        left (the last tiles of a bake): any thread may compute a chunk, this one commits them in
        order. So a texel's sums are added in the same order whoever traced its rays, and the
        result does not depend on the threads. This thread computes chunks too while it waits for
        the next one to commit.
        """
        if self.jobs is None or len(chunks) < 2:
            for c in chunks:
                commit(c, compute(c))
            return
        job = ChunkJob(chunks, compute)
        with self.changed:
            self.jobs.append(job)
            self.changed.notify_all()
        try:
            for i, c in enumerate(chunks):
                commit(c, job.result(i))
        finally:
            with self.changed:
                self.jobs.remove(job)

    def help(self):
        """Compute other threads' chunks until every item is done (or the bake stops)."""
        with self.changed:
            while not self.stop.is_set() and self.pending > 0:
                job = max(self.jobs, key=ChunkJob.left, default=None)
                i = job.claim() if job is not None else None
                if i is None:
                    self.changed.wait()
                    continue
                self.changed.release()
                try:
                    job.run(i)
                finally:
                    self.changed.acquire()


class ChunkJob:
    """The chunks of one round of one tile, claimed in order by its own thread and by helpers."""

    def __init__(self, chunks, compute):
        self.chunks, self.compute = chunks, compute
        self.lock = threading.Lock()
        self.next = 0
        self.results = [None] * len(chunks)
        self.ready = [threading.Event() for _ in chunks]

    def left(self):
        return len(self.chunks) - self.next

    def claim(self):
        """The index of the next chunk no thread has taken, or None."""
        with self.lock:
            i = self.next
            if i >= len(self.chunks):
                return None
            self.next = i + 1
            return i

    def run(self, i):
        try:
            self.results[i] = (True, self.compute(self.chunks[i]))
        except BaseException as e:  # raised on the committing thread, in its turn
            self.results[i] = (False, e)
        self.ready[i].set()

    def result(self, i):
        """Chunk i's result, computing the next open chunks (this one or later ones) until it is
        ready."""
        while not self.ready[i].is_set():
            j = self.claim()
            if j is None:
                self.ready[i].wait()
                break
            self.run(j)
        ok, value = self.results[i]
        self.results[i] = None
        if not ok:
            raise value
        return value


class Stop(Exception):
    """Raised inside workers once the bake is cancelled or another worker failed."""


def run_all(work, items, threads, shared, progress):
    """work(item) for every item, on ``threads`` threads; the first error stops the others and is
    raised, a cancel (``shared.stop``) raises BakeCancelled; progress reaches 1 at the end. Shared by
    the texel bake and the vertex bake (core.targets.corners).

    With several threads, each takes the next item until none is left, then helps the threads
    still working with their chunks of rays (:meth:`Scheduler.run_chunks`) until every item is done:
    no thread idles while the last tiles are traced, and one tile alone is traced by all of them.
    """

    def guarded(item):
        try:
            work(item)
        except Stop:
            pass
        except BaseException:
            shared.halt()
            raise

    if threads == 1:
        for item in items:
            guarded(item)
    else:
        queue = iter(list(items))
        shared.jobs, shared.pending = [], len(items)

        def worker():
            try:
                while not shared.stop.is_set():
                    with shared.changed:
                        item = next(queue, Stop)
                    if item is Stop:
                        break
                    try:
                        guarded(item)
                    finally:
                        with shared.changed:
                            shared.pending -= 1
                            shared.changed.notify_all()
            finally:
                shared.help()

        with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="mc_ao") as pool:
            for f in [pool.submit(worker) for _ in range(threads)]:
                f.result()
    if shared.stop.is_set():
        raise BakeCancelled("the bake was cancelled; nothing was written")
    if progress is not None:
        progress(1.0)


__all__ = ["Scheduler", "ChunkJob", "Stop", "run_all", "is_cancelled"]
