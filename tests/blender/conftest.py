"""Shared setup of the Blender tests: one bpy session with its own user folders.

bpy keeps one Blender session per process, so the tests share it: each test starts from
``blender_helpers.clean_scene()``, and the checkout's add-on is registered by the ``addon`` fixture
only where a test module asks for it (the installed extension registers the same class names).
"""

import os
import shutil
import sys
import tempfile
import threading
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# Blender reads these when bpy is first imported: keep its user preferences, extensions and their
# wheels out of the real home folder.
_USER_DIR = tempfile.mkdtemp(prefix="mc_ao_blender_user_")
os.environ["BLENDER_USER_RESOURCES"] = _USER_DIR


_SESSION = {}


def pytest_sessionfinish(session, exitstatus):
    _SESSION["status"] = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    shutil.rmtree(_USER_DIR, ignore_errors=True)
    bpy = sys.modules.get("bpy")
    if bpy is not None and tuple(bpy.app.version[:2]) == (4, 2) and "status" in _SESSION:
        # The bpy 4.2 module can crash in its own exit handler once Python has finalised (SIGSEGV,
        # status 139, after every test passed; 5.0 does not): end the process with pytest's own
        # status instead, everything written and flushed.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_SESSION["status"])


@pytest.fixture(scope="session")
def bpy():
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy


@pytest.fixture(scope="module")
def addon(bpy):
    """The add-on registered from the checkout (top-level ``mc_ao`` and ``core``), for one test module."""
    import mc_ao

    mc_ao.register()
    yield mc_ao
    mc_ao.unregister()


@pytest.fixture
def scene(bpy, addon):
    """A clean scene with small, fast bake settings (24 x 24, 16 samples, margin 2, 2 threads)."""
    from blender_helpers import clean_scene

    if bpy.data.filepath:
        # An earlier test saved or opened a .blend file: start from an unsaved one, as each test
        # expects (a relative output folder, for one, needs a saved file). The add-on's classes and
        # its scene.mc_ao stay registered across the new file.
        bpy.ops.wm.read_homefile(use_empty=True)
    scene = clean_scene(bpy)
    settings = scene.mc_ao
    settings.resolution = 24
    settings.samples = 16
    settings.margin = 2
    settings.threads = 2
    return scene


@pytest.fixture
def hold_bake(monkeypatch):
    """core.bake (the add-on's one core call) that, after the first finished tile of the named objects,
    waits until cancelled.

    A bake caught in the middle, deterministically: the live image already has tiles in it, the bake
    has not finished, and only Esc (or an undo) lets the worker go on, into core's cancellation.
    Returns hold(*object_names) -> threading.Event set once the bake is held.
    """
    import core

    real = core.bake

    def hold(*names):
        held = threading.Event()

        def bake(target, *args, on_tile=None, cancel=None, **kwargs):
            def tile(*tile_args):
                if on_tile is not None:
                    on_tile(*tile_args)
                if target.name in names:
                    held.set()
                    cancel.wait(30)

            return real(target, *args, on_tile=tile, cancel=cancel, **kwargs)

        monkeypatch.setattr(core, "bake", bake)
        return held

    return hold
