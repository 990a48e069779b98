"""The sidebar tab "MC AO" in the 3D Viewport: the Bake AO button and the settings, grouped."""

import bpy

from . import baking
from . import operators
from . import preview, selected_to_active
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


def wrapped_label(layout, context, text, icon="NONE"):
    """A label that continues on more lines where the region is too narrow for it, none of it cut off.

    The first line has the icon; the others are indented as far, so the text lines up.
    """
    region = context.region
    if region is None or region.width <= 0:  # no window (a script): nothing to fit
        lines = [text]
    else:
        scale = context.preferences.system.ui_scale or 1.0
        lines = wrap_text(text, region.width - LABEL_INSET * scale, lambda t: text_width(t, context))
    col = layout.column(align=True)
    for n, line in enumerate(lines):
        col.label(text=line, icon=icon if n == 0 else ("BLANK1" if icon != "NONE" else "NONE"))


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
            layout.label(text="Baking, Esc cancels", icon="TIME")
            return
        draw_targets(layout, context)
        if operators.last_outcome is not None:
            kind, text = operators.last_outcome
            wrapped_label(layout, context, f"Last bake: {text}", icon=_OUTCOME_ICONS.get(kind, "INFO"))


def draw_targets(layout, context):
    """What the button will bake, or why it cannot; the selected objects it will skip."""
    settings = BakeSettings.from_properties(context.scene.mc_ao)
    # The button greys out when its poll fails; say why under it.
    choice, reason = operators.choice_of(context)
    if reason is not None:
        wrapped_label(layout, context, reason, icon="INFO")
        return
    if settings.use_selected_to_active:
        draw_selected_to_active(layout, context)
        return
    targets = choice.targets
    if settings.vertex_colors:
        domain = "per vertex" if settings.attribute_domain == "POINT" else "per face corner"
        what = f"color attribute {settings.attribute_name} ({domain})"
        if len(targets) == 1:
            wrapped_label(layout, context, f"Into {what}", icon="GROUP_VCOL")
        else:
            wrapped_label(layout, context, f"{len(targets)} objects, each into its {what}", icon="GROUP_VCOL")
    elif len(targets) == 1:
        image_name = " and ".join(settings.quantity_image_name_for(targets[0].name, q, baking.id_name_max_bytes())
                                  for q in settings.quantities)
        extra = " (UDIM tiles)" if settings.use_udim else ""
        if settings.bent_normals:
            extra += f" and {settings.bent_image_name_for(targets[0].name, baking.id_name_max_bytes())}"
        wrapped_label(layout, context, f"Into {image_name}{extra}", icon="IMAGE_DATA")
    else:
        each = "one tiled image each" if settings.use_udim else "one image each"
        layout.label(text=f"{len(targets)} objects, {each}", icon="IMAGE_DATA")
    draw_cost(layout, context, settings, targets)
    skipped = choice.skipped
    for obj in skipped[:MAX_SKIPPED_LINES]:
        why = "no UV map" if obj.type == "MESH" else "not a mesh"
        wrapped_label(layout, context, f"Skipped: {obj.name} ({why})", icon="ERROR")
    if len(skipped) > MAX_SKIPPED_LINES:
        layout.label(text=f"... and {len(skipped) - MAX_SKIPPED_LINES} more skipped", icon="ERROR")


def draw_cost(layout, context, settings, targets, highpoly=(), cage=None):
    """The bake's estimated time and memory (core.execution.cost, calibrated by the bench; the occluders and
    high-poly objects it will use counted apart), and a warning before a bake that will not fit in
    memory."""
    if not targets:
        return
    try:
        cost = baking.bake_cost(settings, targets, context.evaluated_depsgraph_get(),
                                selected=context.selected_objects, view_layer=context.view_layer,
                                threads=resolve_threads(context, settings), highpoly=highpoly, cage=cage)
        available = baking.corelink.load("execution.workers").memory_limit()
    except Exception:  # the core cannot load (no numpy, no embreex): the bake will say why
        return
    wrapped_label(layout, context, f"Estimate: {cost.describe()}", icon="TIME")
    if available is not None and cost.bytes > available:
        wrapped_label(layout, context, f"This bake needs about {cost.bytes / 2 ** 30:.1f} GiB, more than the "
                      f"{available / 2 ** 30:.1f} GiB free: lower the resolution or the processes", icon="ERROR")


class VIEW3D_PT_mc_ao_target(_McAoPanel, bpy.types.Panel):
    """Where the AO goes (Cycles' Target), UDIM tiles, bent normals."""

    bl_label = "Target"
    bl_parent_id = "VIEW3D_PT_mc_ao"

    def draw(self, context):
        settings = context.scene.mc_ao
        layout = self.split_layout()
        # A menu, not two buttons: at the sidebar's default width each half cut the names off
        # ("Image Te...", "Color Attr...").
        layout.prop(settings, "target")
        col = layout.column()
        if settings.target == "VERTEX_COLORS":
            col.prop(settings, "quantity")
            col.prop(settings, "attribute_name", icon="GROUP_VCOL")
            col.prop(settings, "attribute_domain")
            col.prop(settings, "float_buffer", text="Float Color")
            return
        col.prop(settings, "quantity")
        col.prop(settings, "use_udim")
        col.prop(settings, "bent_normals")
        sub = col.column()
        sub.active = settings.bent_normals
        sub.prop(settings, "bent_space")


def draw_selected_to_active(layout, context):
    """Selected to Active: which objects bake onto which, into which image."""
    settings = context.scene.mc_ao
    active, cage = context.active_object, selected_to_active.cage_of(settings)
    highs = selected_to_active.high_objects(context.selected_objects, active, cage)
    names = ", ".join(o.name for o in highs[:MAX_SKIPPED_LINES])
    if len(highs) > MAX_SKIPPED_LINES:
        names += f" and {len(highs) - MAX_SKIPPED_LINES} more"
    bake_settings = BakeSettings.from_properties(settings)
    image_name = bake_settings.image_name_for(active.name, baking.id_name_max_bytes())
    wrapped_label(layout, context, f"From {names} onto {active.name}", icon="MOD_SHRINKWRAP")
    wrapped_label(layout, context, f"Into {image_name}", icon="IMAGE_DATA")
    draw_cost(layout, context, bake_settings, [active], highpoly=highs, cage=cage)


class VIEW3D_PT_mc_ao_selected_to_active(_McAoPanel, bpy.types.Panel):
    """Cycles' Bake panel's "Selected to Active", with the same settings and layout."""

    bl_label = "Selected to Active"
    bl_parent_id = "VIEW3D_PT_mc_ao"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.mc_ao, "use_selected_to_active", text="")

    def draw(self, context):
        settings = context.scene.mc_ao
        layout = self.split_layout()
        layout.active = settings.use_selected_to_active
        col = layout.column()
        col.prop(settings, "use_cage", text="Cage")
        if settings.use_cage:
            col.prop(settings, "cage_object")
            sub = col.column()
            sub.active = settings.cage_object is None  # a cage object replaces the extrusion
            sub.prop(settings, "cage_extrusion", text="Extrusion")
        else:
            col.prop(settings, "cage_extrusion", text="Extrusion")
        # Cycles' name, "Max Ray Distance", is cut off at the sidebar's default width; the tooltip keeps it.
        col.prop(settings, "max_ray_distance", text="Ray Distance")


class VIEW3D_PT_mc_ao_sampling(_McAoPanel, bpy.types.Panel):
    bl_label = "Sampling"
    bl_parent_id = "VIEW3D_PT_mc_ao"

    def draw(self, context):
        settings = context.scene.mc_ao
        layout = self.split_layout()
        col = layout.column()
        col.prop(settings, "samples")
        col.prop(settings, "target_error")
        sub = col.column()
        sub.active = settings.target_error > 0
        sub.prop(settings, "min_samples")
        col = layout.column()
        col.prop(settings, "source")
        col.prop(settings, "distribution")
        col.prop(settings, "seed")
        col.prop(settings, "threads")
        col.prop(settings, "processes")
        col.prop(settings, "denoise")


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


class VIEW3D_PT_mc_ao_occlusion(_McAoPanel, bpy.types.Panel):
    bl_label = "Occlusion"
    bl_parent_id = "VIEW3D_PT_mc_ao"

    def draw(self, context):
        settings = context.scene.mc_ao
        layout = self.split_layout()
        col = layout.column()
        col.prop(settings, "only_local")
        sub = col.column()
        sub.active = not settings.only_local
        sub.prop(settings, "occluders")
        for name in COLLECTION_SETTINGS:
            draw_collections(sub, settings, name)
        col = layout.column()
        col.prop(settings, "ground")
        sub = col.column()
        sub.active = settings.ground == "HEIGHT"
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
        layout = self.split_layout()
        layout.active = settings.target != "VERTEX_COLORS"  # a color attribute bake has no image
        col = layout.column(align=True)
        col.prop(settings, "resolution")
        col.prop(settings, "height")
        col = layout.column()
        col.prop(settings, "margin")
        obj = context.active_object
        if obj is not None and obj.type == "MESH":
            col.prop_search(settings, "uv_map", obj.data, "uv_layers", text="UV Map", icon="GROUP_UVS")
            default = default_uv_map(obj.data)
            if not settings.uv_map and default:
                col.label(text=f"Active render UV map: {default}")
        else:
            col.prop(settings, "uv_map", icon="GROUP_UVS")
        col.prop(settings, "image_name", **_placeholder("<object>_AO"))
        col.prop(settings, "float_buffer")
        col.prop(settings, "error_map")
        col = layout.column()
        col.prop(settings, "channel")
        sub = col.column()
        sub.active = settings.channel != "NONE"
        sub.prop(settings, "into")


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
