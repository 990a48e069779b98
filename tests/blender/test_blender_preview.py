"""Preview on Object: one click shows the baked AO on the object (multiplied into its
materials' Base Color, or through an object-linked copy where the material is not its own), the
same button removes it and leaves every material as it was, and each is one undo step."""

import numpy as np
import pytest

from blender_helpers import add_cube, add_plane, select_only


def tree_state(material):
    """Everything about a material's node tree a preview could change: nodes, links, Base Colors."""
    tree = material.node_tree
    nodes = sorted((n.name, n.bl_idname, tuple(round(c, 3) for c in n.location)) for n in tree.nodes)
    links = sorted((l.from_node.name, l.from_socket.identifier, l.to_node.name, l.to_socket.identifier)
                   for l in tree.links)
    colours = sorted((n.name, tuple(round(c, 6) for c in n.inputs["Base Color"].default_value))
                     for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    return nodes, links, colours, material.name


def object_state(obj):
    return ([(s.link, s.material.name if s.material else None) for s in obj.material_slots],
            [(m.name if m else None) for m in obj.data.materials], obj.active_material_index,
            sorted(obj.keys()), sorted(m.name for m in __import__("bpy").data.materials))


def principled_material(bpy, name, textured=False):
    """A material whose Principled BSDF's Base Color is a colour, or fed by a Checker Texture."""
    material = bpy.data.materials.new(name)
    if material.node_tree is None:
        material.use_nodes = True
    tree = material.node_tree
    principled = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    principled.inputs["Base Color"].default_value = (0.8, 0.3, 0.2, 1.0)
    if textured:
        checker = tree.nodes.new("ShaderNodeTexChecker")
        tree.links.new(checker.outputs["Color"], principled.inputs["Base Color"])
    return material


def preview(bpy, *objects):
    with bpy.context.temp_override(selected_objects=list(objects), active_object=objects[0]):
        return bpy.ops.object.mc_ao_preview("EXEC_DEFAULT", True)


@pytest.fixture
def baked(bpy, scene):
    """Ground (its own textured material) and Block (no material) with baked AO images."""
    ground = add_plane(bpy, "Ground", size=4)
    ground.data.materials.append(principled_material(bpy, "GroundMat", textured=True))
    block = add_cube(bpy, "Block", size=1.0, location=(0.3, 0, 0.6))
    select_only(bpy, ground, block)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    return ground, block


def test_the_ao_is_multiplied_into_the_base_color_and_removed_exactly(bpy, scene, baked):
    ground, block = baked
    material = ground.material_slots[0].material
    before, objects_before = tree_state(material), object_state(ground)
    assert preview(bpy, ground) == {"FINISHED"}
    tree = material.node_tree
    principled = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    mix = principled.inputs["Base Color"].links[0].from_node
    assert mix.bl_idname == "ShaderNodeMix" and mix.blend_type == "MULTIPLY" and mix.data_type == "RGBA"
    a = next(s for s in mix.inputs if s.identifier == "A_Color")
    b = next(s for s in mix.inputs if s.identifier == "B_Color")
    assert a.links[0].from_node.bl_idname == "ShaderNodeTexChecker"  # what fed Base Color still does
    tex = b.links[0].from_node
    assert tex.bl_idname == "ShaderNodeTexImage" and tex.image == bpy.data.images["Ground_AO"]
    uv = tex.inputs["Vector"].links[0].from_node
    assert uv.bl_idname == "ShaderNodeUVMap" and uv.uv_map == ground.data.uv_layers.active.name
    assert ground.material_slots[0].material == material  # edited in place: it is Ground's own
    assert preview(bpy, ground) == {"FINISHED"}  # the same button again
    assert tree_state(material) == before and object_state(ground) == objects_before


def test_an_object_without_material_gets_a_slot_that_goes_again(bpy, scene, baked):
    ground, block = baked
    before = object_state(block)
    assert preview(bpy, block) == {"FINISHED"}
    slot = block.material_slots[0]
    assert slot.link == "OBJECT" and slot.material.name == "Block (AO preview)"
    tree = slot.material.node_tree
    assert any(n.bl_idname == "ShaderNodeTexImage" and n.image.name == "Block_AO" for n in tree.nodes)
    assert preview(bpy, block) == {"FINISHED"}
    assert object_state(block) == before and len(block.material_slots) == 0


def test_a_shared_material_is_left_alone_and_shown_through_a_copy(bpy, scene, baked):
    ground, block = baked
    shared = ground.material_slots[0].material
    block.data.materials.append(shared)  # now used by both objects
    before, ground_before = tree_state(shared), object_state(ground)
    assert preview(bpy, ground) == {"FINISHED"}
    assert tree_state(shared) == before  # untouched
    slot = ground.material_slots[0]
    assert slot.link == "OBJECT" and slot.material.name == "GroundMat (AO preview)"
    assert block.material_slots[0].material == shared  # the other object sees nothing
    copy_tree = slot.material.node_tree
    assert any(n.bl_idname == "ShaderNodeTexChecker" for n in copy_tree.nodes)  # the copy keeps the look
    assert preview(bpy, ground) == {"FINISHED"}
    assert tree_state(shared) == before and object_state(ground) == ground_before
    assert bpy.data.materials.get("GroundMat (AO preview)") is None


def test_showing_and_removing_are_one_undo_step_each(bpy, scene, baked):
    ground, _ = baked
    material_name = ground.material_slots[0].material.name
    before = tree_state(bpy.data.materials[material_name])
    bpy.ops.ed.undo_push(message="baked")
    assert preview(bpy, ground) == {"FINISHED"}
    shown = tree_state(bpy.data.materials[material_name])
    assert shown != before
    assert bpy.ops.ed.undo() == {"FINISHED"}  # Ctrl-Z: as before the click
    assert tree_state(bpy.data.materials[material_name]) == before
    assert "mc_ao_preview" not in bpy.data.objects["Ground"].keys()
    assert bpy.ops.ed.redo() == {"FINISHED"}  # Ctrl-Shift-Z: shown again
    assert tree_state(bpy.data.materials[material_name]) == shown
    ground = bpy.data.objects["Ground"]
    assert preview(bpy, ground) == {"FINISHED"}  # removed ...
    assert tree_state(bpy.data.materials[material_name]) == before
    assert bpy.ops.ed.undo() == {"FINISHED"}  # ... and the removal undone
    assert tree_state(bpy.data.materials[material_name]) == shown


def test_preview_survives_save_and_reopen_and_is_removed_after(bpy, scene, baked, tmp_path):
    ground, _ = baked
    before = tree_state(ground.material_slots[0].material)
    assert preview(bpy, ground) == {"FINISHED"}
    path = str(tmp_path / "preview.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    ground = bpy.data.objects["Ground"]
    assert preview(bpy, ground) == {"FINISHED"}
    assert tree_state(ground.material_slots[0].material) == before


def test_color_attribute_bakes_show_through_a_color_attribute_node(bpy, scene):
    ground = add_plane(bpy, "Ground", size=4)
    ground.data.materials.append(principled_material(bpy, "GroundMat"))
    add_cube(bpy, "Block", size=1.0, location=(0.3, 0, 0.6))
    other = ground.data.color_attributes.new("Paint", "FLOAT_COLOR", "POINT")
    ground.data.color_attributes.active_color = other
    select_only(bpy, ground)
    scene.mc_ao.target = "VERTEX_COLORS"
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    before = tree_state(ground.material_slots[0].material)
    assert preview(bpy, ground) == {"FINISHED"}
    nodes = ground.material_slots[0].material.node_tree.nodes
    attr = next(n for n in nodes if n.bl_idname == "ShaderNodeVertexColor")
    assert attr.layer_name == "AO" and ground.data.color_attributes.active_color.name == "AO"
    assert preview(bpy, ground) == {"FINISHED"}
    assert tree_state(ground.material_slots[0].material) == before
    assert ground.data.color_attributes.active_color.name == "Paint"


def test_an_object_with_nothing_baked_is_told_so(bpy, scene):
    plane = add_plane(bpy, "Fresh", size=2)
    with bpy.context.temp_override(selected_objects=[plane], active_object=plane):
        with pytest.raises(RuntimeError, match="Fresh: it has no baked image 'Fresh_AO' yet: bake it first"):
            bpy.ops.object.mc_ao_preview()
    assert len(plane.material_slots) == 0 and "mc_ao_preview" not in plane.keys()
    np.testing.assert_equal(len(bpy.data.materials), 0)


def test_preview_is_greyed_with_the_reason_until_something_is_baked(bpy, scene):
    plane = add_plane(bpy, "Fresh", size=2)
    with bpy.context.temp_override(selected_objects=[plane], active_object=plane):
        assert not bpy.ops.object.mc_ao_preview.poll()
    select_only(bpy, plane)
    scene.mc_ao.resolution, scene.mc_ao.samples = 8, 2
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    with bpy.context.temp_override(selected_objects=[plane], active_object=plane):
        assert bpy.ops.object.mc_ao_preview.poll()
