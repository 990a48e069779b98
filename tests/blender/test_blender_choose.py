"""One chooser of objects (mc_ao.choose) for the operator, its poll, the panel and the script: from the
same selection they take the same objects and leave out the same ones, and what differs is said where
each front end differs (the script falls back to every mesh, names objects, pairs by suffix)."""

import pytest

from blender_helpers import add_cube, add_plane, clean_scene, select_only

pytestmark = pytest.mark.blender


@pytest.fixture
def scene(bpy, addon):
    scene = clean_scene(bpy)
    ground = add_plane(bpy, "Ground")
    block = add_cube(bpy, "Block", size=1.0, location=(0, 0, 0.6))
    flat = add_plane(bpy, "Flat", location=(5, 0, 0))
    flat.data.uv_layers.remove(flat.data.uv_layers[0])
    bpy.ops.object.light_add(type="POINT")
    bpy.context.active_object.name = "Lamp"
    return scene, ground, block, flat


def script_pick(bpy, **options):
    from mc_ao.choose import Pick

    layer = bpy.context.view_layer.objects
    return Pick([o for o in layer if o.select_get()], layer.active, script=True, **options)


def names(objects):
    return sorted(o.name for o in objects)


def test_the_operator_and_the_script_take_the_same_objects_from_one_selection(bpy, scene):
    from mc_ao import operators
    from mc_ao.choose import Pick, choose
    from mc_ao.settings import BakeSettings

    _, ground, block, flat = scene
    select_only(bpy, block, ground, flat, bpy.data.objects["Lamp"])
    settings = BakeSettings.from_properties(bpy.context.scene.mc_ao)
    ui = choose(settings, Pick(list(bpy.context.selected_objects), bpy.context.active_object), bpy.context.view_layer)
    script = choose(settings, script_pick(bpy), bpy.context.view_layer)
    assert [o.name for o in ui.targets] == [o.name for o in script.targets] == ["Block", "Ground"]
    assert names(ui.skipped) == names(script.skipped) == ["Flat", "Lamp"]
    # The poll and the panel read the same choice.
    choice, reason = operators.choice_of(bpy.context)
    assert reason is None and [o.name for o in choice.targets] == ["Block", "Ground"]
    # "Selected" occluders: the operator's whole selection, the script's baked objects.
    assert names(ui.occluding) == ["Block", "Flat", "Ground", "Lamp"] and names(script.occluding) == ["Block", "Ground"]
    # Their jobs are the same objects' geometry.
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert [j.object_name for j in ui.jobs(depsgraph)] == [j.object_name for j in script.jobs(depsgraph)]


def test_nothing_bakeable_selected_the_operator_refuses_and_the_script_takes_every_mesh(bpy, scene):
    from mc_ao import operators
    from mc_ao.choose import ChoiceError, Pick, choose
    from mc_ao.settings import BakeSettings

    _, ground, block, flat = scene
    select_only(bpy, flat)
    settings = BakeSettings()
    with pytest.raises(ChoiceError, match=r"^Flat has no UV map"):
        choose(settings, Pick([flat], flat), bpy.context.view_layer)
    assert operators.why_not(bpy.context).startswith("Flat has no UV map")
    choice = choose(settings, script_pick(bpy), bpy.context.view_layer)
    assert names(choice.targets) == ["Block", "Ground"] and choice.skipped == []
    assert choice.notes == ["no mesh with a UV map is selected; baking every mesh with a UV map: Block, Ground"]


def test_named_objects_and_suffix_pairs(bpy, scene):
    from mc_ao.choose import ChoiceError, choose
    from mc_ao.settings import BakeSettings

    _, ground, block, flat = scene
    select_only(bpy)
    layer = bpy.context.view_layer
    with pytest.raises(ChoiceError, match=r"^Flat has no UV map"):  # named: an error, not skipped
        choose(BakeSettings(), script_pick(bpy, names=("Ground", "Flat")), layer)
    with pytest.raises(ChoiceError, match=r"^no object 'Nope' in the view layer; its meshes: Block, Flat, Ground$"):
        choose(BakeSettings(), script_pick(bpy, names=("Nope",)), layer)
    block.name, ground.name = "Box_high", "Box_low"
    add_plane(bpy, "Lone_low")
    select_only(bpy)
    settings = BakeSettings(use_selected_to_active=True)
    choice = choose(settings, script_pick(bpy, match_suffix=("_high", "_low")), layer)
    assert [o.name for o in choice.targets] == ["Box_low"]
    assert names(choice.sources["Box_low"]) == ["Box_high", "Box_low"]
    assert choice.notes == ["Lone_low: skipped, there is no Lone_high"]
