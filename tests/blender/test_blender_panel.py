"""The panel never surprises: a greyed-out setting does not count, Bake AO greys out with the reason
where the bake would be refused after the click (cheap checks only), the panel's rows stay the same
over every combination of settings, the summaries say what went where and what occluded it, the
image-name token is {object}, Only Local says whether the ground counts, a preview in Selected to
Active shows the low-poly's AO. (What only a window shows, tests/gui/panel.sh checks in Blender 4.3.)
"""

import itertools
import types

import numpy as np
import pytest

from blender_helpers import add_cube, add_plane, pattern_image, run_bake as run, select_only

pytestmark = pytest.mark.blender


def floor_and_box(bpy):
    floor = add_plane(bpy, "Floor", size=4)
    box = add_cube(bpy, "Box", size=1.0, location=(0, 0, 0.8))
    return floor, box


# -- a greyed-out setting does not count ------------------------------------------------------------

def test_into_left_set_after_channel_goes_back_to_own_image_bakes(bpy, scene, capfd):
    """Channel Red with an Into image, then Channel back to Own Image (Into greys out): Bake AO bakes,
    and the image Into still names is untouched."""
    floor, _ = floor_and_box(bpy)
    select_only(bpy, floor)
    s = scene.mc_ao
    before = pattern_image(bpy, "ORM", 24, 24)
    orm = bpy.data.images["ORM"]
    s.channel, s.into = "R", orm
    s.channel = "NONE"
    assert s.into == orm  # still set, greyed out
    assert bpy.ops.object.mc_ao_bake.poll()
    result, error, out = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None), out
    assert np.array_equal(np.array(bpy.data.images["ORM"].pixels[:]).reshape(before.shape), before)


@pytest.mark.parametrize("greyed", ["error map on a color attribute", "collections under Only Local",
                                    "image settings on a color attribute"])
def test_other_greyed_out_settings_do_not_count(bpy, scene, capfd, greyed):
    from mc_ao.settings import BakeSettings

    floor, _ = floor_and_box(bpy)
    select_only(bpy, floor)
    s = scene.mc_ao
    if greyed == "error map on a color attribute":
        s.target, s.error_map = "VERTEX_COLORS", True
    elif greyed == "collections under Only Local":
        empty = bpy.data.collections.new("Empty")
        scene.collection.children.link(empty)
        s.occluder_collections.add().collection = empty
        s.exclude_collections.add().collection = empty  # both lists: refused when not greyed out
        s.only_local = True
    else:
        s.target, s.channel, s.image_name = "VERTEX_COLORS", "R", "Shared"
    settings = BakeSettings.from_properties(s)
    assert [name for name in ("error_map", "occluder_collections", "channel", "image_name") if settings.greyed(name)]
    result, error, out = run(bpy, capfd)
    assert (result, error) == ({"FINISHED"}, None), out


def test_every_greyed_out_setting_is_one_the_schema_has_and_the_panel_greys(addon):
    """mc_ao.settings.GREYED names settings of the schema; in_effect() puts each at its default."""
    from mc_ao.schema import BY_NAME
    from mc_ao.settings import GREYED, BakeSettings

    assert set(GREYED) <= set(BY_NAME)
    odd = BakeSettings(target="VERTEX_COLORS", channel="R", into="ORM", error_map=True, only_local=True,
                       occluder_collections=("A",), ground="OFF", ground_height=2.0, target_error=0.0,
                       min_samples=4, bent_normals=False, bent_space="OBJECT", save_to_file=False,
                       output_dir="/x", use_selected_to_active=False, use_cage=True, cage_extrusion=0.5)
    shown = odd.in_effect()
    for name in GREYED:
        assert odd.greyed(name), name  # every greyed setting is greyed out in this combination
        expected = BY_NAME[name].default if name not in ("into", "cage_object") else ""
        assert getattr(shown, name) == expected, name
    assert shown.target == "VERTEX_COLORS" and shown.only_local  # what greys them out stays


# -- Bake AO greys out with the reason ----------------------------------------------------------------

def reason(bpy):
    from mc_ao import operators

    assert not bpy.ops.object.mc_ao_bake.poll()
    return operators.why_not(bpy.context)


def test_two_objects_into_one_image_grey_the_button_out(bpy, scene):
    floor, box = floor_and_box(bpy)
    select_only(bpy, floor, box)
    scene.mc_ao.image_name = "Shared"
    assert "would both bake into image 'Shared': put {object} into the Image name, or set Images to One for All" in reason(bpy)
    scene.mc_ao.image_name = "{object}_Shared"
    assert bpy.ops.object.mc_ao_bake.poll()


def test_a_stale_into_greys_the_button_out(bpy, scene):
    floor, _ = floor_and_box(bpy)
    select_only(bpy, floor)
    s = scene.mc_ao
    orm = bpy.data.images.new("ORM", 64, 64)
    s.channel, s.into = "R", orm
    assert "Into image 'ORM' is 64x64, not the bake's 24x24: set Size to 64" in reason(bpy)
    s.resolution = 64
    assert bpy.ops.object.mc_ao_bake.poll()
    s.image_name = "ORM"  # its own image and the Into image at once
    assert "is both Floor's own image and the Into image" in reason(bpy)


def test_an_image_of_the_wrong_kind_greys_the_button_out(bpy, scene):
    floor, _ = floor_and_box(bpy)
    select_only(bpy, floor)
    bpy.data.images.new("Floor_AO", 8, 8, tiled=True)
    assert "image 'Floor_AO' is a tiled image" in reason(bpy)
    scene.mc_ao.use_udim = True
    assert bpy.ops.object.mc_ao_bake.poll()


def test_the_poll_reads_no_file(bpy, scene, tmp_path):
    """An Into image from a file not loaded yet: the poll does not load it (no file access at every
    redraw); the check after the click reads its size."""
    floor, _ = floor_and_box(bpy)
    select_only(bpy, floor)
    pattern_image(bpy, "OnDisk", 32, 32)
    image = bpy.data.images["OnDisk"]
    path = tmp_path / "ondisk.png"
    image.save_render(str(path))
    bpy.data.images.remove(image)
    on_disk = bpy.data.images.load(str(path))
    assert not on_disk.has_data
    scene.mc_ao.channel, scene.mc_ao.into = "R", on_disk
    assert bpy.ops.object.mc_ao_bake.poll()
    assert not on_disk.has_data


# -- the panel's rows stay the same --------------------------------------------------------------------

class RowCounter:
    """A layout that records the shape of what a panel draws: for each column (and the panel itself),
    in the order they are made, how many rows it holds; an item in a column is a row, a row() of items
    (a collection picker and its remove button) one. Two draws of the same shape take the same pixels:
    a column more or less moves what is below it by its spacing, as a row does by its height."""

    def __init__(self, shape, in_row=False):
        object.__setattr__(self, "_shape", shape)
        object.__setattr__(self, "_in_row", in_row)
        object.__setattr__(self, "_counted", False)
        object.__setattr__(self, "_index", len(shape))
        if not in_row:
            shape.append(0)

    def __setattr__(self, name, value):
        pass

    def _item(self, *args, **kwargs):
        if not self._in_row or not self._counted:
            self._shape[self._index if not self._in_row else self._parent] += 1
            object.__setattr__(self, "_counted", True)
        return types.SimpleNamespace()

    label = prop = operator = prop_search = _item

    def column(self, *args, **kwargs):
        return self if self._in_row else RowCounter(self._shape)

    box = column

    def row(self, *args, **kwargs):
        if self._in_row:
            return self
        child = RowCounter(self._shape, True)
        object.__setattr__(child, "_parent", self._index)
        return child

    split = row


def rows_of(bpy, cls):
    shape = []
    fake = types.SimpleNamespace(layout=RowCounter(shape), split_layout=lambda: fake.layout)
    cls.draw(fake, bpy.context)
    return tuple(shape)


SETTINGS_MATRIX = {
    "target": ["IMAGE_TEXTURES", "VERTEX_COLORS"],
    "quantity": [{"AO"}, {"THICKNESS"}, {"AO", "THICKNESS"}],
    "use_selected_to_active": [False, True],
    "use_cage": [False, True],
    "channel": ["NONE", "R"],
    "only_local": [False, True],
    "ground": ["OFF", "HEIGHT"],
    "bent_normals": [False, True],
    "use_udim": [False, True],
    "target_error": [0.0, 0.01],
    "denoise": [False, True],
}


def test_the_panels_rows_are_the_same_over_every_combination_of_settings(bpy, scene):
    """Every panel draws the same number of rows whatever the settings (a wrapped line, a row that
    comes and goes, would move everything below it under the pointer). Each setting of the matrix
    takes each of its values at least once beside every value of every other (pairwise), with the
    selection the bake would take, a reason it would not, and a last bake's line."""
    from mc_ao import operators, panel

    floor, box = floor_and_box(bpy)
    orm = bpy.data.images.new("ORM", 24, 24)
    classes = [getattr(panel, n) for n in dir(panel) if n.startswith("VIEW3D_PT_mc_ao")]
    seen = {cls.__name__: set() for cls in classes}
    names = list(SETTINGS_MATRIX)
    combos = set()
    for a, b in itertools.combinations(names, 2):
        for va, vb in itertools.product(range(len(SETTINGS_MATRIX[a])), range(len(SETTINGS_MATRIX[b]))):
            combos.add(tuple(va if n == a else vb if n == b else 0 for n in names))
    selections = [(floor,), (floor, box), ()]
    outcomes = [None, ("INFO", "Floor: 24x24 into 'Floor_AO' in 0.01 s, 16 samples per texel, " * 3)]
    for i, combo in enumerate(sorted(combos)):
        s = scene.mc_ao
        for name, index in zip(names, combo):
            setattr(s, name, SETTINGS_MATRIX[name][index])
        s.into = orm
        objects = selections[i % len(selections)]
        select_only(bpy, *objects)
        if objects:
            bpy.context.view_layer.objects.active = objects[-1]
        operators.last_outcome = outcomes[i % 2]
        for cls in classes:
            if not hasattr(cls, "poll") or cls.poll(bpy.context):  # as Blender shows it (Object: an active object)
                seen[cls.__name__].add(rows_of(bpy, cls))
    operators.last_outcome = None
    assert {name: sorted(rows) for name, rows in seen.items() if len(rows) != 1} == {}
    assert len(combos) > 50


# -- what the summaries say ----------------------------------------------------------------------------

def test_the_summary_says_what_occluded_the_bake_and_where_the_ground_was(bpy, scene, capfd):
    from mc_ao import operators

    floor, box = floor_and_box(bpy)
    select_only(bpy, box)
    s = scene.mc_ao
    s.ground, s.ground_height = "HEIGHT", -0.25
    result, error, _ = run(bpy, capfd)
    assert result == {"FINISHED"}
    assert operators.last_outcome[1].endswith("; occluded by itself and 1 other object and the ground at -25 cm")
    s.ground, s.only_local = "AUTO", True
    result, error, _ = run(bpy, capfd)
    # Only Local leaves the other objects out, not the ground: at the box's own lowest point
    assert operators.last_outcome[1].endswith("; occluded by itself alone and the ground at 30 cm")


def test_the_summary_names_the_channel_packing_target(bpy, scene, capfd):
    from mc_ao import operators

    floor, _ = floor_and_box(bpy)
    select_only(bpy, floor)
    s = scene.mc_ao
    s.channel, s.into = "G", bpy.data.images.new("ORM", 24, 24)
    result, error, out = run(bpy, capfd)
    assert result == {"FINISHED"}, out
    assert "into 'Floor_AO' and the green channel of 'ORM' in " in operators.last_outcome[1]


def test_lengths_are_in_the_scenes_units(bpy, scene):
    from mc_ao import summaries

    assert summaries.length_text(0.1234) == "12.3 cm"
    scene.unit_settings.system = "IMPERIAL"
    assert summaries.length_text(0.3048).replace(" ", "") in ("1'", "1ft")
    scene.unit_settings.system = "NONE"
    assert summaries.length_text(0.1234) == "0.123 units"
    scene.unit_settings.system = "METRIC"


# -- the Image field's token, Only Local and the ground, the preview --------------------------------

def test_the_image_fields_placeholder_is_the_token_it_takes(addon):
    from mc_ao import panel
    from mc_ao.schema import BY_NAME
    from mc_ao.settings import BakeSettings

    assert panel.IMAGE_NAME_PLACEHOLDER == "{object}_AO"
    assert BakeSettings(image_name=panel.IMAGE_NAME_PLACEHOLDER).image_name_for("Box") == "Box_AO"
    assert "<object>" not in BY_NAME["image_name"].help and '"{object}_AO"' in BY_NAME["image_name"].help


@pytest.mark.parametrize("only_local, ground, words", [
    (False, "OFF", "Occluded by every rendered object"),
    (True, "OFF", "Occluded by each object alone"),
    (True, "AUTO", "Occluded by each object alone, and the ground under each"),
    (True, "HEIGHT", "Occluded by each object alone, and the ground at Z 0.5"),
])
def test_the_occlusion_line_says_whether_the_ground_counts(addon, only_local, ground, words):
    from mc_ao import panel
    from mc_ao.settings import BakeSettings

    settings = BakeSettings(only_local=only_local, ground=ground, ground_height=0.5)
    assert panel.occluded_by(settings.in_effect()) == words
    assert settings.in_effect().ground == ground  # the ground stays in effect under Only Local


def test_a_preview_in_selected_to_active_shows_the_low_polys_ao_alone(bpy, scene, capfd):
    from mc_ao import preview

    low = add_plane(bpy, "Low", size=2)
    high = add_plane(bpy, "High", size=2, location=(0, 0, 0.01))
    select_only(bpy, high, low)
    bpy.context.view_layer.objects.active = low
    scene.mc_ao.use_selected_to_active = True
    assert preview.preview_objects(bpy.context) == [low]
    scene.mc_ao.use_selected_to_active = False
    assert set(preview.preview_objects(bpy.context)) == {low, high}


# -- the estimate prices every setting ----------------------------------------------------------------

def test_the_estimate_prices_every_setting_that_changes_the_work(bpy, scene, monkeypatch):
    """Denoise, a second quantity, UDIM tiles (every tile's texels) and the machine's load each change
    the panel's estimate, in the direction the work does; adaptive sampling says it is the longest."""
    from mc_ao import baking, corelink, panel
    from mc_ao.settings import BakeSettings

    cost_mod = corelink.load("execution.cost")
    monkeypatch.setattr(cost_mod, "machine_load", lambda: (0.0, 2))
    floor, _ = floor_and_box(bpy)
    uv = floor.data.uv_layers.active.data
    for i in range(len(uv)):
        uv[i].uv = (uv[i].uv[0] * 2, uv[i].uv[1])  # over tiles 1001 and 1002
    select_only(bpy, floor)
    s = scene.mc_ao
    s.resolution, s.samples, s.processes, s.threads = 512, 64, 1, 2

    def seconds(**values):
        settings = BakeSettings.from_properties(s, **values).in_effect()
        return baking.bake_cost(settings, [floor], threads=2).seconds

    plain = seconds()
    assert seconds(denoise=True) > plain * 1.05
    assert seconds(quantity=("AO", "THICKNESS")) > plain * 1.6
    assert seconds(use_udim=True) > plain * 1.6  # two tiles' texels, not the one square's
    assert seconds(samples=256) > plain * 3
    monkeypatch.setattr(cost_mod, "machine_load", lambda: (14.0, 2))
    assert seconds() == pytest.approx(8 * plain, rel=0.01)  # 2 of 16 runnable threads' share
    s.target_error = 0.01
    text, _ = panel.cost_text(bpy.context, BakeSettings.from_properties(s).in_effect(), [floor])
    assert text.startswith("Estimate: at most ") or text.startswith("Estimate: under a second")


def test_the_estimate_learns_from_the_bakes_of_the_session(bpy, scene, monkeypatch, capfd):
    """A bake that took twice its estimate moves the next estimates half way there (geometrically);
    bakes under half a second teach nothing."""
    from mc_ao import baking

    monkeypatch.setitem(baking._CALIBRATION, "factor", 1.0)
    baking.learn_from_bake(10.0, 40.0)
    assert baking._CALIBRATION["factor"] == pytest.approx(2.0)
    baking.learn_from_bake(0.2, 4.0)
    assert baking._CALIBRATION["factor"] == pytest.approx(2.0)
    cost = baking.corelink.load("execution.cost").Cost(3.0, 100)
    assert baking.calibrated(cost) == type(cost)(6.0, 100)
    for _ in range(20):
        baking.learn_from_bake(1.0, 1000.0)
    assert baking._CALIBRATION["factor"] == 5.0  # never beyond 5x either way


def test_a_thickness_summary_says_which_distance_it_used(bpy, scene, capfd):
    """Thickness at the default Distance (unlimited): the core takes a twentieth of the object's size,
    and the summary says how far, in the scene's units; with a Distance set, that one."""
    from mc_ao import operators

    _, box = floor_and_box(bpy)
    select_only(bpy, box)
    scene.mc_ao.quantity = {"THICKNESS"}
    result, error, out = run(bpy, capfd)
    assert result == {"FINISHED"}, out
    # the 1 x 1 x 1 box: diagonal sqrt(3), a twentieth of it 8.66 cm
    assert operators.last_outcome[1].endswith("; rays into the mesh up to 8.66 cm (a twentieth of its size: set "
                                              "Distance for another)"), operators.last_outcome
    scene.mc_ao.max_distance = 0.5
    run(bpy, capfd)
    assert operators.last_outcome[1].endswith("; rays into the mesh up to 50 cm"), operators.last_outcome
