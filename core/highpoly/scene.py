"""The high-poly scene: the matching rays' nearest hits, the AO rays from them, contact with the ground
and the occluders, and the low-poly's points the matching rays start from."""

import numpy as np

from ..tracing import ground as _ground
from ..geometry.mesh import Mesh, corner_positions
from ..tracing.tracer import FAR, Tracer, embree_scene
from .extrusion import extruded, towards


#: High-poly meshes of at least this many triangles, with nothing else occluding, trace their AO rays
#: in the robust matching scene instead of a second, fast one (:class:`HighPolyScene`).
ONE_SCENE_TRIANGLES = 1 << 20


def concatenate(meshes, name):
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
        self.high = high = concatenate(highs, "high-poly")
        # Matching: the high-poly meshes alone, in Embree's robust mode (a low-poly lying on the
        # high-poly surface starts its rays on it, see core.tracing.tracer.OCCLUSION_ROBUST).
        self.match_scene = s2a.matching_scene()
        # Occlusion: the high-poly meshes and the occluders, as one mesh (Tracer's contact scene is for a
        # single target; contact here is per high-poly mesh, below).
        if not occluding:
            occluders, ground = [], None
        if occluders or high.triangle_count < ONE_SCENE_TRIANGLES:
            everything = concatenate(highs + list(occluders), "high-poly and occluders")
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


__all__ = ["ONE_SCENE_TRIANGLES", "concatenate", "HighPolyScene", "LowPoints"]
