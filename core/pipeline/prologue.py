"""The first two steps of every bake: check its input against its request, then the prologue.

:func:`check` refuses bad meshes and arrays with an error that names the object and the problem,
before any heavy work; :class:`Prologue` moves the scene into the target's frame
(:func:`normalized_scene`), measures an automatic extrusion, checks memory and cancellation, and
builds the occlusion tracer. Both are the same for every target (texels, UDIM tiles, mesh corners,
selected to active), in this process and in a worker process.
"""

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import BakeCancelled, BakeMemoryError, MeshError, SettingsError
from ..base.machine import available_memory
from ..engine.scheduler import is_cancelled
from ..execution.cost import bake_bytes
from ..geometry.corners import all_corners, check_corners
from ..geometry.mesh import Mesh, mesh_list
from ..highpoly.input import SelectedToActive
from ..post import bent as bent_mod
from ..tracing import ground as ground_mod
from ..tracing.tracer import Tracer
from .result import empty_reason

#: Occluders farther than this many target sizes from the target are refused: float32 rays cannot
#: hold both (and so far away they cannot occlude it measurably).
MAX_SCENE_SPAN = 1e15


def frame_of(target):
    """(centre, unit) of the frame :func:`normalized_scene` moves a bake into."""
    lo, hi = target.positions.min(axis=0), target.positions.max(axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        unit = float(np.max(hi - lo))
    if not math.isfinite(unit):
        raise MeshError(f"mesh {target.name!r} spans more than the largest float ({unit}); scale it down")
    if unit <= 0 or unit < np.finfo(np.float64).tiny * 1e3:
        unit = 1.0  # a point: every triangle is degenerate and skipped anyway
    return (lo + hi) / 2.0, unit


def normalized_scene(target, occluders):
    """The target and its occluders in a frame centred on the target and scaled to its size.

    AO does not depend on the unit (max_distance scales with it), but float32 rays do: a scene
    modelled in metres at 1e13 or at 1e-14 loses the offsets that keep rays off their own surface.
    In this frame the target spans about 1 around the origin whatever units the input used.
    Occluders that are the target again (the same object or the same surface) are dropped: a
    surface coinciding with the target would hide every ray.

    Returns (target, occluders, unit): the world length of one unit of the new frame.
    """
    kept = []
    for o in occluders:
        if o is target or target.same_geometry(o) or any(o is k or k.same_geometry(o) for k in kept):
            continue
        kept.append(o)
    centre, unit = frame_of(target)
    scene = []
    for o in kept:
        m = o.transformed(centre, unit)
        far = float(np.abs(m.positions).max())
        if not far < MAX_SCENE_SPAN:
            raise MeshError(
                f"occluder {o.name!r} reaches {far:.3g} times the size of {target.name!r} away from it; "
                "ray tracing in single precision cannot hold both: leave it out of the occluders"
            )
        scene.append(m)
    return target.transformed(centre, unit), scene, unit


@dataclass
class Checked:
    """A bake's input after :func:`check`, in world space: the target, its occluders (less the
    target, the cage and the high-poly meshes), the selected-to-active input (or None), the bent
    normals' space and the corners to bake (a corner bake's: every corner when none were given)."""

    target: Mesh
    occluders: list
    s2a: SelectedToActive = None
    bent_space: object = None
    corners: np.ndarray = None


def check(request, target, occluders=(), highpoly=None, cage=None, bent_space=None, corners=None, laid_out=False):
    """Check the meshes and arrays of a bake of ``request``; raises the errors :func:`core.bake_ao`
    lists, before any heavy work. Returns :class:`Checked`. ``laid_out``: the target's UV triangles
    come laid out already (a worker process's bake, from its parent), in place of its UVs."""
    if not isinstance(target, Mesh):
        raise SettingsError(f"the target must be a core.Mesh, got {type(target).__name__}")
    if request.kind != "corners" and target.uvs is None and not laid_out:
        raise MeshError(f"mesh {target.name!r} has no UVs: the baker needs a UV map to know where each texel lies")
    occluders = mesh_list(occluders)
    s2a = None
    if highpoly is not None:  # selected to active: checked here, before any work
        if request.bent_normals:
            raise SettingsError("bent normals are not baked with selected to active (highpoly): bake them "
                                "from the high-poly object itself, or bake AO only")
        s2a = SelectedToActive.check(target, highpoly, request.extrusion, request.max_ray_distance, cage)
        occluders = s2a.occluders_of(occluders)
    space = bent_mod.check_space(bent_space, target) if request.bent_normals else None
    if request.kind == "corners":
        corners = all_corners(target) if corners is None else check_corners(corners, target)
    return Checked(target, occluders, s2a, space, corners)


class Prologue:
    """What every bake does before its first ray, whatever its target: move the checked scene into
    the target's frame (:func:`normalized_scene`), measure an automatic extrusion, check memory and
    cancellation, and build the occlusion tracer.

    Attributes: request, target, occluders (normalised), unit (world length of one unit of the frame),
    s2a (the normalised :class:`core.highpoly.input.SelectedToActive` or None), bent_space (checked),
    corners (a corner bake's), frame, name.
    """

    def __init__(self, checked, request, cancel=None):
        target = checked.target
        self.request, self.cancel = request, cancel
        self.s2a = None if checked.s2a is None else checked.s2a.normalized(*frame_of(target), MAX_SCENE_SPAN)
        self.bent_space, self.corners = checked.bent_space, checked.corners
        self.name = target.name
        self.frame = frame_of(target)
        self.target, self.occluders, self.unit = normalized_scene(target, checked.occluders)
        self.shared_tracer = None  # (meshes, tracer) of the scene built last, or kept from the last bake
        if self.s2a is not None:
            self.s2a.resolve(self.target)  # an automatic extrusion, measured from the meshes

    @property
    def triangle_count(self):
        """Triangles of every mesh the bake holds (target, occluders, high-poly meshes and cage)."""
        return (self.target.triangle_count + sum(o.triangle_count for o in self.occluders)
                + (self.s2a.triangle_count if self.s2a else 0))

    @property
    def triangle_counts(self):
        """(target, occluders, high-poly meshes and cage) triangles: :mod:`core.execution.cost` prices them apart."""
        return (self.target.triangle_count, sum(o.triangle_count for o in self.occluders),
                self.s2a.triangle_count if self.s2a else 0)

    def check_memory(self, s):
        """Refuse a bake that would not fit in the memory available (BakeMemoryError), by the one memory
        model (:func:`core.execution.cost.bake_bytes`)."""
        tri_total = self.triangle_count
        need = bake_bytes(s.width, s.height, self.triangle_counts, s.threads, s.chunk_rays, s.samples, s.source,
                          s.replicates, s.tile_shape[0] * s.tile_shape[1])
        avail = available_memory()
        if avail is not None and need > avail:
            raise BakeMemoryError(f"a {s.width} x {s.height} bake of {tri_total} triangles needs about "
                                  f"{need / 2**30:.2f} GiB, but only {avail / 2**30:.2f} GiB is available; "
                                  "lower the resolution")

    def check_cancel(self):
        if is_cancelled(self.cancel):
            raise BakeCancelled("the bake was cancelled before it started")

    def ground_height(self, s):
        """(world height, height in the bake's frame) of the ground plane (:mod:`core.tracing.ground`), or
        (None, None). 'auto': the lowest point of the surface whose AO is baked (the high-poly
        meshes' with selected to active, else the target's)."""
        if s.ground is None:
            return None, None
        centre, unit = self.frame
        if s.ground == "auto":
            baked = self.s2a.highs if self.s2a is not None else [self.target]
            low = min(float(m.positions[:, 2].min()) for m in baked)
            return float(centre[2]) + low * unit, low
        return s.ground, ground_mod.frame_height(s.ground, centre[2], unit)

    def tracer(self, s):
        """The occlusion tracer of the target and its occluders (and the ground), in the bake's frame;
        for a thickness map, of the target alone (:mod:`core.engine.thickness`). A second quantity of the
        same bake whose rays see the same meshes (a thickness map beside AO without occluders) shares
        the first one's Embree scenes (:meth:`core.tracing.tracer.Tracer.sharing`), and so does a
        bake given the scenes a worker kept from its last bake (:meth:`share`)."""
        meshes = [self.target] if s.quantity == "thickness" else [self.target] + self.occluders
        ground = None if s.quantity == "thickness" else self.ground_height(s)[1]
        last = self.shared_tracer
        if last is not None and len(last[0]) == len(meshes) and all(a is b for a, b in zip(last[0], meshes)):
            tracer = last[1].sharing(s.ignore_backfaces, s.falloff, s.max_distance / self.unit, ground=ground)
        else:
            tracer = Tracer(meshes, s.ignore_backfaces, s.falloff, s.max_distance / self.unit, ground=ground)
            self.shared_tracer = (meshes, tracer)
        tracer.constant_answer = s.constant_answer
        return tracer

    def share(self, count, tracer):
        """Trace in ``tracer``, built from this bake's first ``count`` meshes (the target, then its
        occluders: bit for bit the ones it was built from), instead of building one."""
        meshes = [self.target] + self.occluders
        if count <= len(meshes):
            self.shared_tracer = (meshes[:count], tracer)

    def nothing_covered(self, s, uvtris):
        """The error of a texel bake that covered no texel, saying why (the counts of the UV triangles)."""
        return MeshError(f"mesh {self.name!r}: the bake covered no texel of the {s.width} x {s.height} image "
                         f"({empty_reason(uvtris.degenerate_space, uvtris.degenerate, uvtris.outside)}): "
                         "nothing was written")


__all__ = ["Prologue", "Checked", "check", "frame_of", "normalized_scene", "MAX_SCENE_SPAN"]
