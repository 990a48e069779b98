"""The bake settings on every scene (``scene.mc_ao``), made from mc_ao.schema, and the add-on preferences."""

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from . import schema

# Blender 4.5 and later warn about "//" in a path property unless it declares that it supports it;
# older versions do not know the option.
_BLEND_RELATIVE = (
    {"PATH_SUPPORTS_BLEND_RELATIVE"}
    if "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties
    else set()
)


class McAoCollectionRef(bpy.types.PropertyGroup):
    """One entry of a list of collections (Include, Exclude): a pointer, so that renaming the
    collection keeps it chosen."""

    collection: PointerProperty(type=bpy.types.Collection, name="Collection",
                                description="A collection of this scene")


class McAoObjectSettings(bpy.types.PropertyGroup):
    """What one object does in others' bakes (``object.mc_ao``)."""

    occlude_others: BoolProperty(
        name="Occludes Other Objects", default=True,
        description="This object darkens the other objects baked beside it. Off, it occludes only itself "
                    "when it is baked (a floor or a helper that should leave no shadow on the props)",
    )


def _property(setting):
    """The Blender property of one schema setting (its name, tooltip, default, limits, UI hints)."""
    common = {"name": setting.label, "description": setting.help}
    ui = dict(setting.ui)
    kind = setting.kind
    if kind == "int":
        hi = schema.limit(setting)
        if hi is not None and "max" not in ui:
            ui["max"] = hi
        return IntProperty(default=setting.default, min=setting.lo, **common, **ui)
    if kind in ("float", "distance"):
        if setting.lo is not None or kind == "distance":
            ui.setdefault("min", setting.lo or 0.0)
        return FloatProperty(default=setting.default, **common, **ui)
    if kind == "bool":
        return BoolProperty(default=setting.default, **common)
    if kind == "enum":
        return EnumProperty(items=list(setting.items), default=setting.default, **common)
    if kind == "str":
        if ui.pop("blend_relative", False):
            ui["options"] = _BLEND_RELATIVE
        return StringProperty(default=setting.default, **common, **ui)
    if kind == "flags":
        return EnumProperty(items=list(setting.items), default=set(setting.default), options={"ENUM_FLAG"},
                            **common)
    if kind == "collections":
        return CollectionProperty(type=McAoCollectionRef, **common)
    if kind == "image":
        return PointerProperty(type=bpy.types.Image, **common)
    if kind == "object":
        return PointerProperty(type=bpy.types.Object, poll=lambda _self, obj: obj.type == "MESH", **common)
    raise AssertionError(f"unknown kind {kind!r}")


#: Settings of the AO bake, stored with the scene: one property per mc_ao.schema setting, named as the
#: mc_ao.settings.BakeSettings field. The core's limits (MAX_SAMPLES, ...) are read from core.base.request.
McAoSettings = type("McAoSettings", (bpy.types.PropertyGroup,), {
    "__annotations__": {s.name: _property(s) for s in schema.SETTINGS},
    "__doc__": "Settings of the AO bake, stored with the scene",
    "__module__": __name__,
})


class McAoPreferences(bpy.types.AddonPreferences):
    # register() sets bl_idname to the add-on's module name, which differs between an installed
    # extension (bl_ext.<repo>.mc_ao) and a checkout.
    bl_idname = "mc_ao"

    threads: IntProperty(
        name="Default Threads",
        description="Worker threads of a bake whose Threads setting is 0; 0 uses all cores",
        default=0, min=0, soft_max=256,
    )

    def draw(self, context):
        self.layout.prop(self, "threads")


def default_threads(context):
    """The preferences' thread count, or 0 (all cores) when the add-on is not enabled as an add-on."""
    addon = context.preferences.addons.get(McAoPreferences.bl_idname)
    return addon.preferences.threads if addon is not None and addon.preferences is not None else 0


def resolve_threads(context, settings):
    """Thread count for core.bake_ao: the scene's, else the preferences', else None (all cores)."""
    return settings.threads or default_threads(context) or None
