"""The matching rays' starts: along the low-poly's normal pushed out by the extrusion, or from the cage; and
the automatic extrusion, measured from the meshes (see :mod:`core.highpoly`)."""

from dataclasses import dataclass

import numpy as np

from ..montecarlo import warps
from ..geometry.mesh import Mesh, corner_positions
from ..tracing.tracer import FAR


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
    from ..montecarlo.hashing import hash_uniform

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


__all__ = [
    "EXTRUSION_POINTS", "EXTRUSION_SLACK", "EXTRUSION_STEPS", "AutoExtrusion", "surface_points", "auto_extrusion",
    "extruded", "towards"
]
