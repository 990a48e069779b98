"""The Blender side of mc_ao: scene settings, the Bake AO operator, the sidebar panel, preferences.

Nothing here is imported at module level that needs bpy, so the extension package imports without
Blender; register() pulls the bpy modules in.
"""

_classes = ()


def register(addon_name="mc_ao"):
    """Register the classes and ``Scene.mc_ao``; ``addon_name`` keys the add-on preferences."""
    global _classes
    import bpy

    from . import operators, panel, preview, properties

    properties.McAoPreferences.bl_idname = addon_name
    _classes = (
        properties.McAoCollectionRef,
        properties.McAoObjectSettings,
        properties.McAoSettings,
        properties.McAoPreferences,
        operators.OBJECT_OT_mc_ao_bake,
        preview.OBJECT_OT_mc_ao_preview,
        panel.VIEW3D_PT_mc_ao,
        panel.VIEW3D_PT_mc_ao_target,
        panel.VIEW3D_PT_mc_ao_sampling,
        panel.VIEW3D_PT_mc_ao_occlusion,
        panel.MC_AO_OT_collection_add,
        panel.MC_AO_OT_collection_remove,
        panel.VIEW3D_PT_mc_ao_object,
        panel.VIEW3D_PT_mc_ao_selected_to_active,
        panel.VIEW3D_PT_mc_ao_image,
        panel.VIEW3D_PT_mc_ao_output,
    )
    for cls in _classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.mc_ao = bpy.props.PointerProperty(type=properties.McAoSettings)
    bpy.types.Object.mc_ao = bpy.props.PointerProperty(type=properties.McAoObjectSettings)
    for name, handler in operators.HANDLERS.items():
        getattr(bpy.app.handlers, name).append(handler)


def unregister():
    global _classes
    import bpy

    from . import operators

    for name, handler in operators.HANDLERS.items():
        handlers = getattr(bpy.app.handlers, name)
        while handler in handlers:
            handlers.remove(handler)
    for session in list(operators._SESSIONS):
        # Disabled mid-bake: the bake stops and, Blender's data being there, the images it had not
        # finished are put back, as after Esc.
        try:
            session.finish(bpy.context, cancelled=True, why="(the add-on was disabled)")
        except (AttributeError, ReferenceError, RuntimeError):
            session.abandon()
    for run in list(operators._RUNS):
        run.stop()
    # The worker processes of the bakes go with the add-on (only when the core was loaded at all).
    import sys

    from . import corelink

    workers = sys.modules.get(f"{corelink.CORE_NAME}.execution.pool")
    if workers is not None:
        workers.shutdown()
    del bpy.types.Scene.mc_ao
    del bpy.types.Object.mc_ao
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
    _classes = ()
