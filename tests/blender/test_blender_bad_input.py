"""Bad input on the Blender side: bad selections, odd images, unwritable folders, Esc, core failures, undo.

Each case checks what the user is told (the operator's reports, as a script sees them: errors raise
RuntimeError from bpy.ops, infos and warnings are printed) and that the previous image content is
kept wherever a bake does not finish. A modal operator cannot run without a window, so the modal
cases drive mc_ao.operators.BakeSession, which is all the modal does, with the same events
("TIMER", "ESC") that the operator passes on.
"""

import errno
import types

import numpy as np
import pytest

from blender_helpers import (
    add_cube, add_plane, assert_unchanged, new_session, old_file, pattern_image, select_only, tick_until,
)

pytestmark = pytest.mark.blender


# -- helpers ----------------------------------------------------------------------------------------

def strip_uvs(obj):
    while obj.data.uv_layers:
        obj.data.uv_layers.remove(obj.data.uv_layers[0])
    return obj


def add_light(bpy, name="Lamp"):
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 3))
    obj = bpy.context.active_object
    obj.name = name
    return obj


def add_curve(bpy, name="Rope"):
    bpy.ops.curve.primitive_bezier_curve_add(location=(0, 0, 1.5))
    obj = bpy.context.active_object
    obj.name = name
    obj.data.bevel_depth = 0.1  # a surface: it occludes
    return obj


def run_operator(bpy, capfd, *args):
    """bpy.ops.object.mc_ao_bake(*args) as a script calls it: (result, error, reports, stderr).

    result: the operator's result, None when bpy.ops raised; error: the RuntimeError's text that an
    ERROR report makes bpy.ops raise, else None; reports: (type, message) pairs of what the operator
    reported (Blender prints them in background mode); stderr: the console's error stream.
    """
    capfd.readouterr()
    result = error = None
    try:
        result = bpy.ops.object.mc_ao_bake(*args)
    except RuntimeError as exc:
        error = str(exc)
    out, err = capfd.readouterr()
    reports = []
    for line in out.splitlines():
        kind, sep, message = line.partition(": ")
        if sep and kind in ("Info", "Warning", "Error"):
            reports.append((kind.upper(), message))
    return result, error, reports, err


class FakeLayout:
    """Records what a panel's draw() puts in its layout (a panel cannot be drawn without a window)."""

    def __init__(self):
        self.labels = []

    def row(self, **_):
        return self

    column = row

    def operator(self, *_, **__):
        return None

    def label(self, text="", icon="NONE"):
        self.labels.append(text)


def panel_labels(bpy, last_outcome=None):
    """The labels of the main panel (no region: nothing is wrapped), with this last bake's outcome."""
    from mc_ao import operators, panel

    layout = FakeLayout()
    kept, operators.last_outcome = operators.last_outcome, last_outcome
    try:
        panel.VIEW3D_PT_mc_ao.draw(types.SimpleNamespace(layout=layout), bpy.context)
    finally:
        operators.last_outcome = kept
    # the estimate is tested on its own; empty labels are the rows a fixed-height line leaves blank
    return [text for text in layout.labels if text and not str(text).startswith("Estimate: ")]


def execute_without_poll(bpy):
    """The operator's execute() called with poll bypassed: (result, reports)."""
    from mc_ao import operators

    reports = []
    stub = types.SimpleNamespace(report=lambda kind, message: reports.append((next(iter(kind)), message)))
    return operators.OBJECT_OT_mc_ao_bake.execute(stub, bpy.context), reports


# -- a selected object without UVs -------------------------------------------------------------------

def test_object_without_uvs_beside_bakeable_ones_is_skipped_with_a_warning(bpy, scene, capfd):
    ground = add_plane(bpy, "Ground", size=4)
    flat = strip_uvs(add_cube(bpy, "Flat", size=1.0, location=(0, 0, 0.8)))
    old = pattern_image(bpy, "Flat_AO", 8, 8)
    select_only(bpy, ground, flat)

    assert bpy.ops.object.mc_ao_bake.poll()
    assert panel_labels(bpy) == ["Into Ground_AO", "Skipped: Flat (no UV map)"]
    result, error, reports, _ = run_operator(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None)
    assert ("WARNING", "Flat: skipped, it has no UV map (unwrap it first: Edit Mode, U); "
                       "it still occludes the baked objects") in reports
    assert tuple(bpy.data.images["Ground_AO"].size) == (24, 24)
    assert_unchanged(bpy, "Flat_AO", old)


def test_object_without_uvs_alone_cannot_be_baked(bpy, scene, capfd):
    flat = strip_uvs(add_plane(bpy, "Flat", size=4))
    old = pattern_image(bpy, "Flat_AO", 8, 8)
    select_only(bpy, flat)
    message = "Flat has no UV map (unwrap it first: Edit Mode, U)"

    assert not bpy.ops.object.mc_ao_bake.poll()
    assert panel_labels(bpy) == [message]
    _, error, _, _ = run_operator(bpy, capfd)
    assert error == f"Operator bpy.ops.object.mc_ao_bake.poll() {message}"
    assert execute_without_poll(bpy) == ({"CANCELLED"}, [("ERROR", message)])
    assert_unchanged(bpy, "Flat_AO", old)


# -- non-mesh objects in the selection -----------------------------------------------------------------

def test_non_mesh_objects_beside_a_mesh_are_skipped_with_a_warning(bpy, scene, capfd):
    ground = add_plane(bpy, "Ground", size=4)
    lamp = add_light(bpy, "Lamp")
    rope = add_curve(bpy, "Rope")
    select_only(bpy, ground, lamp, rope)

    assert panel_labels(bpy) == ["Into Ground_AO", "Skipped: Lamp (not a mesh), Rope (not a mesh)"]  # one line: the panel stays still
    result, error, reports, _ = run_operator(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None)
    warnings = [message for kind, message in reports if kind == "WARNING"]
    assert warnings[:2] == [
        "Lamp: skipped, it is a light, not a mesh",
        "Rope: skipped, it is a curve, not a mesh; it still occludes the baked objects",
    ]
    # The summary comes last (the status bar shows only the last report) and counts the warnings.
    kind, summary = reports[-1]
    assert kind == "WARNING" and summary.startswith("Ground: 24x24 into 'Ground_AO' in ")
    assert summary.endswith("; 2 warnings before this, in the Info editor")
    assert sorted(i.name for i in bpy.data.images) == ["Ground_AO"]


@pytest.mark.parametrize("kinds, message", [
    (["light"], "Lamp is a light, not a mesh"),
    (["light", "curve"], "None of the selected objects is a mesh"),
])
def test_non_mesh_objects_alone_cannot_be_baked(bpy, scene, capfd, kinds, message):
    objects = [add_light(bpy, "Lamp") if kind == "light" else add_curve(bpy, "Rope") for kind in kinds]
    old = pattern_image(bpy, "Lamp_AO", 8, 8)
    select_only(bpy, *objects)

    assert not bpy.ops.object.mc_ao_bake.poll()
    assert panel_labels(bpy) == [message]
    _, error, _, _ = run_operator(bpy, capfd)
    assert error == f"Operator bpy.ops.object.mc_ao_bake.poll() {message}"
    assert execute_without_poll(bpy) == ({"CANCELLED"}, [("ERROR", message)])
    assert_unchanged(bpy, "Lamp_AO", old)


# -- nothing selected ---------------------------------------------------------------------------------

def test_nothing_selected(bpy, scene, capfd):
    add_plane(bpy, "Ground", size=4)
    old = pattern_image(bpy, "Ground_AO", 8, 8)
    select_only(bpy)
    message = "Nothing is selected: select a mesh object with a UV map"

    assert not bpy.ops.object.mc_ao_bake.poll()
    assert panel_labels(bpy) == [message]
    _, error, _, _ = run_operator(bpy, capfd)
    assert error == f"Operator bpy.ops.object.mc_ao_bake.poll() {message}"
    assert execute_without_poll(bpy) == ({"CANCELLED"}, [("ERROR", message)])
    assert_unchanged(bpy, "Ground_AO", old)


# -- an existing image of another size: resized, as the tooltips say ---------------------------------

def test_the_tooltips_say_an_image_of_another_size_is_resized(bpy, addon):
    from mc_ao import operators

    assert "An existing image of another size is resized to the bake's size" in (
        operators.OBJECT_OT_mc_ao_bake.bl_description
    )
    props = bpy.context.scene.mc_ao.bl_rna.properties
    assert "An existing image of another size is resized to this size" in props["resolution"].description
    assert "resized to the bake's size" in props["image_name"].description


def test_an_image_of_another_size_is_resized_and_reported(bpy, scene, capfd):
    ground = add_plane(bpy, "Ground", size=4)
    pattern_image(bpy, "Ground_AO", 8, 6)
    pointer = bpy.data.images["Ground_AO"].as_pointer()
    select_only(bpy, ground)

    result, _, reports, _ = run_operator(bpy, capfd)
    assert result == {"FINISHED"}
    assert ("INFO", "Ground: image 'Ground_AO' was 8x6, resized to 24x24") in reports
    image = bpy.data.images["Ground_AO"]
    assert image.as_pointer() == pointer and tuple(image.size) == (24, 24) and image.is_float
    assert image.colorspace_settings.name == "Non-Color"


def test_a_file_image_of_another_size_is_resized_and_its_file_left_alone(bpy, scene, capfd, tmp_path):
    ground = add_plane(bpy, "Ground", size=4)
    pattern_image(bpy, "Made", 8, 4)
    made = bpy.data.images["Made"]
    made.filepath_raw = str(tmp_path / "Ground_AO.png")
    made.file_format = "PNG"
    made.save()
    on_disk = (tmp_path / "Ground_AO.png").read_bytes()
    bpy.data.images.remove(made)
    image = bpy.data.images.load(str(tmp_path / "Ground_AO.png"))
    image.name = "Ground_AO"
    select_only(bpy, ground)

    result, _, reports, _ = run_operator(bpy, capfd)
    assert result == {"FINISHED"}
    assert ("INFO", "Ground: image 'Ground_AO' was 8x4, resized to 24x24") in reports
    image = bpy.data.images["Ground_AO"]
    assert tuple(image.size) == (24, 24) and image.colorspace_settings.name == "Non-Color"
    assert (tmp_path / "Ground_AO.png").read_bytes() == on_disk


def test_an_image_of_another_size_is_put_back_when_its_bake_fails(bpy, scene, monkeypatch):
    """A live (modal) bake has resized the image and drawn tiles into it when the core fails."""
    import core

    ground = add_plane(bpy, "Ground", size=4)
    old = pattern_image(bpy, "Ground_AO", 8, 6)
    scene.mc_ao.resolution = 64
    scene.mc_ao.threads = 1
    real = core.bake

    def failing(target, *args, on_tile=None, **kwargs):
        def tile(*tile_args):
            on_tile(*tile_args)
            raise core.MeshError(f"mesh {target.name!r}: simulated failure after a tile")

        return real(target, *args, on_tile=tile, **kwargs)

    monkeypatch.setattr(core, "bake", failing)
    select_only(bpy, ground)
    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    assert tick_until(bpy, session, lambda: False) == {"CANCELLED"}
    assert ("ERROR", "Ground: mesh 'Ground': simulated failure after a tile") in reports
    assert_unchanged(bpy, "Ground_AO", old)


# -- the output folder ---------------------------------------------------------------------------------

def test_an_output_folder_under_a_file_is_refused_before_baking(bpy, scene, capfd, tmp_path):
    ground = add_plane(bpy, "Ground", size=4)
    old = pattern_image(bpy, "Ground_AO", 8, 8)
    blocker = tmp_path / "afile"
    blocker.write_bytes(b"not a folder")
    folder = blocker / "sub"
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = str(folder)
    select_only(bpy, ground)

    result, error, _, _ = run_operator(bpy, capfd)
    assert error == (
        f"Error: Cannot save into the output folder '{folder}': '{blocker}' is a file, not a folder; "
        "nothing was baked\n"
    )
    assert_unchanged(bpy, "Ground_AO", old)  # documented: refused before the bake, the image keeps its pixels
    assert blocker.read_bytes() == b"not a folder"


def test_a_missing_output_folder_is_created(bpy, scene, capfd, tmp_path):
    ground = add_plane(bpy, "Ground", size=4)
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = str(tmp_path / "new" / "deeper")
    select_only(bpy, ground)
    result, _, reports, _ = run_operator(bpy, capfd)
    assert result == {"FINISHED"}
    path = tmp_path / "new" / "deeper" / "Ground_AO.png"
    assert path.is_file()
    assert ("INFO", f"Ground: saved {path} (OpenImageIO)") in reports


def test_a_failed_file_write_keeps_the_bake_in_blender_and_the_old_file(bpy, scene, capfd, tmp_path, monkeypatch):
    """The disk fills up while the file is written: the image keeps the bake, the old file stays."""
    from core.files import imageio

    ground = add_plane(bpy, "Ground", size=4)
    select_only(bpy, ground)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    baked = np.array(bpy.data.images["Ground_AO"].pixels[:])

    path = tmp_path / "Ground_AO.png"
    path.write_bytes(old_file(path, "the previous bake's file"))

    def disk_full(oiio, temp, *args):
        with open(temp, "wb") as fh:
            fh.write(b"half a PNG")
        raise OSError(errno.ENOSPC, "No space left on device")

    # core.files.imageio writes a temporary file through this function, then renames it over the target.
    monkeypatch.setattr(imageio, "_write_temp", disk_full)
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = str(tmp_path)
    result, error, reports, _ = run_operator(bpy, capfd)
    # The status bar shows the last report: the summary, which says an error came before it.
    assert reports[-1][0] == "WARNING" and reports[-1][1].startswith("Ground: 24x24 into 'Ground_AO' in ")
    assert reports[-1][1].endswith("; 1 error before this, in the Info editor")
    assert error == (
        "Error: Ground: the bake is in image 'Ground_AO', but none of its files was written (any file already "
        f"there is unchanged): could not write '{path}': [Errno 28] No space left on device\n"
    )
    assert path.read_bytes() == old_file(path, "the previous bake's file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Ground_AO.png"]  # no temporary file left
    image = bpy.data.images["Ground_AO"]
    assert tuple(image.size) == (24, 24)  # documented: the image in Blender is baked
    np.testing.assert_array_equal(np.array(image.pixels[:]), baked)


def test_blenders_writer_replaces_a_file_only_when_complete(bpy, scene, tmp_path, monkeypatch):
    """Without OpenImageIO the file goes through Blender's writer, also by a temporary file and a rename."""
    from mc_ao import images

    path = tmp_path / "Ground_AO.png"
    path.write_bytes(b"old")
    replaced = []
    real_replace = images.os.replace

    def replace(src, dst):
        replaced.append((src, dst))
        assert path.read_bytes() == b"old"  # untouched until the complete file moves over it
        real_replace(src, dst)

    monkeypatch.setattr(images.os, "replace", replace)
    images.save_pixels_with_blender(np.full((4, 4, 4), 0.5, np.float32), str(path), "PNG", 8)
    assert len(replaced) == 1 and str(replaced[0][1]) == str(path)
    assert path.read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Ground_AO.png"]
    assert ".mc_ao_save" not in bpy.data.images


# -- Esc during a bake ---------------------------------------------------------------------------------

def test_esc_during_a_bake_puts_the_images_back(bpy, scene, hold_bake):
    """Ground finishes, Wall is caught mid-bake with tiles in its resized image, Zed never starts."""
    ground = add_plane(bpy, "Ground", size=4)
    wall = add_plane(bpy, "Wall", size=4, location=(0, 3, 1), rotation=(1.5708, 0, 0))
    zed = add_plane(bpy, "Zed", size=1, location=(3, 0, 0))
    scene.mc_ao.resolution = 64
    scene.mc_ao.threads = 1
    wall_old = pattern_image(bpy, "Wall_AO", 16, 8)
    held = hold_bake("Wall")
    select_only(bpy, zed, wall, ground)

    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    wall_image = lambda: bpy.data.images["Wall_AO"]  # noqa: E731
    tick_until(bpy, session, lambda: held.is_set() and not session.pending and tuple(wall_image().size) == (64, 64))
    assert not np.array_equal(np.array(wall_image().pixels[:64 * 64 * 4]).reshape(64, 64, 4)[..., 0], 0)
    baked_ground = np.array(bpy.data.images["Ground_AO"].pixels[:])

    assert session.on_event(bpy.context, "ESC") == {"CANCELLED"}
    assert reports[-1] == (
        "WARNING", "AO bake cancelled; kept the finished bakes of Ground; the other images are as they were"
    )
    assert_unchanged(bpy, "Wall_AO", wall_old)
    assert "Zed_AO" not in bpy.data.images
    np.testing.assert_array_equal(np.array(bpy.data.images["Ground_AO"].pixels[:]), baked_ground)
    from mc_ao import operators

    assert not operators._RUNS and not operators._SESSIONS
    assert session.on_event(bpy.context, "TIMER") == {"CANCELLED"}  # the modal ends at its next event


def test_a_live_bake_draws_its_tiles_over_the_previous_pixels(bpy, scene, hold_bake):
    """A rebake into an image of the same size: the texels not baked yet still show the previous bake."""
    ground = add_plane(bpy, "Ground", size=4)
    scene.mc_ao.resolution = 512  # one thread: four tiles of 256^2 (core.engine.settings.auto_tile_shape)
    scene.mc_ao.threads = 1
    old = pattern_image(bpy, "Ground_AO", 512, 512, float_buffer=True, is_data=True)
    held = hold_bake("Ground")
    select_only(bpy, ground)
    session, _ = new_session()
    assert session.start(bpy.context, live=True)
    tick_until(bpy, session, lambda: held.is_set() and not session.pending)

    from mc_ao import images

    live = images.pixels_of(bpy.data.images["Ground_AO"])
    changed = np.any(live != old, axis=2)
    from core.engine.settings import auto_tile_shape

    tw, th = auto_tile_shape(512, 512, 1)
    assert tw * th < 512 * 512  # more than one tile
    assert changed.any()  # the first tile is in ...
    assert 0 < changed.sum() <= tw * th  # ... and only the first tile
    assert session.on_event(bpy.context, "ESC") == {"CANCELLED"}
    assert_unchanged(bpy, "Ground_AO", old)


def test_ctrl_c_during_a_blocking_bake_puts_the_images_back(bpy, scene, capfd, monkeypatch):
    """Ctrl-C while a script or `blender -b` waits for the bake: cancelled, the images as they were."""
    from mc_ao import operators

    ground = add_plane(bpy, "Ground", size=4)
    old = pattern_image(bpy, "Ground_AO", 8, 8)
    real = operators.BakeSession._next_message

    def interrupted(self):
        message = real(self)
        if message[0] == "progress":
            raise KeyboardInterrupt
        return message

    monkeypatch.setattr(operators.BakeSession, "_next_message", interrupted)
    select_only(bpy, ground)
    result, error, reports, _ = run_operator(bpy, capfd)
    assert (result, error) == ({"CANCELLED"}, None)
    assert reports[-1] == ("WARNING", "AO bake cancelled; the images are as they were")
    assert_unchanged(bpy, "Ground_AO", old)


# -- an exception inside the core ----------------------------------------------------------------------

def test_a_core_error_is_reported_and_the_other_objects_still_bake(bpy, scene, capfd):
    """A mesh with NaN positions (core.MeshError): named in the report, its image untouched."""
    ground = add_plane(bpy, "Ground", size=4)
    bad = add_plane(bpy, "Bad", size=4, location=(6, 0, 0))
    bad.data.vertices[0].co = (float("nan"), 0.0, 0.0)
    old = pattern_image(bpy, "Bad_AO", 8, 8)
    scene.mc_ao.occluders = "SELF"
    select_only(bpy, ground, bad)

    _, error, reports, stderr = run_operator(bpy, capfd)
    assert error == "Error: Bad: mesh 'Bad': positions contain 3 non-finite values (NaN first at index (0, 0))\n"
    assert "Traceback" not in stderr
    assert reports[-1] == ("WARNING", "AO bake: 1 of 2 objects baked, the failed ones' images are as they were")
    assert_unchanged(bpy, "Bad_AO", old)
    assert tuple(bpy.data.images["Ground_AO"].size) == (24, 24)


def test_an_unexpected_exception_in_the_core_is_reported_not_raised(bpy, scene, capfd, monkeypatch):
    import core

    def broken(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(core, "bake", broken)
    ground = add_plane(bpy, "Ground", size=4)
    old = pattern_image(bpy, "Ground_AO", 8, 8)
    select_only(bpy, ground)
    _, error, _, stderr = run_operator(bpy, capfd)
    assert error == "Error: Ground: bake failed (RuntimeError: boom); see the console\n"
    assert_unchanged(bpy, "Ground_AO", old)
    # The trace is for the console (a bug report), never in the report the user reads.
    assert "mc_ao: the bake of Ground failed:\nTraceback" in stderr


# -- the same seed gives the same image ------------------------------------------------------------------

def test_the_same_seed_gives_the_same_image(bpy, scene):
    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.0, location=(0.3, 0, 0.8))
    scene.mc_ao.seed = 11
    select_only(bpy, ground)

    def bake():
        assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
        return np.array(bpy.data.images["Ground_AO"].pixels[:])

    first, second = bake(), bake()
    np.testing.assert_array_equal(first, second)
    scene.mc_ao.threads = 1  # the seed, not the thread count, decides the image
    np.testing.assert_array_equal(bake(), first)
    scene.mc_ao.seed = 12
    assert not np.array_equal(bake(), first)

    # The modal path, with live tiles, ends with the same image.
    scene.mc_ao.seed = 11
    session, _ = new_session()
    assert session.start(bpy.context, live=True)
    assert tick_until(bpy, session, lambda: False) == {"FINISHED"}
    np.testing.assert_array_equal(np.array(bpy.data.images["Ground_AO"].pixels[:]), first)


# -- undo ------------------------------------------------------------------------------------------------

def test_a_bake_is_one_undo_step(bpy, addon):
    from mc_ao import operators

    assert operators.OBJECT_OT_mc_ao_bake.bl_options == {"REGISTER", "UNDO"}


def test_undo_and_redo_after_a_bake(bpy, scene):
    """Undo takes back the bake and only the bake; redo brings the datablocks back; nothing crashes.

    Blender's undo stores no image pixels: the new image comes back from a redo blank, as
    documented at the operator's bl_options. bpy.ops.ed.undo runs in background mode once
    ed.undo_push has made the undo stack; calling the operator with undo=True is what the UI does.
    """
    ground = add_plane(bpy, "Ground", size=4)
    pattern_image(bpy, "Old", 8, 6)
    select_only(bpy, ground)
    bpy.ops.ed.undo_push(message="scene")
    add_cube(bpy, "Marker", size=0.5, location=(5, 5, 0))  # the step just before the bake
    bpy.ops.ed.undo_push(message="marker")
    select_only(bpy, bpy.data.objects["Ground"])
    assert bpy.ops.object.mc_ao_bake("EXEC_DEFAULT", True) == {"FINISHED"}
    bpy.context.scene.mc_ao.image_name = "Old"
    assert bpy.ops.object.mc_ao_bake("EXEC_DEFAULT", True) == {"FINISHED"}
    assert tuple(bpy.data.images["Old"].size) == (24, 24)

    assert bpy.ops.ed.undo() == {"FINISHED"}  # the bake into Old
    assert tuple(bpy.data.images["Old"].size) == (8, 6) and "Ground_AO" in bpy.data.images
    assert bpy.ops.ed.undo() == {"FINISHED"}  # the bake into Ground_AO
    assert "Ground_AO" not in bpy.data.images
    assert "Marker" in bpy.data.objects  # the step before the bake stays
    assert bpy.ops.ed.redo() == {"FINISHED"}
    assert tuple(bpy.data.images["Ground_AO"].size) == (24, 24)
    assert bpy.ops.ed.redo() == {"FINISHED"}
    assert tuple(bpy.data.images["Old"].size) == (24, 24)

    # Everything still works after that: read the images, bake again.
    for image in bpy.data.images:
        assert len(image.pixels) == image.size[0] * image.size[1] * image.channels
    select_only(bpy, bpy.data.objects["Ground"])
    bpy.context.scene.mc_ao.image_name = ""
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}


def test_undo_during_a_bake_cancels_it_first(bpy, scene, hold_bake):
    """An undo while the modal bake runs: the bake ends (images put back), then the undo runs."""
    ground = add_plane(bpy, "Ground", size=4)
    scene.mc_ao.resolution = 64
    scene.mc_ao.threads = 1
    old = pattern_image(bpy, "Old", 16, 8)
    select_only(bpy, ground)
    bpy.ops.ed.undo_push(message="scene")
    add_cube(bpy, "Marker", size=0.5, location=(5, 5, 0))
    bpy.ops.ed.undo_push(message="marker")
    select_only(bpy, bpy.data.objects["Ground"])
    bpy.context.scene.mc_ao.image_name = "Old"
    held = hold_bake("Ground")

    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    tick_until(bpy, session, lambda: held.is_set() and not session.pending)
    assert tuple(bpy.data.images["Old"].size) == (64, 64)

    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert reports[-1] == ("WARNING", "AO bake cancelled by Undo; the images are as they were")
    assert session.on_event(bpy.context, "TIMER") == {"CANCELLED"}  # the modal ends at its next event
    assert_unchanged(bpy, "Old", old)
    assert "Marker" not in bpy.data.objects  # and the undo did its own work
    from mc_ao import operators

    assert not operators._RUNS and not operators._SESSIONS
