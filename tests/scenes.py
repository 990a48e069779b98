"""Small analytic scenes for the baker's tests, and their exact AO."""

import math

import numpy as np

from core import Mesh

QUAD = np.array([[0, 1, 2], [0, 2, 3]])


def plane(x0=0.0, y0=0.0, x1=1.0, y1=1.0, z=0.0, name="plane", uv=True, flip=False):
    P = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    F = QUAD[:, ::-1] if flip else QUAD
    UV = ((P[F][:, :, :2] - [x0, y0]) / [x1 - x0, y1 - y0]) if uv else None
    return Mesh(P, F, UV, name=name)


def box(lo, hi, name="box"):
    """A closed axis-aligned box, outward winding."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    P = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], float)
    F = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                  [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
    return Mesh(P, F, name=name)


def polygon_form_factor(x, verts):
    """Lambert's contour integral: the form factor from points x (m, 3) with normal +z to a planar
    polygon (k, 3) above their horizon, F = |sum_i gamma_i (n . unit(R_i x R_{i+1}))| / (2 pi)."""
    total = np.zeros(len(x))
    k = len(verts)
    for i in range(k):
        a = verts[i] - x
        b = verts[(i + 1) % k] - x
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        b /= np.linalg.norm(b, axis=1, keepdims=True)
        c = np.cross(a, b)
        gamma = np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1, 1))
        total += gamma * c[:, 2] / np.linalg.norm(c, axis=1)
    return np.abs(total) / (2 * math.pi)


def texel_mean(func, width, height, order=4, to_world=lambda u, v: (u, v)):
    """Mean of func(points (m, 3) on z = 0) over each texel of the unit UV square, by Gauss-Legendre."""
    g, w = np.polynomial.legendre.leggauss(order)
    g, w = (g + 1) / 2, w / 2
    out = np.zeros((height, width))
    for gy, wy in zip(g, w):
        for gx, wx in zip(g, w):
            u = (np.arange(width) + gx) / width
            v = (np.arange(height) + gy) / height
            U, V = np.meshgrid(u, v)
            X, Y = to_world(U, V)
            pts = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
            out += wx * wy * func(pts).reshape(height, width)
    return out
