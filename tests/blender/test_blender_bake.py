"""The Bake AO operator on generated scenes, against core.bake_ao and against predictions."""

import math

import numpy as np
import pytest

from blender_helpers import add_cube, add_plane, image_ao, select_only

pytestmark = pytest.mark.blender


def world_arrays(bpy, obj, with_uvs):
    """The evaluated mesh of ``obj`` in world space, read corner by corner (independently of mc_ao.extract)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        m = np.array(ev.matrix_world)
        positions = np.array([v.co[:] for v in mesh.vertices]) @ m[:3, :3].T + m[:3, 3]
        triangles = np.array([t.vertices[:] for t in mesh.loop_triangles])
        if not with_uvs:
            return dict(positions=positions, triangles=triangles, name=obj.name)
        corners = np.array([t.loops[:] for t in mesh.loop_triangles])
        uv_layer = next(layer for layer in mesh.uv_layers if layer.active_render)
        uvs = np.array([d.uv[:] for d in uv_layer.data])[corners]
        normals = np.array([n.vector[:] for n in mesh.corner_normals]) @ np.linalg.inv(m[:3, :3])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        return dict(positions=positions, triangles=triangles, uvs=uvs, normals=normals[corners], name=obj.name)
    finally:
        ev.to_mesh_clear()


def bake(bpy, *objects):
    select_only(bpy, *objects)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    return [image_ao(bpy.data.images[f"{obj.name}_AO"])[0] for obj in objects]


def texel(settings, x, y, size=4.0):
    """Texel (row, col) over world (x, y) of an untransformed plane of ``size`` centred at the origin."""
    n = settings.resolution
    return int((y / size + 0.5) * n), int((x / size + 0.5) * n)


# -- the image is core.bake_ao of the scene's evaluated, transformed geometry ----------------------

def test_operator_image_equals_core_bake_of_the_same_arrays(bpy, scene):
    import core

    ground = add_plane(bpy, "Ground", size=4, location=(0.3, -0.2, 0.1), rotation=(0.1, 0, 0.4))
    ground.scale = (1.2, 0.9, 1.0)
    sub = ground.modifiers.new("Subdivide", "SUBSURF")
    sub.subdivision_type, sub.levels = "SIMPLE", 1
    block = add_cube(bpy, "Block", size=1.5, location=(0.2, 0.1, 1.0))
    block.rotation_euler = (0.2, 0.3, 0.5)
    block.modifiers.new("Bevel", "BEVEL").width = 0.1
    scene.mc_ao.seed = 7

    (ao,) = bake(bpy, ground)
    image = bpy.data.images["Ground_AO"]
    assert tuple(image.size) == (24, 24) and image.is_float
    assert image.colorspace_settings.name == "Non-Color"
    target = world_arrays(bpy, ground, with_uvs=True)
    assert len(target["triangles"]) == 8  # the modifier's 4 quads, not the plane's 1
    expected = core.bake_ao(
        core.Mesh(**target), occluders=[core.Mesh(**world_arrays(bpy, block, with_uvs=False))],
        resolution=(24, 24), samples=16, min_samples=16, target_error=0.0, max_distance=math.inf,
        distribution="cosine", source="sobol", margin=2, seed=7, threads=2,
        replicates=1,  # the add-on's choice without an error map or adaptive sampling
    )
    np.testing.assert_array_equal(ao, expected.ao)
    assert ao.min() < 0.5 < ao.max()  # the block does shade the ground
    _, alpha = image_ao(image)
    assert np.all(alpha == 1.0)


def test_moving_the_occluder_moves_its_shadow(bpy, scene):
    """Only the occluder's object location changes: the AO moves by as many texels.

    The ground does not occlude itself, so its AO is translation invariant: moving the block by
    1 unit (8 texels here) moves the whole map by 8 texels, up to sampling noise.
    """
    settings = scene.mc_ao
    settings.resolution = 32
    settings.samples = 64
    ground = add_plane(bpy, "Ground", size=4)
    block = add_cube(bpy, "Block", size=1.0, location=(-0.5, 0.2, 0.7))

    (before,) = bake(bpy, ground)
    block.location.x = 0.5
    (after,) = bake(bpy, ground)
    shifted = np.abs(after[:, 8:] - before[:, :-8]).mean()
    unshifted = np.abs(after[:, 8:] - before[:, 8:]).mean()
    assert shifted < 0.03 and unshifted > 4 * shifted
    assert np.argmin(after.mean(axis=0)) - np.argmin(before.mean(axis=0)) in (7, 8, 9)


def test_occluder_modifiers_are_applied(bpy, scene):
    """An Array modifier's copy of the block shades the ground where no object stands."""
    scene.mc_ao.samples = 64
    ground = add_plane(bpy, "Ground", size=4)
    block = add_cube(bpy, "Block", size=0.6, location=(-1.0, 0, 0.4))
    array = block.modifiers.new("Array", "ARRAY")
    array.relative_offset_displace = (3.0, 0.0, 0.0)  # the copy stands at x = -1.0 + 3 * 0.6 = 0.8
    under_copy = texel(scene.mc_ao, 0.8, 0.0)
    under_block = texel(scene.mc_ao, -1.0, 0.0)

    (with_copy,) = bake(bpy, ground)
    array.show_viewport = False
    (without,) = bake(bpy, ground)
    assert with_copy[under_copy] < 0.5 and with_copy[under_block] < 0.5
    assert without[under_copy] > 0.9 and without[under_block] < 0.5


def test_target_modifiers_and_rotation_are_applied(bpy, scene):
    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=2.0, location=(0, 0, 2.0))  # its bottom at z = 1
    centre = texel(scene.mc_ao, 0.0, 0.0)

    (flat,) = bake(bpy, ground)
    displace = ground.modifiers.new("Lift", "DISPLACE")
    displace.mid_level, displace.strength = 0.0, 0.9  # the whole plane rises to z = 0.9
    (lifted,) = bake(bpy, ground)
    assert lifted[centre] < 0.05 < flat[centre] - 0.1

    # Turned upside down the ground faces away from the block: nothing occludes it.
    ground.modifiers.remove(displace)
    ground.rotation_euler.x = math.pi
    (turned,) = bake(bpy, ground)
    assert turned.min() == 1.0


def test_mirrored_objects_bake_like_unmirrored_ones(bpy, scene):
    """A negative scale reverses the winding; faces must still face where their normals point.

    That matters with Ignore Backfaces: the roof faces down at the ground, and mirrored it must
    still shade it rather than let every ray through its back.
    """
    scene.mc_ao.samples = 64
    scene.mc_ao.ignore_backfaces = True
    ground = add_plane(bpy, "Ground", size=4)
    roof = add_plane(bpy, "Roof", size=1.5, location=(0, 0, 0.8), rotation=(math.pi, 0, 0))
    (plain,) = bake(bpy, ground)
    assert plain.min() < 0.5
    ground.scale.x = roof.scale.x = -1.0
    (mirrored,) = bake(bpy, ground)
    assert np.abs(mirrored - plain).mean() < 0.03
    assert np.abs(mirrored - plain[:, ::-1]).mean() < 0.03


# -- images ---------------------------------------------------------------------------------------

def test_existing_image_is_reused_and_8_bit_on_request(bpy, scene):
    ground = add_plane(bpy, "Ground", size=4)
    old = bpy.data.images.new("Ground_AO", 8, 8)
    pointer = old.as_pointer()
    scene.mc_ao.float_buffer = False
    bake(bpy, ground)
    image = bpy.data.images["Ground_AO"]
    assert image.as_pointer() == pointer and len(bpy.data.images) == 1
    assert tuple(image.size) == (24, 24) and not image.is_float
    assert image.colorspace_settings.name == "Non-Color"


def test_image_name_setting_and_one_image_per_object(bpy, scene):
    ground = add_plane(bpy, "Ground", size=4)
    block = add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    scene.mc_ao.image_name = "AO_{object}"
    select_only(bpy, ground, block)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    assert {"AO_Ground", "AO_Block"} <= set(bpy.data.images.keys())

    scene.mc_ao.image_name = "AO"
    with pytest.raises(RuntimeError, match=r"Block and Ground would both bake into image 'AO'"):
        bpy.ops.object.mc_ao_bake()


def test_save_to_file(bpy, scene, tmp_path):
    from core.files import imageio

    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    settings = scene.mc_ao
    settings.save_to_file = True
    settings.output_dir = str(tmp_path)
    settings.file_format = "OPEN_EXR"
    (ao,) = bake(bpy, ground)
    pixels, metadata = imageio.read_image(tmp_path / "Ground_AO.exr")
    np.testing.assert_array_equal(np.squeeze(pixels), ao)  # float image -> float EXR
    assert metadata["object"] == "Ground"


def test_relative_output_folder_needs_a_saved_file(bpy, scene):
    ground = add_plane(bpy, "Ground", size=4)
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = "//textures/"
    select_only(bpy, ground)
    with pytest.raises(RuntimeError, match="not saved yet"):
        bpy.ops.object.mc_ao_bake()
    assert "Ground_AO" not in bpy.data.images


def test_snapshot_restores_a_reused_image_and_removes_a_created_one(bpy, scene):
    from mc_ao import images

    old = bpy.data.images.new("Old", 4, 2, alpha=True)
    pattern = np.linspace(0, 1, 4 * 2 * 4, dtype=np.float32).reshape(2, 4, 4)
    images.set_pixels(old, pattern)
    image, snapshot = images.prepare_image("Old", 8, 8, True)
    images.set_pixels(image, np.zeros((8, 8, 4), np.float32))
    snapshot.restore()
    assert tuple(old.size) == (4, 2) and not old.is_float
    np.testing.assert_allclose(images.pixels_of(old), pattern, atol=1 / 255)

    _, created = images.prepare_image("New", 8, 8, True)
    created.restore()
    assert "New" not in bpy.data.images


# -- errors are reports naming the object, never tracebacks -----------------------------------------

def test_poll_says_why_nothing_can_be_baked(bpy, scene):
    from mc_ao import baking

    select_only(bpy)
    assert not bpy.ops.object.mc_ao_bake.poll()
    assert baking.why_not_bakeable([]) == "Nothing is selected: select a mesh object with a UV map"
    ground = add_plane(bpy, "Ground", size=4)
    ground.data.uv_layers.remove(ground.data.uv_layers[0])
    select_only(bpy, ground)
    assert baking.why_not_bakeable([ground]) == "Ground has no UV map (unwrap it first: Edit Mode, U)"
    with pytest.raises(RuntimeError, match="Ground has no UV map"):
        bpy.ops.object.mc_ao_bake()


def _far_uvs(ground):
    for loop_uv in ground.data.uv_layers[0].uv:
        loop_uv.vector = (1e17, loop_uv.vector[1])


@pytest.mark.parametrize("setting, value, message", [
    ("uv_map", "Missing", r"Ground has no UV map 'Missing' \(UV maps: 'UVMap'\)"),
    (_far_uvs, None, r"Ground: mesh 'Ground': 2 triangles have UV coordinates beyond"),
])
def test_errors_are_reported_with_the_object_name(bpy, scene, setting, value, message):
    ground = add_plane(bpy, "Ground", size=4)
    if callable(setting):
        setting(ground)
    else:
        setattr(scene.mc_ao, setting, value)
    select_only(bpy, ground)
    with pytest.raises(RuntimeError, match=message) as info:
        bpy.ops.object.mc_ao_bake()
    assert "Traceback" not in str(info.value)
    assert "Ground_AO" not in bpy.data.images


def test_a_cancelled_run_reports_cancelled(bpy, scene):
    from mc_ao import bakerun, baking, operators
    from mc_ao.settings import BakeSettings

    ground = add_plane(bpy, "Ground", size=4)
    settings = BakeSettings(resolution=16, samples=8)
    jobs = baking.plan(bpy.context.evaluated_depsgraph_get(), [ground], settings)
    run = bakerun.BakeRun(jobs, settings, threads=1, live=True)
    run.cancel.set()
    run.start()
    run.stop()
    assert [run.messages.get()[0], run.messages.get()[0]] == ["cancelled", "end"]
    assert not operators._RUNS


def test_a_second_bake_is_refused_while_one_runs(bpy, scene):
    from mc_ao import operators

    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, ground)
    running = object()  # what BakeRun.start() registers
    operators._RUNS.add(running)
    try:
        assert bpy.ops.object.mc_ao_bake.poll()  # the button stays clickable ...
        assert bpy.ops.object.mc_ao_bake() == {"CANCELLED"}  # ... and says a bake is running
    finally:
        operators._RUNS.discard(running)
    assert "Ground_AO" not in bpy.data.images


def test_overlapping_uv_islands_are_reported(bpy, scene, capfd):
    ground = add_plane(bpy, "Ground", size=4)
    array = ground.modifiers.new("Copy", "ARRAY")  # a second plane on the same UVs
    array.relative_offset_displace = (1.5, 0.0, 0.0)
    bake(bpy, ground)
    lines = [line for line in capfd.readouterr().out.splitlines() if line.startswith(("Info: ", "Warning: "))]
    # A sentence, not core's key; before the summary, which comes last and counts it.
    assert lines[-2] == (
        "Warning: Ground: 576 texels lie under overlapping UV islands; each averages every surface over it"
    )
    assert lines[-1].startswith("Warning: Ground: 24x24 into 'Ground_AO' in ")
    assert lines[-1].endswith("; 1 warning before this, in the Info editor")


def test_save_without_openimageio_goes_through_blenders_writer(bpy, scene, tmp_path, monkeypatch):
    """Debian's Blender has no OpenImageIO module: the file is then written by Blender itself."""
    from core.files import imageio
    from mc_ao import filewriter

    monkeypatch.setattr(filewriter, "oiio_available", lambda: False)
    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))
    settings = scene.mc_ao
    settings.save_to_file = True
    settings.output_dir = str(tmp_path)
    settings.file_format = "PNG"
    (ao,) = bake(bpy, ground)
    pixels, _ = imageio.read_image(tmp_path / "Ground_AO.png")
    assert pixels.shape == (24, 24, 4)  # RGBA from Blender's writer, 16-bit for a float image
    np.testing.assert_allclose(pixels[..., 0], ao, atol=1 / 65535 + 1e-6)
    assert np.all(pixels[..., 3] == 1.0)
    assert [i.name for i in bpy.data.images] == ["Ground_AO"]  # no temporary image left
