"""What a worker process boots into (:func:`core.execution.pool.boot`): the worker's side of a bake.

The executor's worker loop (:func:`core.execution.worker.main`) calls :func:`self_test`, then
:func:`forget` and :func:`build` for each bake it is sent (a
:class:`core.execution.contracts.WorkerSide`).
"""

import sys

from ..execution import worker as worker_mod
from .remote import build, forget
from .run import self_test


def main():
    """A worker process: bakes the jobs its parent sends until the parent is gone."""
    worker_mod.main(sys.modules[__name__])


__all__ = ["main", "build", "forget", "self_test"]
