"""UDIM tiles in Blender: one tiled image per object, one tile per tile the UVs touch, the
core's tiles exactly; an existing tiled image filled tile by tile (its other tiles kept), one of
another size refused by name; files <name>.<tile>.<ext>; nothing changes before the bake ends."""

import os
import re

import numpy as np
import pytest

from blender_helpers import add_cube, add_plane, new_session, select_only, tick_until


@pytest.fixture
def udim_scene(bpy, scene):
    scene.mc_ao.use_udim = True
    return scene


def spread_uvs(obj, scale=(2.0, 1.0), offset=(0.0, 0.0)):
    """Scale and move the object's UVs: a plane's [0, 1] square onto [0, 2] x [0, 1] (tiles 1001, 1002)."""
    layer = obj.data.uv_layers.active
    for d in layer.uv:
        d.vector = (d.vector[0] * scale[0] + offset[0], d.vector[1] * scale[1] + offset[1])


def ground_over_two_tiles(bpy):
    """A 4 x 2 plane over tiles 1001 (its left half) and 1002 (its right half), a cube over the right half."""
    ground = add_plane(bpy, "Ground", size=2)
    ground.scale = (2, 1, 1)
    bpy.ops.object.select_all(action="DESELECT")
    ground.select_set(True)
    bpy.context.view_layer.objects.active = ground
    bpy.ops.object.transform_apply(scale=True)
    spread_uvs(ground)
    add_cube(bpy, "Block", size=0.8, location=(1.0, 0.0, 0.6))
    select_only(bpy, ground)
    return ground


def core_tiles(bpy, scene):
    """The core's tiles for the scene's bake of Ground (same geometry, settings and seed)."""
    import core
    from mc_ao import baking
    from mc_ao.settings import BakeSettings

    settings = BakeSettings.from_properties(scene.mc_ao)
    obj = bpy.data.objects["Ground"]
    job, = baking.plan(bpy.context.evaluated_depsgraph_get(), [obj], settings, selected=[obj],
                       view_layer=bpy.context.view_layer)
    kw = settings.bake_kwargs(2)
    mesh = core.Mesh(job.target.positions, job.target.triangles, job.target.uvs, job.target.normals, name="Ground")
    occ = [core.Mesh(o.positions, o.triangles, None, o.normals) for o in job.occluders]
    return core.bake_udim(mesh, occ, **kw)


def test_a_plane_over_two_tiles_bakes_into_one_tiled_image(bpy, udim_scene):
    from mc_ao import udim

    ground_over_two_tiles(bpy)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    image = bpy.data.images["Ground_AO"]
    assert image.source == "TILED" and [t.number for t in image.tiles] == [1001, 1002]
    assert all(tuple(t.size) == (24, 24) for t in image.tiles)
    assert image.colorspace_settings.name == "Non-Color" and image.use_fake_user
    assert len(image.packed_files) == 2  # kept in the .blend file, every tile
    tiles = udim.tile_pixels(image)
    want = core_tiles(bpy, udim_scene)
    for number in (1001, 1002):
        np.testing.assert_array_equal(tiles[number][..., 0], want.tiles[number].ao)
        np.testing.assert_array_equal(tiles[number][..., 3], 1.0)
    # The cube stands over the right half: 1002 is the darker tile, and darkest near its middle.
    assert tiles[1002][..., 0].mean() < tiles[1001][..., 0].mean() - 0.05


def test_tiles_far_apart_and_nothing_between(bpy, udim_scene):
    """The left half of a grid keeps its UVs in 1001, the right half's go to 1013 (u in [2, 3),
    v in [1, 2)): two tiles, none of those between."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=2)
    ground = bpy.context.active_object
    ground.name = "Ground"
    layer = ground.data.uv_layers.active
    for poly in ground.data.polygons:
        if poly.center.x > 0:
            for li in poly.loop_indices:
                u, v = layer.uv[li].vector
                layer.uv[li].vector = (u + 2.0, v + 1.0)
    select_only(bpy, ground)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    image = bpy.data.images["Ground_AO"]
    assert [t.number for t in image.tiles] == [1001, 1013]
    assert all(tuple(t.size) == (24, 24) for t in image.tiles)


def test_an_existing_tiled_image_is_filled_tile_by_tile_and_keeps_its_other_tiles(bpy, udim_scene):
    from mc_ao import udim

    ground_over_two_tiles(bpy)
    image = bpy.data.images.new("Ground_AO", 24, 24, alpha=True, float_buffer=True, tiled=True)
    with bpy.context.temp_override(edit_image=image):
        bpy.ops.image.tile_add(number=1005, count=1, fill=True, color=(0.2, 0.4, 0.6, 1.0), width=24, height=24,
                               float=True, alpha=True)
    kept = udim.tile_pixels(bpy.data.images["Ground_AO"], [1005])[1005]
    select_only(bpy, bpy.data.objects["Ground"])
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    image = bpy.data.images["Ground_AO"]
    assert [t.number for t in image.tiles] == [1001, 1002, 1005]
    tiles = udim.tile_pixels(image)
    np.testing.assert_array_equal(tiles[1005], kept)
    want = core_tiles(bpy, udim_scene)
    np.testing.assert_array_equal(tiles[1002][..., 0], want.tiles[1002].ao)


def test_a_tiled_image_of_another_size_or_a_plain_image_is_refused_by_name(bpy, udim_scene):
    ground_over_two_tiles(bpy)
    bpy.data.images.new("Ground_AO", 32, 32, tiled=True)
    session, reports = new_session()
    assert not session.start(bpy.context, live=False)
    assert reports[-1] == ("ERROR", "Ground: tile 1001 of image 'Ground_AO' is 32x32, the bake makes 24x24 tiles; "
                                    "set Size to 32, or choose another Image name")
    assert [tuple(t.size) for t in bpy.data.images["Ground_AO"].tiles] == [(32, 32)]
    bpy.data.images.remove(bpy.data.images["Ground_AO"])
    bpy.data.images.new("Ground_AO", 24, 24)
    session, reports = new_session()
    assert not session.start(bpy.context, live=False)
    assert re.match(r"Ground: image 'Ground_AO' is a generated image, not a tiled \(UDIM\) one", reports[-1][1])
    assert bpy.data.images["Ground_AO"].source == "GENERATED"


def test_esc_leaves_no_tiled_image_behind(bpy, udim_scene, monkeypatch):
    import threading

    import core.pipeline.run

    ground_over_two_tiles(bpy)
    held = threading.Event()
    real = core.pipeline.run.run

    def holding(*args, progress=None, cancel=None, **kwargs):
        def step(fraction):
            held.set()
            cancel.wait(30)
            progress(fraction)
        return real(*args, progress=step, cancel=cancel, **kwargs)

    monkeypatch.setattr(core.pipeline.run, "run", holding)
    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    tick_until(bpy, session, held.is_set)
    assert session.on_event(bpy.context, "ESC") == {"CANCELLED"}
    assert bpy.data.images.get("Ground_AO") is None
    assert "cancelled" in reports[-1][1]


def test_save_to_file_writes_one_file_per_tile_and_links_the_image_to_them(bpy, udim_scene, tmp_path):
    from mc_ao import udim

    ground_over_two_tiles(bpy)
    udim_scene.mc_ao.save_to_file = True
    udim_scene.mc_ao.output_dir = str(tmp_path / "out")
    udim_scene.mc_ao.file_format = "OPEN_EXR"
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    assert sorted(os.listdir(tmp_path / "out")) == ["Ground_AO.1001.exr", "Ground_AO.1002.exr"]
    image = bpy.data.images["Ground_AO"]
    assert image.filepath == str(tmp_path / "out" / "Ground_AO.<UDIM>.exr")
    assert len(image.packed_files) == 0 and [t.number for t in image.tiles] == [1001, 1002]
    import core.files.imageio

    want = core_tiles(bpy, udim_scene)
    for number in (1001, 1002):
        pixels, meta = core.files.imageio.read_image(tmp_path / "out" / f"Ground_AO.{number}.exr")
        np.testing.assert_array_equal(pixels, want.tiles[number].ao)
        assert meta["udim_tile"] == number and meta["udim"] is True and meta["object"] == "Ground"
    tiles = udim.tile_pixels(image)  # Blender reads the linked files back
    np.testing.assert_array_equal(tiles[1002][..., 0], want.tiles[1002].ao)


def test_the_panel_and_the_report_say_udim(bpy, udim_scene):
    ground_over_two_tiles(bpy)
    session, reports = new_session()
    assert session.start(bpy.context, live=False)
    assert session.wait(bpy.context) == {"FINISHED"}
    assert re.match(r"Ground: 2 UDIM tiles \(1001, 1002\) of 24x24 into 'Ground_AO' in", reports[-1][1])


def test_report_keys_of_the_new_bakes_are_the_cores(addon):
    """The notes of UDIM and colour-attribute bakes are keyed by their reports' keys."""
    import core
    from mc_ao import summaries

    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    mesh = core.Mesh(P, F, uvs=P[F][:, :, :2] * 2 - 0.5)
    udim = core.bake_udim(mesh, resolution=8, samples=4, threads=1)
    vertex = core.bake_vertex_ao(mesh, samples=4, threads=1)
    assert set(summaries._TARGET_NOTES) <= set(udim.report) | set(vertex.report)
    assert summaries.input_notes(udim) == [
        "2 triangles reach outside the UDIM tiles (u in [0, 10], v in [0, 100]); the parts outside are not baked"]


def test_the_error_map_of_a_udim_bake_is_a_tiled_image_and_one_file_per_tile(bpy, udim_scene, tmp_path):
    """Error Map with UDIM tiles: "<image>_stderr" is a tiled float image with the AO's tiles, each
    the core's standard error of that tile (two replicates); Save to File writes
    <image>_stderr.<tile>.exr beside the AO's tiles and links the image to them."""
    import core.files.imageio
    from mc_ao import udim

    ground_over_two_tiles(bpy)
    udim_scene.mc_ao.error_map = True
    udim_scene.mc_ao.save_to_file = True
    udim_scene.mc_ao.output_dir = str(tmp_path / "out")
    udim_scene.mc_ao.file_format = "OPEN_EXR"
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    assert sorted(os.listdir(tmp_path / "out")) == [
        "Ground_AO.1001.exr", "Ground_AO.1002.exr", "Ground_AO_stderr.1001.exr", "Ground_AO_stderr.1002.exr"]
    image = bpy.data.images["Ground_AO_stderr"]
    assert image.source == "TILED" and [t.number for t in image.tiles] == [1001, 1002] and image.is_float
    assert image.filepath == str(tmp_path / "out" / "Ground_AO_stderr.<UDIM>.exr")
    want = core_tiles(bpy, udim_scene)
    assert want.tiles[1001].metadata["replicates"] == 2
    tiles = udim.tile_pixels(image)
    for number in (1001, 1002):
        # The files are half-float EXRs (the AO's EXR depth), and the image loads them.
        pixels, meta = core.files.imageio.read_image(tmp_path / "out" / f"Ground_AO_stderr.{number}.exr")
        np.testing.assert_allclose(pixels, want.tiles[number].stderr, rtol=2.0 ** -11, atol=1e-7)
        np.testing.assert_array_equal(tiles[number][..., 0], pixels)
        assert meta["content"] == "stderr" and meta["udim_tile"] == number
    shaded = want.tiles[1002].mask & (want.tiles[1002].ao < 0.95)
    assert shaded.any() and np.all(want.tiles[1002].stderr[shaded] > 0)


def test_the_error_map_of_a_udim_bake_is_packed_without_save_to_file(bpy, udim_scene):
    from mc_ao import udim

    ground_over_two_tiles(bpy)
    udim_scene.mc_ao.error_map = True
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    image = bpy.data.images["Ground_AO_stderr"]
    assert image.source == "TILED" and len(image.packed_files) == 2 and image.use_fake_user
    assert image.colorspace_settings.name == "Non-Color" and image.is_float
    tiles, want = udim.tile_pixels(image), core_tiles(bpy, udim_scene)
    for number in (1001, 1002):
        np.testing.assert_array_equal(tiles[number][..., 0], want.tiles[number].stderr)  # float, exact
