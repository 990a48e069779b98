"""One bake across machines: its tiles as tasks on a Dask cluster (``workers=`` a ``distributed.Client``).

The job goes to every Dask worker once; each sets the bake up once per process and bakes the tiles
it is given, as plain data (a lost worker's tiles are redone elsewhere: the tasks are pure). The
same bits as one process, on machines whose CPUs take the same instruction paths.
"""

from ..base.errors import BakeCancelled, McAoError
from ..engine.scheduler import is_cancelled
from ..engine.tilebaker import TileOut
from .messages import error_of, sum_counters

#: How many times a bake sends its job again after the workers holding it ended.
MAX_JOB_LOSSES = 3


def run_dask(client, task, job, keys, planned, store, progress, cancel, threads=1):
    """Bake ``keys`` of ``job`` as tasks on the Dask cluster of ``client``: ``task(token, job, key)``
    (the layer above's, :func:`core.pipeline.remote.dask_tile`) returns (the tile's values, the
    process, its totals so far); ``store`` each tile as it comes back. The job goes to every worker
    once; a worker lost mid-bake has its tiles redone elsewhere (the tasks are pure), and a job lost with
    every worker that held it is sent again (at most :data:`MAX_JOB_LOSSES` times). Returns what
    :meth:`core.execution.pool.Pool.run` returns."""
    import uuid

    from concurrent.futures import CancelledError

    from distributed import as_completed

    from .daskboot import submittable

    token = uuid.uuid4().hex
    job = dict(job, threads=int(threads), quantum=1 << 62)
    boot = submittable()  # imports the task on the worker, or fails the tile saying why (never a hang)
    pending = dict(enumerate(keys))  # the tiles not stored yet, by their index
    totals, done, round_ = {}, 0, 0
    while pending:
        # The job goes to every worker; Dask keeps one copy of it once the tasks are under way, and a
        # scattered copy cannot be computed again: when the workers holding it end, its tiles come back
        # cancelled, and the job goes out again with the tiles not stored yet.
        [shared_job] = client.scatter([job], broadcast=True, hash=False)
        futures = {client.submit(boot, task.__module__, task.__name__, token, shared_job, key,
                                 key=f"mc_ao-tile-{token}-{round_}-{i}", retries=3, pure=False): i
                   for i, key in pending.items()}
        lost = 0
        try:
            for fut in as_completed(futures):
                if is_cancelled(cancel):
                    raise BakeCancelled("the bake was cancelled; nothing was written")
                try:
                    out, process, total = fut.result()
                except CancelledError:
                    lost += 1  # its job was lost with the workers that held it: sent again below
                    continue
                except BaseException as e:
                    name = type(e).__name__
                    raise error_of(name, str(e)) if isinstance(e, McAoError) else e
                store(TileOut(**out))
                del pending[futures[fut]]
                totals[process] = total  # each process's latest totals: a redone tile counts once
                done += 1
                if progress is not None:
                    progress(min(done / max(len(keys), 1), 1.0))
        except BaseException:
            client.cancel(list(futures))
            raise
        round_ += 1
        if pending and (not lost or round_ > MAX_JOB_LOSSES):
            raise McAoError(f"the Dask cluster lost the bake's job {round_} times (its workers ended while "
                            f"{len(pending)} of {len(keys)} tiles were unbaked): see the workers' logs")
    parts = list(totals.values())
    counters = sum_counters(parts)
    return (sum(p["rays"] for p in parts), sum(p["trace_seconds"] for p in parts),
            sum(p["trace_cpu_seconds"] for p in parts), counters)


__all__ = ["run_dask"]
