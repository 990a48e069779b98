"""What the executor is given by the layer above it: a bake to run, and what runs it in other processes.

The executor knows no bake kinds. It bakes any :class:`TileBake` (an image's texels, face corners,
several quantities over one layout), here or in worker processes, and a worker process boots into
the module a :class:`Remote` names, which builds the bake from a job (plain data) as a
:class:`WorkerSide`.
"""

from dataclasses import dataclass
from typing import Any, Callable, Protocol


class TileBake(Protocol):
    """A bake set up after its prologue, as the executor runs it."""

    planned: int  # samples the bake will take at most (progress)

    def trace_setup(self, shared, cancel, on_rays=None) -> None:
        """Build the tracing (scene, pattern, kernel, start stage) on scheduler ``shared``."""

    def tile(self, key, directions=True):
        """Bake tile ``key``: its :class:`core.engine.tilebaker.TileOut`."""


class WorkerSide(Protocol):
    """The module a worker process boots into (its ``main()`` runs :func:`core.execution.worker.main`)."""

    def self_test(self) -> str:
        """The digest of a tiny bake, which every worker must share with its parent."""

    def forget(self, job: dict) -> None:
        """Let go what the last bake kept that ``job`` will not use (before it is built)."""

    def build(self, job: dict, cancel, progress) -> tuple:
        """(bake, its scheduler, threads) of ``job``: a :class:`TileBake` with ``start.counters()``,
        ``scene_reused`` (it traced in the scenes kept from the last bake) and ``request_data`` (plain
        data the worker's line of the report carries back: the options it baked with)."""


@dataclass(frozen=True)
class Remote:
    """What runs a bake's tiles in other processes, given by the layer above
    (:data:`core.pipeline.run.REMOTE`).

    entry : the module, inside the core package, that a worker process boots into (a
        :class:`WorkerSide` with a ``main()``); self_test : this process's digest of the self-test bake;
    dask_tile : the task a Dask worker runs, ``dask_tile(token, job, key)`` -> (tile values, process,
        totals), importable by its module's name there.
    """

    entry: str
    self_test: Callable[[], str]
    dask_tile: Callable[..., Any]


__all__ = ["TileBake", "WorkerSide", "Remote"]
