"""mc_ao core: Monte Carlo hemisphere sampling and a per-texel ambient occlusion baker (no Blender)."""

from ._version import __version__
from .errors import (
    BakeCancelled,
    BakeMemoryError,
    ImageWriteError,
    McAoError,
    MeshError,
    MeshTypeError,
    SettingsError,
)
from . import cost, stats, warps
from .integrate import Estimate, estimate, integrate
from .stats import RunningStats
from .mesh import Mesh
from .bake import BakeResult, bake_ao, bake_maps
from .imageio import ImageReadError
from .udim import UdimResult, bake_udim, bake_udim_maps
from .vertices import VertexBakeResult, bake_vertex_ao, bake_vertex_maps

__all__ = [
    "__version__", "Mesh", "bake_ao", "BakeResult", "integrate", "estimate", "Estimate", "RunningStats",
    "stats", "warps", "McAoError", "MeshError", "MeshTypeError", "SettingsError", "BakeMemoryError",
    "BakeCancelled", "ImageWriteError", "ImageReadError", "bake_udim", "UdimResult", "bake_vertex_ao",
    "VertexBakeResult", "bake_maps", "bake_udim_maps", "bake_vertex_maps",
]
