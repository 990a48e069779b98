"""Messages between a bake's process and its worker processes: pickles of plain data over pipes.

A message is a pickle (protocol 5) of plain data (arrays, numbers, strings, dicts, never a core
object: in Blender the parent's core is ``bl_ext.<repository>.mc_ao.core`` and a worker's is
``core``) whose arrays travel out of band, straight from their memory. A worker's error comes back
as its class name and message and is raised here as the core's own class (:func:`error_of`).
"""

import pickle
import struct

from ..base import errors as errors_mod
from ..base.errors import McAoError

_HEADER = struct.Struct("<Q")


class BakeWorkerError(McAoError, RuntimeError):
    """A worker process ended before its bake did (killed, or out of memory)."""


def send(stream, obj):
    """Write ``obj`` as a message: a pickle (protocol 5) whose arrays travel out of band, each
    array's bytes written straight from its memory after the pickle (no copy of them into the
    pickle, none on the way in: a worker's scene arrives in the buffers its arrays then use)."""
    buffers = []
    data = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    views = [b.raw() for b in buffers]
    stream.write(_HEADER.pack(len(data)) + _HEADER.pack(len(views)) + b"".join(_HEADER.pack(v.nbytes) for v in views))
    stream.write(data)
    for v in views:
        stream.write(v)
    stream.flush()


def receive(stream):
    """The next message, or None at the end of the stream."""
    head = _read(stream, 2 * _HEADER.size)
    if head is None:
        return None
    size, count = _HEADER.unpack(head[:_HEADER.size])[0], _HEADER.unpack(head[_HEADER.size:])[0]
    sizes = _read(stream, count * _HEADER.size) if count else b""
    if sizes is None:
        return None
    data = _read(stream, size)
    if data is None:
        return None
    buffers = []
    for i in range(count):
        buf = _read(stream, _HEADER.unpack_from(sizes, i * _HEADER.size)[0])
        if buf is None:
            return None
        buffers.append(buf)
    return pickle.loads(data, buffers=buffers)


def _read(stream, n):
    """``n`` bytes of ``stream`` in one writable buffer (an array unpickled from it uses it as it
    is), or None at the end of the stream."""
    out = bytearray(n)
    view, got = memoryview(out), 0
    while got < n:
        k = stream.readinto(view[got:])
        if not k:
            return None
        got += k
    return out


def error_of(name, message):
    """The core's exception class ``name`` (a worker's error) with its message."""
    cls = getattr(errors_mod, name, None)
    if isinstance(cls, type) and issubclass(cls, Exception):
        return cls(message)
    builtin = {"MemoryError": MemoryError, "ValueError": ValueError, "TypeError": TypeError}.get(name)
    if builtin is not None:
        return builtin(message)
    return BakeWorkerError(f"a worker process failed: {name}: {message}")


def sum_counters(parts):
    """The start stages' counters of several processes, added up (texts: the first given; a bake of
    several quantities has each quantity's counters under its name, added up the same way)."""
    counters = {}
    for p in parts:
        _add_counters(counters, p["counters"])
    return counters


def _add_counters(into, counters):
    for k, v in counters.items():
        if isinstance(v, dict):
            _add_counters(into.setdefault(k, {}), v)
        elif isinstance(v, (int, float)) and k != "directions_per_point":
            into[k] = into.get(k, 0) + v
        elif into.get(k) is None:
            into[k] = v


__all__ = ["BakeWorkerError", "send", "receive", "error_of", "sum_counters"]
