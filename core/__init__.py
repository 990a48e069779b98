"""mc_ao core: Monte Carlo hemisphere sampling and a per-texel ambient occlusion baker (no Blender).

The names below are loaded when first used (PEP 562): importing ``core`` or one of its numpy-free
modules (:mod:`core.base.request`, the options of a bake) does not load numpy or embreex.
"""

import importlib

from ._version import __version__

#: Each public name and the module (inside this package) that defines it.
_WHERE = {
    "McAoError": "base.errors", "MeshError": "base.errors", "MeshTypeError": "base.errors",
    "SettingsError": "base.errors", "BakeMemoryError": "base.errors", "BakeCancelled": "base.errors",
    "ImageWriteError": "base.errors",
    "BakeRequest": "base.request", "OPTIONS": "base.request",
    "cost": "execution.cost", "stats": "montecarlo.stats", "warps": "montecarlo.warps",
    "Estimate": "montecarlo.integrate", "estimate": "montecarlo.integrate", "integrate": "montecarlo.integrate",
    "RunningStats": "montecarlo.stats",
    "Mesh": "geometry.mesh",
    "Atlas": "targets.atlas", "AtlasRecord": "files.atlasrecord",
    "ImageReadError": "files.imageio",
    "bake": "pipeline.api", "bake_ao": "pipeline.api", "bake_maps": "pipeline.api", "bake_udim": "pipeline.api",
    "bake_udim_maps": "pipeline.api", "bake_vertex_ao": "pipeline.api", "bake_vertex_maps": "pipeline.api",
    "BakeResult": "pipeline.result", "UdimResult": "pipeline.api", "VertexBakeResult": "pipeline.api",
}
_MODULES = {"cost", "stats", "warps"}


def __getattr__(name):
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module = importlib.import_module(f"{__name__}.{where}")
    value = module if name in _MODULES else getattr(module, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_WHERE))


__all__ = ["__version__"] + list(_WHERE)
