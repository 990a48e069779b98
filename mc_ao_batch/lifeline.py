"""End a process when the process that started it is gone: standard library only, no bpy, no imports
from this package, so any process can use it (a batch task's bake, a bake's worker processes).

Linux has the kernel do it: :func:`die_with_parent` sets ``PR_SET_PDEATHSIG`` (``prctl`` through
ctypes), and the kernel sends the signal when the parent dies, however it dies (also SIGKILL).
Elsewhere (macOS, Windows) :func:`watch_parent` runs a daemon thread that waits on the parent
(Windows: a process handle; POSIX: polling ``getppid()``, which changes once the parent is gone) and
ends this process at once. :func:`hold_on` does whichever this system has.

A parent hands the arrangement to a child it starts in two ways, both made by :func:`child_options`:
on Linux, ``preexec_fn`` sets the signal in the child before it runs anything (no window in which the
parent's death goes unnoticed); everywhere, the environment variable ``MC_AO_PARENT_PID`` names the
parent, so that a child that calls :func:`from_environment` early (scripts/bake_ao.py does) holds on
to it by either means.
"""

import os
import signal
import sys
import threading

__all__ = ["ENV", "die_with_parent", "watch_parent", "hold_on", "child_options", "from_environment"]

#: The environment variable naming the process a child must not outlive.
ENV = "MC_AO_PARENT_PID"
_PR_SET_PDEATHSIG = 1
_GONE_STATUS = 128 + 9  # as if killed (SIGKILL), the status the Linux way gives


def die_with_parent(parent_pid=None, sig=signal.SIGKILL if hasattr(signal, "SIGKILL") else None):
    """Have the kernel send ``sig`` to this process when its parent dies (Linux). True when set.

    ``parent_pid``: the parent this process expects; when the parent is already another one (the
    expected one died before this call), the process ends here. Safe in ``preexec_fn``. False, and
    nothing done, where the system has no ``prctl`` (then use :func:`watch_parent`).
    """
    if not sys.platform.startswith("linux") or sig is None:
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    if parent_pid is not None and os.getppid() != parent_pid:
        os._exit(_GONE_STATUS)  # the parent died before the signal was set: it will never come
    return True


def _wait_windows(pid):
    """Block until process ``pid`` ends (Windows); False when it cannot be waited on."""
    import ctypes

    synchronize, infinite = 0x00100000, 0xFFFFFFFF
    kernel32 = ctypes.windll.kernel32
    handle = kernel32.OpenProcess(synchronize, False, pid)
    if not handle:
        return True  # no such process any more
    try:
        kernel32.WaitForSingleObject(handle, infinite)
    finally:
        kernel32.CloseHandle(handle)
    return True


def watch_parent(parent_pid, on_gone=None, interval=0.5):
    """Start a daemon thread that calls ``on_gone()`` once process ``parent_pid`` is gone.

    ``on_gone`` defaults to ending this process at once (``os._exit``: no cleanup runs, so nothing is
    written after the parent is gone). POSIX: the thread checks every ``interval`` seconds whether
    ``getppid()`` is still ``parent_pid``; Windows: it waits on the parent's process handle. Returns
    the thread.
    """
    if on_gone is None:
        def on_gone():
            os._exit(_GONE_STATUS)

    stop = threading.Event()

    def watch():
        if os.name == "nt":
            _wait_windows(parent_pid)
        else:
            while os.getppid() == parent_pid:
                if stop.wait(interval):
                    return
        on_gone()

    thread = threading.Thread(target=watch, name="mc_ao lifeline", daemon=True)
    thread.stop = stop
    thread.start()
    return thread


def hold_on(parent_pid):
    """End this process when ``parent_pid`` (its parent) is gone, by the best means here: the kernel's
    parent-death signal on Linux, else a watching thread. Returns "signal" or "watch"."""
    if die_with_parent(parent_pid):
        return "signal"
    watch_parent(parent_pid)
    return "watch"


def child_options(env=None):
    """``subprocess.Popen`` keyword arguments for a child that must not outlive this process:
    ``preexec_fn`` (Linux) and ``env`` with :data:`ENV` set to this process's id."""
    me = os.getpid()
    options = {"env": dict(os.environ if env is None else env, **{ENV: str(me)})}
    if sys.platform.startswith("linux"):
        options["preexec_fn"] = lambda: die_with_parent(me) and None
    return options


def from_environment():
    """Hold on to the parent that :data:`ENV` names, if it is set and is this process's parent.

    Returns "signal", "watch", or None (no such variable, or it names another live process: a
    grandchild that inherited the variable holds on to nothing). Ends this process when the named
    parent is already gone (POSIX).
    """
    try:
        parent = int(os.environ.get(ENV, ""))
    except ValueError:
        return None
    if parent != os.getppid():
        if os.name != "nt" and not _alive(parent):
            os._exit(_GONE_STATUS)  # the parent died before this process got here
        return None
    return hold_on(parent)


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # another user's process: it exists
    return True
