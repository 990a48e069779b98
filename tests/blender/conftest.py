"""Shared setup of the Blender tests: one bpy session with its own user folders.

bpy keeps one Blender session per process, so the tests share it: each test starts from
``blender_helpers.clean_scene()``, and the checkout's add-on is registered by the ``addon`` fixture
only where a test module asks for it (the installed extension registers the same class names).
"""

import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# Blender reads these when bpy is first imported: keep its user preferences, extensions and their
# wheels out of the real home folder.
_USER_DIR = tempfile.mkdtemp(prefix="mc_ao_blender_user_")
os.environ["BLENDER_USER_RESOURCES"] = _USER_DIR


def pytest_unconfigure(config):
    shutil.rmtree(_USER_DIR, ignore_errors=True)


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

    scene = clean_scene(bpy)
    settings = scene.mc_ao
    settings.resolution = 24
    settings.samples = 16
    settings.margin = 2
    settings.threads = 2
    return scene
