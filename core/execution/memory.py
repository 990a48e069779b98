"""What each process of a bake holds: the bytes of its arrays, its resident and peak memory."""

import os

import numpy as np

from ..base.machine import process_memory


def held_bytes(*roots, depth=8):
    """Bytes of the numpy arrays reachable from ``roots`` through attributes, dicts, lists and
    tuples (each memory block counted once, views and slices by their base): what a bake holds in
    its meshes, tables and scenes' arrays. Embree's own scene memory is not an array and is not
    counted here."""
    seen_obj, blocks = set(), {}
    todo = [(r, 0) for r in roots]
    while todo:
        obj, d = todo.pop()
        if obj is None or id(obj) in seen_obj:
            continue
        seen_obj.add(id(obj))
        if isinstance(obj, np.ndarray):
            base = obj
            while isinstance(base.base, np.ndarray):
                base = base.base
            if base.base is None or isinstance(base.base, (bytes, bytearray, memoryview)):
                blocks[id(base)] = base.nbytes
            else:  # a view of memory numpy does not own (a buffer, a pickle's): its own size
                blocks[id(obj)] = max(blocks.get(id(obj), 0), obj.nbytes)
            continue
        if d >= depth or isinstance(obj, (str, bytes, int, float, bool, type)) or callable(obj) and not hasattr(obj, "__dict__"):
            continue
        if isinstance(obj, dict):
            todo.extend((v, d + 1) for v in obj.values())
        elif isinstance(obj, (list, tuple, set, frozenset)):
            todo.extend((v, d + 1) for v in obj)
        else:
            attrs = getattr(obj, "__dict__", None)
            if isinstance(attrs, dict):
                todo.extend((v, d + 1) for v in attrs.values())
            for name in getattr(type(obj), "__slots__", ()):
                todo.append((getattr(obj, name, None), d + 1))
    return int(sum(blocks.values()))


def memory_entry(process, held_from=(), start=None, ready=None):
    """One process's line of ``report['worker_memory']``: its resident bytes now, its peak, and the
    bytes of the arrays its bake holds (``report.worker_memory`` of :class:`core.BakeResult`)."""
    now, peak = process_memory()
    out = {"process": process, "pid": os.getpid(), "rss": now, "peak": peak, "held": held_bytes(*held_from)}
    if start is not None:
        out["start"] = start
    if ready is not None:
        out["ready"] = ready
    return out


__all__ = ["held_bytes", "memory_entry"]
