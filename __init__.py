"""mc_ao extension entry point: Blender calls register()/unregister() of this package.

Installed, this package is ``bl_ext.<repository>.mc_ao`` and contains ``core/`` (no Blender) and
``mc_ao/`` (the Blender side) as subpackages. Importing it needs neither bpy nor numpy: everything
that does is imported inside register(), so tools can import the package outside Blender.
"""


def register():
    from .mc_ao import register as _register

    # The add-on's module name is this package's name; preferences are keyed by it.
    _register(addon_name=__name__)


def unregister():
    from .mc_ao import unregister as _unregister

    _unregister()
