"""Rays: the Embree scenes of a bake, occlusion queries, contact probes, and the hook that sees every ray.

Every ray the baker traces goes through :class:`Tracer`, one call into embreex per chunk, timed
(wall and thread CPU seconds) so a bake can report how much of it was spent inside Embree. A caller
may pass ``on_rays`` to :func:`core.bake_ao`; it receives a :class:`RayBatch` after every call, which
is how the benchmark records a bake's own rays and how the tests check what the baker traces.

Ray origins are pushed off the surface along the geometric normal by :meth:`Tracer.offset`, which
grows with the scene's size and with the point's distance from the origin (float32 rays lose
absolute precision with both).
"""

import copy
import functools
import math
import time
from dataclasses import dataclass

import numpy as np

from . import ground as _ground
from ..geometry.mesh import corner_positions

#: Offsets off the surface: relative to the scene's bounding-box diagonal and to |position|.
EPS_SCENE = 1e-6
EPS_POSITION = 2.0 ** -18
#: Embree's largest useful ray length (float32).
FAR = 1e37


def falloff_visibility(distance, max_distance, power):
    """V of a ray that met an occluder at ``distance`` with a distance falloff of ``power`` > 0:
    1 - (1 - t / max_distance)^power, so a near occluder blocks fully and one at ``max_distance``
    not at all (a plain occluder, without falloff, gives V = 0)."""
    return 1.0 - np.clip(1.0 - np.asarray(distance, np.float64) / max_distance, 0.0, 1.0) ** power


@dataclass(frozen=True)
class RayBatch:
    """One call into Embree, as handed to an ``on_rays`` hook. Arrays are read-only views, valid
    during the call only (copy what you keep).

    origins, directions : (n, 3) float32; directions are not always unit length (see ``tfar``).
    tfar : (n,) float32, each ray's length in units of its direction (0 for a ray not traced because
        its direction points below the geometric surface; it counts as occluded).
    occluded : (n,) bool, Embree's answer, or the ground's for rays that cross it (before samples
        below the surface or in contact are counted as occluded).
    texels : (n,) int64, the flat texel index (row * width + column) each ray belongs to.
    samples : (n,) int64, each ray's sample index within its texel's replicate.
    seconds, cpu_seconds : wall and thread CPU time of the Embree call.
    replicate : which of the texels' independent replicates (see core.engine.estimators) the rays belong to.
    """

    origins: np.ndarray
    directions: np.ndarray
    tfar: np.ndarray
    occluded: np.ndarray
    texels: np.ndarray
    samples: np.ndarray
    seconds: float
    cpu_seconds: float
    replicate: int = 0


#: Whether the scene the bake's occlusion rays are traced in (:class:`Tracer`) is built in Embree's
#: robust mode. embreex's EmbreeScene() asks for it (RTC_SCENE_FLAG_ROBUST); Embree's own default is
#: off, and off it traced the bake's own occlusion rays 11-21% faster on this machine (one thread,
#: 256^2 bakes' rays replayed: Suzanne scene 201 -> 158 ns a ray, a 131k-triangle terrain 225 ->
#: 191, a 1M-triangle grid 344 -> 306), with the same occlusion answer for every one of their 6.4M
#: rays. What robust mode buys is watertight edges. From inside a closed sphere, rays in random
#: directions leaked through it 5 times in 8 million without it (57k triangles; 11 in 8 million at
#: 638k) and never with it, an AO bias of about 1e-6; rays aimed exactly at its shared edges and
#: vertices leak 9.4% of the time without it and 0.1% with it (tests/test_embree_upload.py). Sample
#: rays are not aimed at edges. Scenes whose rays start on surfaces on purpose (contact probes;
#: high-poly matching, where a low-poly lying on the high-poly surface must find it at distance 0)
#: stay robust.
OCCLUSION_ROBUST = False


def embree_scene(meshes, robust=True):
    """A committed Embree scene of ``meshes`` (one geometry), and its positions; ``robust``: Embree's
    robust mode (see :data:`OCCLUSION_ROBUST`)."""
    from embreex import rtcore_scene

    if len(meshes) == 1:  # no copies of one mesh's arrays (hundreds of MB for millions of triangles)
        positions, tris = meshes[0].positions, meshes[0].triangles
    else:
        positions = np.concatenate([m.positions for m in meshes])
        offsets = np.cumsum([0] + [len(m.positions) for m in meshes[:-1]])
        tris = np.concatenate([m.triangles + o for m, o in zip(meshes, offsets)])
    scene = rtcore_scene.EmbreeScene(robust=bool(robust))
    geometry = add_triangles(scene, positions, tris)
    # Commit (build the BVH) now, once, before any worker thread traces.
    scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32), query="OCCLUDED",
              dists=np.ones(1, np.float32))
    return scene, geometry, positions


def add_triangles(scene, positions, triangles):
    """Attach a triangle geometry of ``positions`` (V, 3) and ``triangles`` (T, 3) to an embreex
    scene not yet committed; returns what keeps it alive (or None).

    embreex's ``TriangleMesh`` copies the arrays into Embree element by element through Python
    indexing, about 1.4 us per triangle (1.4 s of a 1M-triangle bake, more than Embree's own BVH
    build). The same copy is done here with Embree's C API (``rtcSetNewGeometryBuffer`` and one
    memmove per buffer) on the library embreex itself loaded, see :mod:`core.tracing.embree_upload`;
    where that is not available (another platform's layout, an embreex that changed) the binding's
    own path is used, with the same result.
    """
    from . import embree_upload

    p32 = np.ascontiguousarray(positions, dtype=np.float32)
    t32 = np.ascontiguousarray(triangles, dtype=np.uint32)
    if embree_upload.available():
        embree_upload.attach_triangles(scene, p32, t32)
        return None
    from embreex.mesh_construction import TriangleMesh

    return TriangleMesh(scene, p32, t32.astype(np.int32))


def offset_points(points, normals, e, dtype=np.float64):
    """points + normals * e[:, None] as ``dtype`` (points, normals (n, 3), e (n,)), column by column
    (numpy's loops over an inner axis of 3 and a broadcast (n, 1) factor are several times slower);
    computed in float64 (or wider), then rounded, as the (n, 3) form."""
    out = np.empty((len(points), 3), dtype)
    for c in range(3):
        out[:, c] = np.asarray(points[:, c], np.float64) + normals[:, c] * e
    return out


class Tracer:
    """Occlusion queries against the committed Embree scene of the target and its occluders.

    Contact: a face of another object lying on the target's surface (a box resting on a floor) sits
    where the pushed-off ray origin cannot see it: the origin starts inside the box. Cycles, which
    starts rays on the surface and skips only the triangle they leave, finds that face at distance 0
    and calls the point occluded, which is right for a point in contact. To agree, samples are first
    probed against a second scene of the occluders alone with a ray of length 2 * offset crossing the
    surface along the normal: a hit means other geometry coincides with the surface there, and the
    sample is occluded in every direction.

    The ground (:mod:`core.tracing.ground`), when there is one, is asked after Embree for every ray the
    tracer is given, and joins the contact probes: every target and path sees it.

    Parameters
    ----------
    meshes : the target first, then its occluders (in the baker's normalised frame).
    ignore_backfaces, falloff, max_distance : as in :func:`core.bake_ao` (max_distance in the same frame).
    ground : None, or the height (in the same frame) of the analytic ground plane z = ground.
    scene : None, or a committed Embree scene of exactly ``meshes`` (one geometry, in their order) to
        trace in, instead of building one (a selected-to-active bake's matching scene).
    """

    def __init__(self, meshes, ignore_backfaces=False, falloff=0.0, max_distance=float("inf"), ground=None,
                 scene=None):
        if scene is None:
            self.scene, self._mesh, _ = embree_scene(meshes, robust=OCCLUSION_ROBUST)
        else:
            self.scene, self._mesh = scene, None
        self._meshes = list(meshes)
        self.contact_scene = embree_scene(meshes[1:])[0] if len(meshes) > 1 else None
        if len(meshes) > 1:
            corners = np.concatenate([corner_positions(m.positions, m.triangles) for m in meshes[1:]])  # (m, 3, 3)
            self._occ_lo, self._occ_hi = corners.min(axis=1), corners.max(axis=1)
        # Column by column: numpy's reductions over the long axis of a (V, 3) array are slow.
        lo = np.array([min(m.positions[:, k].min() for m in meshes) for k in range(3)])
        hi = np.array([max(m.positions[:, k].max() for m in meshes) for k in range(3)])
        self.extent = float(np.linalg.norm(hi - lo))
        self.ignore_backfaces = ignore_backfaces
        self.falloff = falloff
        self.max_distance = max_distance
        self.tfar = np.float32(min(max_distance, FAR))
        #: Only occlusion is asked (not hit distances): one query per ray.
        self.simple = not ignore_backfaces and falloff == 0
        #: Benchmarks only: every query answers "not occluded" without calling Embree, so that a bake
        #: measures its own work alone (``bake_ao(..., constant_answer=True)``; the result is not AO).
        self.constant_answer = False
        self.ground = None if ground is None else float(ground)

    def sharing(self, ignore_backfaces=False, falloff=0.0, max_distance=float("inf"), ground=None):
        """A tracer of the same meshes (the same Embree scenes, built once) asked with other settings:
        the quantities of one bake whose rays see the same meshes (:func:`core.bake_maps`)."""
        out = copy.copy(self)
        out.ignore_backfaces, out.falloff, out.max_distance = ignore_backfaces, falloff, max_distance
        out.tfar = np.float32(min(max_distance, FAR))
        out.simple = not ignore_backfaces and falloff == 0
        out.constant_answer = False
        out.ground = None if ground is None else float(ground)
        return out

    def hold(self, meshes):
        """Hold ``meshes`` (the same bits as the ones this tracer was built from) instead of those: a
        worker that keeps this tracer for its next bake lets the last bake's meshes go."""
        self._meshes = list(meshes)

    @functools.cached_property
    def face_normals(self):
        """(T, 3) unit face normals of every triangle of the scene (asked for by back-face culling only)."""
        return np.concatenate([m.face_normals for m in self._meshes])

    @property
    def touches(self):
        """Whether anything can touch the target (occluders or the ground): contact probes are needed."""
        return self.contact_scene is not None or self.ground is not None

    def offset(self, max_abs):
        """Distance to push ray origins off the surface, given each point's largest |coordinate|."""
        return EPS_SCENE * self.extent + EPS_POSITION * max_abs

    def point_offset(self, points):
        """:meth:`offset` of points (n, 3): their largest |coordinate| as elementwise maxima of the
        columns (numpy's max over an axis of 3 is several times slower)."""
        a = np.abs(points)
        return self.offset(np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2]))

    def occluded(self, origins, directions, tfar):
        """The occlusion answer per ray (n,) bool: Embree's, or the ground's where the ray crosses it
        (those rays are not handed to Embree); ``tfar`` (n,) float32 may be overwritten."""
        if self.constant_answer:
            return np.zeros(len(tfar), bool)
        if self.ground is None:
            return self.scene.run(origins, directions, query="OCCLUDED", dists=tfar) >= 0
        out = _ground.crossing(origins[:, 2], directions[:, 2], tfar, self.ground, True,
                               unlimited=not math.isfinite(self.max_distance))
        rest = np.flatnonzero(~out)
        if len(rest) == len(out):
            return self.scene.run(origins, directions, query="OCCLUDED", dists=tfar) >= 0
        if len(rest):
            out[rest] = self.scene.run(origins[rest], directions[rest], query="OCCLUDED", dists=tfar[rest]) >= 0
        return out

    def near_occluders(self, lo, hi):
        """Per box [lo, hi] (n, 3), whether some occluder triangle's bounding box overlaps it: a
        cheap, conservative test of where contact probes can find anything."""
        lo, hi = np.atleast_2d(lo), np.atleast_2d(hi)
        out = np.zeros(len(lo), bool)
        if self.ground is not None:
            out |= (lo[:, 2] <= self.ground) & (hi[:, 2] >= self.ground)
        if self.contact_scene is None or not len(lo):
            return out
        # Only occluders overlapping the boxes' union can overlap any of them.
        ulo, uhi = lo.min(axis=0), hi.max(axis=0)
        cand = np.flatnonzero(np.all((self._occ_lo <= uhi) & (self._occ_hi >= ulo), axis=1))
        for c0 in range(0, len(cand), 256):
            c = cand[c0:c0 + 256]
            out |= np.any(np.all((self._occ_lo[c][None] <= hi[:, None]) & (self._occ_hi[c][None] >= lo[:, None]),
                                 axis=2), axis=1)
        return out

    def contact(self, points, normals, lengths=None):
        """Per point (n, 3), whether another object's surface (or the ground) crosses the segment of
        length 2 * offset through it along its unit geometric normal (n, 3): whether something
        touches it."""
        points = np.asarray(points, dtype=np.float64)
        normals = np.asarray(normals)
        e = self.point_offset(points) if lengths is None else np.asarray(lengths, np.float64)
        if self.contact_scene is None:
            hit = np.zeros(len(points), bool)
        else:
            below = offset_points(points, normals, -e, np.float32)
            hit = self.contact_scene.run(below, np.ascontiguousarray(normals, dtype=np.float32), query="OCCLUDED",
                                         dists=(2.0 * e).astype(np.float32)) >= 0
        if self.ground is not None:
            hit |= _ground.touching(points[:, 2], normals[:, 2], e, self.ground)
        return hit

    def visibility(self, origins, directions, tfar):
        """Per ray, 1 for unoccluded within its length, 0 for occluded, between with falloff; rays whose
        ``tfar`` is 0 are not traced (they count as occluded). Used when hit distances matter."""
        if self.constant_answer:
            return np.where(np.asarray(tfar) > 0, 1.0, 0.0)
        org = np.asarray(origins, dtype=np.float64)
        dirs = np.asarray(directions, dtype=np.float64)
        n = len(org)
        length = np.linalg.norm(dirs, axis=1)
        dirs = dirs / np.where(length > 0, length, 1.0)[:, None]
        reach = np.asarray(tfar, dtype=np.float64) * length  # world length of each ray
        o32 = np.ascontiguousarray(org, dtype=np.float32)
        d32 = np.ascontiguousarray(dirs, dtype=np.float32)
        remaining = reach.astype(np.float32)
        travelled = np.zeros(n)
        vis = np.where(reach > 0, 1.0, 0.0)
        todo = np.flatnonzero(reach > 0)
        floor = None
        if self.ground is not None:
            # Embree looks no farther than the ground; a ray that meets nothing before it meets the ground.
            endless = np.where(reach > 0, np.inf, 0.0) if not math.isfinite(self.max_distance) else reach
            floor = _ground.distance(org[:, 2], dirs[:, 2], endless, self.ground, not self.ignore_backfaces)
            reach = np.minimum(reach, floor)
            remaining = reach.astype(np.float32)
            met = np.zeros(n, bool)
        for _ in range(64):
            if not len(todo):
                break
            out = self.scene.run(o32[todo], d32[todo], dists=remaining[todo].copy(), output=True)
            prim = out["primID"]
            hit = prim >= 0
            t = out["tfar"].astype(np.float64)
            if self.ignore_backfaces:
                back = hit & (np.einsum("ij,ij->i", self.face_normals[np.maximum(prim, 0)], dirs[todo]) > 0)
            else:
                back = np.zeros_like(hit)
            front = hit & ~back
            idx = todo[front]
            dist = travelled[idx] + t[front]
            vis[idx] = falloff_visibility(dist, self.max_distance, self.falloff) if self.falloff > 0 else 0.0
            if floor is not None:
                met[idx] = True
            # Back-face hits: continue from just past the hit point with the distance left.
            cont = todo[back]
            if len(cont):
                hit_at = org[cont] + dirs[cont] * (travelled[cont] + t[back])[:, None]
                step = t[back] + self.point_offset(hit_at)
                travelled[cont] += step
                o32[cont] = (org[cont] + dirs[cont] * travelled[cont, None]).astype(np.float32)
                remaining[cont] = np.maximum(reach[cont] - travelled[cont], 0).astype(np.float32)
                cont = cont[remaining[cont] > 0]
            todo = cont
        if floor is not None:
            down = np.flatnonzero(~met & np.isfinite(floor) & (vis > 0))
            if len(down):
                vis[down] = (falloff_visibility(floor[down], self.max_distance, self.falloff) if self.falloff > 0
                             else 0.0)
        return vis


class Clock:
    """Wall and thread-CPU seconds spent in a block, added to running totals."""

    __slots__ = ("wall", "cpu", "last_wall", "last_cpu", "_w", "_c")

    def __init__(self):
        self.wall = self.cpu = self.last_wall = self.last_cpu = 0.0

    def __enter__(self):
        self._w = time.perf_counter()
        self._c = time.thread_time()
        return self

    def __exit__(self, *exc):
        self.last_wall = time.perf_counter() - self._w
        self.last_cpu = time.thread_time() - self._c
        self.wall += self.last_wall
        self.cpu += self.last_cpu
        return False


__all__ = ["RayBatch", "Tracer", "falloff_visibility", "add_triangles", "embree_scene", "offset_points", "OCCLUSION_ROBUST", "EPS_SCENE", "EPS_POSITION", "FAR"]
