"""mc_ao_batch.lifeline: a process ends when the process that started it is gone, also when that one
is killed with SIGKILL: the batch's guard and its bake, by the kernel's parent-death signal (Linux)
and by the watching thread (every system).

Nothing waits on a clock for the answer: each process says when it is ready on a pipe, and the test
waits (at most a minute) for the orphan to be gone.
"""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
GUARD = ROOT / "mc_ao_batch" / "guard.py"

pytestmark = pytest.mark.skipif(os.name == "nt", reason="signals and /proc: POSIX")

# A bake stand-in: says its pid, then waits for ever (its stdin is /dev/null: it cannot read EOF).
SLEEPER = "import os, signal; print(os.getpid(), flush=True); signal.pause()"


def gone(pid):
    """True once ``pid`` has exited (a zombie that nobody reaps counts as exited)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            state = f.read().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return True
    return state in ("Z", "X")


def wait_gone(pid, limit=60.0):
    deadline = time.monotonic() + limit
    while not gone(pid):
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            return False
        time.sleep(0.02)
    return True


def test_a_killed_guard_takes_its_bake_with_it():
    guard = subprocess.Popen([sys.executable, str(GUARD), "--", sys.executable, "-c", SLEEPER],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        bake = int(guard.stdout.readline())
        guard.kill()  # SIGKILL: the guard's own handlers never run
        guard.wait()
        assert wait_gone(bake), "the bake outlived its guard"
    finally:
        if guard.poll() is None:
            guard.kill()


@pytest.mark.parametrize("how", ["hold_on", "watch_parent"])
def test_a_child_holding_on_ends_when_its_parent_is_killed(how):
    """The parent starts a child that holds on to it (the kernel's signal or the watching thread alone,
    as on macOS and Windows), then is killed."""
    child = textwrap.dedent(f"""
        import os, signal, sys
        sys.path.insert(0, {str(ROOT)!r})
        from mc_ao_batch import lifeline
        lifeline.{how}(os.getppid())
        print(os.getpid(), flush=True)
        signal.pause()
    """)
    parent = textwrap.dedent(f"""
        import signal, subprocess, sys
        subprocess.Popen([sys.executable, "-c", {child!r}], stdin=subprocess.DEVNULL)
        signal.pause()
    """)
    proc = subprocess.Popen([sys.executable, "-c", parent], stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        pid = int(proc.stdout.readline())
        proc.kill()
        proc.wait()
        assert wait_gone(pid), "the child outlived its parent"
    finally:
        if proc.poll() is None:
            proc.kill()


def test_a_child_whose_named_parent_is_already_gone_ends_at_once(tmp_path):
    code = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(ROOT)!r})
        from mc_ao_batch import lifeline
        lifeline.from_environment()
        print("still here")
    """)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    env = dict(os.environ, MC_AO_PARENT_PID=str(dead.pid))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 137 and "still here" not in proc.stdout
    # a process that inherited the variable from a grandparent that is alive holds on to nothing
    env = dict(os.environ, MC_AO_PARENT_PID=str(os.getpid()))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "still here" in proc.stdout


def test_importing_needs_nothing_but_the_standard_library():
    code = ("import sys; sys.path.insert(0, 'mc_ao_batch'); import lifeline; "
            "assert not {'bpy', 'numpy', 'core', 'mc_ao'} & set(sys.modules)")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
