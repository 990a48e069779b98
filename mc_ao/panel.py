"""The sidebar tab "MC AO" in the 3D Viewport: the Bake AO button and the settings, grouped."""

import bpy

from . import baking
from . import operators
from . import preview, schema, selected_to_active
from .operators import OBJECT_OT_mc_ao_bake, is_running
from .extract import default_uv_map
from .properties import resolve_threads
from .settings import BakeSettings

# Selected objects that will not be baked are listed under the button, up to this many lines.
MAX_SKIPPED_LINES = 3
# The icon of the last bake's line in the panel, by the type of its last report.
_OUTCOME_ICONS = {"INFO": "CHECKMARK", "WARNING": "ERROR", "ERROR": "CANCEL"}
# UILayout.prop() takes a placeholder for an empty text field in newer Blender versions (4.3 and
# 5.0 have it), not in every version this extension supports.
_HAS_PLACEHOLDER = "placeholder" in bpy.types.UILayout.bl_rna.functions["prop"].parameters


def _placeholder(text):
    return {"placeholder": text} if _HAS_PLACEHOLDER else {}


# Pixels of a sidebar's width that a label's text cannot use, at UI scale 1: the panel's margins,
# the label's icon, and the strip of tabs at the region's edge. Measured in Blender 4.3 (UI scale
# 1.04, sidebar 291 pixels with its tabs): texts that blf measures at 208 pixels fit, 215 were cut
# off; 84 leaves room for 203.
LABEL_INSET = 84


def text_width(text, context):
    """Width in pixels of ``text`` in the UI's label font and size (Blender's font engine, blf)."""
    import blf

    prefs = context.preferences
    scale = prefs.system.ui_scale or prefs.view.ui_scale  # the first is 0 without a window
    blf.size(0, prefs.ui_styles[0].widget.points * scale)
    return blf.dimensions(0, text)[0]


def wrap_text(text, width, measure):
    """``text`` cut into lines, at spaces, that each measure at most ``width`` (a single long word
    stays whole on its own line). ``measure(text)`` is the width of a text."""
    lines = []
    for word in text.split():
        if lines and measure(lines[-1] + " " + word) <= width:
            lines[-1] += " " + word
        else:
            lines.append(word)
    return lines or [""]


def fitted_lines(text, width, measure, lines):
    """``text`` cut into exactly ``lines`` lines that each measure at most ``width`` (at spaces; a
    single long word is cut, and text that does not fit ends in an ellipsis), padded with empty lines:
    a label that takes the same rows whatever it says, so the panel below it never moves."""
    out = []
    for word in text.split():
        if out and measure(out[-1] + " " + word) <= width:
            out[-1] += " " + word
        else:
            out.append(word)
    if len(out) > lines:  # the rest does not fit: the last line ends in an ellipsis, at a space where one is
        out = out[:lines]
        words = out[-1].split()
        while len(words) > 1 and measure(" ".join(words) + " \u2026") > width:
            words.pop()
        out[-1] = " ".join(words) + " \u2026"
    for i, line in enumerate(out):
        while measure(line) > width and len(line) > 1:  # a word longer than the line
            line = line[:-2] + "\u2026"
        out[i] = line
    return out + [""] * (lines - len(out))


def label_width(context):
    """The pixels a label's text may take in the region, or None without a window (a script)."""
    region = context.region
    if region is None or region.width <= 0:
        return None
    scale = context.preferences.system.ui_scale or 1.0
    return region.width - LABEL_INSET * scale


def fixed_label(layout, context, text, lines=1, icon="NONE"):
    """A label of exactly ``lines`` rows (see fitted_lines): the first with the icon, the others
    indented as far, so the text lines up."""
    width = label_width(context)
    if width is None:  # no window: nothing to fit
        rows = ([text] + [""] * (lines - 1)) if text else [""] * lines
    else:
        rows = fitted_lines(text, width, lambda t: text_width(t, context), lines)
    col = layout.column(align=True)
    for n, line in enumerate(rows):
        shown = icon if n == 0 and line else ("BLANK1" if icon != "NONE" else "NONE")
        col.label(text=line, icon=shown)


class _McAoPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "MC AO"

    def split_layout(self):
        """The panel's layout with labels left of the fields, as Blender's own property panels."""
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        return layout


#: Rows of the panel's lines under the buttons, the same whatever they say (the panel never jumps
#: under the pointer while settings change): what the button bakes (or why it cannot), the estimate,
#: a note (memory, skipped objects), and the last bake's outcome.
WHAT_LINES, ESTIMATE_LINES, NOTE_LINES, LAST_LINES = 2, 2, 1, 2
#: Rows of the Occlusion section's line that says what occludes (its text changes, its rows do not).
OCCLUDED_BY_LINES = 2


def values(context):
    """The scene's bake settings as the panel shows them: a greyed-out one at its default."""
    return BakeSettings.from_properties(context.scene.mc_ao).in_effect()


class VIEW3D_PT_mc_ao(_McAoPanel, bpy.types.Panel):
    bl_label = "Ambient Occlusion"

    def draw(self, context):
        layout = self.layout
        row = layout.row()
        row.scale_y = 1.5
        row.operator(OBJECT_OT_mc_ao_bake.bl_idname, icon="RENDER_STILL")
        shown = preview.has_preview(context.active_object)
        layout.operator(preview.OBJECT_OT_mc_ao_preview.bl_idname, icon="HIDE_ON" if shown else "SHADING_TEXTURE",
                        text="Remove AO Preview" if shown else "Preview on Object", depress=shown)
        if is_running():
            draw_lines(layout, context, ("Baking, Esc cancels", "TIME"))
        else:
            draw_targets(layout, context)
        outcome = operators.last_outcome
        kind, text = outcome if outcome is not None else ("INFO", "")
        fixed_label(layout, context, f"Last bake: {text}" if text else "", LAST_LINES,
                    icon=_OUTCOME_ICONS.get(kind, "INFO") if text else "NONE")


def draw_targets(layout, context):
    """What the button will bake, or why it cannot (WHAT_LINES), its estimate (ESTIMATE_LINES) and a
    note (NOTE_LINES: memory, the selected objects it will skip), always in the same rows."""
    settings = values(context)
    # The button greys out when its poll fails; say why under it.
    choice, reason = operators.choice_of(context)
    note, note_icon = "", "NONE"
    if reason is not None:
        draw_lines(layout, context, (reason, "INFO"))
        return
    if settings.use_selected_to_active:
        what, icon, targets, highpoly, cage = selected_to_active_text(context, settings)
    else:
        what, icon, targets, highpoly, cage = targets_text(settings, choice.targets), "IMAGE_DATA", choice.targets, (), None
        if settings.vertex_colors:
            icon = "GROUP_VCOL"
        skipped = choice.skipped
        if skipped:
            names = [f"{obj.name} ({'no UV map' if obj.type == 'MESH' else 'not a mesh'})"
                     for obj in skipped[:MAX_SKIPPED_LINES]]
            more = f" and {len(skipped) - MAX_SKIPPED_LINES} more" if len(skipped) > MAX_SKIPPED_LINES else ""
            note, note_icon = f"Skipped: {', '.join(names)}{more}", "ERROR"
    estimate, too_big = cost_text(context, settings, targets, highpoly, cage)
    draw_lines(layout, context, (what, icon), (estimate, "ERROR" if too_big else "TIME"), (note, note_icon))


def draw_lines(layout, context, what, estimate=("", "NONE"), note=("", "NONE")):
    """The lines under the buttons, each ``(text, icon)``, in their fixed rows: always the same
    labels in the same columns (a column more or less moves what is below by its spacing)."""
    for (text, icon), lines in ((what, WHAT_LINES), (estimate, ESTIMATE_LINES), (note, NOTE_LINES)):
        fixed_label(layout, context, text, lines, icon=icon if text else "NONE")


def atlas_line(settings, targets):
    """What a bake into shared images says before it runs: "3 objects into one image 'Atlas'", or
    per material image; None where each object has an image of its own."""
    from .atlas import groups, shared

    if not shared(settings):
        return None
    try:
        images = groups(settings, targets, baking.id_name_max_bytes())
    except Exception as exc:  # an object without an image node: the bake would say the same
        return str(exc)
    parts = []
    for name, objects in images:
        n = len(objects)
        parts.append(f"{n} object{'s' if n != 1 else ''} into one image {name!r}" if n > 1
                     else f"{objects[0].name} into image {name!r}")
    return "; ".join(parts)


def targets_text(settings, targets):
    """What the button bakes, in words: into which images (or colour attribute)."""
    shared = atlas_line(settings, targets)
    if shared is not None:
        return shared
    if settings.vertex_colors:
        domain = "per vertex" if settings.attribute_domain == "POINT" else "per face corner"
        what = f"color attribute {settings.attribute_name} ({domain})"
        return f"Into {what}" if len(targets) == 1 else f"{len(targets)} objects, each into its {what}"
    if len(targets) == 1:
        name = targets[0].name
        images = [settings.quantity_image_name_for(name, q, baking.id_name_max_bytes()) for q in settings.quantities]
        if settings.bent_normals:
            images.append(settings.bent_image_name_for(name, baking.id_name_max_bytes()))
        text = f"Into {' and '.join(images)}" + (" (UDIM tiles)" if settings.use_udim else "")
    else:
        text = f"{len(targets)} objects, " + ("one tiled image each" if settings.use_udim else "one image each")
    if settings.channel != "NONE":
        text += f", AO also into {CHANNEL_WORDS[settings.channel]} of {settings.into}"
    return text


#: A Channel setting as the panel's lines name it.
CHANNEL_WORDS = {"R": "the red", "G": "the green", "B": "the blue", "A": "the alpha"}


def cost_text(context, settings, targets, highpoly=(), cage=None):
    """(the estimate's line, whether the bake will not fit in memory): the bake's estimated time and
    memory (core.execution.cost, calibrated by the bench; the occluders and high-poly objects it will
    use counted apart), and, before a bake that will not fit, the memory free."""
    if not targets:
        return "", False
    try:
        cost = baking.bake_cost(settings, targets, context.evaluated_depsgraph_get(),
                                selected=context.selected_objects, view_layer=context.view_layer,
                                threads=resolve_threads(context, settings), highpoly=highpoly, cage=cage)
        available = baking.corelink.load("execution.executor").memory_limit()
    except Exception:  # the core cannot load (no numpy, no embreex): the bake will say why
        return "", False
    described = baking.calibrated(cost).describe()
    if settings.target_error > 0:  # adaptive sampling stops texels early: the estimate is the most it takes
        described = described.replace("about ", "at most ", 1)
    text = f"Estimate: {described}"
    if available is not None and cost.bytes > available:
        return f"{text}, more than the {available / 2 ** 30:.1f} GiB free: lower Size or Processes", True
    return text, False


def selected_to_active_text(context, settings):
    """Selected to Active: which objects bake onto which, into which image; (text, icon, targets,
    high-poly objects, cage)."""
    props = context.scene.mc_ao
    active, cage = context.active_object, selected_to_active.cage_of(props)
    highs = selected_to_active.high_objects(context.selected_objects, active, cage)
    names = ", ".join(o.name for o in highs[:MAX_SKIPPED_LINES])
    if len(highs) > MAX_SKIPPED_LINES:
        names += f" and {len(highs) - MAX_SKIPPED_LINES} more"
    image_name = settings.image_name_for(active.name, baking.id_name_max_bytes())
    return f"From {names} onto {active.name}, into {image_name}", "MOD_SHRINKWRAP", [active], highs, cage


class VIEW3D_PT_mc_ao_target(_McAoPanel, bpy.types.Panel):
    """Where the AO goes (Cycles' Target), UDIM tiles, bent normals."""

    bl_label = "Target"
    bl_parent_id = "VIEW3D_PT_mc_ao"

    def draw(self, context):
        settings = context.scene.mc_ao
        v = BakeSettings.from_properties(settings)
        layout = self.split_layout()
        # A menu, not two buttons: at the sidebar's default width each half cut the names off
        # ("Image Te...", "Color Attr...").
        layout.prop(settings, "target")
        col = layout.column()
        col.prop(settings, "quantity")
        # Four rows either way: switching the target moves nothing below.
        if settings.target == "VERTEX_COLORS":
            col.prop(settings, "attribute_name", icon="GROUP_VCOL")
            col.prop(settings, "attribute_domain")
            col.column().prop(settings, "float_buffer", text="Float Color")  # the shape of Space's row below
            return
        col.prop(settings, "use_udim")
        col.prop(settings, "bent_normals")
        sub = col.column()
        sub.active = not v.greyed("bent_space")
        sub.prop(settings, "bent_space")


class VIEW3D_PT_mc_ao_selected_to_active(_McAoPanel, bpy.types.Panel):
    """Cycles' Bake panel's "Selected to Active", with the same settings and layout."""

    bl_label = "Selected to Active"
    bl_parent_id = "VIEW3D_PT_mc_ao"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.mc_ao, "use_selected_to_active", text="")

    def draw(self, context):
        settings = context.scene.mc_ao
        v = BakeSettings.from_properties(settings)
        layout = self.split_layout()
        layout.active = settings.use_selected_to_active
        col = layout.column()
        col.prop(settings, "use_cage", text="Cage")
        # Every row always there, greyed where it does not apply: ticking Cage moves nothing.
        for name, text in (("cage_object", None), ("cage_extrusion", "Extrusion")):
            sub = col.column()
            sub.active = not v.greyed(name)  # a cage object replaces the extrusion
            sub.prop(settings, name, **({"text": text} if text else {}))
        # Cycles' name, "Max Ray Distance", is cut off at the sidebar's default width; the tooltip keeps it.
        col.prop(settings, "max_ray_distance", text="Ray Distance")


class VIEW3D_PT_mc_ao_sampling(_McAoPanel, bpy.types.Panel):
    bl_label = "Sampling"
    bl_parent_id = "VIEW3D_PT_mc_ao"

    def draw(self, context):
        settings = context.scene.mc_ao
        v = BakeSettings.from_properties(settings)
        layout = self.split_layout()
        col = layout.column()
        col.prop(settings, "samples")
        col.prop(settings, "target_error")
        sub = col.column()
        sub.active = not v.greyed("min_samples")
        sub.prop(settings, "min_samples")
        col = layout.column()
        col.prop(settings, "source")
        col.prop(settings, "distribution")
        col.prop(settings, "seed")
        col.prop(settings, "threads")
        col.prop(settings, "processes")
        col.prop(settings, "denoise")
        # The core's options that are settings by themselves (mc_ao.schema.FROM_CORE): each as it comes,
        # greyed out where the bake's kind does not take it.
        for setting in schema.FROM_CORE:
            sub = col.row()
            sub.active = not v.greyed(setting.name)
            sub.prop(settings, setting.name)


# The scene settings that are lists of collections (Include, Exclude).
COLLECTION_SETTINGS = ("occluder_collections", "exclude_collections")


class MC_AO_OT_collection_add(bpy.types.Operator):
    """Add a collection to the list (the active collection, if it is not listed yet)"""

    bl_idname = "mc_ao.collection_add"
    bl_label = "Add Collection"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}

    setting: bpy.props.EnumProperty(items=[(n, n, "") for n in COLLECTION_SETTINGS], options={"HIDDEN"})

    def execute(self, context):
        items = getattr(context.scene.mc_ao, self.setting)
        item = items.add()
        active = getattr(context, "collection", None)
        listed = {i.collection for i in items}
        if active is not None and active is not context.scene.collection and active not in listed:
            item.collection = active
        return {"FINISHED"}


class MC_AO_OT_collection_remove(bpy.types.Operator):
    """Remove this collection from the list"""

    bl_idname = "mc_ao.collection_remove"
    bl_label = "Remove Collection"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}

    setting: bpy.props.EnumProperty(items=[(n, n, "") for n in COLLECTION_SETTINGS], options={"HIDDEN"})
    index: bpy.props.IntProperty(options={"HIDDEN"})

    def execute(self, context):
        items = getattr(context.scene.mc_ao, self.setting)
        if 0 <= self.index < len(items):
            items.remove(self.index)
        return {"FINISHED"}


def draw_collections(layout, settings, name):
    """A list of collection pickers under the setting's label, each with a remove button, and an add button."""
    label = settings.bl_rna.properties[name].name
    items = getattr(settings, name)
    col = layout.column(align=True)
    for i, item in enumerate(items):
        row = col.row(align=True)
        row.prop(item, "collection", text=label if i == 0 else " ")
        op = row.operator(MC_AO_OT_collection_remove.bl_idname, text="", icon="REMOVE")
        op.setting, op.index = name, i
    row = col.row(align=True)
    row.use_property_split = False
    split = row.split(factor=0.4, align=True)
    left = split.row()
    left.alignment = "RIGHT"
    left.label(text="" if len(items) else label)
    split.operator(MC_AO_OT_collection_add.bl_idname, text="Add Collection", icon="ADD").setting = name


def occluded_by(v):
    """What occludes the baked objects with settings ``v`` (in effect), in words: the panel's line
    above the occlusion settings, so that Only Local says whether the ground still counts."""
    if v.only_local or v.occluders == "SELF":
        who = "each object alone"
    else:
        who = "every rendered object" if v.occluders == "VISIBLE" else "the selected objects"
        if v.occluder_collections:
            who = ("objects in " if v.occluders == "VISIBLE" else who + " in ") + ", ".join(v.occluder_collections)
        if v.exclude_collections:
            who += ", not in " + ", ".join(v.exclude_collections)
    if v.ground == "AUTO":
        who += ", and the ground under each"
    elif v.ground == "HEIGHT":
        who += f", and the ground at Z {v.ground_height:g}"
    if "thickness" in v.quantities:
        who += " (thickness: the object alone)"
    return f"Occluded by {who}"


class VIEW3D_PT_mc_ao_occlusion(_McAoPanel, bpy.types.Panel):
    bl_label = "Occlusion"
    bl_parent_id = "VIEW3D_PT_mc_ao"

    def draw(self, context):
        settings = context.scene.mc_ao
        v = BakeSettings.from_properties(settings)
        fixed_label(self.layout, context, occluded_by(v.in_effect()), OCCLUDED_BY_LINES, icon="INFO")
        layout = self.split_layout()
        col = layout.column()
        col.prop(settings, "only_local")
        sub = col.column()
        sub.active = not v.greyed("occluders")
        sub.prop(settings, "occluders")
        for name in COLLECTION_SETTINGS:
            draw_collections(sub, settings, name)
        # Not under Only Local's greyed-out group: the ground counts with Only Local too (the line above says so).
        col = layout.column()
        col.prop(settings, "ground")
        sub = col.column()
        sub.active = not v.greyed("ground_height")
        sub.prop(settings, "ground_height")
        col = layout.column()
        col.prop(settings, "max_distance")
        col.prop(settings, "ignore_backfaces")


class VIEW3D_PT_mc_ao_object(_McAoPanel, bpy.types.Panel):
    """The active object's own part in others' bakes."""

    bl_label = "Object"
    bl_parent_id = "VIEW3D_PT_mc_ao"

    @classmethod
    def poll(cls, context):
        return context.active_object is not None

    def draw(self, context):
        obj = context.active_object
        if obj is None or getattr(obj, "mc_ao", None) is None:
            return
        # the whole row for the checkbox's name: in a split layout's half it is cut off
        self.layout.prop(obj.mc_ao, "occlude_others")


class VIEW3D_PT_mc_ao_image(_McAoPanel, bpy.types.Panel):
    bl_label = "Image"
    bl_parent_id = "VIEW3D_PT_mc_ao"

    def draw(self, context):
        settings = context.scene.mc_ao
        v = BakeSettings.from_properties(settings)
        layout = self.split_layout()
        layout.active = not v.greyed("resolution")  # a color attribute bake has no image
        col = layout.column(align=True)
        col.prop(settings, "resolution")
        col.prop(settings, "height")
        col = layout.column()
        col.prop(settings, "margin")
        col.prop(settings, "fix_seams")
        obj = context.active_object
        if obj is not None and obj.type == "MESH":
            col.prop_search(settings, "uv_map", obj.data, "uv_layers", text="UV Map", icon="GROUP_UVS")
        else:
            col.prop(settings, "uv_map", icon="GROUP_UVS")
        # Always one row: which UV map the active object bakes into.
        default = default_uv_map(obj.data) if obj is not None and obj.type == "MESH" else ""
        row = col.row()
        row.active = False
        row.label(text=f"Active render UV map: {default}" if not settings.uv_map and default else "")
        col.prop(settings, "images")
        for name in ("atlas", "image_name"):  # always both rows: the one not in use greyed out
            row = col.row()
            row.active = not v.greyed(name)
            if name == "image_name":
                row.prop(settings, "image_name", **_placeholder(IMAGE_NAME_PLACEHOLDER))
            else:
                row.prop(settings, name)
        col.prop(settings, "float_buffer")
        col.prop(settings, "error_map")
        row = col.row()
        row.active = not v.greyed("id_map")
        row.prop(settings, "id_map")
        col = layout.column()
        col.prop(settings, "channel")
        sub = col.column()
        sub.active = not v.greyed("into")
        sub.prop(settings, "into")


#: The Image field's placeholder: the name an empty field gives, in the token the field takes.
IMAGE_NAME_PLACEHOLDER = "{object}_AO"


class VIEW3D_PT_mc_ao_output(_McAoPanel, bpy.types.Panel):
    bl_label = "Save to File"
    bl_parent_id = "VIEW3D_PT_mc_ao"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.mc_ao, "save_to_file", text="")

    def draw(self, context):
        settings = context.scene.mc_ao
        layout = self.split_layout()
        layout.active = settings.save_to_file
        layout.prop(settings, "file_format")
        layout.prop(settings, "output_dir")
        layout.prop(settings, "link_to_file")
