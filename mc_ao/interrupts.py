"""Ctrl-C held off while one object's files are written, so that a cancel leaves each object with all
its new files or none of them. No bpy.

A KeyboardInterrupt raised between two of an object's files (its PNG replaced, its EXR not) would
leave a mix of two bakes that no message could describe simply; :func:`held_off` lets the writes of
the object in hand finish (they are quick next to a bake) and raises the interrupt right after.
"""

import contextlib
import signal
import threading

__all__ = ["held_off"]


@contextlib.contextmanager
def held_off():
    """Run the block with SIGINT deferred: a Ctrl-C during it raises KeyboardInterrupt when it ends.

    Outside the main thread (where Python cannot set signal handlers), or where SIGINT is not
    Python's to handle (ignored, or a handler other than the default one), the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    caught = []
    previous = signal.signal(signal.SIGINT, lambda *_: caught.append(True))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt
