"""The input of a selected-to-active bake: the high-poly meshes, the cage and the distances, checked, and in
the bake's frame (see :mod:`core.highpoly`)."""

import math

import numpy as np

from ..base.errors import MeshError, SettingsError
from ..geometry.mesh import Mesh
from ..tracing.tracer import embree_scene
from .extrusion import auto_extrusion
from .scene import concatenate


def as_list(highpoly):
    if isinstance(highpoly, Mesh):
        return [highpoly]
    try:
        return list(highpoly)
    except TypeError:
        raise SettingsError(f"highpoly must be a core.Mesh or a list of them, got {type(highpoly).__name__}") from None


class SelectedToActive:
    """The checked input of a selected-to-active bake, in world space (see the module docstring).

    Built by :meth:`check` from :func:`core.bake_ao`'s arguments; :meth:`normalized` moves it into the
    bake's frame.
    """

    def __init__(self, target, highs, extrusion, max_ray_distance, cage):
        self.target, self.highs, self.cage = target, highs, cage
        # ``extrusion`` None: automatic, measured by :meth:`resolve` (:func:`auto_extrusion`).
        self.extrusion, self.max_ray_distance = extrusion, max_ray_distance
        self.auto = extrusion is None
        self.measure = None  # the automatic extrusion's figures (AutoExtrusion), once measured
        self._frame_target = None
        self.unit = 1.0
        self._match_scene = None

    @classmethod
    def check(cls, target, highpoly, extrusion, max_ray_distance, cage):
        """Refuse bad meshes with an error naming them and saying what to change (``extrusion`` and
        ``max_ray_distance``: a request's, checked)."""
        highs = as_list(highpoly)
        for h in highs:
            if not isinstance(h, Mesh):
                raise SettingsError(f"high-poly meshes must be core.Mesh objects, got {type(h).__name__}")
        if not highs:
            raise SettingsError(f"selected to active needs at least one high-poly mesh to bake onto {target.name!r}")
        for h in highs:
            if h is target:
                raise SettingsError(f"{target.name!r} is the low-poly target and cannot also be a high-poly mesh "
                                    "baked onto itself; leave it out of the high-poly meshes")
        # The distances were checked with the request (core.base.request): None (measured) or >= 0, finite.
        limit = float(max_ray_distance)
        if cage is not None:
            if not isinstance(cage, Mesh):
                raise SettingsError(f"the cage must be a core.Mesh, got {type(cage).__name__}")
            if cage is target:
                raise SettingsError(f"the cage {cage.name!r} is the low-poly target itself; a cage is a copy of it "
                                    "with its vertices moved outwards, around the high-poly surface")
            same = (cage.positions.shape == target.positions.shape and cage.triangles.shape == target.triangles.shape
                    and np.array_equal(cage.triangles, target.triangles))
            if not same:
                raise MeshError(
                    f"the cage {cage.name!r} does not have the topology of the low-poly {target.name!r} "
                    f"({len(cage.positions)} vertices and {len(cage.triangles)} triangles against "
                    f"{len(target.positions)} and {len(target.triangles)}, or other triangles): a cage must be a "
                    f"copy of {target.name!r} with only its vertices moved"
                )
        return cls(target, highs, extrusion, 0.0 if math.isinf(limit) else limit, cage)

    def occluders_of(self, occluders):
        """The occluders less the target, the cage and the high-poly meshes (which occlude anyway)."""
        skip = [self.target] + ([self.cage] if self.cage is not None else []) + self.highs
        return [o for o in occluders if not any(o is k or k.same_geometry(o) for k in skip)]

    @property
    def triangle_count(self):
        return sum(h.triangle_count for h in self.highs) + (self.cage.triangle_count if self.cage is not None else 0)

    def normalized(self, centre, unit, max_span=float("inf")):
        """The same input in the bake's frame: positions (p - centre) / unit, distances / unit.

        A high-poly mesh or cage reaching ``max_span`` target sizes or farther is refused (single
        precision rays cannot hold both), as :func:`core.pipeline.prologue.normalized_scene` refuses occluders.
        """
        highs = [h.transformed(centre, unit) for h in self.highs]
        cage = None if self.cage is None else self.cage.transformed(centre, unit)
        for what, original, m in [("high-poly mesh", h, n) for h, n in zip(self.highs, highs)] + (
                [("cage", self.cage, cage)] if cage is not None else []):
            far = float(np.abs(m.positions).max())
            if not far < max_span:
                raise MeshError(f"{what} {original.name!r} reaches {far:.3g} times the size of {self.target.name!r} "
                                "away from it; ray tracing in single precision cannot hold both: move it onto "
                                f"{self.target.name!r}")
        out = SelectedToActive(self.target, highs, None if self.auto else self.extrusion / unit,
                               self.max_ray_distance / unit, cage)
        out.unit = unit
        out.world = self
        return out

    def matching_scene(self):
        """The high-poly meshes as one committed Embree scene, robust (built once, shared by the
        automatic extrusion and :class:`HighPolyScene`, which traces the AO rays in it too when
        nothing else occludes)."""
        if self._match_scene is None:
            self._match_scene = embree_scene([concatenate(self.highs, "high-poly")])[0]
        return self._match_scene

    def resolve(self, target):
        """In the bake's frame (``target`` normalised): an automatic extrusion measured from the
        meshes (:func:`auto_extrusion`), also set on the world input; nothing to do otherwise (a
        given extrusion, or a cage, which does not use one)."""
        self._frame_target = target
        if not self.auto:
            return
        if self.cage is not None:
            self.extrusion = self.world.extrusion = 0.0
            return
        self.world.extrusion = self.measured().extrusion * self.unit
        # In the frame as normalized() takes a given one (world / unit): a worker process, handed the
        # world value, computes the same bits.
        self.extrusion = self.world.extrusion / self.unit

    def measured(self):
        """The automatic extrusion's measure (:class:`AutoExtrusion`, the bake's frame), taken now if
        it was not (a bake with a given extrusion asks for it only to say what would fit)."""
        if self.measure is None:
            high = concatenate(self.highs, "high-poly")
            self.measure = auto_extrusion(self._frame_target, self.matching_scene(), high)
        return self.measure

    def metadata(self):
        """What goes into the files' metadata and the result's settings (world units)."""
        world = getattr(self, "world", self)
        return {"selected_to_active": True, "highpoly": ", ".join(h.name for h in world.highs),
                "extrusion": world.extrusion if world.cage is None else 0.0,
                "extrusion_auto": bool(world.auto and world.cage is None),
                "max_ray_distance": world.max_ray_distance,
                "cage": world.cage.name if world.cage is not None else ""}


__all__ = ["as_list", "SelectedToActive"]
