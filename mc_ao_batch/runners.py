"""The engines that run batch tasks: a pool of local processes, and Dask. Neither schedules anything itself.

Both call :func:`mc_ao_batch.task.run_task` once per task and feed the caller's progress from the
tasks' own events (started, finished), in the main thread.

- local: ``concurrent.futures`` threads, each waiting on one task's process; N at a time.
- dask: ``distributed``; a ``LocalCluster`` of N single-threaded worker processes on 127.0.0.1, or a
  running scheduler. A task whose worker dies is run again on another worker by Dask's scheduler (up
  to :data:`ALLOWED_FAILURES` times for a local cluster; a scheduler of your own has its own
  ``distributed.scheduler.allowed-failures``); the record says how many tries it took.
"""

import logging
import os
import queue
import threading
import traceback
from concurrent.futures import ThreadPoolExecutor

from .task import _record, run_task

#: Worker deaths one task may see before Dask gives up on it (``allowed-failures``).
ALLOWED_FAILURES = 3
TOPIC = "mc_ao-batch"


class Interrupted(KeyboardInterrupt):
    """Ctrl-C reached a runner: ``records`` holds every task's record, the finished ones as they
    finished and the others failed as interrupted, for the batch summary."""

    def __init__(self, records):
        super().__init__()
        self.records = records


def _interrupted_records(tasks, records):
    """``records`` (finished tasks) and an "interrupted" failure for each task without one."""
    done = {r["index"] for r in records}
    return list(records) + [_record(t, "failed", error="interrupted: the batch stopped before it finished")
                            for t in tasks if t.index not in done]


def _bug_record(task, exc):
    text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)).rstrip()
    return _record(task, "failed", error=f"internal error in the batch runner:\n{text}")


def run_local(tasks, *, workers, progress, force=False, blender=None):
    """Run ``tasks`` N at a time, each in its own process; return their records."""
    events = queue.Queue()
    running = {}
    lock = threading.Lock()
    stopping = threading.Event()

    def one(task):
        if stopping.is_set():
            events.put(("done", _record(task, "failed", error="cancelled before it started")))
            return

        def on_process(proc):
            with lock:
                running[task.index] = proc
            if stopping.is_set():
                proc.stdin.close()

        try:
            record = run_task(task, force=force, blender=blender, on_process=on_process,
                              on_start=lambda info: events.put(("started", info)))
        except BaseException as exc:  # a bug here must not hang the batch
            record = _bug_record(task, exc)
        if stopping.is_set() and record["status"] == "failed":
            record["error"] = "interrupted: its bake was stopped"  # not the bake's own failure
        with lock:
            running.pop(task.index, None)
        events.put(("done", record))

    records = []
    pool = ThreadPoolExecutor(max_workers=max(1, workers), thread_name_prefix="mc_ao-batch")
    try:
        for task in tasks:
            pool.submit(one, task)
        while len(records) < len(tasks):
            kind, payload = events.get()
            if kind == "started":
                progress.started(payload)
            else:
                records.append(payload)
                progress.finished(payload)
    except KeyboardInterrupt:
        stopping.set()
        with lock:
            for proc in running.values():
                try:
                    proc.stdin.close()  # the guard ends the bake
                except OSError:
                    pass
        pool.shutdown(wait=True, cancel_futures=True)
        while not events.empty():  # the tasks that ended while the pool stopped
            kind, payload = events.get()
            if kind == "done":
                records.append(payload)
        raise Interrupted(_interrupted_records(tasks, records)) from None
    pool.shutdown(wait=True)
    return records


def bake_environment():
    """This worker's environment without what Dask's nanny set for the worker process itself.

    The nanny starts workers with ``distributed.nanny.pre-spawn-environ`` (MALLOC_TRIM_THRESHOLD_=65536
    and one thread for OpenMP, MKL and OpenBLAS). They are meant for the worker, not for programs it
    starts, and the malloc setting alone makes a bake 2.3 times slower (measured: 256^2 at 64 samples,
    5.5 s -> 10.7 s). A variable whose value differs from the nanny's was set by someone else: kept.
    """
    import dask
    import distributed  # noqa: F401 (loads distributed's defaults into dask.config)

    env = dict(os.environ)
    for key, value in (dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {}).items():
        if env.get(key) == str(value):
            del env[key]
    return env


def _dask_task(task, force, blender):
    """Runs on a Dask worker: the task, reporting its start on the batch's event topic."""
    from distributed import get_worker

    worker = get_worker()

    def on_start(info):
        info = dict(info, worker=worker.address)
        worker.log_event(TOPIC, info)

    return run_task(task, force=force, blender=blender, on_start=on_start, env=bake_environment())


def start_local_cluster(workers):
    """A ``LocalCluster`` of ``workers`` single-threaded worker processes, listening on 127.0.0.1 only."""
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES}):
        # No dashboard; the scheduler's HTTP server (health, metrics) on a free port: on its default,
        # 8787, a second cluster on the machine printed a UserWarning into every batch's output.
        return LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
            dashboard_address=None, silence_logs=logging.ERROR,
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
        )


def run_dask(tasks, *, workers, progress, scheduler=None, force=False, blender=None):
    """Run ``tasks`` on Dask: a local cluster of ``workers`` processes, or the scheduler at ``scheduler``."""
    try:
        from distributed import Client
        from distributed.client import FutureCancelledError
        from distributed.scheduler import KilledWorker
    except ImportError:
        raise RuntimeError(
            "--runner dask needs the distributed package: pip install -r requirements-batch.txt"
        ) from None

    from .daskboot import suspicious_counts, submittable

    cluster = None if scheduler else start_local_cluster(workers)
    client = Client(scheduler or cluster, timeout="60s")
    boot = submittable()  # imports the batch's code on the worker, or fails the task saying why
    events = queue.Queue()
    try:
        client.subscribe_topic(TOPIC, lambda event: events.put(("started", event[1])))
        futures = {}
        for task in tasks:
            future = client.submit(boot, task.to_dict(), force, blender, pure=False,
                                   key=f"mc_ao-bake-{task.index}-{os.urandom(4).hex()}")
            futures[future.key] = (future, task)
            future.add_done_callback(lambda f: events.put(("done", f.key)))

        records, starts = {}, {}
        while len(records) < len(tasks):
            try:
                kind, payload = events.get()
            except KeyboardInterrupt:
                raise Interrupted(_interrupted_records(tasks, records.values())) from None
            if kind == "started":
                starts[payload.get("index")] = starts.get(payload.get("index"), 0) + 1
                progress.started(payload)
                continue
            future, task = futures[payload]
            if payload in records:
                continue
            try:
                record = future.result()
            except KilledWorker as exc:
                record = _record(task, "failed", error=(
                    f"the worker running it died {ALLOWED_FAILURES} times (Dask gave up on it): {exc}"))
            except FutureCancelledError:
                record = _record(task, "failed", error="cancelled")
            except Exception as exc:
                record = _bug_record(task, exc)
            if "cannot_import" in record:  # the worker could not import the batch's code (mc_ao_batch.daskboot)
                record = _record(task, "failed", error=record["cannot_import"])
            records[payload] = record
            progress.finished(record)
        try:
            # the scheduler knows how many workers died running each task
            deaths = client.run_on_scheduler(suspicious_counts, keys=list(futures))
            tries = {key: n + 1 for key, n in deaths.items()}
        except Exception:  # a scheduler that cannot tell: count the starts seen
            tries = {key: max(1, starts.get(futures[key][1].index, 0)) for key in futures}
        for key, record in records.items():
            record["attempts"] = tries.get(key, 1) if record["status"] != "skipped" else 0
        return [records[k] for k in futures]
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
