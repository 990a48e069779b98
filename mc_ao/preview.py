"""Preview on Object: the baked AO shown on the object in the viewport with one click, removed by the next.

How (the Mix node's sockets looked up by identifier, the same on Blender 4.2 and 5.0):

- a material of the object's that is its own (local, used by this object alone) and shades with a
  Principled BSDF: the AO is multiplied into the Base Color there. Between whatever fed Base Color
  (a link, or its colour) and the input go a Mix node (Multiply, factor 1) and the AO's source (an
  Image Texture of the AO image through a UV Map node of the bake's UV map, or a Color Attribute
  node of the AO attribute). The added nodes carry the tag ``node["mc_ao_preview"]``, and the Mix
  node remembers the link it replaced (node name and socket identifier): removing the preview
  relinks it and deletes the tagged nodes, and only those;
- any other material (shared with other objects, linked from a library, without nodes, without a
  Principled BSDF) is left untouched: the object's slot shows a copy of it with the same insertion
  (or, where the copy has no Principled BSDF, a plain preview material: base colour times AO)
  through an object-linked slot; removal puts the slot's link and material back and deletes the copy;
- an object without material slots gets one object-linked slot with a preview material, removed again;
- what was changed is recorded on the object (``obj["mc_ao_preview"]``, JSON), so removal works after
  saving and reopening the file too; a 3D Viewport in Solid or Wireframe shading is switched to
  Material Preview (and back on removal, if it still shows Material Preview).

The operator has the UNDO flag: showing and removing are one undo step each, and Ctrl-Z after either
gives back the materials exactly as they were.
"""

import json

import bpy

from . import baking
from .extract import default_uv_map
from .settings import BakeSettings

TAG = "mc_ao_preview"
RECORD = "mc_ao_preview"
COPY_SUFFIX = " (AO preview)"


def _sock(collection, identifier):
    return next(s for s in collection if s.identifier == identifier)


def has_preview(obj):
    return obj is not None and RECORD in obj.keys()


def source_of(obj, settings):
    """("IMAGE", image) or ("ATTRIBUTE", name) of the object's baked AO, or (None, reason)."""
    if settings.target == "VERTEX_COLORS":
        name = settings.attribute_name
        if obj.type != "MESH" or obj.data.color_attributes.get(name) is None:
            return None, f"it has no color attribute {name!r} yet: bake it first"
        return "ATTRIBUTE", name
    name = settings.image_name_for(obj.name, baking.id_name_max_bytes())
    image = bpy.data.images.get(name)
    if image is None:
        return None, f"it has no baked image {name!r} yet: bake it first"
    return "IMAGE", image


def _active_output(tree):
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    for node in outputs:
        if node.is_active_output:
            return node
    return outputs[0] if outputs else None


def _principled_nodes(tree):
    """The Principled BSDF nodes that shade the material: reachable from its active output's Surface."""
    out = _active_output(tree)
    if out is None:
        return []
    found, seen, todo = [], set(), [out.inputs["Surface"]]
    while todo:
        socket = todo.pop()
        for link in socket.links:
            node = link.from_node
            if node.name in seen:
                continue
            seen.add(node.name)
            if node.bl_idname == "ShaderNodeBsdfPrincipled":
                found.append(node)
            else:
                todo.extend(s for s in node.inputs if s.type == "SHADER")
    return found


def _uses_nodes(material):
    """Whether the material shades with its node tree (always from Blender 5.0, whose
    Material.use_nodes is deprecated and warns when read)."""
    if material.node_tree is None:
        return False
    return True if bpy.app.version >= (5, 0, 0) else material.use_nodes


def _own(material):
    """Whether the preview may edit ``material`` itself: local, used by one object slot, with nodes."""
    users = material.users - (1 if material.use_fake_user else 0)
    return material.library is None and users <= 1 and _uses_nodes(material) and _principled_nodes(material.node_tree)


def _insert(material, kind, source, uv_map):
    """Multiply the AO into the Base Color of every Principled BSDF of ``material``; True if any."""
    tree = material.node_tree
    nodes, links = tree.nodes, tree.links
    done = False
    for principled in _principled_nodes(tree):
        base = principled.inputs["Base Color"]
        x, y = principled.location
        mix = nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        mix.blend_type = "MULTIPLY"
        mix.clamp_result = False
        mix.label = "AO preview"
        mix.location = (x - 220, y - 40)
        _sock(mix.inputs, "Factor_Float").default_value = 1.0
        a = _sock(mix.inputs, "A_Color")
        a.default_value = tuple(base.default_value)
        if base.is_linked:
            link = base.links[0]
            mix["mc_ao_from"] = [link.from_node.name, link.from_socket.identifier]
            links.new(link.from_socket, a)
        if kind == "IMAGE":
            tex = nodes.new("ShaderNodeTexImage")
            tex.image = source
            tex.label = "AO"
            tex.location = (x - 520, y - 160)
            uv = nodes.new("ShaderNodeUVMap")
            uv.uv_map = uv_map or ""
            uv.location = (x - 720, y - 220)
            links.new(uv.outputs["UV"], tex.inputs["Vector"])
            added = [tex, uv]
            nodes.active = tex  # Solid shading's Texture color shows the active image node
        else:
            tex = nodes.new("ShaderNodeVertexColor")
            tex.layer_name = source
            tex.label = "AO"
            tex.location = (x - 520, y - 160)
            added = [tex]
        links.new(tex.outputs["Color"], _sock(mix.inputs, "B_Color"))
        links.new(_sock(mix.outputs, "Result_Color"), base)
        for node in [mix] + added:
            node[TAG] = 1
            node.name = f"{TAG} {node.bl_idname}"
        done = True
    return done


def _remove_inserted(material):
    """Undo _insert(): relink what each preview Mix node replaced, delete the tagged nodes."""
    tree = material.node_tree
    if tree is None:
        return
    nodes, links = tree.nodes, tree.links
    for mix in [n for n in nodes if TAG in n.keys() and n.bl_idname == "ShaderNodeMix"]:
        targets = [link.to_socket for link in _sock(mix.outputs, "Result_Color").links]
        origin = mix.get("mc_ao_from")
        source = None
        if origin is not None:
            node = nodes.get(origin[0])
            if node is not None:
                source = next((s for s in node.outputs if s.identifier == origin[1]), None)
        for socket in targets:
            for link in list(socket.links):
                links.remove(link)
            if source is not None:
                links.new(source, socket)
    for node in [n for n in nodes if TAG in n.keys()]:
        nodes.remove(node)


def _preview_material(name, colour, kind, source, uv_map):
    """A material of its own: a Principled BSDF whose Base Color is ``colour`` times the AO."""
    material = bpy.data.materials.new(name)
    if material.node_tree is None:
        material.use_nodes = True
    tree = material.node_tree
    principled = next((n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"), None)
    if principled is None:
        principled = tree.nodes.new("ShaderNodeBsdfPrincipled")
        out = _active_output(tree) or tree.nodes.new("ShaderNodeOutputMaterial")
        tree.links.new(principled.outputs["BSDF"], out.inputs["Surface"])
    principled.inputs["Base Color"].default_value = tuple(colour)
    _insert(material, kind, source, uv_map)
    material[TAG] = 1
    return material


def show(obj, settings, space=None):
    """Show the AO on ``obj``; returns None, or why not (a sentence without the object's name)."""
    if has_preview(obj):
        return None
    kind, source = source_of(obj, settings)
    if kind is None:
        return source
    uv_map = (settings.uv_map or default_uv_map(obj.data)) if kind == "IMAGE" else ""
    record = {"slots": [], "added_slot": False, "shading": None, "active_material_index": obj.active_material_index}
    slots = obj.material_slots
    if len(slots) == 0:
        obj.data.materials.append(None)
        record["added_slot"] = True
    for index, slot in enumerate(obj.material_slots):
        material = slot.material
        entry = {"index": index, "link": slot.link,
                 "object_material": slot.material.name if slot.link == "OBJECT" and slot.material is not None else ""}
        if material is not None and _own(material):
            _insert(material, kind, source, uv_map)
            entry.update(mode="insert", material=material.name)
        else:
            if material is not None and _uses_nodes(material):
                copy = material.copy()
                copy.name = material.name + COPY_SUFFIX
                if copy.library is None and _insert(copy, kind, source, uv_map):
                    copy[TAG] = 1
                    preview = copy
                else:
                    bpy.data.materials.remove(copy)
                    preview = None
            else:
                preview = None
            if preview is None:
                colour = material.diffuse_color if material is not None else (0.8, 0.8, 0.8, 1.0)
                base = material.name if material is not None else obj.name
                preview = _preview_material(base + COPY_SUFFIX, colour, kind, source, uv_map)
            slot.link = "OBJECT"
            slot.material = preview
            entry.update(mode="object", material=preview.name)
        record["slots"].append(entry)
    if kind == "ATTRIBUTE":
        attrs = obj.data.color_attributes
        record["active_color"] = attrs.active_color.name if attrs.active_color is not None else ""
        attrs.active_color = attrs[source]
    if space is not None and space.type == "VIEW_3D" and space.shading.type in {"SOLID", "WIREFRAME"}:
        record["shading"] = space.shading.type
        space.shading.type = "MATERIAL"
    obj[RECORD] = json.dumps(record)
    return None


def hide(obj, space=None):
    """Remove the preview of ``obj`` exactly (see the module docstring)."""
    if not has_preview(obj):
        return
    try:
        record = json.loads(obj[RECORD])
    except (TypeError, ValueError):
        record = {"slots": []}
    slots = obj.material_slots
    for entry in record.get("slots", []):
        index = entry.get("index", -1)
        if entry.get("mode") == "insert":
            material = bpy.data.materials.get(entry.get("material", ""))
            if material is not None:
                _remove_inserted(material)
        elif 0 <= index < len(slots):
            slot = slots[index]
            preview = slot.material if slot.link == "OBJECT" else None
            if entry.get("object_material"):
                slot.material = bpy.data.materials.get(entry["object_material"])
            elif slot.link == "OBJECT":
                slot.material = None
            slot.link = entry.get("link", "DATA")
            name = entry.get("material", "")
            copy = bpy.data.materials.get(name)
            if copy is not None and TAG in copy.keys() and copy.users == 0:
                bpy.data.materials.remove(copy)
            elif preview is not None and TAG in preview.keys() and preview.users == 0:
                bpy.data.materials.remove(preview)
    if record.get("added_slot") and len(obj.material_slots):
        # The object's slot too (Mesh.materials.pop() leaves the object's own slot count as it was).
        obj.active_material_index = len(obj.material_slots) - 1
        with bpy.context.temp_override(object=obj):
            bpy.ops.object.material_slot_remove()
    if "active_material_index" in record:
        obj.active_material_index = record["active_material_index"]
    if record.get("active_color"):
        attrs = obj.data.color_attributes
        if attrs.get(record["active_color"]) is not None:
            attrs.active_color = attrs[record["active_color"]]
    if record.get("shading") and space is not None and space.type == "VIEW_3D" \
            and space.shading.type == "MATERIAL":
        space.shading.type = record["shading"]
    del obj[RECORD]


def preview_objects(context):
    """The selected meshes whose AO a preview shows: with Selected to Active on, the active object alone
    (the low-poly that was baked; the high-poly objects have no AO of their own to show)."""
    meshes = [obj for obj in context.selected_objects if obj.type == "MESH"]
    props = getattr(context.scene, "mc_ao", None)
    if props is not None and props.use_selected_to_active:
        return [obj for obj in meshes if obj is context.active_object]
    return meshes


class OBJECT_OT_mc_ao_preview(bpy.types.Operator):
    bl_idname = "object.mc_ao_preview"
    bl_label = "Preview AO on Object"
    bl_description = (
        "Show the baked AO on the selected objects, multiplied into their materials' Base Color (a "
        "shared or library material is left as it is: the object shows a copy), in Material Preview; "
        "click again to remove it, exactly. One undo step either way"
    )
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        meshes = preview_objects(context)
        if not meshes:
            cls.poll_message_set("Select a mesh object that has a baked AO")
            return False
        if any(has_preview(obj) for obj in meshes):
            return True  # the click removes it
        # Greyed out, with the reason, where no selected mesh has a baked AO to show yet.
        settings = BakeSettings.from_properties(context.scene.mc_ao).in_effect()
        reasons = [(obj, source_of(obj, settings)) for obj in meshes]
        missing = [(obj, why) for obj, (kind, why) in reasons if kind is None]
        if len(missing) == len(meshes):
            obj, why = missing[0]
            cls.poll_message_set(f"{obj.name}: {why}")
            return False
        return True

    def execute(self, context):
        settings = BakeSettings.from_properties(context.scene.mc_ao).in_effect()
        objects = preview_objects(context)
        space = context.space_data if context.area is not None and context.area.type == "VIEW_3D" else None
        active = context.active_object if context.active_object in objects else objects[0]
        if has_preview(active):
            for obj in objects:
                hide(obj, space)
            self.report({"INFO"}, f"AO preview removed from {', '.join(o.name for o in objects)}")
            return {"FINISHED"}
        shown, problems = [], []
        for obj in objects:
            why = show(obj, settings, space)
            if why is None:
                shown.append(obj.name)
            else:
                problems.append(f"{obj.name}: {why}")
        if not shown:
            self.report({"ERROR"}, "; ".join(problems))
            return {"CANCELLED"}
        for problem in problems:
            self.report({"WARNING"}, problem)
        self.report({"INFO"}, f"AO preview on {', '.join(shown)}; click again to remove it")
        return {"FINISHED"}
