"""Small analytic scenes for the baker's tests, and their exact AO."""

import numpy as np

from core import Mesh
from core.montecarlo.analytic import polygon_form_factor, texel_mean  # noqa: F401  (the tests import them from here)

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

