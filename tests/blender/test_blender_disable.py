"""The add-on disabled in the middle of a bake: the bake stops at once, writes no file, leaves no
half-baked image behind, and the add-on enables and bakes again."""

import pytest

from blender_helpers import add_plane, new_session, select_only, tick_until

pytestmark = pytest.mark.blender


def test_disabling_the_add_on_mid_bake_stops_it_and_leaves_nothing_half_done(bpy, scene, tmp_path, hold_bake):
    import mc_ao
    from mc_ao import bakerun

    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, ground)
    settings = scene.mc_ao
    settings.resolution, settings.threads = 64, 1
    settings.save_to_file, settings.output_dir = True, str(tmp_path)
    held = hold_bake("Ground")
    session, _ = new_session()
    assert session.start(bpy.context, live=True)
    tick_until(bpy, session, lambda: held.is_set() and not session.pending)
    assert "Ground_AO" in bpy.data.images  # created by the bake, tiles drawn in
    run = session.run
    mc_ao.unregister()
    try:
        assert not run.thread.is_alive() and not bakerun.RUNS  # stopped, not left running
        assert list(tmp_path.iterdir()) == []  # no file
        assert "Ground_AO" not in bpy.data.images  # the image the bake made is gone again
    finally:
        mc_ao.register()
    scene = bpy.context.scene
    scene.mc_ao.resolution, scene.mc_ao.samples, scene.mc_ao.threads = 16, 4, 1
    select_only(bpy, ground)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    assert "Ground_AO" in bpy.data.images
