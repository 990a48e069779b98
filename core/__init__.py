"""mc_ao core: Monte Carlo hemisphere sampling and a per-texel ambient occlusion baker (no Blender)."""

from ._version import __version__
from .base.errors import (
    BakeCancelled,
    BakeMemoryError,
    ImageWriteError,
    McAoError,
    MeshError,
    MeshTypeError,
    SettingsError,
)
from .execution import cost
from .montecarlo import stats, warps
from .montecarlo.integrate import Estimate, estimate, integrate
from .montecarlo.stats import RunningStats
from .geometry.mesh import Mesh
from .pipeline.bake import BakeResult, bake_ao, bake_maps
from .files.imageio import ImageReadError
from .targets.udim import UdimResult, bake_udim, bake_udim_maps
from .targets.corners import VertexBakeResult, bake_vertex_ao, bake_vertex_maps

__all__ = [
    "__version__", "Mesh", "bake_ao", "BakeResult", "integrate", "estimate", "Estimate", "RunningStats",
    "stats", "warps", "McAoError", "MeshError", "MeshTypeError", "SettingsError", "BakeMemoryError",
    "BakeCancelled", "ImageWriteError", "ImageReadError", "bake_udim", "UdimResult", "bake_vertex_ao",
    "VertexBakeResult", "bake_maps", "bake_udim_maps", "bake_vertex_maps",
]
