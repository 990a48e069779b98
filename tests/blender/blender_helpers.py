"""Scene builders and image readers for the Blender tests (a module of its own: a name no other test folder uses)."""

import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


# The first bytes of each kind of file a bake writes: a test's "previous file" must be of the kind its
# name says, or the bake refuses to replace it (mc_ao.filecheck.replace_problem).
MAGIC = {".png": b"\x89PNG\r\n\x1a\n", ".exr": b"\x76\x2f\x31\x01", ".tif": b"II*\x00", ".ply": b"ply\n"}


def old_file(name, text):
    """The bytes of an old file at ``name`` that a bake may replace: its kind's magic, then ``text``."""
    return MAGIC.get(Path(str(name)).suffix, b"") + (text.encode() if isinstance(text, str) else text)


def clean_scene(bpy):
    """Remove every object, mesh and image, and reset the scene's bake settings."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    for collection in (bpy.data.meshes, bpy.data.images, bpy.data.materials):
        for block in list(collection):
            collection.remove(block)
    scene = bpy.context.scene
    bpy.context.view_layer.update()
    if hasattr(scene, "mc_ao"):
        for name in scene.mc_ao.bl_rna.properties.keys():
            if name not in {"rna_type", "name"}:
                scene.mc_ao.property_unset(name)
    # The worlds' AO distance, which Cycles' AO bake reads, set by tests that run Cycles: one test's
    # Cycles reference must not leak into the next test's (a factory scene has no world).
    scene.world = None
    for world in list(bpy.data.worlds):
        bpy.data.worlds.remove(world)
    return scene


def add_plane(bpy, name="Plane", size=4.0, location=(0, 0, 0), rotation=(0, 0, 0)):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    return obj


def add_cube(bpy, name="Cube", size=2.0, location=(0, 0, 0)):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    return obj


def run_bake(bpy, capfd):
    """bpy.ops.object.mc_ao_bake() as a script calls it: (result, the error message or None, what it
    printed: its reports)."""
    capfd.readouterr()
    result = error = None
    try:
        result = bpy.ops.object.mc_ao_bake()
    except RuntimeError as exc:
        error = str(exc)
    out, _ = capfd.readouterr()
    return result, error, out


def select_only(bpy, *objects):
    for obj in bpy.context.view_layer.objects:
        if obj is not None:
            obj.select_set(obj in objects)
    bpy.context.view_layer.objects.active = objects[0] if objects else None


def image_ao(image):
    """The R channel of an image as (H, W) float32 (what the bake wrote as AO), and the alpha."""
    w, h = image.size
    px = np.empty(w * h * 4, dtype=np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, 4)
    return px[..., 0], px[..., 3]


# -- images and bake sessions, as the modal operator drives them ---------------------------------

def pattern_image(bpy, name, width, height, float_buffer=False, is_data=False):
    """An image with recognisable pixels (what a user's previous bake or painting would be)."""
    from mc_ao import images

    image = bpy.data.images.new(name, width, height, alpha=True, float_buffer=float_buffer, is_data=is_data)
    pattern = np.random.default_rng(len(name)).random((height, width, 4), dtype=np.float32)
    pattern = np.round(pattern * 255) / 255  # exact in an 8-bit image too
    images.set_pixels(image, pattern)
    return images.pixels_of(image)


def assert_unchanged(bpy, name, pixels):
    from mc_ao import images

    image = bpy.data.images.get(name)
    assert image is not None, f"image {name} is gone"
    assert tuple(image.size) == (pixels.shape[1], pixels.shape[0])
    np.testing.assert_array_equal(images.pixels_of(image), pixels)


def new_session():
    """A BakeSession reporting into a list, as the operator's self.report would."""
    from mc_ao import operators

    reports = []
    session = operators.BakeSession(lambda kind, message: reports.append((next(iter(kind)), message)))
    return session, reports


def tick_until(bpy, session, done, timeout=30.0):
    """Send timer events until done() or the session ends; return the last event's result."""
    deadline = time.monotonic() + timeout
    while True:
        result = session.on_event(bpy.context, "TIMER")
        if done() or result != {"PASS_THROUGH"}:
            return result
        assert time.monotonic() < deadline, "the bake did not get there in time"
        time.sleep(0.005)
