"""The first code a Dask worker runs for a batch task: it imports the batch's code, or fails the task
saying why. Standard library only, and shipped to the worker by value (its code travels with the task).

Dask unpickles a task's function where the worker reads its messages: a function pickled by
reference (``mc_ao_batch.runners._dask_task``) that the worker cannot import breaks the worker's
connection instead of failing the task, and the batch waits for it forever. This module's
:func:`run` is sent by value (:func:`submittable`), so unpickling it needs nothing of ours; the
batch's modules are imported when the task runs, and a worker that cannot import them (another
``mc_ao`` first on its path, no checkout of the batch's code there) fails the task with the import
error, the worker's interpreter and the start of its ``sys.path`` (returned as ``{"cannot_import": text}``,
which the runner makes the task's failed record: the worker itself stays up for other work).
"""


def run(task, force, blender):
    """Import the batch's runner on this worker and run ``task`` (a Task's dict) there: its record, or
    ``{"cannot_import": why}``."""
    import importlib
    import socket
    import sys

    try:
        runners = importlib.import_module("mc_ao_batch.runners")
    except Exception as exc:  # noqa: BLE001 (any failure to import is this task's failure, said as it is)
        found = sys.modules.get("mc_ao")
        where = f"; the mc_ao it found is {getattr(found, '__file__', None)!r}" if found is not None else ""
        return {"cannot_import": (
            f"the Dask worker on {socket.gethostname()} cannot import the batch's code: {type(exc).__name__}: {exc}"
            f"{where} (its Python {sys.executable}, the start of its sys.path {sys.path[:4]!r}); start the "
            "workers where mc_ao_batch and mc_ao import (the repository's folder on their PYTHONPATH)")}
    return runners._dask_task(task, force, blender)


def suspicious_counts(dask_scheduler, keys):
    """On the scheduler: how many workers died running each task of ``keys`` (by value, like :func:`run`)."""
    out = {}
    for key in keys:
        ts = dask_scheduler.tasks.get(key)
        out[key] = ts.suspicious if ts is not None else 0
    return out


def submittable():
    """:func:`run` as a function of no module (``__main__``'s): Dask pickles a task graph with the standard
    pickle, which sends a module's function by its name (the worker would have to import this module);
    a ``__main__`` function Dask and cloudpickle send by value, code and all."""
    import types

    boot = types.FunctionType(run.__code__, {"__builtins__": __builtins__}, "mc_ao_batch_boot")
    boot.__module__, boot.__qualname__, boot.__doc__ = "__main__", "mc_ao_batch_boot", run.__doc__
    return boot
