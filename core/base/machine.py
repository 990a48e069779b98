"""The machine a bake runs on: its cores and its memory (no numpy: the add-on asks before loading the core).

One place for each: :func:`cpu_count` (the cores this process may use), :func:`available_memory`
(what a new allocation may take), :func:`memory_limit` (that, or less where a container's cgroup
says so), :func:`process_memory` and :func:`reset_peak` (this process's resident and peak bytes).
"""

import os
import sys


def cpu_count():
    """The cores this process may run on (its affinity where the OS has one, else every core)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def available_memory():
    """Bytes of memory available to a new allocation (MemAvailable on Linux), or None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def memory_limit():
    """Bytes of memory this process may still use: the smaller of the machine's available memory and
    what its container (cgroup v2 or v1) has left; None if neither is known."""
    limits = [available_memory()]
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            with open(limit_file) as f:
                text = f.read().strip()
            if text == "max":
                continue
            with open(usage_file) as f:
                limits.append(int(text) - int(f.read().strip()))
        except (OSError, ValueError):
            continue
    known = [x for x in limits if x is not None]
    return min(known) if known else None


def process_memory():
    """(resident bytes now, peak resident bytes) of this process: VmRSS and VmHWM from
    /proc/self/status (Linux); elsewhere (None, the peak from getrusage where there is one)."""
    now = peak = None
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    now = int(line.split()[1]) * 1024
                elif line.startswith("VmHWM:"):
                    peak = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if peak is None:
        try:
            import resource

            # ru_maxrss: bytes on macOS, KiB elsewhere.
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * (1 if sys.platform == "darwin" else 1024)
        except (ImportError, OSError, AttributeError):
            pass
    return now, peak


def reset_peak():
    """Start this process's peak (VmHWM) afresh, where Linux allows it (writing 5 to
    /proc/self/clear_refs); a worker does it before each bake, so its peak is that bake's."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


__all__ = ["cpu_count", "available_memory", "memory_limit", "process_memory", "reset_peak"]
