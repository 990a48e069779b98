"""Registration, the package's Blender-free import, the manifest."""

import subprocess
import sys
import textwrap
import tomllib

import pytest

from blender_helpers import ROOT

pytestmark = pytest.mark.blender

CLASS_NAMES = (
    "McAoSettings", "McAoPreferences", "OBJECT_OT_mc_ao_bake", "VIEW3D_PT_mc_ao",
    "VIEW3D_PT_mc_ao_sampling", "VIEW3D_PT_mc_ao_occlusion", "VIEW3D_PT_mc_ao_image",
    "VIEW3D_PT_mc_ao_output", "VIEW3D_PT_mc_ao_selected_to_active",
)


def _handler_counts(bpy):
    return {name: len(getattr(bpy.app.handlers, name)) for name in dir(bpy.app.handlers)
            if isinstance(getattr(bpy.app.handlers, name), list)}


def _left_behind(bpy):
    """What of the add-on Blender knows about: registered classes, the scene property, the operator."""
    from mc_ao import operators, panel, properties

    classes = list({name: getattr(module, name) for module in (operators, panel, properties)
                    for name in CLASS_NAMES if hasattr(module, name)}.values())
    assert len(classes) == len(CLASS_NAMES)
    found = [cls.__name__ for cls in classes if cls.is_registered]
    found += [name for name in CLASS_NAMES if hasattr(bpy.types, name) and name not in found]
    if hasattr(bpy.types.Scene, "mc_ao") or "mc_ao" in bpy.types.Scene.bl_rna.properties:
        found.append("Scene.mc_ao")
    if "mc_ao_bake" in dir(bpy.ops.object):
        found.append("bpy.ops.object.mc_ao_bake")
    return sorted(found)


def test_register_unregister_twice_leaves_nothing(bpy):
    import mc_ao

    handlers = _handler_counts(bpy)
    assert _left_behind(bpy) == []
    for _ in range(2):
        mc_ao.register()
        assert _left_behind(bpy) == sorted([*CLASS_NAMES, "Scene.mc_ao", "bpy.ops.object.mc_ao_bake"])
        assert bpy.context.scene.mc_ao.bl_rna.properties["samples"].default == 128
        mc_ao.unregister()
        assert _left_behind(bpy) == []
        assert _handler_counts(bpy) == handlers
    assert not mc_ao.operators._RUNS


def test_package_imports_without_blender_or_numpy():
    # The extension package (the repository root) is importable under any name; register() is
    # where bpy, numpy and embreex come in.
    code = textwrap.dedent(f"""
        import importlib.util, sys
        spec = importlib.util.spec_from_file_location(
            "some_name", {str(ROOT / "__init__.py")!r}, submodule_search_locations=[{str(ROOT)!r}])
        pkg = importlib.util.module_from_spec(spec)
        sys.modules["some_name"] = pkg
        spec.loader.exec_module(pkg)
        assert callable(pkg.register) and callable(pkg.unregister)
        heavy = sorted(m for m in ("bpy", "numpy", "embreex", "OpenImageIO") if m in sys.modules)
        assert not heavy, heavy
        from some_name.mc_ao import corelink
        assert corelink.CORE_NAME == "some_name.core", corelink.CORE_NAME
        assert corelink.load().__name__ == "some_name.core"
        print("ok")
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd="/")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def test_checkout_import_finds_top_level_core():
    from mc_ao import corelink

    assert corelink.CORE_NAME == "core"


def test_manifest_is_valid_and_lists_wheels_for_every_platform():
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import build_extension
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    import core

    with open(ROOT / "blender_manifest.toml", "rb") as fh:
        manifest = tomllib.load(fh)
    assert manifest["id"] == "mc_ao"
    assert manifest["version"] == core.__version__
    assert manifest["blender_version_min"] == "4.2.0"
    assert "files" in manifest["permissions"]
    # cp311 (Blender 4.2 to 5.0) and cp313 (5.1 and later) for each platform, nothing else
    for platform in manifest["platforms"]:
        tags = sorted(build_extension.parse_wheel(w)[2] for w in manifest["wheels"]
                      if platform in build_extension.wheel_platforms(w))
        assert tags == ["cp311", "cp313"], (platform, tags)
    assert len(manifest["wheels"]) == 2 * len(manifest["platforms"])

    builder = build_extension.bpy_extension_builder()
    assert builder is not None, "the bpy module carries Blender's extension builder"
    out = subprocess.run([sys.executable, str(builder), "validate", str(ROOT)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_the_properties_limits_are_the_cores(bpy, addon):
    """Samples and size stop where the core's refusal starts: read from core.base.request, not copied."""
    import core.base.request

    from mc_ao import properties

    assert not hasattr(properties, "MAX_SAMPLES") and not hasattr(properties, "MAX_RESOLUTION")
    rna = bpy.types.Scene.bl_rna.properties["mc_ao"].fixed_type.properties
    assert rna["samples"].hard_max == rna["min_samples"].hard_max == core.base.request.MAX_SAMPLES
    assert rna["resolution"].hard_max == rna["height"].hard_max == core.base.request.MAX_RESOLUTION


def test_every_schema_setting_is_a_property_with_its_default(bpy, addon):
    from blender_helpers import clean_scene
    from mc_ao import schema
    from mc_ao.settings import BakeSettings

    clean_scene(bpy)  # every setting back to its default
    rna = bpy.types.Scene.bl_rna.properties["mc_ao"].fixed_type.properties
    for setting in schema.SETTINGS:
        prop = rna[setting.name]
        assert (prop.name, prop.description) == (setting.label, setting.help), setting.name
        if setting.kind == "flags":  # an enum-flag property: its default is a set
            assert prop.default_flag == set(setting.default) and BakeSettings().quantity == setting.default
        elif setting.kind == "collections":  # a list, empty by default
            assert len(getattr(bpy.context.scene.mc_ao, setting.name)) == 0 and setting.default == ()
        elif setting.kind not in ("object", "image"):
            assert prop.default == setting.default == getattr(BakeSettings(), setting.name), setting.name
    assert BakeSettings.from_properties(bpy.context.scene.mc_ao) == BakeSettings()


def test_the_panel_names_the_image_a_long_object_name_bakes_into(bpy, addon):
    from blender_helpers import add_plane, clean_scene, select_only
    from mc_ao import baking
    from mc_ao.settings import BakeSettings

    clean_scene(bpy)
    obj = add_plane(bpy, name="x" * 300)  # Blender keeps what fits its ID names
    select_only(bpy, obj)
    name = BakeSettings().image_name_for(obj.name, baking.id_name_max_bytes())
    assert name.endswith("_AO") and len(name.encode()) <= baking.id_name_max_bytes()
    texts = []

    class Layout:
        def __getattr__(self, attr):
            return lambda *a, **k: (texts.append(k.get("text", "")), self)[1]

    from mc_ao import panel

    panel.draw_targets(Layout(), bpy.context)
    assert any(name in t for t in texts), texts
