"""Ctrl-C and SIGTERM, for the script: held off while one object's files are written, so that a cancel
leaves each object with all its new files or none of them, and SIGTERM ending a run as Ctrl-C does (the
summary written, what was saved said). No bpy.

A KeyboardInterrupt raised between two of an object's files (its PNG replaced, its EXR not) would
leave a mix of two bakes that no message could describe simply; :func:`held_off` lets the writes of
the object in hand finish (they are quick next to a bake) and raises the interrupt right after.
"""

import contextlib
import signal
import threading

__all__ = ["held_off", "Terminated", "sigterm_interrupts"]


class Terminated(KeyboardInterrupt):
    """SIGTERM reached the script (a farm's job cancelled, ``kill``, a batch stopping): it stops as a
    Ctrl-C stops it, and says which it was."""


def _ours(signum, default):
    """Whether Python may take ``signum`` here: the main thread, and its handler the default one
    (``default``) or one set outside Python (None: Blender's own)."""
    if threading.current_thread() is not threading.main_thread():
        return False
    handler = signal.getsignal(signum)
    return handler is default or handler is None


def _raise_terminated(*_):
    raise Terminated


@contextlib.contextmanager
def sigterm_interrupts():
    """Run the block with SIGTERM raising :class:`Terminated` (a KeyboardInterrupt) in the main thread,
    where SIGTERM's handler is the default one (or Blender's); the handler before it comes back after."""
    if not hasattr(signal, "SIGTERM") or not _ours(signal.SIGTERM, signal.SIG_DFL):
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous if previous is not None else signal.SIG_DFL)


@contextlib.contextmanager
def held_off():
    """Run the block with SIGINT (and a SIGTERM that :func:`sigterm_interrupts` takes) deferred: one
    arriving during it raises KeyboardInterrupt (or :class:`Terminated`) when it ends.

    Outside the main thread (where Python cannot set signal handlers), or where SIGINT is not
    Python's to handle (ignored, or a handler other than the default one), the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread() \
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    caught = []
    previous = signal.signal(signal.SIGINT, lambda *_: caught.append(KeyboardInterrupt))
    term = getattr(signal, "SIGTERM", None)
    previous_term = None
    if term is not None and signal.getsignal(term) is _raise_terminated:
        previous_term = signal.signal(term, lambda *_: caught.append(Terminated))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if previous_term is not None:
            signal.signal(term, previous_term)
    if caught:
        raise caught[-1] if Terminated not in caught else Terminated
