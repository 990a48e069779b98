"""An object's files are written all together or not at all, by the operator: a cancelled object
writes none of them, one whose second file cannot be written writes none either, and the report
says which objects' files were written (mc_ao.outputs.save_files)."""

import os

import pytest

from blender_helpers import add_cube, add_plane, new_session, old_file, select_only, tick_until

pytestmark = pytest.mark.blender


def previous(folder, names):
    """Files of an earlier bake at ``names``; returns {name: bytes}."""
    for name in names:
        (folder / name).write_bytes(old_file(name, f"the previous {name}"))
    return {name: (folder / name).read_bytes() for name in names}


def files_in(folder):
    return sorted(p.name for p in folder.iterdir())


def test_esc_writes_every_file_of_a_finished_object_and_none_of_the_cancelled_one(bpy, scene, tmp_path, hold_bake):
    block = add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.8))  # baked first (name order)
    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, block, ground)
    settings = scene.mc_ao
    settings.threads, settings.error_map, settings.bent_normals = 1, True, True
    settings.save_to_file, settings.output_dir, settings.file_format = True, str(tmp_path), "OPEN_EXR"
    names = ["Block_AO.exr", "Block_AO_stderr.exr", "Block_BentNormal.exr",
             "Ground_AO.exr", "Ground_AO_stderr.exr", "Ground_BentNormal.exr"]
    old = previous(tmp_path, names)
    held = hold_bake("Ground")
    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    tick_until(bpy, session, lambda: held.is_set() and not session.pending)
    assert session.on_event(bpy.context, "ESC") == {"CANCELLED"}
    assert reports[-1] == ("WARNING", "AO bake cancelled; kept the finished bakes of Block; the other images are "
                                      "as they were; every file of Block is written, none of the others'")
    for name in names:
        changed = (tmp_path / name).read_bytes() != old[name]
        assert changed == name.startswith("Block"), name  # all of Block's, none of Ground's
    assert files_in(tmp_path) == sorted(names)  # no temporary file left


def test_a_cancel_before_any_object_finished_says_no_file_was_written(bpy, scene, tmp_path, hold_bake):
    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, ground)
    scene.mc_ao.threads = 1
    scene.mc_ao.save_to_file, scene.mc_ao.output_dir = True, str(tmp_path)
    old = previous(tmp_path, ["Ground_AO.png"])
    held = hold_bake("Ground")
    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    tick_until(bpy, session, lambda: held.is_set() and not session.pending)
    assert session.on_event(bpy.context, "ESC") == {"CANCELLED"}
    assert reports[-1] == ("WARNING", "AO bake cancelled; the images are as they were; no file was written")
    assert (tmp_path / "Ground_AO.png").read_bytes() == old["Ground_AO.png"]


def test_a_second_file_that_cannot_be_written_leaves_the_first_as_it_was(bpy, scene, tmp_path):
    """The AO's PNG could be written, its error map's EXR cannot (read-only): neither is replaced,
    and the report names the file that failed and says that none was written."""
    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, ground)
    settings = scene.mc_ao
    settings.error_map = True
    settings.save_to_file, settings.output_dir = True, str(tmp_path)
    old = previous(tmp_path, ["Ground_AO.png", "Ground_AO_stderr.exr"])
    stderr_file = tmp_path / "Ground_AO_stderr.exr"
    stderr_file.chmod(0o444)
    reports = []
    session, reports = new_session()
    assert session.start(bpy.context, live=False)
    assert session.wait(bpy.context) == {"FINISHED"}  # baked: the image in Blender has it
    errors = [text for kind, text in reports if kind == "ERROR"]
    assert errors == [
        "Ground: the bake is in image 'Ground_AO', but none of its files was written (any file already there is "
        f"unchanged): '{stderr_file}' is read-only (its write permission is off): it was left as it is; make it "
        "writable, or choose another folder or name, to replace it"]
    assert {n: (tmp_path / n).read_bytes() for n in old} == old
    assert files_in(tmp_path) == sorted(old)
    assert "Ground_AO" in bpy.data.images and "Ground_AO_stderr" in bpy.data.images
    os.chmod(stderr_file, 0o644)
