"""Selected to active: the AO of high-poly meshes baked into the UVs of a low-poly one, by Cycles' rules.

A stage between surface sampling (:mod:`core.geometry.surface`) and direction sampling: each sample point of a
texel on the low-poly surface is moved to the high-poly surface the way Blender's bake does it
(``source/blender/render/intern/bake.cc``: ``RE_bake_pixels_populate_from_objects``,
``calc_point_from_barycentric_extrusion``, ``calc_point_from_barycentric_cage``,
``cast_ray_highpoly``), and AO is evaluated there (``intern/cycles/kernel/integrator/
init_from_bake.h``, ``shade_surface.h``: ``integrate_surface_ao``). The rules, exactly:

1. **The matching ray.** For a point p of the low-poly's triangle at barycentrics (u, v), with n the
   low-poly's normal there (the normalised interpolation of its corner normals on smooth faces, the
   face normal on flat ones):

   - *extrusion* (no cage): origin ``p + e n``, direction ``-n``, e the extrusion distance (given,
     or measured: see below): the ray starts outside the low surface and points back into it, along
     the normal only (a high surface farther out than ``e`` is never found);
   - *cage*: origin the cage's point of the same triangle at the same barycentrics, direction from
     it towards p (normalised; it does not stop at p). A cage point on p gives no direction: a miss.
     The extrusion is not used with a cage.

2. **The hit.** The nearest intersection with any high-poly mesh at distance ``t >= 0`` from the
   origin (front or back faces alike), if ``t <= max_ray_distance`` (measured from the extruded or
   cage point, not from p; 0 = no limit). Several high-poly meshes are one scene: the nearest hit
   among all of them wins.

3. **A miss.** A sample point whose ray finds nothing has no value: its samples are not traced and
   not counted. A texel's value is the mean over its points that found the high-poly surface (the
   part of the texel that matched); a texel none of whose points matched is left uncovered (``mask``
   False, ``miss`` True in the result), like the texels Cycles leaves unbaked, and the margin fills
   those within reach of covered texels (the rest stay 0). Misses are counted (``missed``).

4. **AO at the hit point** q: cosine-weighted (or uniform) directions about the high-poly's own
   shading normal there, the normalised interpolation of its corner normals (the face normal on flat
   faces), in the high-poly's own orientation, whatever side the matching ray came from (Cycles
   shades the hit as if seen from along that normal: a high-poly with flipped normals gets the AO of
   its other side). Rays leave from q pushed off along the high-poly's geometric normal on the
   shading normal's side; directions below the geometric surface count as occluded, as everywhere
   in the baker (:mod:`core.pipeline.run`).

5. **Occluders**: the high-poly meshes and the ``occluders`` given (Cycles: every other visible
   object of the view layer); never the low-poly target or the cage, even when passed among the
   occluders. Another object's face lying on the high-poly surface occludes the points it touches
   (contact, as :class:`core.tracing.tracer.Tracer` explains for the target).

The extrusion trap, and the automatic extrusion. With a too small extrusion (Cycles' default 0), a
point under a place where the high-poly bulges out of the low-poly starts its matching ray inside
the high-poly, and the ray meets the high-poly's far side from behind: the texel bakes the inside of
the high-poly (bright or dark blobs), and no ray "missed". With a too large one, in concave places a
ray starts beyond another part of the high-poly (the far wall of a slot) and matches that. The
default extrusion (None or 'auto') is measured from the meshes by :func:`auto_extrusion`: walking out
along the low-poly's normal from points spread over it, a surface met from behind is one the point
lies under (the extrusion must pass it), the first met from the front is another part across a gap
(the extrusion must stay short of it); the extrusion is the smallest that serves nearly every point.
``report['extrusion']`` says what was used. Whatever the extrusion, the bake counts the matching
rays that meet the high-poly from behind (its face normal along the ray) and, above
:data:`BEHIND_WARNING` of them, puts a warning naming the objects and what fits in
``report['warnings']``. A cage is used as given.

Differences from Cycles, by design: Cycles casts one matching ray per texel, at its centre, and then
jitters its AO samples over the high-poly triangle that ray hit; here every sample point has its own
position in the texel and its own matching ray, so a texel is the mean over the high-poly surface
its whole square maps to (the two agree in expectation where the AO field is smooth, not texel by
texel on detail finer than a texel). The matching rays are traced once per sample *point*, and
each point takes a block of :data:`DIRECTIONS_PER_POINT` directions (consecutive samples of the
texel's pattern: a stratified set), so they cost a fraction of the AO rays. The extrusion and the
max ray distance are world distances along the world-space normal; Cycles adds the extrusion in the
low-poly's object space (the same for a uniformly scaled object, whose scale the caller multiplies
in: :mod:`mc_ao.baking` does). Texels: mc_ao covers every texel a UV triangle touches, Cycles those
whose centre a triangle covers. Material normal maps and transparency of the high-poly are not seen.

The standard error (``stderr``). A texel's error has two parts: its directions, and the positions of
its P = samples / g sample points (the variance of the AO over the part of the high-poly surface the
texel maps to, over P). With replicates (``replicates`` >= 2, the default; the add-on's with an error
map or adaptive sampling) each replicate draws its own points, positions and directions, from its own
keys (:meth:`core.engine.patterns.TexelPattern.keys`), and ``stderr`` is the spread of the replicates
(:class:`core.engine.estimators.ErrorModel`, ``grouped``: for every source, since a point's block of
directions shares its position and the samples are not independent): both parts, pooled over the
texel's window like every error map. A replicate whose points all missed gives its texel no degrees
of freedom (it takes its neighbours' pooled error). Adaptive rounds stop on that interval; the
misses' texels take no round after the first. With one replicate ``stderr`` is the samples' spread,
the directions' part alone: where the AO changes within a texel (detail finer than a texel) the error
is larger than it says. tests/test_highpoly.py checks both against the exact values. The pooling
assumes the error varies smoothly over the image; it does not where the high-poly's AO jumps inside
single texels (a box resting on the high-poly, its footprint's edge cutting texels at 64 spp: there
the position part dominates and the pooled ``stderr`` is about 1.7 times too small, and 2-3 times
too large on the texels around them; measured, not tested).

Everything here runs in the bake's normalised frame (:func:`core.pipeline.prologue.normalized_scene`): the
extrusion and the distance scale with it. A sample point draws its position from its index in the
texel's pattern and its directions from the indices of its block, so bakes stay bit-identical for
any thread count, tile size and chunk size.
"""

import math
import threading
from dataclasses import dataclass

import numpy as np

from ..tracing import ground as _ground
from ..montecarlo import warps
from ..base.errors import MeshError, SettingsError
from ..engine.adaptive import replicate_samples
from ..engine.estimators import TexelEstimates
from ..engine.kernel import TileContext
from ..geometry.mesh import Mesh, corner_positions
from ..geometry.raster import rasterize_tile
from ..geometry.surface import SurfaceTable, point_table, point_units
from ..engine.tilebaker import ChunkSums
from ..tracing.tracer import FAR, Clock, Tracer, embree_scene

#: High-poly meshes of at least this many triangles, with nothing else occluding, trace their AO rays
#: in the robust matching scene instead of a second, fast one (:class:`HighPolyScene`).
ONE_SCENE_TRIANGLES = 1 << 20
#: Directions traced per sample point (the most: fewer when the sample counts are not multiples).
DIRECTIONS_PER_POINT = 64
#: Points spread over the low-poly surface (by area) that the check before a bake casts matching rays from.
PRECHECK_POINTS = 1 << 12
_TAG_PRECHECK = 31


def directions_per_point(samples, min_samples, adaptive, replicates=1):
    """Directions per sample point: the largest power of two up to :data:`DIRECTIONS_PER_POINT` that
    divides each replicate's share of the sample count (:func:`core.engine.adaptive.replicate_samples`)
    and, with adaptive sampling, each replicate's share of the minimum (the first round): every round
    of every replicate is then whole points (the later rounds' counts are powers of two at least
    twice the first, or the share: :class:`core.engine.adaptive.SamplingPlan`)."""
    g = DIRECTIONS_PER_POINT
    for cap in replicate_samples(samples, replicates):
        g = math.gcd(g, int(cap))
    if adaptive:
        g = math.gcd(g, max(1, -(-int(min(min_samples, samples)) // int(replicates))))
    return g


def as_list(highpoly):
    if isinstance(highpoly, Mesh):
        return [highpoly]
    try:
        return list(highpoly)
    except TypeError:
        raise SettingsError(f"highpoly must be a core.Mesh or a list of them, got {type(highpoly).__name__}") from None


def _distance(value, what):
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise SettingsError(f"{what} must be a number, got {value!r}") from None
    if math.isnan(value) or value < 0:
        raise SettingsError(f"{what} must be a distance >= 0, got {value}")
    return value


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
        """Refuse bad input with an error naming the meshes and saying what to change."""
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
        if extrusion is None or (isinstance(extrusion, str) and extrusion == "auto"):
            extrusion = None  # measured from the meshes (auto_extrusion)
        else:
            extrusion = _distance(extrusion, "the extrusion")
        limit = _distance(max_ray_distance, "the max ray distance (0 = no limit)")
        if extrusion is not None and not math.isfinite(extrusion):
            raise SettingsError(f"the extrusion must be a finite distance, got {extrusion}")
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
            self._match_scene = embree_scene([_concatenate(self.highs, "high-poly")])[0]
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
            high = _concatenate(self.highs, "high-poly")
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


def _concatenate(meshes, name):
    """One Mesh of ``meshes`` (their triangles in order, vertex indices shifted), corner normals kept."""
    if len(meshes) == 1:
        return meshes[0]
    offsets = np.cumsum([0] + [len(m.positions) for m in meshes[:-1]])
    return Mesh(np.concatenate([m.positions for m in meshes]),
                np.concatenate([m.triangles + o for m, o in zip(meshes, offsets)]),
                normals=np.concatenate([m.normals for m in meshes]), name=name)


class HighPolyScene:
    """The high-poly side of a bake in its normalised frame: the matching scene, the occlusion tracer,
    and each high-poly triangle's corners and normals (to shade a hit), computed for the triangles
    hit (nothing of the kind is kept per triangle: a high-poly has millions).

    One Embree scene where memory matters: when nothing but the high-poly meshes occludes (no other
    occluders, or a thickness map) and they hold :data:`ONE_SCENE_TRIANGLES` or more, the matching
    scene traces the AO rays too, saving the second scene (93 bytes a triangle in every process: about
    a gigabyte per process for ten million triangles). The matching scene is built in Embree's robust
    mode (the matching rays need it, :data:`core.tracing.tracer.OCCLUSION_ROBUST`), which traced the AO rays
    25-30% slower than the fast mode of a second scene (140 against 108 ns a ray on a 131k-triangle
    high-poly, 222 against 178 on 2M, one thread), and answers a few rays grazing its edges
    differently (1 in 4.2 million there). Smaller high-poly meshes keep the fast second scene.

    Parameters
    ----------
    s2a : a normalised :class:`SelectedToActive`; occluders : the other occluders (normalised);
    ignore_backfaces, falloff, max_distance : as in :func:`core.bake_ao` (max_distance in the frame);
    ground : the ground plane's height in the frame, or None (:mod:`core.tracing.ground`); occluding : False
    for a thickness map (:mod:`core.engine.thickness`): the high-poly meshes alone occlude, without contact.
    """

    def __init__(self, s2a, occluders, ignore_backfaces, falloff, max_distance, ground=None, occluding=True):
        self.s2a = s2a
        highs = s2a.highs
        self.ends = np.cumsum([h.triangle_count for h in highs])  # owner of triangle t: searchsorted
        self.high = high = _concatenate(highs, "high-poly")
        # Matching: the high-poly meshes alone, in Embree's robust mode (a low-poly lying on the
        # high-poly surface starts its rays on it, see core.tracing.tracer.OCCLUSION_ROBUST).
        self.match_scene = s2a.matching_scene()
        # Occlusion: the high-poly meshes and the occluders, as one mesh (Tracer's contact scene is for a
        # single target; contact here is per high-poly mesh, below).
        if not occluding:
            occluders, ground = [], None
        if occluders or high.triangle_count < ONE_SCENE_TRIANGLES:
            everything = _concatenate(highs + list(occluders), "high-poly and occluders")
            self.tracer = Tracer([everything], ignore_backfaces, falloff, max_distance, ground=ground)
        else:
            self.tracer = Tracer([high], ignore_backfaces, falloff, max_distance, ground=ground,
                                 scene=self.match_scene)
        self.limit = np.float32(min(s2a.max_ray_distance, FAR) if s2a.max_ray_distance > 0 else FAR)
        self.contact = _Contact(highs if occluding else [], list(occluders), self.tracer)

    def corners(self, tri):
        """(n, 3, 3) corner positions of high-poly triangles ``tri``."""
        return corner_positions(self.high.positions, self.high.triangles[tri])

    def face_normals(self, tri):
        """(n, 3) unit face normals of high-poly triangles ``tri``."""
        return self.high.face_geometry_of(tri)[1]

    def owner(self, tri):
        """Which high-poly mesh each of triangles ``tri`` belongs to."""
        return np.searchsorted(self.ends, tri, side="right")

    def match(self, origins, directions):
        """Cast matching rays (m, 3) float64; returns (hit (m,) bool, and for the hits: high-poly
        triangle, point q (float64), unit shading normal, unit geometric normal on its side)."""
        o32 = np.ascontiguousarray(origins, dtype=np.float32)
        d32 = np.ascontiguousarray(directions, dtype=np.float32)
        out = self.match_scene.run(o32, d32, dists=np.full(len(o32), self.limit, np.float32), output=True)
        prim = out["primID"]
        hit = prim >= 0
        tri = prim[hit].astype(np.int64)
        weights = np.empty((len(tri), 3))
        weights[:, 1] = out["u"][hit]
        weights[:, 2] = out["v"][hit]
        weights[:, 0] = 1.0 - weights[:, 1] - weights[:, 2]
        q = np.einsum("ij,ijk->ik", weights, self.corners(tri))
        n = np.einsum("ij,ijk->ik", weights, self.high.corner_normals(tri))
        ln = np.sqrt(np.einsum("ij,ij->i", n, n))
        fn = self.face_normals(tri)
        good = (ln > 1e-12) & np.any(fn != 0, axis=1)  # a hit on a triangle of no area has no normal
        if not good.all():
            keep = np.flatnonzero(hit)[good]
            hit = np.zeros_like(hit)
            hit[keep] = True
            tri, q, n, ln, fn = tri[good], q[good], n[good], ln[good], fn[good]
        n /= ln[:, None]
        gn = np.where((np.einsum("ij,ij->i", fn, n) < 0)[:, None], -fn, fn)
        return hit, tri, q, n, gn


class _Contact:
    """Contact between a high-poly mesh and the other meshes (other high-poly meshes, occluders).

    For each high-poly mesh whose bounding box comes within reach of other triangles, an Embree scene
    of those triangles; a sample point in contact (another object's face through it, found by a probe
    across the surface, as :meth:`core.tracing.tracer.Tracer.contact`) is occluded in every direction.
    """

    def __init__(self, highs, occluders, tracer):
        self.tracer = tracer
        self.scenes = {}
        others = highs + occluders
        grow = 2.0 * tracer.offset(max((float(np.abs(m.positions).max()) for m in others), default=0.0))
        boxes = [(m.positions.min(axis=0) - grow, m.positions.max(axis=0) + grow) for m in others]
        for i in range(len(highs)):
            lo, hi = boxes[i]
            parts = []
            for j, m in enumerate(others):
                if j == i or np.any(boxes[j][0] > hi) or np.any(boxes[j][1] < lo):
                    continue
                corners = corner_positions(m.positions, m.triangles)
                near = np.all((corners.max(axis=1) >= lo) & (corners.min(axis=1) <= hi), axis=1)
                if near.any():
                    parts.append(corners[near])
            if parts:
                corners = np.concatenate(parts)
                mesh = Mesh(corners.reshape(-1, 3), np.arange(3 * len(corners)).reshape(-1, 3), name="contact")
                self.scenes[i] = (embree_scene([mesh])[0], corners.min(axis=1), corners.max(axis=1))

    def touching(self, owner, tri_corners, points, gn):
        """Per point (on high-poly mesh ``owner``, triangle corners (m, 3, 3)), whether another
        object's surface (or the ground) crosses it."""
        out = np.zeros(len(points), bool)
        if self.tracer.ground is not None:
            out |= _ground.touching(points[:, 2], gn[:, 2], self.tracer.point_offset(points), self.tracer.ground)
        for i in np.unique(owner):
            entry = self.scenes.get(int(i))
            if entry is None:
                continue
            scene, olo, ohi = entry
            sel = np.flatnonzero(owner == i)
            c = tri_corners[sel]
            grow = 2.0 * self.tracer.offset(np.abs(c).max(axis=(1, 2)))[:, None]
            lo, hi = c.min(axis=1) - grow, c.max(axis=1) + grow
            ulo, uhi = lo.min(axis=0), hi.max(axis=0)
            cand = np.flatnonzero(np.all((olo <= uhi) & (ohi >= ulo), axis=1))
            if not len(cand):
                continue
            near = np.zeros(len(sel), bool)
            for c0 in range(0, len(cand), 256):
                k = cand[c0:c0 + 256]
                near |= np.any(np.all((olo[k][None] <= hi[:, None]) & (ohi[k][None] >= lo[:, None]), axis=2), axis=1)
            idx = sel[near]
            if not len(idx):
                continue
            p = points[idx]
            e = self.tracer.point_offset(p)
            below = (p - gn[idx] * e[:, None]).astype(np.float32)
            hit = scene.run(below, np.ascontiguousarray(gn[idx], dtype=np.float32), query="OCCLUDED",
                            dists=(2.0 * e).astype(np.float32))
            out[idx[hit >= 0]] = True
        return out



class LowPoints:
    """The low-poly's sample points and their matching rays (normalised frame, float64).

    ``table`` is the target's :class:`core.geometry.surface.SurfaceTable`; ``cage_table`` the cage's, built on
    the target's UV triangles (same triangles, same texel-space maps), or None for extrusion.
    """

    def __init__(self, s2a, table, cage_table):
        self.s2a, self.table, self.cage_table = s2a, table, cage_table
        # Per triangle, [P0, Px, Py] and [N0, Nx, Ny] (or the cage's positions) as one (T, 3, 3) map each:
        # a point is [1, a, b] times its triangle's map.
        # In float64: the tables keep float32 maps, every computation reads them in float64.
        self.position = np.stack([table.P0, table.Px, table.Py], axis=1).astype(np.float64)
        if cage_table is None:
            self.second = np.stack([table.N0, table.Nx, table.Ny], axis=1).astype(np.float64)
        else:
            self.second = np.stack([cage_table.P0, cage_table.Px, cage_table.Py], axis=1).astype(np.float64)

    def rays(self, tri, a, b):
        """Matching rays of the points at texel-space offsets (a, b) from their triangles' first corners.

        Returns (p, origins, unit directions, usable): ``usable`` is False where a cage point lies on
        its low-poly point (no direction: a miss, as in Cycles).
        """
        x = np.empty((len(tri), 3))
        x[:, 0] = 1.0
        x[:, 1] = a
        x[:, 2] = b
        p = np.einsum("ij,ijk->ik", x, self.position[tri])
        other = np.einsum("ij,ijk->ik", x, self.second[tri])
        if self.cage_table is None:
            return (p,) + extruded(p, other, self.table.take("FN", tri), self.s2a.extrusion)
        return (p,) + towards(other, p)


#: Points spread over the low-poly surface (by area) that the automatic extrusion is measured from.
EXTRUSION_POINTS = 1 << 12
#: The automatic extrusion is the smallest that serves all but this share of the points (of those that
#: the best extrusion serves): points it gives up are those whose need is far out of line.
EXTRUSION_SLACK = 1e-3
#: Headroom above the measured need: this share of it, plus EXTRUSION_FLOOR target sizes.
EXTRUSION_HEADROOM, EXTRUSION_FLOOR = 0.05, 1e-4
#: Crossings followed along each point's normal before giving up (nested high-poly shells).
EXTRUSION_STEPS = 16
_TAG_EXTRUSION = 37


@dataclass
class AutoExtrusion:
    """The automatic extrusion and what it was measured from (the bake's frame): ``extrusion``; per
    point, ``need`` (the extrusion it needs) and ``limit`` (the most it stands); ``served``: the
    share of the points whose interval holds the extrusion."""

    extrusion: float
    need: np.ndarray
    limit: np.ndarray
    served: float


def surface_points(mesh, count, tag):
    """``count`` points on ``mesh``'s triangles of positive area, spread by area (stratified,
    deterministic): (triangle, barycentric weights (count, 3))."""
    from ..engine.patterns import hash_uniform

    area = mesh.areas
    valid = np.flatnonzero(area > 0)
    if not len(valid):
        return valid, np.zeros((0, 3))
    cdf = np.cumsum(area[valid])
    cdf /= cdf[-1]
    k = np.arange(count, dtype=np.uint64)
    u = (np.arange(count) + hash_uniform(np.uint64(1), k, np.uint64(tag))) / count
    tri = valid[np.minimum(np.searchsorted(cdf, u, side="right"), len(valid) - 1)]
    w0, w1 = warps.square_to_triangle(hash_uniform(np.uint64(2), k, np.uint64(tag)),
                                      hash_uniform(np.uint64(3), k, np.uint64(tag)))
    return tri, np.stack([w0, w1, 1.0 - w0 - w1], axis=1)


def auto_extrusion(target, match_scene, face_normals, count=EXTRUSION_POINTS):
    """The extrusion that lets the most matching rays find the right high-poly surface, measured from
    the meshes (all in the bake's frame).

    A matching ray starts at p + e n and goes back along -n, taking the nearest high-poly surface
    (Cycles' rule). It finds the surface that belongs to p when the segment from p + e n to that
    surface crosses no other part of the high-poly. Walking from p (just below it) out along +n
    through the high-poly's surfaces tells, per point, which e do that:

    - a surface met from behind (its normal along +n) is one the walk leaves the high-poly through:
      p lies inside the high-poly, which bulges out of the low-poly there, and e must reach past it.
      ``need`` is the distance of the last such crossing before the first surface met from the front;
    - the first surface met from the front (its normal against +n) is another part of the high-poly
      across a gap (the far wall of a concave part, a neighbouring fold): a ray starting beyond it
      would take that part instead. ``limit`` is its distance (inf where the walk meets none).

    Each point is served by any e in [need, limit). The extrusion is the smallest e that serves as
    many points as the best e does, less EXTRUSION_SLACK of them (a few points that need far more
    than the rest, deep under an overhang, do not push every other ray out past its far walls), plus
    EXTRUSION_HEADROOM of it and EXTRUSION_FLOOR (rays that start exactly on the surface they should
    find), kept inside the served interval. Where the high-poly lies wholly inside the low-poly every
    need is 0 and the extrusion is the floor. ``count`` points are spread over the whole low-poly by
    area (not only the part the UVs bake), so every UDIM tile and target of one object gets the same
    extrusion.
    """
    tri, w = surface_points(target, count, _TAG_EXTRUSION)
    if not len(tri):
        return AutoExtrusion(0.0, np.zeros(0), np.zeros(0), 1.0)
    # ``face_normals``: the high-poly's (T, 3), or the high-poly Mesh (its normals of the triangles hit).
    fn_of = ((lambda i: face_normals.face_geometry_of(i)[1]) if isinstance(face_normals, Mesh)
             else (lambda i: face_normals[i]))
    p = np.einsum("ij,ijk->ik", w, corner_positions(target.positions, target.triangles[tri]))
    _, n, _ = extruded(p, np.einsum("ij,ijk->ik", w, target.normals[tri]), target.face_normals[tri], 0.0)
    n = -n  # extruded() returns the ray direction, -n
    m = len(p)
    size = float(np.max(target.positions.max(axis=0) - target.positions.min(axis=0))) or 1.0
    from ..tracing.tracer import EPS_POSITION, EPS_SCENE

    step = 2.0 * (EPS_SCENE * size + EPS_POSITION * np.abs(p).max(axis=1))
    need = np.zeros(m)
    limit = np.full(m, np.inf)
    at = -step  # distance along +n from p of each walk's current origin
    todo = np.arange(m)
    n32 = np.ascontiguousarray(n, np.float32)
    for _ in range(EXTRUSION_STEPS):
        if not len(todo):
            break
        origin = (p[todo] + n[todo] * at[todo, None]).astype(np.float32)
        out = match_scene.run(origin, n32[todo], dists=np.full(len(todo), FAR, np.float32), output=True)
        prim = out["primID"]
        hit = prim >= 0
        t = at[todo] + out["tfar"].astype(np.float64)
        behind = hit & (np.einsum("ij,ij->i", fn_of(np.maximum(prim, 0)), n[todo]) > 0)
        front = hit & ~behind
        limit[todo[front]] = np.maximum(t[front], 0.0)
        need[todo[behind]] = np.maximum(t[behind], 0.0)
        at[todo[behind]] = t[behind] + step[todo[behind]]
        todo = todo[behind]
    # The smallest e serving (nearly) as many points as the best: coverage(e) = #(need <= e) - #(limit <= e).
    cand = np.unique(np.concatenate([[0.0], need]))
    ns, ls = np.sort(need), np.sort(limit)

    def served(e):
        return np.searchsorted(ns, e, side="right") - np.searchsorted(ls, e, side="right")

    cover = served(cand)
    best = int(cover.max())
    e = float(cand[np.flatnonzero(cover >= best - EXTRUSION_SLACK * m)[0]])
    out = e * (1.0 + EXTRUSION_HEADROOM) + EXTRUSION_FLOOR * size
    if served(np.array([out]))[0] < served(np.array([e]))[0]:
        # Headroom would cross a far wall: halfway to the nearest limit above e instead.
        above = ls[ls > e]
        out = e + 0.5 * (float(above[0]) - e) if len(above) else out
    return AutoExtrusion(out, need, limit, float(served(np.array([out]))[0]) / m)


def extruded(p, n, fn, extrusion):
    """Extrusion rays: origin p + e n, direction -n, n the normalised interpolated normal (``fn`` where
    it vanishes); all usable."""
    ln = np.sqrt(np.einsum("ij,ij->i", n, n))
    ok = ln > 1e-12
    if ok.all():
        n /= ln[:, None]
    else:
        n = np.where(ok[:, None], n / np.where(ok, ln, 1.0)[:, None], fn)
    return p + extrusion * n, -n, np.ones(len(p), bool)


def towards(origin, p):
    """Cage rays: from the cage point towards the low-poly point; unusable where they coincide."""
    d = p - origin
    ln = np.linalg.norm(d, axis=1)
    usable = ln > 0
    return origin, d / np.where(usable, ln, 1.0)[:, None], usable


class HighPolyStart:
    """The start stage of a selected-to-active bake (see :mod:`core.engine.tilebaker`): each sample point of
    a texel on the low-poly surface casts its matching ray, and the ``per_point`` samples of a point
    that found the high-poly surface start there, with the high-poly's normal: the hits are units of
    constant points (:func:`core.geometry.surface.point_table`) that the one kernel traces as it traces mesh
    vertices. Point j of a texel takes the position of the texel's sample j (u2, u3, through the
    kernel's own placement, :meth:`core.engine.kernel.Kernel.positions`) and the directions of its samples
    j g .. j g + g - 1; misses are not traced and not counted.
    """

    grouped = True
    locate = False

    def __init__(self, stage, settings):
        self.stage, self.points, self.scene = stage, stage.points, stage.scene
        self.per_point = stage.g
        self.lock = threading.Lock()
        self.matching_rays = 0
        self.behind = 0  # matching rays that met the high-poly from behind (they started inside it)
        self.missed = 0
        self.partial = 0
        self.found = 0
        # The check before the bake (HighPolyStage) counts as matching too.
        self.match_seconds = stage.check_seconds
        self.match_cpu_seconds = stage.check_cpu_seconds

    def estimates(self, count, replicates):
        est = TexelEstimates(count, replicates)
        est.points = np.zeros(count, np.int64)   # sample points cast per texel (all replicates)
        est.missed = np.zeros(count, np.int64)   # of which found no high-poly surface
        return est

    def contact(self, frag, width, samples):
        return np.zeros(len(frag.texels), bool)  # contact is found per matched point (HighPolyScene)

    def curved(self, units, unit, located):
        return np.zeros(len(unit), bool)  # the hits take the smooth form, whatever the low-poly's

    def keep(self, est, texels):
        """A texel none of whose points found the high-poly surface takes no further rounds."""
        return ~((est.points[texels] > 0) & (est.n[texels] == 0))

    def run(self, kernel, tile, curved, unit, first, k, squares, located, vectors, replicates):
        """Pieces of ``k`` sample points from ``first`` of each piece's unit: their matching rays, then
        ``per_point`` AO rays from each point that found the high-poly surface, through the kernel."""
        units, scene, g = tile.units, self.scene, self.per_point
        npieces = len(unit)
        inside, stage = Clock(), Clock()
        with stage:
            a, b = kernel.positions(tile, unit, first, k, squares, replicates)
            tri = np.repeat(units.tri[unit], k)
            _, origins, directions, usable = self.points.rays(tri, a.reshape(-1), b.reshape(-1))
            cast = np.flatnonzero(usable)
            with inside:
                found, htri, hq, hn, hgn = scene.match(origins[cast], directions[cast])
                point = cast[found]  # index (piece * k + j) of every point that hit
                behind = int(np.count_nonzero(np.einsum("ij,ij->i", scene.face_normals(htri), directions[point]) > 0))
                hcorners = scene.corners(htri)
                touch = None
                if (scene.contact.scenes or scene.tracer.ground is not None) and len(point):
                    touch = scene.contact.touching(scene.owner(htri), hcorners, hq, hgn)
        nh = len(point)
        piece = point // k
        hits = np.bincount(piece, minlength=npieces)
        with self.lock:
            self.matching_rays += len(cast)
            self.behind += behind
            self.missed += npieces * k - nh
            self.match_seconds += stage.wall
            self.match_cpu_seconds += stage.cpu
        work = npieces * k * g
        if nh == 0:
            zero = np.zeros(npieces)
            if vectors is not None:
                vectors[...] = 0.0
            return ChunkSums(hits * g, zero, zero, vectors, work, len(cast), inside.wall, inside.cpu, hits)
        # The hits as units of constant points, in the smooth form (one call for all of them).
        table = point_table(hq, hn, hgn, hcorners, smooth=True)
        ids = np.arange(nh, dtype=np.int64)
        hit_tile = TileContext(table, point_units(ids, units.texel[unit][piece]), tile.keys, tile.texel_ids,
                               np.zeros(tile.texels, bool), scene.tracer.offset, tris=ids, blocked=touch,
                               inward=tile.inward)
        vec = None if vectors is None else np.empty((nh, 3))
        s1, s2, rays, sec, cpu = kernel.run(hit_tile, True, ids, (first[piece] + point % k) * g, g, nh, vectors=vec,
                                            replicates=None if replicates is None else replicates[piece])
        s1 = np.bincount(piece, weights=s1, minlength=npieces)
        s2 = np.bincount(piece, weights=s2, minlength=npieces)
        if vectors is not None:
            for c in range(3):
                vectors[:, c] = np.bincount(piece, weights=vec[:, c], minlength=npieces)
        return ChunkSums(hits * g, s1, s2, vectors, work, len(cast) + rays, inside.wall + sec, inside.cpu + cpu, hits)

    def commit(self, est, texel, k, hits, replicate):
        np.add.at(est.points, texel, k)
        np.add.at(est.missed, texel, k - hits)

    # -- the whole bake --------------------------------------------------------------------------------

    def lost(self, est):
        """Per texel of a finished tile: none of its points matched (uncovered, left to the margin)."""
        lost = est.n == 0
        with self.lock:
            self.partial += int(np.count_nonzero((est.missed > 0) & ~lost))
            self.found += int(np.count_nonzero(~lost))
        return lost

    def counters(self):
        """What this process counted (summed over worker processes by :func:`finish_report`)."""
        return {"matching_rays": self.matching_rays, "behind": self.behind, "missed": self.missed,
                "partial": self.partial,
                "matching_seconds": self.match_seconds, "matching_cpu_seconds": self.match_cpu_seconds,
                "directions_per_point": self.per_point,
                "nothing_matched": self.stage.nothing_matched() if self.matching_rays and not self.found else None}


#: More than this share of the matching rays meeting the high-poly from behind gets a warning.
BEHIND_WARNING = 0.01


def finish_report(counters, miss, mask, s2a=None):
    """The report entries of a selected-to-active bake from its counters (one process's, or several
    added up), with the extrusion used and the warnings of ``s2a`` (the normalised input); raises
    MeshError when no texel matched at all."""
    if counters["matching_rays"] and not mask.any():
        raise MeshError(counters["nothing_matched"] or "no matching ray found the high-poly surface")
    extra = {}
    warnings = []
    if s2a is not None:
        world = s2a.world
        extra["extrusion"] = world.extrusion if world.cage is None else 0.0
        if s2a.measure is not None:
            extra["extrusion_served"] = s2a.measure.served
        behind = counters.get("behind", 0)
        rays = counters["matching_rays"]
        if rays and behind > BEHIND_WARNING * rays:
            low, highs = world.target.name, ", ".join(repr(h.name) for h in world.highs)
            if world.cage is not None:
                fix = (f"make the cage {world.cage.name!r} enclose the high-poly surface everywhere, without "
                       "reaching past other parts of it")
            elif world.auto:
                fix = (f"the automatic extrusion ({world.extrusion:.4g}) serves "
                       f"{100.0 * s2a.measured().served:.1f}% of the points it measured: the high-poly is too far "
                       f"from {low!r} in places for any one extrusion; use a cage")
            else:
                need = s2a.measured().extrusion * s2a.unit
                fix = (f"the extrusion is {world.extrusion:.4g}, and about {need:.4g} fits these meshes: leave it "
                       "automatic (None), set it near that, or use a cage")
            warnings.append(
                f"{low!r}: {100.0 * behind / rays:.1f}% of the matching rays met the high-poly surface of {highs} from "
                f"behind: they started inside it (an extrusion smaller than how far it bulges out of {low!r}) or "
                f"behind another part of it (an extrusion reaching past a far wall), and those texels bake the wrong "
                f"side (bright or dark blobs); {fix}")
    extra["matching_rays_behind"] = counters.get("behind", 0)
    extra["warnings"] = warnings
    return dict(extra, **{"matching_rays": counters["matching_rays"], "missed_matching_rays": counters["missed"],
            "missed_texels": int(miss.sum()), "partly_missed_texels": counters["partial"],
            "directions_per_point": counters["directions_per_point"],
            "matching_seconds": counters["matching_seconds"],
            "matching_cpu_seconds": counters["matching_cpu_seconds"]})


class HighPolyStage:
    """Everything a selected-to-active bake sets up before its tiles: the high-poly scene, the
    low-poly's points, and the check that some matching ray finds the high-poly surface at all.

    Parameters
    ----------
    s2a : a normalised :class:`SelectedToActive`; target : the normalised target; occluders : the
    normalised occluders (target, cage and high-poly meshes left out); uvtris, table, bins : the
    target's UV triangles, surface table and tiles (:mod:`core.geometry.raster`, :mod:`core.geometry.surface`);
    settings : :class:`core.engine.settings.BakeSettings`; unit : world length of one unit of the frame;
    cancelled : callable, True to stop (checked while scanning).
    """

    def __init__(self, s2a, target, occluders, uvtris, table, bins, settings, unit, cancelled=lambda: False,
                 ground=None, occluding=True):
        self.s2a, self.target, self.uvtris, self.table, self.unit = s2a, target, uvtris, table, unit
        self.s = settings
        self.g = directions_per_point(settings.samples, settings.min_samples, settings.adaptive,
                                      settings.replicates)
        self.scene = HighPolyScene(s2a, occluders, settings.ignore_backfaces, settings.falloff,
                                   settings.max_distance / unit, ground=ground, occluding=occluding)
        cage_table = None
        if s2a.cage is not None:
            cage = s2a.cage
            cage_table = SurfaceTable.build(cage, uvtris)
        self.points = LowPoints(s2a, table, cage_table)
        self._probe = None
        clock = Clock()
        with clock:
            found = self._any_match(bins, cancelled)
        self.check_seconds, self.check_cpu_seconds = clock.wall, clock.cpu
        if not found:
            raise MeshError(self.nothing_matched())

    def start(self):
        """The start stage the tile baker traces this bake's tiles with."""
        return HighPolyStart(self, self.s)

    # -- the check before baking -----------------------------------------------------------------------

    def _surface_points(self):
        """PRECHECK_POINTS points on the target's bakeable triangles, spread by area (stratified,
        deterministic): (triangle, barycentric weights (n, 3))."""
        valid = np.flatnonzero(self.uvtris.valid)
        if not len(valid):
            return valid, np.zeros((0, 3))
        area = self.target.areas[valid]
        cdf = np.cumsum(area)
        cdf /= cdf[-1]
        n = PRECHECK_POINTS
        from ..engine.patterns import hash_uniform

        k = np.arange(n, dtype=np.uint64)
        u = (np.arange(n) + hash_uniform(np.uint64(1), k, np.uint64(_TAG_PRECHECK))) / n
        tri = valid[np.minimum(np.searchsorted(cdf, u, side="right"), len(valid) - 1)]
        w0, w1 = warps.square_to_triangle(hash_uniform(np.uint64(2), k, np.uint64(_TAG_PRECHECK)),
                                          hash_uniform(np.uint64(3), k, np.uint64(_TAG_PRECHECK)))
        return tri, np.stack([w0, w1, 1.0 - w0 - w1], axis=1)

    def _point_rays(self, tri, w):
        m = self.target
        p = np.einsum("ij,ijk->ik", w, corner_positions(m.positions, m.triangles[tri]))
        if self.s2a.cage is None:
            n = np.einsum("ij,ijk->ik", w, m.normals[tri])
            return p, extruded(p, n, m.face_normals[tri], self.s2a.extrusion)
        c = np.einsum("ij,ijk->ik", w, corner_positions(self.s2a.cage.positions, self.s2a.cage.triangles[tri]))
        return p, towards(c, p)

    def _any_match(self, bins, cancelled):
        """Whether some matching ray finds the high-poly surface: first from points spread over the
        surface by area; where none does, from every texel the bake covers (one point each), so that a
        high-poly matching only a small part of the low-poly is not refused."""
        tri, w = self._surface_points()
        if not len(tri):
            return True  # nothing to bake: the bake says so itself
        p, (origin, direction, usable) = self._point_rays(tri, w)
        self._probe = (p, origin, direction, usable)
        if self.scene.match(origin[usable], direction[usable])[0].any():
            return True
        s = self.s
        for ty, tx in sorted(bins):
            if cancelled():
                from ..base.errors import BakeCancelled

                raise BakeCancelled("the bake was cancelled before it started")
            frag = rasterize_tile(self.uvtris, bins[(ty, tx)], s.width, s.height, *s.tile_bounds((ty, tx)),
                                  locate=False)
            full = frag.full_tri >= 0
            t_full = frag.full_tri[full]
            xy_full = np.stack([frag.texels[full] % s.width, frag.texels[full] // s.width], axis=1) + 0.5
            xy_sub = frag.sub_xy.mean(axis=1)
            t = np.concatenate([t_full, frag.sub_tri])
            xy = np.concatenate([xy_full, xy_sub]).astype(np.float64)
            if not len(t):
                continue
            origin = self.table.take("origin", t)
            a = xy[:, 0] - origin[:, 0]
            b = xy[:, 1] - origin[:, 1]
            _, origin, direction, usable = self.points.rays(t, a, b)
            if self.scene.match(origin[usable], direction[usable])[0].any():
                return True
        return False

    def nothing_matched(self):
        """Why no matching ray found the high-poly surface, and what to change (world units)."""
        world = getattr(self.s2a, "world", self.s2a)
        low = world.target.name
        highs = ", ".join(repr(h.name) for h in world.highs)
        unit = self.unit
        head = f"no matching ray from {low!r} found the high-poly surface of {highs}, so nothing could be baked"
        if self._probe is None:
            return head
        p, origin, direction, usable = self._probe
        if not usable.any():
            return (f"{head}: the cage {world.cage.name!r} lies on {low!r} itself; move its vertices outwards, "
                    f"so that it encloses the high-poly surface")
        o, d = origin[usable], direction[usable]
        far = self._distances(o, d)
        if far.size:
            need = float(far.min()) * unit
            return (f"{head}: the nearest high-poly surface along the rays lies {need:.4g} from where they start, "
                    f"beyond the max ray distance {world.max_ray_distance:.4g}; raise the max ray distance above "
                    f"{need:.4g}, or set it to 0 (no limit)")
        back = self._distances(o, -d)
        if back.size:
            if world.cage is not None:
                return (f"{head}: the high-poly surface lies outside the cage {world.cage.name!r} (the rays go "
                        f"from the cage towards {low!r}); enlarge the cage so that it encloses the high-poly surface")
            gap = float(np.quantile(back, 0.99)) * unit + world.extrusion
            return (f"{head}: the high-poly surface lies outside {low!r}, up to {gap:.4g} above it along its "
                    f"normals, farther than the extrusion ({world.extrusion:.4g}) pushes the rays out; raise the "
                    f"extrusion above {gap:.4g}")
        return (f"{head}: no high-poly surface lies along {low!r}'s normals at all; the high-poly objects must "
                f"lie over {low!r}'s surface (move them onto it, or check that the right objects are selected)")

    def _distances(self, origins, directions):
        """Distances to the nearest high-poly surface along rays, no length limit (hits only)."""
        out = self.scene.match_scene.run(np.ascontiguousarray(origins, np.float32),
                                         np.ascontiguousarray(directions, np.float32),
                                         dists=np.full(len(origins), FAR, np.float32), output=True)
        return out["tfar"][out["primID"] >= 0].astype(np.float64)


__all__ = ["SelectedToActive", "as_list", "HighPolyStage", "HighPolyStart", "HighPolyScene", "DIRECTIONS_PER_POINT",
           "directions_per_point", "finish_report"]
