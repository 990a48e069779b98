"""Colour attributes: Target = Color Attributes bakes AO per vertex or face corner as Cycles
does (checked against Cycles' own AO bake into a colour attribute), refuses what it cannot write
(naming the object and the attribute), changes nothing until it finishes, and is one undo step."""

import numpy as np
import pytest

from blender_helpers import add_cube, clean_scene, new_session, select_only, tick_until

N = 1024  # samples, for both bakers


def grid(bpy, name="Grid", subdivisions=12, size=4.0):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=subdivisions, y_subdivisions=subdivisions, size=size)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    return obj


def values(obj, name, srgb=False):
    attr = obj.data.color_attributes[name]
    out = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color_srgb" if srgb else "color", out)
    return out.reshape(-1, 4)


@pytest.fixture
def scene(bpy, addon):
    scene = clean_scene(bpy)
    scene.mc_ao.target = "VERTEX_COLORS"
    scene.mc_ao.samples = 64
    scene.mc_ao.threads = 2
    return scene


def cycles_bake(bpy, scene, obj, name, domain):
    """Cycles' AO bake into a new float colour attribute ``name`` (its active one), N samples."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = N
    scene.cycles.use_adaptive_sampling = False
    attr = obj.data.color_attributes.new(name, "FLOAT_COLOR", domain)
    obj.data.color_attributes.active_color = attr
    select_only(bpy, obj)
    assert bpy.ops.object.bake(type="AO", target="VERTEX_COLORS") == {"FINISHED"}
    return values(obj, name)[:, 0].astype(float)


@pytest.mark.parametrize("domain", ["CORNER", "POINT"])
def test_agrees_with_cycles_bake_into_a_color_attribute(bpy, scene, domain):
    """A grid with a cube resting on it (contact) and one hovering over it: every value of the
    attribute agrees with Cycles' within the noise of the two estimates (binomial at N samples,
    each; Sobol' points are less noisy), and there is no bias over the whole grid."""
    obj = grid(bpy)
    add_cube(bpy, "Resting", size=1.0, location=(0.3, 0.2, 0.5))
    add_cube(bpy, "Hovering", size=0.8, location=(-1.1, -0.9, 0.7))
    reference = cycles_bake(bpy, scene, obj, "CyclesAO", domain)
    scene.mc_ao.samples = N
    scene.mc_ao.attribute_domain = domain
    select_only(bpy, obj)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    ao = values(obj, "AO")
    assert obj.data.color_attributes["AO"].domain == domain
    assert obj.data.color_attributes["AO"].data_type == "FLOAT_COLOR"
    np.testing.assert_array_equal(ao[:, 3], 1.0)
    np.testing.assert_array_equal(ao[:, 0], ao[:, 1])
    mine = ao[:, 0].astype(float)
    count = len(obj.data.loops) if domain == "CORNER" else len(obj.data.vertices)
    assert len(mine) == count
    a = np.clip((mine + reference) / 2, 1 / N, 1 - 1 / N)
    sigma = np.sqrt(2 * a * (1 - a) / N)
    d = mine - reference
    assert np.all(np.abs(d) < 5 * sigma + 1e-3), (np.abs(d / sigma).max(), np.abs(d).max())
    assert abs(d.mean()) < 4 * np.sqrt((sigma ** 2).sum()) / len(d) + 1e-4, d.mean()
    # The scene has every kind of point: open, partly occluded, and in contact under the resting cube.
    assert mine.max() > 0.95 and mine.min() < 0.05 and np.any((mine > 0.3) & (mine < 0.8))


def test_point_domain_is_the_mean_of_the_corners_and_bytes_are_srgb(bpy, scene):
    """The same bake in both domains (same seed): each vertex's value is the plain mean of its
    corners' (Cycles' rule); a byte attribute stores the sRGB encoding of the linear AO."""
    obj = grid(bpy, subdivisions=6)
    add_cube(bpy, "Block", size=1.0, location=(0.2, 0.1, 0.7))
    select_only(bpy, obj)
    scene.mc_ao.attribute_domain = "CORNER"
    scene.mc_ao.attribute_name = "Corners"
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    corners = values(obj, "Corners")[:, 0].astype(float)
    scene.mc_ao.attribute_domain = "POINT"
    scene.mc_ao.attribute_name = "Points"
    scene.mc_ao.float_buffer = False
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    attr = obj.data.color_attributes["Points"]
    assert (attr.data_type, attr.domain) == ("BYTE_COLOR", "POINT")
    verts = np.array([loop.vertex_index for loop in obj.data.loops])
    mean = np.bincount(verts, weights=corners) / np.bincount(verts)
    srgb = values(obj, "Points", srgb=True)[:, 0]
    x = np.clip(mean, 0, 1)
    want = np.where(x < 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(srgb, want, atol=0.6 / 255 + 1e-6)
    assert np.ptp(mean) > 0.2  # the block darkens some vertices


@pytest.mark.parametrize("existing, settings, message", [
    (("AO", "FLOAT_COLOR", "CORNER"), {}, r"Grid: color attribute 'AO' is a float color on the Face Corner "
                                          r"domain, the bake would write a float color on the Vertex domain; "
                                          r"set Domain to Face Corner"),
    (("AO", "BYTE_COLOR", "POINT"), {}, r"Grid: color attribute 'AO' is a byte color .* turn 32-bit Float off"),
    (("AO", "FLOAT", "POINT"), {}, r"Grid: its mesh 'Grid' has an attribute 'AO' of type FLOAT .* not a color"),
])
def test_an_attribute_of_another_type_or_domain_is_refused_by_name(bpy, scene, existing, settings, message):
    obj = grid(bpy, subdivisions=2)
    name, kind, domain = existing
    obj.data.attributes.new(name, kind, domain)
    before = {a.name: (a.data_type, a.domain) for a in obj.data.attributes}
    select_only(bpy, obj)
    session, reports = new_session()
    assert not session.start(bpy.context, live=False)
    assert reports and reports[-1][0] == "ERROR"
    import re
    assert re.search(message, reports[-1][1]), reports[-1][1]
    assert {a.name: (a.data_type, a.domain) for a in obj.data.attributes} == before


def test_modifiers_that_change_the_corners_are_refused_and_deforming_ones_baked(bpy, scene):
    obj = grid(bpy, subdivisions=3)
    obj.modifiers.new("Subdivision", "SUBSURF")
    select_only(bpy, obj)
    session, reports = new_session()
    assert not session.start(bpy.context, live=False)
    assert "Grid: its modifiers change the mesh" in reports[-1][1]
    assert obj.data.color_attributes.get("AO") is None
    obj.modifiers.clear()
    wave = obj.modifiers.new("Displace", "DISPLACE")
    wave.strength = 0.3
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    assert len(values(obj, "AO")) == len(obj.data.vertices)


def test_meshes_without_uv_maps_are_baked_and_a_shared_mesh_is_refused(bpy, scene):
    obj = grid(bpy, subdivisions=2)
    while obj.data.uv_layers:
        obj.data.uv_layers.remove(obj.data.uv_layers[0])
    twin = bpy.data.objects.new("Twin", obj.data)
    bpy.context.scene.collection.objects.link(twin)
    select_only(bpy, obj)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}  # no UV map needed
    obj.data.color_attributes.remove(obj.data.color_attributes["AO"])
    select_only(bpy, obj, twin)
    session, reports = new_session()
    assert not session.start(bpy.context, live=False)
    assert "Grid and Twin share the mesh 'Grid'" in reports[-1][1]
    assert obj.data.color_attributes.get("AO") is None


def test_esc_leaves_the_mesh_as_it_was_and_a_finished_bake_is_one_undo_step(bpy, scene, monkeypatch):
    """Nothing is written before the object's bake ends: Esc in the middle leaves no attribute.
    A finished bake is one undo step: Ctrl-Z removes the attribute it created, Ctrl-Shift-Z brings
    it back with its values."""
    import threading

    import core

    obj = grid(bpy, subdivisions=6)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.7))
    select_only(bpy, obj)
    held = threading.Event()
    real = core.bake

    def holding(*args, progress=None, cancel=None, **kwargs):
        def step(fraction):
            held.set()
            cancel.wait(30)
            if progress is not None:
                progress(fraction)
        return real(*args, progress=step, cancel=cancel, **kwargs)

    monkeypatch.setattr(core, "bake", holding)
    session, reports = new_session()
    assert session.start(bpy.context, live=True)
    tick_until(bpy, session, held.is_set)
    assert session.on_event(bpy.context, "ESC") == {"CANCELLED"}
    assert obj.data.color_attributes.get("AO") is None
    monkeypatch.setattr(core, "bake", real)

    bpy.ops.ed.undo_push(message="before the bake")
    assert bpy.ops.object.mc_ao_bake("EXEC_DEFAULT", True) == {"FINISHED"}
    baked = values(bpy.data.objects["Grid"], "AO")
    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert bpy.data.objects["Grid"].data.color_attributes.get("AO") is None
    assert bpy.ops.ed.redo() == {"FINISHED"}
    np.testing.assert_array_equal(values(bpy.data.objects["Grid"], "AO"), baked)


def test_save_to_file_writes_the_ply_of_each_object(bpy, scene, tmp_path):
    from core.files.plyio import read_ply

    obj = grid(bpy, subdivisions=3)
    add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.7))
    select_only(bpy, obj)
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = str(tmp_path / "out")
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    positions, sizes, verts, ao, meta = read_ply(tmp_path / "out" / "Grid_AO.ply")
    assert len(positions) == len(obj.data.vertices) and len(sizes) == len(obj.data.polygons)
    np.testing.assert_allclose(ao, values(obj, "AO")[:, 0], atol=1e-6)
    assert meta["object"] == "Grid" and meta["domain"] == "point" and meta["attribute"] == "AO"


def test_adaptive_sampling_of_color_attributes_uses_the_error_model(bpy, scene):
    """Noise Threshold on a colour-attribute bake: two replicates, corners far from the cube stop at
    Min Samples, shaded ones go on; the attribute holds the core's values for the job."""
    from mc_ao import baking, vertex_colors
    from mc_ao.settings import BakeSettings

    obj = grid(bpy)
    add_cube(bpy, "Hovering", size=0.8, location=(-1.1, -0.9, 0.7))
    scene.mc_ao.samples, scene.mc_ao.min_samples, scene.mc_ao.target_error = 512, 32, 0.02
    scene.mc_ao.max_distance = 1.0
    scene.mc_ao.attribute_domain = "CORNER"
    select_only(bpy, obj)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    got = values(obj, "AO")[:, 0].astype(float)
    settings = BakeSettings.from_properties(scene.mc_ao)
    assert settings.replicates == 2 and settings.bake_kwargs()["replicates"] == 2
    (job,) = baking.plan(bpy.context.evaluated_depsgraph_get(), [obj], settings, selected=[obj])
    r = job.run(settings, threads=2)
    assert r.metadata["replicates"] == 2
    np.testing.assert_allclose(got, vertex_colors.values(r, job.target.extra, "CORNER"), atol=1e-6)
    assert r.samples.min() == 32 and r.samples.max() > 64
    assert np.all(r.samples[r.ao < 0.9] > 32)


def test_the_error_map_does_not_count_for_color_attributes(bpy, scene):
    """A colour attribute has no room for the standard error: the panel greys Error Map out with the
    Image section, and a greyed-out setting does not count: the bake goes ahead without an error map
    (the script refuses --stderr with --target vertex-colors: tests/blender/test_blender_script_targets.py)."""
    obj = grid(bpy, subdivisions=2)
    scene.mc_ao.error_map = True
    select_only(bpy, obj)
    session, reports = new_session()
    assert session.start(bpy.context, live=False)
    assert tick_until(bpy, session, lambda: False) == {"FINISHED"}
    assert obj.data.color_attributes.get("AO") is not None
    assert not [image for image in bpy.data.images if image.name.endswith("_stderr")]


def test_the_button_is_greyed_with_the_reason_when_modifiers_make_the_bake_impossible(bpy, scene):
    from mc_ao import operators

    obj = grid(bpy, subdivisions=2)
    obj.modifiers.new("Subdivision", "SUBSURF")
    select_only(bpy, obj)
    bpy.context.view_layer.update()  # the UI draws the button after the depsgraph evaluated the modifier
    assert scene.mc_ao.target == "VERTEX_COLORS"
    assert not bpy.ops.object.mc_ao_bake.poll()
    assert operators.why_not(bpy.context).startswith("Grid: its modifiers change the mesh")
    obj.modifiers.clear()
    bpy.context.view_layer.update()
    assert bpy.ops.object.mc_ao_bake.poll() and operators.why_not(bpy.context) is None
