"""Selected to Active in Blender, against Cycles' own selected-to-active AO bake.

The operator bakes the selected objects onto the active one into ``<active>_AO`` with Cycles'
settings (``scene.mc_ao.use_selected_to_active``, ``cage_extrusion``, ``max_ray_distance``,
``use_cage``, ``cage_object``); the button, its tooltip and the panel say why it is disabled in this
mode; errors name the objects; the report counts the sample points that missed the high-poly. The
comparison with Cycles bakes a displaced, finely subdivided grid and an occluder onto a flat low
plane below, at and above the high surface.
"""

import math
import types

import numpy as np
import pytest

from blender_helpers import add_cube, add_plane, image_ao, run_bake, select_only

pytestmark = pytest.mark.blender


def run(bpy, capfd):
    """bpy.ops.object.mc_ao_bake() as a script calls it: (result, error, reports)."""
    result, error, out = run_bake(bpy, capfd)
    reports = []
    for line in out.splitlines():
        kind, sep, message = line.partition(": ")
        if sep and kind in ("Info", "Warning", "Error"):
            reports.append((kind.upper(), message))
    return result, error, reports


def sculpt(bpy, name="High", size=2.4, cuts=48, amplitude=0.06, location=(0, 0, 0)):
    """A finely subdivided grid displaced by smooth bumps (a sculpt stand-in), smooth shaded."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts, size=size, location=location)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    co = np.empty(3 * len(obj.data.vertices))
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 2] = amplitude * (np.sin(3.1 * co[:, 0] + 0.4) * np.cos(2.3 * co[:, 1]) + 0.5 * np.sin(7.0 * co[:, 1]))
    obj.data.vertices.foreach_set("co", co.ravel())
    obj.data.update()
    for p in obj.data.polygons:
        p.use_smooth = True
    return obj


def s2a_scene(scene, **settings):
    s = scene.mc_ao
    s.use_selected_to_active = True
    s.cage_extrusion = 0.3
    for key, value in settings.items():
        setattr(s, key, value)
    return s


def panel_labels(bpy):
    from mc_ao import operators, panel

    operators.last_outcome = None  # no "Last bake" line
    labels = []

    class Layout:
        def __getattr__(self, attr):
            return lambda *a, **k: (labels.append(k.get("text", "")) if attr == "label" else None, self)[1]

    panel.VIEW3D_PT_mc_ao.draw(types.SimpleNamespace(layout=Layout()), bpy.context)
    return [t for t in labels if t and not t.startswith("Estimate: ")]  # tested on its own (test_blender_reports)


# -- the operator ---------------------------------------------------------------------------------

def test_bakes_the_selected_objects_onto_the_active_one(bpy, scene, capfd):
    low = add_plane(bpy, "Low", size=2)
    high = sculpt(bpy)
    add_cube(bpy, "Box", size=0.5, location=(0.3, 0.2, 0.45))  # visible: it occludes
    s2a_scene(scene)
    select_only(bpy, low, high)  # the active object last, as in Cycles
    bpy.context.view_layer.objects.active = low
    assert bpy.ops.object.mc_ao_bake.poll()
    assert panel_labels(bpy)[-1:] == ["From High onto Low, into Low_AO"]
    result, error, reports = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None)
    assert "High_AO" not in bpy.data.images and "Box_AO" not in bpy.data.images
    ao, _ = image_ao(bpy.data.images["Low_AO"])
    assert ao.shape == (24, 24) and 0.0 <= ao.min() < ao.max() == 1.0
    kind, text = reports[-1]
    assert kind == "INFO" and text.startswith("Low: 24x24 from High into 'Low_AO' in ")
    assert text.endswith("; no sample point missed the high-poly")
    # The high surface's own AO: the box darkens the texels under it, the bumps' valleys the others.
    under = ao[12:16, 14:18].mean()
    assert under < ao[:, :6].mean() - 0.1


def test_misses_are_counted_and_their_texels_left_to_the_margin(bpy, scene, capfd):
    low = add_plane(bpy, "Low", size=2)
    half = add_plane(bpy, "Half", size=1, location=(-0.5, 0, 0.05))  # covers x < 0 of the low plane, y in [-.5, .5]
    s2a_scene(scene, cage_extrusion=0.1, margin=0)
    select_only(bpy, low, half)
    bpy.context.view_layer.objects.active = low
    result, error, reports = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None)
    points = 24 * 24  # 16 samples a texel: one sample point each
    missed = points - 12 * 12
    assert ("WARNING", f"Low: {missed} texels find no high-poly surface along their rays and are left to the margin; "
                       "a larger extrusion or max ray distance reaches farther") in reports
    kind, text = reports[-1]
    assert kind == "WARNING" and f"; {missed} of {points} sample points missed the high-poly" in text
    assert text.endswith("1 warning before this, in the Info editor")
    ao, alpha = image_ao(bpy.data.images["Low_AO"])
    assert np.all(ao[6:18, :12] == 1.0) and np.all(ao[:, 12:] == 0.0)


def test_the_error_map_and_adaptive_sampling_bake_selected_to_active(bpy, scene, capfd):
    # Error Map and Noise Threshold on (two replicates, adaptive rounds): "<active>_AO_stderr" holds the
    # core's standard error of the same job, 0 where the texels missed the high-poly, > 0 where the box
    # shades the high plane; the rounds stop open texels at Min Samples.
    from mc_ao import selected_to_active
    from mc_ao.settings import BakeSettings

    low = add_plane(bpy, "Low", size=2)
    half = add_plane(bpy, "Half", size=1, location=(-0.5, 0, 0.05))  # covers x < 0 of the low plane, y in [-.5, .5]
    add_cube(bpy, "Box", size=0.2, location=(-0.5, 0.0, 0.25))
    s2a_scene(scene, cage_extrusion=0.1, margin=0, error_map=True, samples=1024, min_samples=16,
              target_error=0.05)
    select_only(bpy, low, half)
    bpy.context.view_layer.objects.active = low
    result, error, reports = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None)
    ao, _ = image_ao(bpy.data.images["Low_AO"])
    se, _ = image_ao(bpy.data.images["Low_AO_stderr"])
    settings = BakeSettings.from_properties(scene.mc_ao)
    assert settings.replicates == 2
    job = selected_to_active.plan(bpy.context.evaluated_depsgraph_get(), low, [low, half], settings,
                                  view_layer=bpy.context.view_layer)
    r = job.run(settings, threads=2)
    np.testing.assert_array_equal(se, r.stderr)
    np.testing.assert_array_equal(ao, r.ao)
    assert r.miss.sum() == 24 * 24 - 12 * 12 and np.all(se[r.miss] == 0)
    shaded = r.mask & (r.ao < 0.95)
    assert shaded.any() and np.all(se[shaded] > 0)
    assert r.samples[r.mask].min() == 16 and r.samples[shaded].max() > 16


def test_several_selected_objects_bake_onto_the_active_one(bpy, scene, capfd):
    # Two halves of a plane at 0.05 (a box is no high-poly: lights and empties are skipped with a
    # warning, meshes and curves are sources), onto the low plane: every point finds one of them.
    low = add_plane(bpy, "Low", size=2)
    left = add_plane(bpy, "Left", size=1, location=(-0.5, 0, 0.05))
    left.scale.y = 2
    right = add_plane(bpy, "Right", size=1, location=(0.5, 0, 0.05))
    right.scale.y = 2
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 3))
    lamp = bpy.context.active_object
    lamp.name = "Lamp"
    s2a_scene(scene, cage_extrusion=0.1, margin=0)
    select_only(bpy, low, left, right, lamp)
    bpy.context.view_layer.objects.active = low
    assert panel_labels(bpy)[-1:] == ["From Left, Right onto Low, into Low_AO"]
    result, error, reports = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None)
    assert ("WARNING", "Lamp: skipped, it is a light, not a mesh") in reports
    kind, text = reports[-1]
    assert text.startswith("Low: 24x24 from Left, Right into 'Low_AO' in ")
    assert text.endswith("; no sample point missed the high-poly; 1 warning before this, in the Info editor")
    ao, _ = image_ao(bpy.data.images["Low_AO"])
    assert np.all(ao == 1.0)  # open planes


def test_cage_object_of_the_extruded_low_poly_bakes_as_the_extrusion(bpy, scene, capfd):
    low = add_plane(bpy, "Low", size=2)
    high = sculpt(bpy)
    s2a_scene(scene, samples=64)
    select_only(bpy, low, high)
    bpy.context.view_layer.objects.active = low
    assert run(bpy, capfd)[0] == {"FINISHED"}
    extruded = image_ao(bpy.data.images["Low_AO"])[0].copy()
    # The low plane extruded by 0.3. Visible, it would occlude as any other object, but as the cage
    # it never does (as in Cycles).
    cage = add_plane(bpy, "Cage", size=2, location=(0, 0, 0.3))
    scene.mc_ao.use_cage = True
    scene.mc_ao.cage_object = cage
    scene.mc_ao.cage_extrusion = 0.0  # not used with a cage object
    select_only(bpy, low, high)
    bpy.context.view_layer.objects.active = low
    result, error, reports = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None), reports
    assert np.array_equal(image_ao(bpy.data.images["Low_AO"])[0], extruded)


def test_cage_without_an_object_extrudes_along_vertex_normals(bpy, scene):
    # Cycles' generated cage is the low-poly always smooth (its vertex normals, not the split
    # mesh's): a flat-shaded cube's corners extrude diagonally.
    from mc_ao import selected_to_active
    from mc_ao.settings import BakeSettings

    cube = add_cube(bpy, "Low", size=2)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.uv.smart_project()
    bpy.ops.object.mode_set(mode="OBJECT")
    high = sculpt(bpy)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for use_cage, corner in ((False, 1.0), (True, 1.0 / math.sqrt(3))):
        settings = BakeSettings(use_selected_to_active=True, use_cage=use_cage, cage_extrusion=0.1)
        job = selected_to_active.plan(depsgraph, cube, [cube, high], settings)
        n = job.target.normals.reshape(-1, 3)
        assert np.allclose(np.abs(n).max(axis=1), corner, atol=1e-6)


def test_the_extrusion_follows_the_low_polys_scale(bpy, scene, capfd):
    from mc_ao import selected_to_active
    from mc_ao.settings import BakeSettings

    low = add_plane(bpy, "Low", size=1)
    high = sculpt(bpy)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    settings = BakeSettings(use_selected_to_active=True, cage_extrusion=0.1)
    low.scale = (2, 2, 2)
    bpy.context.view_layer.update()
    job = selected_to_active.plan(bpy.context.evaluated_depsgraph_get(), low, [low, high], settings)
    assert job.extrusion == pytest.approx(0.2) and job.notes == []
    low.scale = (1, 2, 4)
    bpy.context.view_layer.update()
    job = selected_to_active.plan(bpy.context.evaluated_depsgraph_get(), low, [low, high], settings)
    assert job.extrusion == pytest.approx(0.2)
    assert job.notes == ["Low has a non-uniform scale: the extrusion is applied along its world normals, scaled by "
                         "2 (Cycles scales it per axis); apply the scale (Ctrl A) for the same result as Cycles"]
    del depsgraph


def test_the_low_poly_never_occludes_and_the_occluders_setting_adds_the_others(bpy, scene, capfd):
    low = add_plane(bpy, "Low", size=2, location=(0, 0, 0.2))  # above the high surface: it would hide the box
    high = sculpt(bpy)
    add_cube(bpy, "Box", size=0.5, location=(0.3, 0.2, 0.6))
    s2a_scene(scene, samples=64, cage_extrusion=0.1)
    select_only(bpy, low, high)
    bpy.context.view_layer.objects.active = low
    assert run(bpy, capfd)[0] == {"FINISHED"}
    above = image_ao(bpy.data.images["Low_AO"])[0].copy()
    low.location.z = -0.2
    scene.mc_ao.cage_extrusion = 0.5
    assert run(bpy, capfd)[0] == {"FINISHED"}
    below = image_ao(bpy.data.images["Low_AO"])[0].copy()
    assert np.mean(above == below) > 0.99 and abs(float(np.mean(above - below))) < 1e-3
    scene.mc_ao.occluders = "SELF"  # the high-poly alone: the box no longer darkens it
    assert run(bpy, capfd)[0] == {"FINISHED"}
    alone = image_ao(bpy.data.images["Low_AO"])[0]
    assert alone[12:16, 14:18].mean() > below[12:16, 14:18].mean() + 0.1


# -- what it refuses, and why ----------------------------------------------------------------------

def test_the_button_and_panel_say_why_it_is_disabled_in_this_mode(bpy, scene, capfd):
    from mc_ao import operators

    low = add_plane(bpy, "Low", size=2)
    high = sculpt(bpy)
    s2a_scene(scene)

    def reason():
        assert not bpy.ops.object.mc_ao_bake.poll()
        text = operators.why_not(bpy.context)
        assert panel_labels(bpy)[-1] == text
        result, error, _ = run(bpy, capfd)
        assert result is None and text in error  # the poll message is the error a script sees
        return text

    select_only(bpy, low)
    assert reason() == "Selected to Active: select the high-poly objects to bake from, then Low last"
    select_only(bpy, high, low)
    bpy.context.view_layer.objects.active = None
    assert reason() == "Selected to Active needs an active object: the low-poly to bake onto (select it last)"
    bpy.context.view_layer.objects.active = high  # the sculpt has no UV map
    while high.data.uv_layers:
        high.data.uv_layers.remove(high.data.uv_layers[0])
    assert reason() == ("Selected to Active: the active object High has no UV map (unwrap it first: Edit Mode, U)")
    bpy.ops.object.light_add(type="POINT")
    lamp = bpy.context.active_object
    lamp.name = "Lamp"
    select_only(bpy, lamp, low)
    assert reason() == "Selected to Active: the active object Lamp is a light, not a mesh to bake onto"
    bpy.context.view_layer.objects.active = low
    assert reason() == "Selected to Active: none of the objects selected besides Low has a surface to bake from"
    scene.mc_ao.use_cage = True
    scene.mc_ao.cage_object = low
    select_only(bpy, low, high)
    assert reason() == "Selected to Active: the cage object is Low itself; choose a copy of it, moved outwards"
    scene.mc_ao.use_cage = False
    select_only(bpy, low, high)
    # What Selected to Active does not bake (UDIM tiles, colour attributes, bent normals), said before the selection.
    for prop, value, text in [("target", "VERTEX_COLORS", "set Target to Image Textures"),
                              ("use_udim", True, "turn off UDIM Tiles"), ("bent_normals", True, "turn off Bent Normals")]:
        setattr(scene.mc_ao, prop, value)
        assert text in reason()
        scene.mc_ao.property_unset(prop)
    assert bpy.ops.object.mc_ao_bake.poll()
    scene.mc_ao.use_selected_to_active = False  # the usual bake: each selected mesh with a UV map
    assert bpy.ops.object.mc_ao_bake.poll()


def test_a_cage_of_another_topology_is_refused_naming_both(bpy, scene, capfd):
    low = add_plane(bpy, "Low", size=2)
    high = sculpt(bpy)
    cage = add_plane(bpy, "Cage", size=2.2, location=(0, 0, 0.3))
    mod = cage.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = 1
    s2a_scene(scene, use_cage=True, cage_object=cage)
    select_only(bpy, low, high)
    bpy.context.view_layer.objects.active = low
    result, error, _ = run(bpy, capfd)
    assert result is None
    assert ("the cage object Cage does not have the topology of Low after modifiers (Cage: 9 vertices, 4 faces, "
            "16 corners; Low: 4 vertices, 1 faces, 4 corners): the cage must be a copy of Low with only its "
            "vertices moved") in error
    assert "Low_AO" not in bpy.data.images


def test_every_ray_missing_is_refused_saying_what_to_change(bpy, scene, capfd):
    low = add_plane(bpy, "Low", size=2, location=(0, 0, -0.3))  # below the high surface
    high = sculpt(bpy)
    s2a_scene(scene, cage_extrusion=0.01)  # an extrusion set by hand, too short
    select_only(bpy, low, high)
    bpy.context.view_layer.objects.active = low
    result, error, reports = run(bpy, capfd)
    assert result is None
    assert ("Low: no matching ray from 'Low' found the high-poly surface of 'High', so nothing could be baked: "
            "the high-poly surface lies outside 'Low', up to ") in error
    assert "raise the extrusion above 0.3" in error or "raise the extrusion above 0.4" in error
    assert "Low_AO" not in bpy.data.images
    # Extrusion 0, the default, is measured from the meshes: the same pair bakes.
    scene.mc_ao.cage_extrusion = 0.0
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"} and "Low_AO" in bpy.data.images


def test_settings_are_checked_before_baking(bpy, scene, capfd):
    from mc_ao import schema
    from mc_ao.settings import BakeSettings

    assert schema.problems(BakeSettings(cage_extrusion=-1.0)) == [
        ("cage_extrusion", "must be a finite distance >= 0, not -1.0")]
    assert schema.problems(BakeSettings(max_ray_distance=float("nan"))) == [
        ("max_ray_distance", "must be a distance >= 0 (0 or inf = unlimited), not nan")]
    props = bpy.context.scene.mc_ao.bl_rna.properties
    assert props["cage_extrusion"].hard_min == props["max_ray_distance"].hard_min == 0.0
    # Cycles' names, so that users know them.
    for name in ("use_selected_to_active", "cage_extrusion", "max_ray_distance", "use_cage", "cage_object"):
        assert props[name].name == bpy.types.BakeSettings.bl_rna.properties[name].name


# -- against Cycles -------------------------------------------------------------------------------

RES, SPP, DISTANCE, EXTRUSION = 24, 256, 1.0, 0.3


def cycles_bake(bpy, low, high):
    """Cycles' selected-to-active AO bake of ``high`` onto ``low`` (notes: selected_to_active.md, 6)."""
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device, c.samples, c.use_denoising, c.use_adaptive_sampling, c.seed = "CPU", SPP, False, False, 0
    scene.render.threads_mode, scene.render.threads = "FIXED", 2
    scene.world = scene.world or bpy.data.worlds.new("World")
    scene.world.light_settings.distance = DISTANCE
    # The AO of the surface itself (bench/comparators/cycles.py); Cycles' object setting moved from obj.cycles (4.2)
    # to the object (5.0).
    owner = high if hasattr(high, "shadow_terminator_geometry_offset") else high.cycles
    owner.shadow_terminator_geometry_offset = 0.0
    image = bpy.data.images.new("Cycles_AO", RES, RES, alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    mat = bpy.data.materials.new("Bake")
    if mat.node_tree is None:  # before 5.0 (where Material.use_nodes is deprecated, to go in 6.0)
        mat.use_nodes = True
    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    mat.node_tree.nodes.active = node
    low.data.materials.clear()
    low.data.materials.append(mat)
    select_only(bpy, low, high)
    bpy.context.view_layer.objects.active = low
    bpy.ops.object.bake(type="AO", use_selected_to_active=True, cage_extrusion=EXTRUSION, max_ray_distance=0.0,
                        use_cage=False, margin=0, use_clear=True)
    ao = image_ao(image)[0].copy()
    bpy.data.images.remove(image)
    low.data.materials.clear()
    return ao


@pytest.mark.parametrize("low_z", [-0.15, 0.0, 0.15])
def test_agrees_with_cycles_selected_to_active_with_the_low_plane_below_at_or_above(bpy, scene, capfd, low_z):
    # The sculpt stand-in (bumps of +-0.09) and a hovering box onto a flat low plane 0.15 below,
    # through, or 0.15 above the high surface, extrusion 0.3 (larger than the gap below): in both
    # bakers the matching rays reach the same surface, so each gives the same image at every height
    # (bit for bit in Cycles, notes section 3.2).
    low = add_plane(bpy, "Low", size=2, location=(0, 0, low_z))
    high = sculpt(bpy)
    add_cube(bpy, "Box", size=0.6, location=(0.35, 0.2, 0.45))
    cyc = cycles_bake(bpy, low, high)
    s2a_scene(scene, resolution=RES, samples=SPP, margin=0, max_distance=DISTANCE, cage_extrusion=EXTRUSION)
    select_only(bpy, low, high)
    bpy.context.view_layer.objects.active = low
    result, error, reports = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None), reports
    assert reports[-1][1].endswith("; no sample point missed the high-poly")
    mc, _ = image_ao(bpy.data.images["Low_AO"])
    assert cyc.min() > 0 and (cyc < 0.5).any()  # Cycles baked every texel, and the box shows
    # Mean difference within noise: per texel the two estimates' variances add, each at most the
    # binomial AO (1 - AO) / n of independent samples (both bakers' stratified samples do better).
    # Measured: mean difference 1e-4 against a standard error of 1.2e-3; taking the AO about the
    # low-poly's normal instead of the high-poly's makes it 0.015.
    d = (cyc - mc).astype(np.float64)
    se = np.sqrt(np.sum(2 * (mc * (1 - mc)) / SPP)) / d.size
    assert abs(d.mean()) < 4 * se + 2e-3, (d.mean(), se)
    # Mean absolute difference small: no more than noise of that size makes, plus a little for the
    # two bakers' sample positions (Cycles': near each texel's centre; mc_ao's: over the texel).
    noise = np.mean(np.sqrt(2 * mc * (1 - mc) / SPP)) * math.sqrt(2 / math.pi)
    assert np.abs(d).mean() < 1.3 * noise + 0.005, (np.abs(d).mean(), noise)
