"""Baking ten objects in a row keeps memory bounded: the process grows by the images it keeps, no more.

Measured as the resident set (VmRSS) and its peak (VmHWM) from /proc/self/status, after each of ten
bakes of distinct objects into ten new (packed) images, called as the UI calls the operator (with an undo
push, which also makes Blender keep the operator, and with it its BakeSession, in its history).
"""

import ctypes
import gc
import os

import pytest

from blender_helpers import clean_scene, select_only

pytestmark = pytest.mark.blender

SIZE = 512  # image side: an image (4 MiB) stands well out of the allocator's noise
BAKES = 10
WARM_UP = 2  # bakes before the baseline: the first ones load the core, Embree, thread arenas
# What Blender keeps of each new image: its RGBA float pixels, and the same again packed (an
# uncompressed float OpenEXR, which the .blend file and the undo steps take their copy from).
IMAGE_MIB = 2 * SIZE * SIZE * 4 * 4 / 2**20
SLACK_IMAGES = 3  # allowed beyond the kept images: the allocator's noise measured here is about 2


def fixed_mmap_threshold():
    """Make glibc's malloc serve every block of 128 KiB or more by mmap, and so return it when freed.

    By default the threshold rises after the first large block is freed (up to 32 MiB), and later
    arrays of a few MiB then come from the heap, where freed ones stay resident in pieces: RSS would
    swing by several MiB from one bake to the next without anything being held. What is still
    referenced stays resident either way, so this takes noise out of the measurement, not leaks.
    """
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 128 * 1024)  # M_MMAP_THRESHOLD; setting it turns the dynamic threshold off
    except (OSError, AttributeError):
        pass


def memory_mib():
    """{"VmRSS": MiB, "VmHWM": MiB} after a garbage collection and handing freed heap back to the OS."""
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)  # so that RSS shows what is held, not what is cached
    except (OSError, AttributeError):
        pass
    values = {}
    with open("/proc/self/status") as fh:
        for line in fh:
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                values[key] = int(value.split()[0]) / 1024
    return values


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads /proc/self/status (Linux)")
def test_ten_bakes_in_a_row_keep_memory_bounded(bpy, addon):
    from mc_ao.extract import MeshArrays

    scene = clean_scene(bpy)
    settings = scene.mc_ao
    settings.resolution = SIZE
    settings.samples = 1
    settings.threads = 1
    settings.margin = 2
    settings.occluders = "SELECTED"
    cubes = []  # a cube bakes in milliseconds (its UV islands are small): the images dominate
    for k in range(BAKES):
        bpy.ops.mesh.primitive_cube_add(location=(3 * k, 0, 0))
        cubes.append(bpy.context.active_object.name)
    bpy.ops.ed.undo_push(message="ten cubes")
    fixed_mmap_threshold()

    samples = []
    for name in cubes:
        select_only(bpy, bpy.data.objects[name])
        assert bpy.ops.object.mc_ao_bake("EXEC_DEFAULT", True) == {"FINISHED"}
        samples.append(memory_mib())
    assert len([i for i in bpy.data.images if i.name.endswith("_AO")]) == BAKES

    rss = [s["VmRSS"] for s in samples]
    hwm = [s["VmHWM"] for s in samples]
    kept = (BAKES - WARM_UP) * IMAGE_MIB
    bound = kept + SLACK_IMAGES * IMAGE_MIB
    growth_rss = rss[-1] - rss[WARM_UP - 1]
    growth_hwm = hwm[-1] - hwm[WARM_UP - 1]
    numbers = (
        f"VmRSS after each bake (MiB): {', '.join(f'{v:.1f}' for v in rss)}; "
        f"VmHWM: {', '.join(f'{v:.1f}' for v in hwm)}; growth over bakes {WARM_UP + 1}-{BAKES}: "
        f"RSS {growth_rss:.1f} MiB, peak {growth_hwm:.1f} MiB, for {BAKES - WARM_UP} new images of "
        f"{IMAGE_MIB:.1f} MiB ({kept:.1f} MiB); bound {bound:.1f} MiB"
    )
    print(numbers)
    assert growth_rss < bound, numbers
    assert growth_hwm < bound, numbers

    # Blender keeps the registered operators for its history, and each holds its BakeSession: the
    # sessions must not hold on to the bakes' geometry (or images' old pixels) once finished.
    assert len(bpy.context.window_manager.operators) > 0
    gc.collect()
    assert not [o for o in gc.get_objects() if isinstance(o, MeshArrays)]
