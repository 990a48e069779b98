"""The add-on's draw() code against this Blender's own UILayout: run under bpy 5.0 and 4.2 (CI runs
both), it shows that every layout function, keyword, icon and enum value the panels use exists in
both. A panel cannot be drawn without a window, and a keyword or icon that one Blender lacks fails
only when the panel is drawn, in the user's sidebar: so each call is checked against
``bpy.types.UILayout.bl_rna``, in the scene states that take each branch of the draw code.
"""

import types

import pytest

from blender_helpers import add_cube, add_plane, select_only

pytestmark = pytest.mark.blender


class CheckingLayout:
    """Stands in for a UILayout: each function, keyword, enum value (icons) and property assigned
    must exist in the running Blender's UILayout; ``prop(data, name)`` must name a property of data."""

    def __init__(self, bpy, calls):
        object.__setattr__(self, "_bpy", bpy)
        object.__setattr__(self, "_rna", bpy.types.UILayout.bl_rna)
        object.__setattr__(self, "_calls", calls)

    def _where(self):
        return f"in Blender {self._bpy.app.version_string}"

    def __setattr__(self, name, value):
        prop = self._rna.properties.get(name)
        assert prop is not None and not prop.is_readonly, f"UILayout has no writable {name!r} {self._where()}"
        if prop.type == "ENUM":
            assert value in {item.identifier for item in prop.enum_items}, f"UILayout.{name} = {value!r}"

    def __getattr__(self, name):
        func = self._rna.functions.get(name)
        assert func is not None, f"UILayout has no function {name!r} {self._where()}"
        inputs = [p for p in func.parameters if not p.is_output]
        outputs = [p for p in func.parameters if p.is_output]

        def call(*args, **kwargs):
            names = [p.identifier for p in inputs]
            assert len(args) <= len(names), f"UILayout.{name}: too many arguments"
            bound = dict(zip(names, args))
            for key, value in kwargs.items():
                assert key in names, f"UILayout.{name}() takes no {key!r} {self._where()}"
                bound[key] = value
            for p in inputs:
                if p.is_required:
                    assert p.identifier in bound, f"UILayout.{name}() needs {p.identifier!r}"
                value = bound.get(p.identifier)
                if p.type == "ENUM" and isinstance(value, str) and not p.is_enum_flag:
                    assert value in {item.identifier for item in p.enum_items}, (
                        f"UILayout.{name}({p.identifier}={value!r}): no such value {self._where()}")
            for data_key, prop_key in (("data", "property"), ("search_data", "search_property")):
                if data_key in bound and prop_key in bound and hasattr(bound[data_key], "bl_rna"):
                    assert bound[prop_key] in bound[data_key].bl_rna.properties, (
                        f"UILayout.{name}: {bound[data_key].bl_rna.identifier} has no {bound[prop_key]!r}")
            self._calls.append((name, bound))
            if outputs and outputs[0].type == "POINTER" and outputs[0].fixed_type.identifier == "UILayout":
                return CheckingLayout(self._bpy, self._calls)
            return types.SimpleNamespace()  # operator properties and the like: anything may be set

        return call


def draw(bpy, cls, context, calls):
    """``cls.draw_header`` and ``cls.draw`` on a stand-in ``self`` with a CheckingLayout."""
    fake = types.SimpleNamespace(layout=CheckingLayout(bpy, calls))
    for klass in reversed(cls.__mro__):
        if klass.__module__.startswith("mc_ao"):
            for key, value in vars(klass).items():
                if isinstance(value, types.FunctionType):
                    setattr(fake, key, types.MethodType(value, fake))
    for method in ("draw_header", "draw"):
        if hasattr(fake, method):
            getattr(fake, method)(context)


def drawn_classes(addon, bpy):
    return [cls for cls in addon._classes if any(k.__module__.startswith("mc_ao") and "draw" in vars(k)
                                                  for k in cls.__mro__)]


STATES = ["nothing selected", "mesh with UVs", "mesh without UVs", "a light active", "two meshes"]


@pytest.mark.parametrize("state", STATES)
def test_panels_use_only_what_this_blenders_uilayout_has(bpy, scene, addon, state):
    ground = add_plane(bpy, "Ground")
    block = add_cube(bpy, "Block", size=1.0, location=(0, 0, 1))
    if state == "nothing selected":
        select_only(bpy)
    elif state == "mesh with UVs":
        select_only(bpy, ground)
    elif state == "mesh without UVs":
        block.data.uv_layers.remove(block.data.uv_layers[0])
        select_only(bpy, block, ground)
    elif state == "a light active":
        bpy.ops.object.light_add(type="POINT")
        select_only(bpy, bpy.context.active_object, ground)
    else:
        select_only(bpy, ground, block)
    scene.mc_ao.save_to_file = True
    classes = drawn_classes(addon, bpy)
    assert {cls.__name__ for cls in classes} >= {"VIEW3D_PT_mc_ao", "VIEW3D_PT_mc_ao_image", "McAoPreferences"}
    calls = []
    # A sidebar as narrow as Blender's default, so that the labels that wrap are drawn line by line.
    context = types.SimpleNamespace(scene=scene, selected_objects=bpy.context.selected_objects,
                                    active_object=bpy.context.view_layer.objects.active,
                                    region=types.SimpleNamespace(width=240), preferences=bpy.context.preferences,
                                    view_layer=bpy.context.view_layer,
                                    evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get)
    for cls in classes:
        if cls.__name__ == "McAoPreferences":
            fake = types.SimpleNamespace(layout=CheckingLayout(bpy, calls), threads=0)
            cls.draw(fake, context)
        else:
            draw(bpy, cls, context, calls)
    drawn = {name for name, _ in calls}
    assert {"operator", "prop"} <= drawn
    assert "label" in drawn or state == "mesh with UVs"


def test_checking_layout_refuses_what_uilayout_lacks(bpy, scene, addon):
    """The stand-in fails where Blender would: an unknown keyword, icon, function or property."""
    layout = CheckingLayout(bpy, [])
    layout.label(text="fine", icon="INFO")
    layout.prop(scene.mc_ao, "samples", text="")
    for bad in (lambda: layout.label(text="x", icon="NO_SUCH_ICON"),
                lambda: layout.label(text="x", no_such_keyword=1),
                lambda: layout.no_such_function(),
                lambda: layout.prop(scene.mc_ao, "no_such_setting"),
                lambda: setattr(layout, "no_such_property", 1)):
        with pytest.raises(AssertionError):
            bad()
