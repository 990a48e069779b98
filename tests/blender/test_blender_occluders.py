"""Which objects occlude (mc_ao.occluders), Only Local, Occludes Other Objects, the ground, the
quantity and the channel, in the real bpy: through the operator as the panel sets them, through the
script, and against Cycles' own bake of the same scene.

The scene: a 4 x 4 floor (the baked object) with box A over its left half and box B over its right
half, 0.1 above it; max distance 1. A box darkens the half under it (mean AO about 0.85 there); the
other half stays open (about 0.996).
"""

import math
import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_cube, add_plane, clean_scene, image_ao, run_bake, select_only

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
DARK, OPEN = 0.93, 0.98  # a half under a box is below DARK, an open one above OPEN (measured: 0.85, 0.996)


def run(bpy, capfd):
    """bpy.ops.object.mc_ao_bake() as a script calls it: (result, error, reports)."""
    result, error, out = run_bake(bpy, capfd)
    reports = [tuple(line.split(": ", 1)) for line in out.splitlines() if line.startswith(("Info:", "Warning:",
                                                                                            "Error:"))]
    return result, error, reports


def move_to(obj, collection):
    for c in list(obj.users_collection):
        c.objects.unlink(obj)
    collection.objects.link(obj)


def new_collection(bpy, name, parent=None):
    collection = bpy.data.collections.new(name)
    (parent or bpy.context.scene.collection).children.link(collection)
    return collection


@pytest.fixture(autouse=True)
def no_collections(bpy, addon):
    """Each test starts without the collections and node groups of the one before."""
    for collection in list(bpy.data.collections):
        bpy.data.collections.remove(collection)
    for group in list(bpy.data.node_groups):
        bpy.data.node_groups.remove(group)


def floor_and_boxes(bpy, scene):
    """Floor, box A in collection Occ, box B in Occ's child Carve."""
    s = scene.mc_ao
    s.max_distance, s.margin, s.processes = 1.0, 0, 1
    floor = add_plane(bpy, "Floor", size=4)
    a = add_cube(bpy, "A", size=0.8, location=(-1, 0, 0.5))
    b = add_cube(bpy, "B", size=0.8, location=(1, 0, 0.5))
    occ = new_collection(bpy, "Occ")
    carve = new_collection(bpy, "Carve", occ)
    move_to(a, occ)
    move_to(b, carve)
    return floor, a, b


def set_collections(bpy, scene, include=(), exclude=()):
    s = scene.mc_ao
    for name, names in (("occluder_collections", include), ("exclude_collections", exclude)):
        items = getattr(s, name)
        items.clear()
        for n in names:
            items.add().collection = bpy.data.collections[n]


def bake_halves(bpy, capfd, target):
    """Bake ``target`` through the operator: (mean AO of the left half, of the right half)."""
    for image in list(bpy.data.images):
        bpy.data.images.remove(image)
    bpy.context.view_layer.update()  # objects and collections made through bpy.data join the view layer
    select_only(bpy, target)
    result, error, reports = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None), reports
    ao, _ = image_ao(bpy.data.images[f"{target.name}_AO"])
    w = ao.shape[1]
    return float(ao[:, : w // 2].mean()), float(ao[:, w // 2:].mean())


def dark(value):
    return value < DARK


def is_open(value):
    return value > OPEN


# -- what counts as rendered ------------------------------------------------------------------------

@pytest.mark.parametrize("how, counts", [
    ("eye", True), ("viewport", True), ("render", False),
    ("collection_viewport", True), ("collection_render", False), ("collection_excluded", False),
    ("layer_hidden", True),
])
def test_all_rendered_counts_what_cycles_bake_counts(bpy, scene, capfd, how, counts):
    floor, a, b = floor_and_boxes(bpy, scene)
    carve = bpy.data.collections["Carve"]
    layer = bpy.context.view_layer.layer_collection.children["Occ"].children["Carve"]
    if how == "eye":
        b.hide_set(True)
    elif how == "viewport":
        b.hide_viewport = True
    elif how == "render":
        b.hide_render = True
    elif how == "collection_viewport":
        carve.hide_viewport = True
    elif how == "collection_render":
        carve.hide_render = True
    elif how == "collection_excluded":
        layer.exclude = True
    elif how == "layer_hidden":
        layer.hide_viewport = True
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left)
    assert dark(right) if counts else is_open(right), (how, right)


def test_a_viewport_disabled_object_with_modifiers_is_noted(bpy, scene, capfd):
    floor, a, b = floor_and_boxes(bpy, scene)
    b.modifiers.new("Bevel", "BEVEL")
    b.hide_viewport = True
    select_only(bpy, floor)
    result, error, reports = run(bpy, capfd)
    assert result == {"FINISHED"}
    assert any("B is disabled in viewports" in m and "without its modifiers" in m for _, m in reports), reports


# -- Include and Exclude ---------------------------------------------------------------------------

def test_include_takes_the_collection_and_the_collections_inside_it(bpy, scene, capfd):
    floor, a, b = floor_and_boxes(bpy, scene)
    set_collections(bpy, scene, include=["Occ"])
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left) and dark(right)
    set_collections(bpy, scene, include=["Carve"])
    left, right = bake_halves(bpy, capfd, floor)
    assert is_open(left) and dark(right)


def test_excluding_a_collection_inside_an_included_one_carves_it_out_and_back(bpy, scene, capfd):
    floor, a, b = floor_and_boxes(bpy, scene)
    set_collections(bpy, scene, include=["Occ"], exclude=["Carve"])
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left) and is_open(right)
    # the nearer collection decides: Carve (B's own) is included, Occ around it excluded
    set_collections(bpy, scene, include=["Carve"], exclude=["Occ"])
    left, right = bake_halves(bpy, capfd, floor)
    assert is_open(left) and dark(right)
    # Exclude alone: every rendered object but those
    set_collections(bpy, scene, exclude=["Carve"])
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left) and is_open(right)


def test_an_object_that_both_lists_claim_equally_is_refused_by_name(bpy, scene, capfd):
    floor, a, b = floor_and_boxes(bpy, scene)
    other = new_collection(bpy, "Other")
    other.objects.link(a)  # A directly in Occ and in Other
    set_collections(bpy, scene, include=["Occ"], exclude=["Other"])
    select_only(bpy, floor)
    result, error, reports = run(bpy, capfd)
    assert result is None and "Floor_AO" not in bpy.data.images
    assert "A is in the occluder collection 'Occ' and the excluded collection 'Other' alike" in error, error


def bad_plan(bpy, floor, **settings):
    from mc_ao import baking
    from mc_ao.extract import ExtractError
    from mc_ao.settings import BakeSettings

    with pytest.raises(ExtractError) as info:
        baking.plan(bpy.context.evaluated_depsgraph_get(), [floor], BakeSettings(**settings), selected=[floor])
    return str(info.value)


def test_bad_collections_are_refused_before_any_work_naming_them(bpy, scene, capfd):
    floor, a, b = floor_and_boxes(bpy, scene)
    new_collection(bpy, "Empty")
    bpy.data.collections.new("Elsewhere").objects.link(bpy.data.objects.new("Lone", None))  # in no scene
    assert "occluder collection 'Nope' does not exist" in bad_plan(bpy, floor, occluder_collections=("Nope",))
    assert "excluded collection 'Nope' does not exist" in bad_plan(bpy, floor, exclude_collections=("Nope",))
    assert "occluder collection 'Empty' is empty" in bad_plan(bpy, floor, occluder_collections=("Empty",))
    assert "'Elsewhere' is not in scene" in bad_plan(bpy, floor, exclude_collections=("Elsewhere",))
    assert "'Occ' is both an occluder collection and an excluded one" in bad_plan(
        bpy, floor, occluder_collections=("Occ",), exclude_collections=("Occ",))
    # and from the panel: the operator reports it, no image is made
    set_collections(bpy, scene, include=["Empty"])
    select_only(bpy, floor)
    result, error, _ = run(bpy, capfd)
    assert result is None and "'Empty' is empty" in error and "Floor_AO" not in bpy.data.images
    # the same list under Only Local, which greys it out: a greyed-out setting does not count, the
    # bake goes ahead (the script, which has no greyed-out options, still refuses such a list)
    scene.mc_ao.only_local = True
    result, error, _ = run(bpy, capfd)
    assert result == {"FINISHED"} and error is None


# -- instances ---------------------------------------------------------------------------------------

def box_instance(bpy, collection, location, name="Instancer"):
    """An empty in ``collection`` instancing collection Src (one box, excluded from the view layer)."""
    src = bpy.data.collections.get("Src")
    if src is None:
        src = new_collection(bpy, "Src")
        box = add_cube(bpy, "SrcBox", size=0.8, location=(0, 0, 0))
        move_to(box, src)
        bpy.context.view_layer.layer_collection.children["Src"].exclude = True
    empty = bpy.data.objects.new(name, None)
    empty.instance_type, empty.instance_collection = "COLLECTION", src
    empty.location = location
    collection.objects.link(empty)
    return empty


@pytest.mark.parametrize("instancer_hidden", [False, True])
def test_collection_instances_belong_to_the_instancers_collections(bpy, scene, capfd, instancer_hidden):
    floor, a, b = floor_and_boxes(bpy, scene)
    bpy.data.objects.remove(b)
    box_instance(bpy, bpy.data.collections["Carve"], (1, 0, 0.5))
    if instancer_hidden:  # hidden instancers have no instances in the viewport: mc_ao places them
        bpy.data.objects["Instancer"].hide_set(True)
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left) and dark(right)
    set_collections(bpy, scene, exclude=["Carve"])
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left) and is_open(right)
    set_collections(bpy, scene, include=["Carve"])
    left, right = bake_halves(bpy, capfd, floor)
    assert is_open(left) and dark(right)
    bpy.data.objects["Instancer"].hide_render = True
    set_collections(bpy, scene)
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left) and is_open(right)


def geometry_nodes_instancer(bpy, source, location):
    """A one-vertex mesh whose geometry nodes put ``source`` on its point."""
    mesh = bpy.data.meshes.new("Point")
    mesh.from_pydata([(0, 0, 0)], [], [])
    obj = bpy.data.objects.new("Scatter", mesh)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    group = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    inp, out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    info, place = nodes.new("GeometryNodeObjectInfo"), nodes.new("GeometryNodeInstanceOnPoints")
    info.inputs["Object"].default_value = source
    links.new(inp.outputs[0], place.inputs["Points"])
    links.new(info.outputs["Geometry"], place.inputs["Instance"])
    links.new(place.outputs[0], out.inputs[0])
    obj.modifiers.new("Scatter", "NODES").node_group = group
    return obj


def test_geometry_nodes_instances_count_with_their_instancer(bpy, scene, capfd):
    floor, a, b = floor_and_boxes(bpy, scene)
    b.hide_render = True  # B itself does not occlude; the instance of it does
    scatter = geometry_nodes_instancer(bpy, b, (1, 0, 0.5))
    bpy.context.view_layer.update()
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left) and dark(right)
    scatter.mc_ao.occlude_others = False  # the instancer's setting is its instances'
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left) and is_open(right)


# -- Occludes Other Objects, Only Local -------------------------------------------------------------

def fold(bpy, name="Fold"):
    """One object of two faces meeting at a right angle (a floor and a wall): it occludes itself."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0), (-1, 1, 2), (1, 1, 2)], [],
                     [(0, 1, 2, 3), (3, 2, 5, 4)])
    mesh.uv_layers.new()
    uv = mesh.uv_layers[0].data
    for i, (u, v) in enumerate([(0, 0), (1, 0), (1, 0.5), (0, 0.5), (0, 0.5), (1, 0.5), (1, 1), (0, 1)]):
        uv[i].uv = (u, v)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def test_occludes_other_objects_off_leaves_the_others_but_still_occludes_itself(bpy, scene, capfd):
    floor, a, b = floor_and_boxes(bpy, scene)
    a.mc_ao.occlude_others = False
    left, right = bake_halves(bpy, capfd, floor)
    assert is_open(left) and dark(right)
    # baked itself, an object that occludes only itself is darkened by itself as before
    for obj in (floor, a, b):
        bpy.data.objects.remove(obj)
    shape = fold(bpy)
    shape.mc_ao.occlude_others = True
    on = bake_halves(bpy, capfd, shape)
    shape.mc_ao.occlude_others = False
    off = bake_halves(bpy, capfd, shape)
    assert on == off and on[0] < DARK  # bit-identical, and the fold darkens itself


@pytest.mark.parametrize("how", ["only_local", "SELF"])
def test_only_local_leaves_each_object_to_itself(bpy, scene, capfd, how):
    floor, a, b = floor_and_boxes(bpy, scene)
    if how == "only_local":
        scene.mc_ao.only_local = True
    else:
        scene.mc_ao.occluders = "SELF"
    # cosine directions on a flat floor with no occluder: every ray escapes, AO is exactly 1
    select_only(bpy, floor)
    assert run(bpy, capfd)[0] == {"FINISHED"}
    ao, alpha = image_ao(bpy.data.images["Floor_AO"])
    assert (ao[alpha > 0] == 1.0).all()
    scene.mc_ao.only_local = False
    scene.mc_ao.occluders = "VISIBLE"
    left, right = bake_halves(bpy, capfd, floor)
    assert dark(left) and dark(right)


# -- against Cycles ----------------------------------------------------------------------------------

RES, SPP, DISTANCE = 24, 256, 1.0


def cycles_floor_ao(bpy, floor):
    """Cycles' AO bake of ``floor`` (what renders occludes), as bench/comparators/cycles.py runs it."""
    scene = bpy.context.scene
    engine = scene.render.engine
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device, c.samples, c.use_denoising, c.use_adaptive_sampling, c.seed = "CPU", SPP, False, False, 0
    scene.render.threads_mode, scene.render.threads = "FIXED", 2
    scene.world = scene.world or bpy.data.worlds.new("World")
    scene.world.light_settings.distance = DISTANCE
    owner = floor if hasattr(floor, "shadow_terminator_geometry_offset") else floor.cycles
    owner.shadow_terminator_geometry_offset = 0.0
    image = bpy.data.images.new("Cycles_AO", RES, RES, alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    mat = bpy.data.materials.new("Bake")
    if mat.node_tree is None:
        mat.use_nodes = True
    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    mat.node_tree.nodes.active = node
    floor.data.materials.clear()
    floor.data.materials.append(mat)
    select_only(bpy, floor)
    bpy.ops.object.bake(type="AO", margin=0, use_clear=True)
    ao = image_ao(image)[0].copy()
    bpy.data.images.remove(image)
    floor.data.materials.clear()
    scene.render.engine = engine
    return ao


def assert_agrees(mc, cyc):
    # Per texel the two estimates' variances add, each at most the binomial AO (1 - AO) / n of
    # independent samples (both bakers' stratified samples do better): the agreement bounds of
    # test_blender_selected_to_active.
    d = (cyc - mc).astype(np.float64)
    se = np.sqrt(np.sum(2 * (mc * (1 - mc)) / SPP)) / d.size
    assert abs(d.mean()) < 4 * se + 2e-3, (d.mean(), se)
    noise = np.mean(np.sqrt(2 * mc * (1 - mc) / SPP)) * math.sqrt(2 / math.pi)
    print(f"against Cycles: mean difference {d.mean():.5f} (standard error {se:.5f}), mean absolute difference "
          f"{np.abs(d).mean():.5f} (noise {noise:.5f})")
    assert np.abs(d).mean() < 1.3 * noise + 0.005, (np.abs(d).mean(), noise)


def test_exclude_agrees_with_cycles_baking_with_those_objects_hidden_from_render(bpy, scene, capfd):
    floor, a, b = floor_and_boxes(bpy, scene)
    hidden = add_cube(bpy, "Hidden", size=0.6, location=(0, 1.2, 0.4))
    hidden.hide_set(True)  # hidden by eye: renders, so it occludes in both
    s = scene.mc_ao
    s.resolution, s.samples, s.max_distance = RES, SPP, DISTANCE
    b.hide_render = True
    cyc = cycles_floor_ao(bpy, floor)
    b.hide_render = False
    set_collections(bpy, scene, exclude=["Carve"])
    select_only(bpy, floor)
    assert run(bpy, capfd)[0] == {"FINISHED"}
    mc, _ = image_ao(bpy.data.images["Floor_AO"])
    assert (cyc[:, : RES // 2] < 0.9).any() and (cyc[:, RES // 2:] > 0.99).mean() > 0.5  # A shows, B does not
    assert_agrees(mc, cyc)


# -- ground, quantity, channel from the panel ---------------------------------------------------------

def wall_ao(z, distance):
    """AO of a point on a vertical wall at height z over an endless ground, rays up to ``distance``."""
    a = np.clip(z / distance, 0.0, 1.0)
    return 1 - (np.arccos(a) - a * np.sqrt(1 - a * a)) / np.pi


@pytest.mark.parametrize("ground, height, below", [("AUTO", 0.0, 0.0), ("HEIGHT", -0.5, 0.5)])
def test_the_ground_from_the_panel_occludes_a_wall_as_the_formula_says(bpy, scene, capfd, ground, height, below):
    s = scene.mc_ao
    s.resolution, s.samples, s.max_distance, s.margin, s.processes = 16, 64, 1.0, 0, 1
    s.ground, s.ground_height = ground, height
    # a 2 x 2 wall from z = 0 to 2 facing along x: u = 0 at its top, u = 1 at its foot
    wall = add_plane(bpy, "Wall", size=2, location=(0, 0, 1), rotation=(0, math.pi / 2, 0))
    select_only(bpy, wall)
    assert run(bpy, capfd)[0] == {"FINISHED"}
    ao, _ = image_ao(bpy.data.images["Wall_AO"])
    w = ao.shape[1]
    # each column's texels cover heights over the column's width: the formula averaged over it
    sub = (np.arange(w)[:, None] + (np.arange(64)[None, :] + 0.5) / 64) / w
    expected = wall_ao(2 * (1 - sub) + below, s.max_distance).mean(axis=1)
    column = ao.mean(axis=0)
    se = np.sqrt(np.maximum(expected * (1 - expected), 1e-4) / s.samples / ao.shape[0])
    assert (np.abs(column - expected) < 4 * se + 2e-3).all(), np.c_[column, expected, se]
    assert column[-1] < 0.9  # the foot of the wall is darkened (the test can fail)


def test_quantity_thickness_and_both_from_the_panel(bpy, scene, capfd):
    s = scene.mc_ao
    s.max_distance, s.processes, s.margin = 1.0, 1, 0
    box = add_cube(bpy, "Slab", size=1.0)

    def bake(*quantities):
        for image in list(bpy.data.images):
            bpy.data.images.remove(image)
        s.quantity = set(quantities)
        select_only(bpy, box)
        assert run(bpy, capfd)[0] == {"FINISHED"}
        return {name: image_ao(bpy.data.images[name])[0] for name in ("Slab_AO", "Slab_Thickness")
                if name in bpy.data.images}

    ao = bake("AO")["Slab_AO"]
    thick = bake("THICKNESS")
    assert list(thick) == ["Slab_Thickness"]
    thick = thick["Slab_Thickness"]
    covered = ao == 1.0  # a lone convex box: every AO ray escapes where it is baked; 0 elsewhere
    assert covered.mean() > 0.3 and (ao[~covered] == 0).all()
    # a unit cube, rays of length 1 into it: most meet the far side (dark)
    assert 0 < thick[covered].mean() < 0.5 and thick.max() <= 1
    both = bake("AO", "THICKNESS")
    np.testing.assert_array_equal(both["Slab_AO"], ao)  # each the same bake as alone
    np.testing.assert_array_equal(both["Slab_Thickness"], thick)


def test_a_channel_is_checked_against_the_image_before_any_work(bpy, scene, capfd, tmp_path):
    import dataclasses

    from core.files import imageio
    from mc_ao import baking
    from mc_ao.settings import BakeSettings

    floor = add_plane(bpy, "Floor", size=4)
    s = scene.mc_ao
    select_only(bpy, floor)
    rgb = tmp_path / "orm.png"
    imageio.write_image(str(rgb), np.full((8, 8, 3), 0.5, np.float32), bits=8)
    image = bpy.data.images.load(str(rgb))
    s.channel, s.into = "A", image
    result, error, _ = run(bpy, capfd)
    assert result is None and "image 'orm.png' has no A channel (it has 3: R, G, B)" in error, error
    s.channel = "R"
    result, error, _ = run(bpy, capfd)
    # the image has a red channel, but not the bake's size: refused, rather than baking somewhere else
    assert result is None and "image 'orm.png' is 8x8, not the bake's 24x24" in error, error
    assert "Floor_AO" not in bpy.data.images
    # a file: core.files.imageio's check names it and the channels it has
    settings = BakeSettings(channel="A", into=str(rgb), resolution=8)
    assert "orm.png" in baking.channel_problem(settings, {}) and "A" in baking.channel_problem(settings, {})
    assert baking.channel_problem(dataclasses.replace(settings, channel="G"), {}) is None  # it has G, 8 x 8
    s.into = None
    result, error, _ = run(bpy, capfd)
    assert result is None and "into" in error.lower(), error


# -- the script --------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def blend_file(bpy, addon, tmp_path_factory):
    scene = clean_scene(bpy)
    floor, a, b = floor_and_boxes(bpy, scene)
    a.mc_ao.occlude_others = False
    path = tmp_path_factory.mktemp("occluders") / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def run_script(*args):
    return subprocess.run([sys.executable, SCRIPT, *map(str, args)], capture_output=True, text=True, timeout=300)


def script_halves(blend_file, tmp_path, *args):
    from core.files import imageio

    out = tmp_path / "out"
    proc = run_script(blend_file, "--objects", "Floor", "--samples", "16", "--resolution", "24", "--margin", "0",
                      "--max-distance", "1", "--threads", "2", "--processes", "1", "--output", out, "--format",
                      "exr", "--bits", "float", *args)
    assert proc.returncode == 0, proc.stderr
    ao, metadata = imageio.read_image(str(out / "Floor_AO.exr"))
    ao = ao[..., 0] if ao.ndim == 3 else ao
    return (float(ao[:, :12].mean()), float(ao[:, 12:].mean())), metadata, out


def test_the_script_reads_occludes_other_objects_from_the_file(blend_file, tmp_path):
    # A does not occlude others (saved with the file), B does; the script has no add-on registered
    (left, right), metadata, _ = script_halves(blend_file, tmp_path)
    assert is_open(left) and dark(right)
    assert "occluder_collections" not in metadata and "only_local" not in metadata


def test_the_script_takes_collections_only_local_ground_and_both_quantities(blend_file, tmp_path):
    (left, right), metadata, _ = script_halves(blend_file, tmp_path, "--exclude-collections", "Carve")
    assert is_open(left) and is_open(right) and metadata["exclude_collections"] == "Carve"
    (left, right), metadata, _ = script_halves(blend_file, tmp_path, "--only-local", "--ground-height", "-0.2")
    assert metadata["only_local"] is True or metadata["only_local"] in (1, "1", "True", "true")
    assert metadata["ground"] == "height" and float(metadata["ground_height"]) == -0.2
    assert left == right == 1.0  # only the floor itself, and a ground below it that it faces away from
    (left, right), metadata, out = script_halves(blend_file, tmp_path, "--quantity", "ao", "thickness", "--ground")
    assert sorted(p.name for p in out.iterdir()) == ["Floor_AO.exr", "Floor_Thickness.exr"]
    assert metadata["ground"] == "auto" and left == right == 0.0  # the floor lies on its ground: in contact
    from core.files import imageio

    assert imageio.read_image(str(out / "Floor_Thickness.exr"))[1]["map"] == "thickness"


@pytest.mark.parametrize("args, message", [
    (["--occluder-collections", "Nope"], "occluder collection 'Nope' does not exist"),
    (["--exclude-collections", "Occ", "--occluder-collections", "Occ"], "remove it from one list"),
    (["--channel", "R", "--into", "Nope"], "there is no image named 'Nope'"),
    (["--channel", "R", "--into", "missing.png"], "missing.png"),
    (["--ground", "--ground-height", "1"], "--ground and --ground-height both place the ground"),
])
def test_the_script_refuses_bad_input_with_exit_2_naming_it(blend_file, tmp_path, args, message):
    out = tmp_path / "out"
    proc = run_script(blend_file, "--objects", "Floor", "--samples", "4", "--resolution", "8", "--output", out, *args)
    assert proc.returncode == 2 and message in proc.stderr, proc.stderr
    assert not out.exists() or not any(out.iterdir())


# -- the panel -----------------------------------------------------------------------------------------

def test_the_panel_adds_and_removes_collections_and_shows_every_new_setting(bpy, scene):
    import types

    from mc_ao import panel

    occ = new_collection(bpy, "Occ")
    new_collection(bpy, "Other")
    bpy.context.view_layer.active_layer_collection = bpy.context.view_layer.layer_collection.children["Occ"]
    s = scene.mc_ao
    assert bpy.ops.mc_ao.collection_add(setting="occluder_collections") == {"FINISHED"}
    assert [i.collection for i in s.occluder_collections] == [occ]  # the active collection, to start with
    assert bpy.ops.mc_ao.collection_add(setting="occluder_collections") == {"FINISHED"}
    assert [i.collection for i in s.occluder_collections] == [occ, None]  # listed already: an empty picker
    s.occluder_collections[1].collection = bpy.data.collections["Other"]
    assert bpy.ops.mc_ao.collection_remove(setting="occluder_collections", index=0) == {"FINISHED"}
    assert [i.collection.name for i in s.occluder_collections] == ["Other"]
    from mc_ao.settings import BakeSettings

    assert BakeSettings.from_properties(s).occluder_collections == ("Other",)
    drawn = []

    class Recorder:
        def __getattr__(self, name):
            if name == "prop":
                return lambda data, prop, **kw: drawn.append(prop)
            return lambda *a, **k: self

        def __setattr__(self, name, value):
            pass

    floor = add_plane(bpy, "Floor")
    select_only(bpy, floor)
    for cls in (panel.VIEW3D_PT_mc_ao_occlusion, panel.VIEW3D_PT_mc_ao_target, panel.VIEW3D_PT_mc_ao_image,
                panel.VIEW3D_PT_mc_ao_object):
        cls.draw(types.SimpleNamespace(layout=Recorder(), split_layout=lambda: Recorder()), bpy.context)
    for name in ("only_local", "occluders", "collection", "ground", "ground_height", "quantity", "channel", "into",
                 "occlude_others"):
        assert name in drawn, name
    # every new setting has a tooltip (its description)
    rna = type(s).bl_rna.properties
    for name in ("occluder_collections", "exclude_collections", "only_local", "ground", "ground_height", "quantity",
                 "channel", "into"):
        assert len(rna[name].description) > 20, name
    assert len(floor.mc_ao.bl_rna.properties["occlude_others"].description) > 20


def test_instances_agree_with_cycles_also_under_a_hidden_instancer(bpy, scene, capfd):
    # B as a collection instance whose instancer is hidden by eye (the viewport makes no instances for
    # it; mc_ao places them) and A as a geometry-nodes instance: Cycles renders both.
    floor, a, b = floor_and_boxes(bpy, scene)
    bpy.data.objects.remove(b)
    instancer = box_instance(bpy, bpy.data.collections["Carve"], (1, 0, 0.5))
    instancer.hide_set(True)
    a.hide_render = True  # A itself does not occlude; its instance does
    geometry_nodes_instancer(bpy, a, (-1, 0, 0.5))
    bpy.context.view_layer.update()
    s = scene.mc_ao
    s.resolution, s.samples, s.max_distance = RES, SPP, DISTANCE
    cyc = cycles_floor_ao(bpy, floor)
    left, right = bake_halves(bpy, capfd, floor)
    mc, _ = image_ao(bpy.data.images["Floor_AO"])
    assert dark(left) and dark(right)
    assert_agrees(mc, cyc)


def test_a_skipped_object_that_occludes_only_itself_is_not_said_to_occlude(bpy, scene, capfd):
    floor, a, b = floor_and_boxes(bpy, scene)
    while a.data.uv_layers:
        a.data.uv_layers.remove(a.data.uv_layers[0])
    a.mc_ao.occlude_others = False
    select_only(bpy, floor, a)
    result, error, reports = run(bpy, capfd)
    assert result == {"FINISHED"}
    assert ("Warning", "A: skipped, it has no UV map (unwrap it first: Edit Mode, U)") in reports, reports


def test_both_quantities_keep_an_error_map_each(bpy, scene, capfd, tmp_path):
    s = scene.mc_ao
    s.max_distance, s.processes, s.error_map = 1.0, 1, True
    s.quantity = {"AO", "THICKNESS"}
    s.save_to_file, s.output_dir, s.file_format = True, str(tmp_path), "OPEN_EXR"
    box = add_cube(bpy, "Slab", size=1.0)
    select_only(bpy, box)
    result, error, reports = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None), reports
    for name in ("Slab_AO", "Slab_AO_stderr", "Slab_Thickness", "Slab_Thickness_stderr"):
        assert name in bpy.data.images, name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Slab_AO.exr", "Slab_AO_stderr.exr", "Slab_Thickness.exr",
                                                          "Slab_Thickness_stderr.exr"]
    from core.files import imageio

    assert imageio.read_image(str(tmp_path / "Slab_Thickness.exr"))[1]["map"] == "thickness"
    assert "map" not in imageio.read_image(str(tmp_path / "Slab_AO.exr"))[1]
