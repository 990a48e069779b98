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
