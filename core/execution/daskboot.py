"""The first code a Dask worker runs for a tile of a bake: it imports the task under the core's name, or
fails the tile saying why. Standard library only, and sent to the worker by value (its code travels with
the task, :func:`submittable`).

Dask unpickles a task's function where the worker reads its messages: a function pickled by reference
that the worker cannot import (no core there, another ``core`` first on its path) broke the worker's
connection instead of failing the task, and the bake waited forever. Here the worker imports the task
when it runs it, and a worker that cannot fails the tile with the import error, its interpreter and the
start of its ``sys.path``.
"""


def run(module, name, *args):
    """Import ``module`` (the task's, under the core's name in the parent: ``core``, ``mc_ao_core``) on
    this worker and call its ``name`` with ``args``."""
    import importlib
    import socket
    import sys

    try:
        task = getattr(importlib.import_module(module), name)
    except Exception as exc:  # noqa: BLE001 (any failure to import is the tile's failure, said as it is)
        raise RuntimeError(
            f"the Dask worker on {socket.gethostname()} cannot import the core as {module!r}: "
            f"{type(exc).__name__}: {exc} (its Python {sys.executable}, the start of its sys.path "
            f"{sys.path[:4]!r}); install the core there (pip install the repository, which installs "
            "mc_ao_core) or start the workers with the repository's folder on their PYTHONPATH") from None
    return task(*args)


def submittable():
    """:func:`run` as a function of no module (``__main__``'s, which Dask and cloudpickle send by value,
    code and all: a function of a module is sent by its name, which the worker would have to import)."""
    import types

    boot = types.FunctionType(run.__code__, {"__builtins__": __builtins__}, "mc_ao_dask_boot")
    boot.__module__, boot.__qualname__, boot.__doc__ = "__main__", "mc_ao_dask_boot", run.__doc__
    return boot
