"""The process a batch task runs in: it starts the bake and ends it when whoever started the task is gone.

    python guard.py -- COMMAND [ARGS...]

A runner starts this with a pipe on its standard input and keeps the pipe's other end open while it
waits. When the runner's process dies (a Dask worker killed, a runner interrupted), the operating
system closes that end; this process reads end-of-file and kills the bake at once, so no orphaned
bake keeps running beside the retried one. A runner that wants to stop a task closes the pipe. Also
SIGTERM, SIGINT and SIGHUP end the bake before this process exits, and when this process itself is
killed (SIGKILL, which nothing can catch) the bake ends too (mc_ao_batch.lifeline). The exit status
is the bake's, or 128 + N when signal N ended it (as a shell reports it). Standard library only: it
runs wherever the batch does.
"""

import os
import signal
import subprocess
import sys
import threading

if __package__:
    from . import lifeline
else:  # run as a script: this folder is on sys.path
    import lifeline


def main(argv):
    if argv[:1] == ["--"]:
        argv = argv[1:]
    if not argv:
        print("guard.py: usage: guard.py -- COMMAND [ARGS...]", file=sys.stderr)
        return 2
    try:
        # The bake ends with this process however it ends (also SIGKILL): the parent-death signal on
        # Linux, elsewhere the bake watches this process (mc_ao_batch.lifeline).
        child = subprocess.Popen(argv, stdin=subprocess.DEVNULL, **lifeline.child_options())
    except OSError as exc:
        print(f"bake_batch: cannot start {argv[0]!r}: {exc.strerror or exc}", file=sys.stderr)
        return 127

    def stop(*_):
        try:
            child.kill()
        except OSError:
            pass

    def watch_parent():
        try:
            while sys.stdin.buffer.read(4096):
                pass
        except (OSError, ValueError):
            pass
        stop()  # end of file: the runner is gone, or asks us to stop

    for name in ("SIGTERM", "SIGINT", "SIGHUP"):  # no SIGHUP on Windows
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), stop)
    threading.Thread(target=watch_parent, name="guard", daemon=True).start()
    code = child.wait()
    return code if code >= 0 else 128 - code


if __name__ == "__main__":
    status = main(sys.argv[1:])
    sys.stdout.flush()
    sys.stderr.flush()
    # os._exit: the watcher thread is blocked reading stdin, which a normal interpreter shutdown
    # would wait on (and abort over)
    os._exit(status)
