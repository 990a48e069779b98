"""Exact ambient occlusion for scenes where it is known in closed form, to check the baker against.

A point on a plane (normal +z) under a planar polygon lying wholly above the plane's horizon sees the
polygon with Lambert's form factor F; with nothing else around, AO = 1 - F. Lambert's contour
integral gives F exactly for any polygon: F = |sum_i gamma_i (n . unit(R_i x R_{i+1}))| / (2 pi), with
R_i the unit vectors from the point to the vertices and gamma_i the angle between R_i and R_{i+1}.
"""

import math

import numpy as np


def polygon_form_factor(points, verts):
    """Form factor from points (m, 3), each with normal +z, to the polygon ``verts`` (k, 3) above them."""
    points = np.asarray(points, dtype=np.float64)
    verts = np.asarray(verts, dtype=np.float64)
    total = np.zeros(len(points))
    for i in range(len(verts)):
        a = verts[i] - points
        b = verts[(i + 1) % len(verts)] - points
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        b /= np.linalg.norm(b, axis=1, keepdims=True)
        c = np.cross(a, b)
        gamma = np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0))
        total += gamma * c[:, 2] / np.linalg.norm(c, axis=1)
    return np.abs(total) / (2.0 * math.pi)


def regular_polygon(radius, height, vertices, centre=(0.0, 0.0)):
    """The vertices (k, 3) of a regular polygon at z = height, as Blender's circle primitive makes it."""
    phi = 2.0 * math.pi * np.arange(vertices) / vertices
    return np.stack([centre[0] + radius * np.cos(phi), centre[1] + radius * np.sin(phi),
                     np.full(vertices, float(height))], axis=1)


def texel_mean(func, width, height, bounds=(0.0, 0.0, 1.0, 1.0), order=4):
    """Mean of ``func(points (m, 3) on z = 0)`` over each texel of a plane mapped onto the whole UV square.

    ``bounds`` (x0, y0, x1, y1) is the plane's extent in world space (u = 0 at x0, v = 0 at y0).
    Gauss-Legendre of ``order`` x ``order`` nodes per texel; returns (height, width), row 0 at v = 0.
    """
    x0, y0, x1, y1 = bounds
    g, w = np.polynomial.legendre.leggauss(order)
    g, w = (g + 1) / 2, w / 2
    out = np.zeros((height, width))
    for gy, wy in zip(g, w):
        for gx, wx in zip(g, w):
            U, V = np.meshgrid((np.arange(width) + gx) / width, (np.arange(height) + gy) / height)
            X, Y = x0 + (x1 - x0) * U, y0 + (y1 - y0) * V
            pts = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
            out += wx * wy * np.asarray(func(pts)).reshape(height, width)
    return out


def plane_under_polygon_ao(verts, width, height, bounds=(0.0, 0.0, 1.0, 1.0)):
    """Exact texel AO of a plane (mapped onto the whole UV square) under the polygon ``verts``."""
    return texel_mean(lambda p: 1.0 - polygon_form_factor(p, verts), width, height, bounds)


def box_on_plane_point_ao(points, lo, hi):
    """Exact AO of points (m, 3) on the plane z = 0 (normal +z) beside a box [lo, hi] resting on it.

    The box (lo[2] = 0) is convex, so from a point on the floor outside its footprint the occluded
    part of the hemisphere is the projection of the box's side faces that face the point, which do
    not overlap: F is the sum of their Lambert form factors (the top face faces away from every
    point below it). Points inside the footprint touch the box's bottom face: AO 0.
    """
    points = np.asarray(points, dtype=np.float64)
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    if z0 != 0.0:
        raise ValueError("the box must rest on the plane z = 0")
    faces = [  # (outward normal axis, sign, the face's corners in order)
        ((0, -1.0), [(x0, y0, 0), (x0, y1, 0), (x0, y1, z1), (x0, y0, z1)]),
        ((0, 1.0), [(x1, y0, 0), (x1, y0, z1), (x1, y1, z1), (x1, y1, 0)]),
        ((1, -1.0), [(x0, y0, 0), (x0, y0, z1), (x1, y0, z1), (x1, y0, 0)]),
        ((1, 1.0), [(x0, y1, 0), (x1, y1, 0), (x1, y1, z1), (x0, y1, z1)]),
    ]
    total = np.zeros(len(points))
    for (axis, sign), corners in faces:
        plane_at = corners[0][axis]
        facing = sign * (points[:, axis] - plane_at) > 0
        if facing.any():
            total[facing] += polygon_form_factor(points[facing], np.array(corners, dtype=np.float64))
    inside = (points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)
    return np.where(inside, 0.0, 1.0 - total)


def plane_beside_box_ao(lo, hi, width, height, bounds=(0.0, 0.0, 1.0, 1.0), order=6):
    """Exact texel AO of a plane (mapped onto the whole UV square) with the box [lo, hi] resting on it.

    The AO jumps from 0 to about 1/2 at the box's footprint, so texels that the footprint's edges cut
    are integrated piece by piece: Gauss-Legendre on each part between the edges (a rule across
    the jump would err by up to a node's weight times the jump).
    """
    x0, y0, x1, y1 = bounds
    g, w = np.polynomial.legendre.leggauss(order)
    g, w = (g + 1) / 2, w / 2

    def pieces(n, a, b, cuts):
        # per texel column/row: the sub-intervals between the cuts that fall inside it, in [0, 1]
        out = []
        for i in range(n):
            t0, t1 = a + (b - a) * i / n, a + (b - a) * (i + 1) / n
            edges = [t0] + sorted(c for c in cuts if t0 < c < t1) + [t1]
            out.append([((e0 - t0) / (t1 - t0), (e1 - t0) / (t1 - t0)) for e0, e1 in zip(edges[:-1], edges[1:])])
        return out

    px = pieces(width, x0, x1, (lo[0], hi[0]))
    py = pieces(height, y0, y1, (lo[1], hi[1]))
    out = np.zeros((height, width))
    for i in range(height):
        for j in range(width):
            total = 0.0
            for a0, a1 in px[j]:
                for b0, b1 in py[i]:
                    u = (j + a0 + (a1 - a0) * g) / width
                    v = (i + b0 + (b1 - b0) * g) / height
                    U, V = np.meshgrid(u, v)
                    pts = np.stack([x0 + (x1 - x0) * U.ravel(), y0 + (y1 - y0) * V.ravel(), np.zeros(U.size)], 1)
                    vals = box_on_plane_point_ao(pts, lo, hi).reshape(order, order)
                    total += (a1 - a0) * (b1 - b0) * float(w @ vals @ w)
            out[i, j] = total
    return out
