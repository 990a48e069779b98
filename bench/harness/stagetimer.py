"""Thread-CPU time of a bake by stage: named functions of the core wrapped for the length of a run.

A stage is a function or method of the core found by its name (``"Kernel._gather"``,
``"rasterize_tile"``) in whichever core module defines it, so the table survives modules moving
between folders; names that no module defines any more are listed as missing, never silently
dropped. Each wrapped call adds the thread CPU time it took to its stage, less the time of the
stages it called (exclusive time): the stages and "other" add up to the run's thread CPU time.

Only the calling thread is timed (a one-thread bake in this process); the overhead is two
``time.thread_time()`` calls per wrapped call (a few hundred calls a bake).
"""

import functools
import inspect
import sys
import time
from contextlib import contextmanager


def _core_modules():
    import core.pipeline.api  # noqa: F401  (the core loads its modules when first used: every module of a bake)

    return [m for name, m in list(sys.modules.items()) if m is not None and (name == "core" or name.startswith("core."))]


def resolve(name):
    """Every (owner, attribute, function) that ``name`` ("func" or "Class.method") names in the loaded
    core modules: a function is patched in every module that imported it by name, a method once on
    its class."""
    found, seen = [], set()
    if "." in name:
        cls_name, attr = name.split(".", 1)
        for m in _core_modules():
            cls = vars(m).get(cls_name)
            if inspect.isclass(cls) and attr in vars(cls) and id(cls) not in seen:
                seen.add(id(cls))
                raw = vars(cls)[attr]
                found.append((cls, attr, raw))
        return found
    target = None
    for m in _core_modules():
        f = vars(m).get(name)
        if inspect.isfunction(f) and f.__module__ == m.__name__:
            target = f
            break
    if target is None:
        return []
    for m in _core_modules():
        if vars(m).get(name) is target:
            found.append((m, name, target))
    return found


class StageTimer:
    """Exclusive thread-CPU seconds and call counts per stage, over the ``with timer.run():`` block."""

    def __init__(self, stages):
        self.stages = list(stages)  # (stage label, function name)
        self.seconds = {label: 0.0 for label, _ in self.stages}
        self.calls = {label: 0 for label, _ in self.stages}
        self.missing = []
        self.total = 0.0
        self._stack = []

    def _wrap(self, label, f):
        timer = self

        @functools.wraps(f)
        def timed(*args, **kwargs):
            t0 = time.thread_time()
            timer._stack.append(0.0)
            try:
                return f(*args, **kwargs)
            finally:
                dt = time.thread_time() - t0
                inner = timer._stack.pop()
                timer.seconds[label] += dt - inner
                timer.calls[label] += 1
                if timer._stack:
                    timer._stack[-1] += dt

        return timed

    @contextmanager
    def run(self):
        patched = []
        for label, name in self.stages:
            hits = resolve(name)
            if not hits:
                self.missing.append(name)
            for owner, attr, raw in hits:
                if isinstance(raw, staticmethod):
                    new = staticmethod(self._wrap(label, raw.__func__))
                elif isinstance(raw, classmethod):
                    new = classmethod(self._wrap(label, raw.__func__))
                else:
                    new = self._wrap(label, raw)
                patched.append((owner, attr, raw))
                setattr(owner, attr, new)
        t0 = time.thread_time()
        try:
            yield self
        finally:
            self.total += time.thread_time() - t0
            for owner, attr, raw in reversed(patched):
                setattr(owner, attr, raw)

    def table(self):
        """[(label, seconds, calls)] in the stages' order, then ("other", the rest, 0)."""
        labels = dict.fromkeys(label for label, _ in self.stages)  # several names may share a label
        out = [(label, self.seconds[label], self.calls[label]) for label in labels]
        out.append(("other (not in a named stage)", self.total - sum(s for _, s, _ in out), 0))
        return out
